r"""The model callbacks of every mechanism, written once and read from the parameter vector.

Each function here is one ``fastvi.Model`` callback; what the mechanism is — its rows,
loads and linear potential — comes from ``params`` in the layout of
:mod:`fastvi.bodies.packing`. The functions live in a source file, so numba caches their
compiled form on disk, and a new mechanism of the same sizes ``(n, m)`` compiles nothing.

Conventions: a row or load record starts at float ``r`` (``l``) of ``params``; its bodies are
``(oa, na)`` and ``(ob, nb)`` (first coordinate, number of 3-vector slots: 4 for a rigid
body, 1 for a point mass, 0 for the ground); ``_expr`` evaluates a vector expression
``Σ_j w_j Q_j + c``. Nothing allocates: vectors are tuples.

The helpers are ``register_jitable``: compiled into the callbacks, plain Python otherwise.
"""

from __future__ import annotations

import math

from numba.extending import register_jitable

from .packing import (DRIVE_ANGLE, FORCE, H_LOADS, H_NLOADS, H_ROWS, HEADER, L_C, L_K, L_LAW,
                      L_OFFA, L_REST, L_V1, L_V2, L_V3, LOAD_W, R_C0, R_KIND, R_LAW, R_OFFA, R_U1,
                      R_U2, R_W1, R_W2, ROTARY_SPRING, ROW_W, SLOTS, SPRING, STATIC, TORQUE,
                      VECTOR_SPRING)


# ============================================================================ small pieces
@register_jitable
def _law(p, b, t):
    """θ(t) and θ'(t) of the profile at ``p[b:b+6]`` (``½ α`` is stored)."""
    arg = p[b + 4] * t + p[b + 5]
    th = p[b] + p[b + 1] * t + p[b + 2] * t * t + p[b + 3] * math.sin(arg)
    dth = p[b + 1] + 2.0 * p[b + 2] * t + p[b + 3] * p[b + 4] * math.cos(arg)
    return th, dth


@register_jitable
def _slot_col(j, oa, na, ob, nb):
    """First coordinate of slot ``j`` (0–3: body A, 4–7: body B), or −1 if the body lacks it."""
    k = j & 3
    if j < 4:
        return oa + 3 * k if k < na else -1
    return ob + 3 * k if k < nb else -1


@register_jitable
def _expr(q, p, e, oa, na, ob, nb, with_constant):
    """``Σ_j w_j Q_j (+ c)``: the vector expression at ``p[e:e+EXPR]`` evaluated on ``q``
    (on a velocity, without the constant, it is the expression's rate)."""
    x = y = z = 0.0
    if with_constant:
        x, y, z = p[e + SLOTS], p[e + SLOTS + 1], p[e + SLOTS + 2]
    for j in range(SLOTS):
        w = p[e + j]
        if w != 0.0:
            o = _slot_col(j, oa, na, ob, nb)
            if o >= 0:
                x += w * q[o]
                y += w * q[o + 1]
                z += w * q[o + 2]
    return x, y, z


@register_jitable
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@register_jitable
def _dot_grad(p, bu, bw, j, U, W):
    """``∂(U·W)/∂Q_j = u_j W + w_j U``."""
    u, w = p[bu + j], p[bw + j]
    return u * W[0] + w * U[0], u * W[1] + w * U[1], u * W[2] + w * U[2]


@register_jitable
def _head(p, r, off):
    """``(oa, na, ob, nb)`` of the record at ``r`` whose body fields start at ``r + off``."""
    return int(p[r + off]), int(p[r + off + 1]), int(p[r + off + 2]), int(p[r + off + 3])


# ============================================================================ constraints
@register_jitable
def _factors(p, r, kind, t):
    """``(f₁, f₂, s)`` of a row and their time derivatives."""
    if kind == STATIC:
        return 1.0, 0.0, 0.0, 0.0, 0.0, 0.0
    th, dth = _law(p, r + R_LAW, t)
    if kind == DRIVE_ANGLE:
        c, s = math.cos(th), math.sin(th)
        return c, -s, 0.0, -s * dth, -c * dth, 0.0
    return 1.0, 0.0, th, 0.0, 0.0, dth


@register_jitable
def _terms(q, p, r, kind, oa, na, ob, nb):
    """The expressions ``U₁, W₁, U₂, W₂`` of a row at ``q`` (the second pair only for a driven
    angle)."""
    U1 = _expr(q, p, r + R_U1, oa, na, ob, nb, True)
    W1 = _expr(q, p, r + R_W1, oa, na, ob, nb, True)
    U2 = W2 = (0.0, 0.0, 0.0)
    if kind == DRIVE_ANGLE:
        U2 = _expr(q, p, r + R_U2, oa, na, ob, nb, True)
        W2 = _expr(q, p, r + R_W2, oa, na, ob, nb, True)
    return U1, W1, U2, W2


@register_jitable
def _row(p, a, t):
    """``(r, kind, oa, na, ob, nb, factors)`` of row ``a`` at time ``t``."""
    r = int(p[H_ROWS]) + a * ROW_W
    kind = int(p[r + R_KIND])
    oa, na, ob, nb = _head(p, r, R_OFFA)
    return r, kind, oa, na, ob, nb, _factors(p, r, kind, t)


@register_jitable
def _constraint(t, q, p, out):
    for a in range(out.shape[0]):
        r, kind, oa, na, ob, nb, f = _row(p, a, t)
        U1, W1, U2, W2 = _terms(q, p, r, kind, oa, na, ob, nb)
        out[a] = f[0] * _dot(U1, W1) + f[1] * _dot(U2, W2) + p[r + R_C0] - f[2]


@register_jitable
def _constraint_rate(t, q, p, out):
    """``∂g/∂t``: zero but for the driven rows."""
    for a in range(out.shape[0]):
        r, kind, oa, na, ob, nb, f = _row(p, a, t)
        if kind == STATIC:
            out[a] = 0.0
            continue
        U1, W1, U2, W2 = _terms(q, p, r, kind, oa, na, ob, nb)
        out[a] = f[3] * _dot(U1, W1) + f[4] * _dot(U2, W2) - f[5]


@register_jitable
def _jacobian(t, q, p, out):
    # writes only the slots with a non-zero weight: the declared pattern (packing.row_columns)
    for a in range(out.shape[0]):
        r, kind, oa, na, ob, nb, f = _row(p, a, t)
        U1, W1, U2, W2 = _terms(q, p, r, kind, oa, na, ob, nb)
        for j in range(SLOTS):
            col = _slot_col(j, oa, na, ob, nb)
            if col < 0 or (p[r + R_U1 + j] == 0.0 and p[r + R_W1 + j] == 0.0
                           and p[r + R_U2 + j] == 0.0 and p[r + R_W2 + j] == 0.0):
                continue
            g1 = _dot_grad(p, r + R_U1, r + R_W1, j, U1, W1)
            g2 = _dot_grad(p, r + R_U2, r + R_W2, j, U2, W2)
            for c in range(3):
                out[a, col + c] = f[0] * g1[c] + f[1] * g2[c]


@register_jitable
def _add_bilinear(p, bu, bw, s, oa, na, ob, nb, out):
    """``out += s ∇²(U·W)``: ``s (u_i w_j + w_i u_j) 1₃`` on the slot blocks (i, j)."""
    for i in range(SLOTS):
        ui = p[bu + i]
        ci = _slot_col(i, oa, na, ob, nb)
        if ui == 0.0 or ci < 0:
            continue
        for j in range(SLOTS):
            wj = p[bw + j]
            cj = _slot_col(j, oa, na, ob, nb)
            if wj == 0.0 or cj < 0:
                continue
            h = s * ui * wj
            for c in range(3):
                out[ci + c, cj + c] += h
                out[cj + c, ci + c] += h


@register_jitable
def _constraint_hessian(t, q, eta, p, out):
    out[:, :] = 0.0
    for a in range(eta.shape[0]):
        if eta[a] == 0.0:
            continue
        r, kind, oa, na, ob, nb, f = _row(p, a, t)
        _add_bilinear(p, r + R_U1, r + R_W1, eta[a] * f[0], oa, na, ob, nb, out)
        if kind == DRIVE_ANGLE:
            _add_bilinear(p, r + R_U2, r + R_W2, eta[a] * f[1], oa, na, ob, nb, out)


# ============================================================================ loads
@register_jitable
def _angle(q, p, l, oa, na, ob, nb):
    """The rotary spring's state: ``U_x = c₁`` (in A), ``U_y = c₂`` (in A), ``W = b₁`` (in B),
    ``x = c₁·b₁``, ``y = c₂·b₁`` and the angle ``δ = θ − θ₀`` wrapped to (−π, π]."""
    Ux = _expr(q, p, l + L_V1, oa, na, ob, nb, True)
    Uy = _expr(q, p, l + L_V2, oa, na, ob, nb, True)
    W = _expr(q, p, l + L_V3, oa, na, ob, nb, True)
    x, y = _dot(Ux, W), _dot(Uy, W)
    c0, s0 = math.cos(p[l + L_REST]), math.sin(p[l + L_REST])
    delta = math.atan2(y * c0 - x * s0, x * c0 + y * s0)
    return Ux, Uy, W, x, y, delta


@register_jitable
def _angle_grad(p, l, j, st):
    """``∂θ/∂Q_j = (x ∂y − y ∂x)/ρ²`` on slot ``j``."""
    Ux, Uy, W, x, y, _ = st
    gx = _dot_grad(p, l + L_V1, l + L_V3, j, Ux, W)
    gy = _dot_grad(p, l + L_V2, l + L_V3, j, Uy, W)
    r2 = x * x + y * y
    return (x * gy[0] - y * gx[0]) / r2, (x * gy[1] - y * gx[1]) / r2, (x * gy[2] - y * gx[2]) / r2


@register_jitable
def _angle_hess(p, l, i, j, a, b, st):
    r"""``∂²θ/∂(Q_i)_a ∂(Q_j)_b`` with ``θ = atan2(y, x)``:
    ``[∂_i y ∂_j x − ∂_i x ∂_j y + x ∂_ij y − y ∂_ij x]/ρ² − 2 (x ∂_i y − y ∂_i x)(x ∂_j x + y ∂_j y)/ρ⁴``."""
    Ux, Uy, W, x, y, _ = st
    gxi = _dot_grad(p, l + L_V1, l + L_V3, i, Ux, W)[a]
    gyi = _dot_grad(p, l + L_V2, l + L_V3, i, Uy, W)[a]
    gxj = _dot_grad(p, l + L_V1, l + L_V3, j, Ux, W)[b]
    gyj = _dot_grad(p, l + L_V2, l + L_V3, j, Uy, W)[b]
    r2 = x * x + y * y
    h = (gyi * gxj - gxi * gyj) / r2 - 2.0 * (x * gyi - y * gxi) * (x * gxj + y * gyj) / (r2 * r2)
    if a == b:
        w = l + L_V3
        hx = p[l + L_V1 + i] * p[w + j] + p[w + i] * p[l + L_V1 + j]
        hy = p[l + L_V2 + i] * p[w + j] + p[w + i] * p[l + L_V2 + j]
        h += (x * hy - y * hx) / r2
    return h


@register_jitable
def _angle_rate(p, l, v, oa, na, ob, nb, st):
    """``θ̇ = Σ_j ∂θ/∂Q_j · Q̇_j``."""
    acc = 0.0
    for j in range(SLOTS):
        o = _slot_col(j, oa, na, ob, nb)
        if o >= 0:
            g = _angle_grad(p, l, j, st)
            acc += g[0] * v[o] + g[1] * v[o + 1] + g[2] * v[o + 2]
    return acc


@register_jitable
def _spring_state(q, p, l, oa, na, ob, nb):
    """``r = x_A − x_B`` and ``|r|``."""
    r = _expr(q, p, l + L_V1, oa, na, ob, nb, True)
    return r, math.sqrt(_dot(r, r))


@register_jitable
def _load(p, k):
    """``(l, kind, oa, na, ob, nb)`` of load ``k``."""
    l = int(p[H_LOADS]) + k * LOAD_W
    oa, na, ob, nb = _head(p, l, L_OFFA)
    return l, int(p[l]), oa, na, ob, nb


@register_jitable
def _elastic(p, l, kind):
    """A spring with a stiffness (it enters the potential)."""
    return p[l + L_K] != 0.0 and kind != TORQUE and kind != FORCE


@register_jitable
def _add_weighted(p, l, oa, na, ob, nb, K, out):
    """``out += w_i w_j K`` on every slot block (i, j) of the spring's ``r``, ``K`` a 3×3
    matrix as a 9-tuple (row major)."""
    for i in range(SLOTS):
        wi = p[l + L_V1 + i]
        ci = _slot_col(i, oa, na, ob, nb)
        if wi == 0.0 or ci < 0:
            continue
        for j in range(SLOTS):
            wj = p[l + L_V1 + j]
            cj = _slot_col(j, oa, na, ob, nb)
            if wj == 0.0 or cj < 0:
                continue
            for a in range(3):
                for b in range(3):
                    out[ci + a, cj + b] += wi * wj * K[3 * a + b]


@register_jitable
def _add_angle_blocks(p, l, oa, na, ob, nb, st, v, alpha, beta, gamma, out):
    """``out += α ∇θ ∇θᵀ + β ∇²θ + γ ∇θ (∇²θ v)ᵀ`` for a rotary spring's angle."""
    for i in range(SLOTS):
        ci = _slot_col(i, oa, na, ob, nb)
        if ci < 0:
            continue
        gi = _angle_grad(p, l, i, st)
        for j in range(SLOTS):
            cj = _slot_col(j, oa, na, ob, nb)
            if cj < 0:
                continue
            gj = _angle_grad(p, l, j, st)
            for b in range(3):
                hv = 0.0  # (∇²θ v)_(j, b)
                if gamma != 0.0:
                    for kk in range(SLOTS):
                        ck = _slot_col(kk, oa, na, ob, nb)
                        if ck >= 0:
                            for c in range(3):
                                hv += _angle_hess(p, l, j, kk, b, c, st) * v[ck + c]
                for a in range(3):
                    h = _angle_hess(p, l, i, j, a, b, st) if beta != 0.0 else 0.0
                    out[ci + a, cj + b] += alpha * gi[a] * gj[b] + beta * h + gamma * gi[a] * hv


@register_jitable
def _add_slots(p, base, oa, na, ob, nb, f, s, out):
    """``out[slot j] += s w_j f`` for the weights ``w`` at ``p[base:]``."""
    for j in range(SLOTS):
        w = p[base + j]
        o = _slot_col(j, oa, na, ob, nb)
        if w != 0.0 and o >= 0:
            for c in range(3):
                out[o + c] += s * w * f[c]


@register_jitable
def _add_angle_grad(p, l, oa, na, ob, nb, st, s, out):
    """``out += s ∇θ``."""
    for j in range(SLOTS):
        o = _slot_col(j, oa, na, ob, nb)
        if o >= 0:
            g = _angle_grad(p, l, j, st)
            for c in range(3):
                out[o + c] += s * g[c]


@register_jitable
def _potential(q, p):
    acc = 0.0
    for i in range(q.shape[0]):
        acc += p[HEADER + i] * q[i]
    for k in range(int(p[H_NLOADS])):
        l, kind, oa, na, ob, nb = _load(p, k)
        if not _elastic(p, l, kind):
            continue
        if kind == ROTARY_SPRING:
            ext = _angle(q, p, l, oa, na, ob, nb)[5]
        else:
            length = _spring_state(q, p, l, oa, na, ob, nb)[1]
            ext = length - p[l + L_REST] if kind == SPRING else length
        acc += 0.5 * p[l + L_K] * ext * ext
    return acc


@register_jitable
def _potential_grad(q, p, out):
    for i in range(q.shape[0]):
        out[i] = p[HEADER + i]
    for k in range(int(p[H_NLOADS])):
        l, kind, oa, na, ob, nb = _load(p, k)
        if not _elastic(p, l, kind):
            continue
        stiff = p[l + L_K]
        if kind == ROTARY_SPRING:
            st = _angle(q, p, l, oa, na, ob, nb)
            _add_angle_grad(p, l, oa, na, ob, nb, st, stiff * st[5], out)
            continue
        r, length = _spring_state(q, p, l, oa, na, ob, nb)
        coef = stiff * (1.0 - p[l + L_REST] / length) if kind == SPRING else stiff
        _add_slots(p, l + L_V1, oa, na, ob, nb, r, coef, out)


@register_jitable
def _potential_hessian(q, p, out):
    out[:, :] = 0.0
    for k in range(int(p[H_NLOADS])):
        l, kind, oa, na, ob, nb = _load(p, k)
        if not _elastic(p, l, kind):
            continue
        stiff = p[l + L_K]
        if kind == ROTARY_SPRING:
            st = _angle(q, p, l, oa, na, ob, nb)
            _add_angle_blocks(p, l, oa, na, ob, nb, st, q, stiff, stiff * st[5], 0.0, out)
            continue
        r, length = _spring_state(q, p, l, oa, na, ob, nb)
        # k [(1 − L/|r|) 1 + (L/|r|³) r rᵀ]; k 1 for a zero-length spring
        rest = p[l + L_REST] if kind == SPRING else 0.0
        iso = stiff * (1.0 - rest / length) if kind == SPRING else stiff
        rad = stiff * rest / (length * length * length) if kind == SPRING else 0.0
        K = (iso + rad * r[0] * r[0], rad * r[0] * r[1], rad * r[0] * r[2],
             rad * r[1] * r[0], iso + rad * r[1] * r[1], rad * r[1] * r[2],
             rad * r[2] * r[0], rad * r[2] * r[1], iso + rad * r[2] * r[2])
        _add_weighted(p, l, oa, na, ob, nb, K, out)


@register_jitable
def _applied(p, l, t):
    """``s(t) f`` of a force or torque."""
    s = _law(p, l + L_LAW, t)[0]
    b = l + L_V1 + SLOTS
    return s * p[b], s * p[b + 1], s * p[b + 2]


@register_jitable
def _force(t, q, v, p, out):
    for i in range(q.shape[0]):
        out[i] = 0.0
    for k in range(int(p[H_NLOADS])):
        l, kind, oa, na, ob, nb = _load(p, k)
        if kind == TORQUE:  # ½ τ × d_I on each director
            fx, fy, fz = _applied(p, l, t)
            for d in range(1, 4):
                o = oa + 3 * d
                out[o] += 0.5 * (fy * q[o + 2] - fz * q[o + 1])
                out[o + 1] += 0.5 * (fz * q[o] - fx * q[o + 2])
                out[o + 2] += 0.5 * (fx * q[o + 1] - fy * q[o])
            continue
        if kind == FORCE:  # (f, X₁ f, X₂ f, X₃ f) on body A
            _add_slots(p, l + L_V1, oa, na, ob, nb, _applied(p, l, t), 1.0, out)
            continue
        damp = p[l + L_C]
        if damp == 0.0:
            continue
        if kind == ROTARY_SPRING:
            st = _angle(q, p, l, oa, na, ob, nb)
            _add_angle_grad(p, l, oa, na, ob, nb, st, -damp * _angle_rate(p, l, v, oa, na, ob, nb, st), out)
            continue
        r, length = _spring_state(q, p, l, oa, na, ob, nb)
        rd = _expr(v, p, l + L_V1, oa, na, ob, nb, False)
        if kind == SPRING:  # along the line: −c (r·ṙ/|r|²) r
            _add_slots(p, l + L_V1, oa, na, ob, nb, r, -damp * _dot(r, rd) / (length * length), out)
        else:
            _add_slots(p, l + L_V1, oa, na, ob, nb, rd, -damp, out)


@register_jitable
def _force_jacobian(t, q, v, p, out, wrt_v):
    """``∂F/∂q`` (``wrt_v`` false) or ``∂F/∂v``."""
    out[:, :] = 0.0
    for k in range(int(p[H_NLOADS])):
        l, kind, oa, na, ob, nb = _load(p, k)
        if kind == TORQUE:
            if wrt_v:
                continue
            fx, fy, fz = _applied(p, l, t)
            for d in range(1, 4):  # ∂(½ τ × d)/∂d = ½ τ̂
                o = oa + 3 * d
                out[o, o + 1] += -0.5 * fz
                out[o, o + 2] += 0.5 * fy
                out[o + 1, o] += 0.5 * fz
                out[o + 1, o + 2] += -0.5 * fx
                out[o + 2, o] += -0.5 * fy
                out[o + 2, o + 1] += 0.5 * fx
            continue
        damp = p[l + L_C]
        if kind == FORCE or damp == 0.0:
            continue
        if kind == ROTARY_SPRING:
            st = _angle(q, p, l, oa, na, ob, nb)
            if wrt_v:  # −c ∇θ ∇θᵀ
                _add_angle_blocks(p, l, oa, na, ob, nb, st, v, -damp, 0.0, 0.0, out)
            else:  # −c [θ̇ ∇²θ + ∇θ (∇²θ v)ᵀ]
                rate = _angle_rate(p, l, v, oa, na, ob, nb, st)
                _add_angle_blocks(p, l, oa, na, ob, nb, st, v, 0.0, -damp * rate, -damp, out)
            continue
        if kind == VECTOR_SPRING:  # −c ṙ
            if wrt_v:
                _add_weighted(p, l, oa, na, ob, nb, (-damp, 0.0, 0.0, 0.0, -damp, 0.0, 0.0, 0.0, -damp), out)
            continue
        r, length = _spring_state(q, p, l, oa, na, ob, nb)
        rd = _expr(v, p, l + L_V1, oa, na, ob, nb, False)
        l2 = length * length
        if wrt_v:  # −c r rᵀ/|r|²
            c = -damp / l2
            K = (c * r[0] * r[0], c * r[0] * r[1], c * r[0] * r[2], c * r[1] * r[0], c * r[1] * r[1],
                 c * r[1] * r[2], c * r[2] * r[0], c * r[2] * r[1], c * r[2] * r[2])
        else:  # −c [(r ṙᵀ + (r·ṙ) 1)/|r|² − 2 (r·ṙ) r rᵀ/|r|⁴]
            c, rr = -damp / l2, _dot(r, rd)
            e = -2.0 * rr / l2
            K = (c * (r[0] * rd[0] + rr + e * r[0] * r[0]), c * (r[0] * rd[1] + e * r[0] * r[1]),
                 c * (r[0] * rd[2] + e * r[0] * r[2]), c * (r[1] * rd[0] + e * r[1] * r[0]),
                 c * (r[1] * rd[1] + rr + e * r[1] * r[1]), c * (r[1] * rd[2] + e * r[1] * r[2]),
                 c * (r[2] * rd[0] + e * r[2] * r[0]), c * (r[2] * rd[1] + e * r[2] * r[1]),
                 c * (r[2] * rd[2] + rr + e * r[2] * r[2]))
        _add_weighted(p, l, oa, na, ob, nb, K, out)


# ============================================================================ the callbacks
# Two spellings each: without the time (an autonomous mechanism) and with it first
# (``time_dependent=True``: a mechanism with a drive); fastvi.Model picks by signature.
def potential(q, p):
    return _potential(q, p)


def potential_t(t, q, p):
    return _potential(q, p)


def potential_grad(q, p, out):
    _potential_grad(q, p, out)


def potential_grad_t(t, q, p, out):
    _potential_grad(q, p, out)


def potential_hessian(q, p, out):
    _potential_hessian(q, p, out)


def potential_hessian_t(t, q, p, out):
    _potential_hessian(q, p, out)


def constraint(q, p, out):
    _constraint(0.0, q, p, out)


def constraint_t(t, q, p, out):
    _constraint(t, q, p, out)


def constraint_jacobian(q, p, out):
    _jacobian(0.0, q, p, out)


def constraint_jacobian_t(t, q, p, out):
    _jacobian(t, q, p, out)


def constraint_hessian(q, eta, p, out):
    _constraint_hessian(0.0, q, eta, p, out)


def constraint_hessian_t(t, q, eta, p, out):
    _constraint_hessian(t, q, eta, p, out)


def constraint_time_derivative(t, q, p, out):
    _constraint_rate(t, q, p, out)


def force(t, q, v, p, out):
    _force(t, q, v, p, out)


def force_jacobian_q(t, q, v, p, out):
    _force_jacobian(t, q, v, p, out, False)


def force_jacobian_v(t, q, v, p, out):
    _force_jacobian(t, q, v, p, out, True)


def model_callbacks(time_dependent: bool, springs: bool, forced: bool) -> dict:
    """The ``fastvi.Model`` keyword arguments of a mechanism: the callbacks in the spelling
    its time dependence needs, ``potential_hessian=0`` without springs (gravity is linear),
    and the force callbacks only when it has dampers or applied loads."""
    timed = time_dependent
    kw = dict(potential=potential_t if timed else potential,
              potential_grad=potential_grad_t if timed else potential_grad,
              potential_hessian=(potential_hessian_t if timed else potential_hessian) if springs else 0,
              constraint=constraint_t if timed else constraint,
              constraint_jacobian=constraint_jacobian_t if timed else constraint_jacobian,
              constraint_hessian=constraint_hessian_t if timed else constraint_hessian)
    if timed:
        kw["constraint_time_derivative"] = constraint_time_derivative
    if forced:
        kw.update(force=force, force_jacobian_q=force_jacobian_q, force_jacobian_v=force_jacobian_v)
    return kw
