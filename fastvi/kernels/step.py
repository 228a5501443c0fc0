r"""One step of the constrained Galerkin variational integrator (``docs/method.md``).

Unknowns ``X = (ΔQ^1 … ΔQ^s, η_0 … η_{J−1})`` with ``ΔQ^ν = Q^ν − q_k`` (increments keep
the step well scaled and exactly variational, given consistent tables) and the constraint
impulses ``η_j``. Residual rows ``(E_0 … E_{s−1}, C_1 … C_J)``:

    E_ν = δ_{ν0} p_k + ∂S_u/∂Q^ν − Σ_{j<J} ℓ_ν(d_j) G_jᵀ η_j
    C_j = g(q(d_j))

with ``∂S_u/∂Q^ν = h Σ_i b_i [ℓ_ν(c_i) ∂L/∂q + (1/h) ℓ'_ν(c_i) M v](q_i, v_i)``. After Newton,

    P = ∂S_u/∂Q^s − Σ_{j<J} ℓ_s(d_j) G_jᵀ η_j,   p_{k+1} = P − G(q_{k+1})ᵀ η_J,
    (G M⁻¹ Gᵀ) η_J = G M⁻¹ P   at q_{k+1}                      (RATTLE projection)

Two Newton variants solve these equations (``docs/method.md`` §9–10):

* ``full``: the exact Newton matrix, assembled and factored at every iteration;
* ``auto`` (default): the *mechanics matrix* — the mass block ``(1/h) A ⊗ M̄`` with
  ``M̄ = M(q_k)`` and the exact constraint-Jacobian blocks, the force and constraint
  Hessians dropped (they are O((ωh)²) relative to the mass block). Its inverse factors
  into ``h A⁻¹ ⊗ M̄⁻¹`` and a Schur complement of size ``J m`` on the impulses (inverted
  once a step), so an iteration costs one residual and a few small products. It contracts like (ωh)²; when it
  contracts slower than ``MECH_THETA_MAX`` (stiff springs) the step is redone with the
  full Newton, which then stays on for ``FULL_HOLD`` steps.

Model, method, options and scratch arrive as the named tuples of :mod:`.layout`, passed
between the compiled functions by pointer (:func:`fastvi._numba.byref`); nothing here
allocates. The step is compiled once as a C entry point, and its three large stages as C
functions it calls by address (:func:`step_kernel`, ``docs/decisions/0010-kernel-shape.md``).
"""

from collections import namedtuple

import numba
import numpy as np
from numba.core import sigutils, types
from numba.core.ccallback import CFunc
from .._launch import _key
from .._numba import CalledAs, byref, hot, hot_inline, only_if, own, ptr, quiet
from .banded import (add_entry, assembly_map, clear_band, gt_times, mech_impulses_structured,
                     mech_rows_sparse, newton_banded, project_structured, put_entry,
                     schur_structured)
from .layout import (FD_T, FD_T_POINTS, CHESS, CJAC, CON, F_AUGMENT, F_DIAG, F_EX_CHESS, F_EX_FJQ,
                     F_EX_FJV, F_EX_GT, F_EX_KHESS, F_EX_MJAC, F_EX_PHESS, F_CH_PATTERN, F_FJ_PATTERN,
                     F_FORCE,
                     F_FORCE_Q0, F_LINPOT, F_M, F_MASSFN, F_TIME, F_TSLOT, FJQ, FJV, FORCE, GT, H_FG, H_FULL, H_HIST, H_MBAR, KGRAD, MASS, MJAC,
                     NEEDS_FULL_NEWTON, NEWTON_FAILED, NEWTON_FULL, NONFINITE, OK, PGRAD, PHESS,
                     POT, KHESS, S_FULL,
                     S_G, S_GV, S_ITERS, S_RES, S_WORK, S_WORK_F, SI_A, SI_BSPAN, SI_FSPAN, SI_GCOL,
                     SI_GPTR, SI_GSPAN,
                     SI_HC_BCOL,
                     SI_HC_COLS, SI_HC_CPTR, SI_HC_NG, SI_HC_PPTR, SI_HC_ROWS, SI_S, SI_SC, SINGULAR,
                     SINGULAR_CONSTRAINTS, SINGULAR_MASS, SOLVE_BANDED, SOLVE_DENSE, is_timed,
                     fit_newton_fields, linear_potential, make_workspace, sizes)
from .layout import as_loop_view, loop_view, specialize as layout_specialize
from .linalg import (augmented_mass, invert, invert_unpivoted, lu_factor, lu_factor_small,
                     lu_solve, lu_solve_small)

__all__ = ["make_workspace", "assemble", "assemble_at", "residual_dependence", "newton_matrix", "add_block", "plan_spans", "residual", "linear_force", "step", "step_kernel",
           "take_step", "step_once", "clear_rows", "cached_cfunc", "assemble_function", "ASSEMBLE_SIGNATURE",
           "end_momentum", "velocity_residual", "hidden_residual", "constraint_rate",
           "jacobian_rate"]

_FD_REL = 6.0554544523933395e-06  # cbrt(machine epsilon): central differences' best step
#: the mechanics matrix is abandoned for the full Newton when successive increments shrink
#: by less than this factor: each of its iterations costs a residual, and at θ = 0.25 it
#: needs about as many as the full Newton costs in assembly and LU
#: (docs/decisions/0001-mechanics-newton.md)
MECH_THETA_MAX = 0.25
#: steps the full Newton stays on after the mechanics matrix failed (then it is tried again)
FULL_HOLD = 32
#: the two-step predictor is used while it differs from the one-step one by at most this
#: fraction of the last step's displacement (its asymptotic range;
#: docs/decisions/0008-predictor.md)
PREDICT_TRUST = 1e-1
#: up to this many coordinates the constant-mass part of the residual is formed coordinate
#: by coordinate, above it with vectorised loops over the coordinates (the same arithmetic)
_MASS_ROWS_SMALL = 8


# ----------------------------------------------------------------------------- derivatives
#: what _fd_vec_jacobian differentiates: by q, by q and symmetrised (a Hessian), by v
_FD_Q, _FD_HESSIAN, _FD_V = 0, 1, 2


@hot_inline
def _symmetrize(out, n):
    """``out ← (out + outᵀ) / 2``: a Hessian by differences, symmetric as the exact one."""
    for a in range(n):
        for b in range(a + 1, n):
            t = 0.5 * (out[a, b] + out[b, a])
            out[a, b] = t
            out[b, a] = t


@hot
def _fd_vec_jacobian(fn, kind, q, v, prm, out, xa, fa, fb, n):
    """out[:, b] = ∂f/∂x_b by central differences of a vector callback f(q, v), with x = q
    (``kind`` ``_FD_Q``, or ``_FD_HESSIAN``: symmetrised) or x = v (``_FD_V``)."""
    wrt_v = kind == _FD_V
    x = v if wrt_v else q
    for b in range(n):
        for a in range(n):
            xa[a] = x[a]
        dx = _FD_REL * max(1.0, abs(x[b]))
        xa[b] = x[b] + dx
        if wrt_v:
            fn(ptr(q), ptr(xa), ptr(prm), ptr(fa))
        else:
            fn(ptr(xa), ptr(v), ptr(prm), ptr(fa))
        xa[b] = x[b] - dx
        if wrt_v:
            fn(ptr(q), ptr(xa), ptr(prm), ptr(fb))
        else:
            fn(ptr(xa), ptr(v), ptr(prm), ptr(fb))
        inv = 0.5 / dx
        for a in range(n):
            out[a, b] = (fa[a] - fb[a]) * inv
    if kind == _FD_HESSIAN:
        _symmetrize(out, n)


@hot
def fd_momentum_jacobian(fmass, q, v, prm, out, qa, Ma, n):
    """out[a, b] = ∂(M(q) v)_a / ∂q_b by central differences of the mass callback."""
    for b in range(n):
        for a in range(n):
            qa[a] = q[a]
        dq = _FD_REL * max(1.0, abs(q[b]))
        qa[b] = q[b] + dq
        fmass(ptr(qa), ptr(qa), ptr(prm), ptr(Ma))
        for a in range(n):
            acc = 0.0
            for c in range(n):
                acc += Ma[a, c] * v[c]
            out[a, b] = acc
        qa[b] = q[b] - dq
        fmass(ptr(qa), ptr(qa), ptr(prm), ptr(Ma))
        inv = 0.5 / dq
        for a in range(n):
            acc = 0.0
            for c in range(n):
                acc += Ma[a, c] * v[c]
            out[a, b] = (out[a, b] - acc) * inv


@hot
def fd_constraint_hessian(fjac, q, eta, prm, out, qa, Gp, Gm, n, m):
    """out = Σ_a η_a ∇²g_a = ∂(Gᵀη)/∂q by central differences of the Jacobian callback.

    ``Gp``/``Gm`` are zeroed first: they double as scratch elsewhere, and a callback with a
    declared pattern writes only its non-zeros."""
    for c in range(m):
        for a in range(n):
            Gp[c, a] = 0.0
            Gm[c, a] = 0.0
    for b in range(n):
        for a in range(n):
            qa[a] = q[a]
        dq = _FD_REL * max(1.0, abs(q[b]))
        qa[b] = q[b] + dq
        fjac(ptr(qa), ptr(qa), ptr(prm), ptr(Gp))
        qa[b] = q[b] - dq
        fjac(ptr(qa), ptr(qa), ptr(prm), ptr(Gm))
        inv = 0.5 / dq
        for a in range(n):
            acc = 0.0
            for c in range(m):
                acc += (Gp[c, a] - Gm[c, a]) * eta[c]
            out[a, b] = acc * inv
    _symmetrize(out, n)


@hot
def fd_constraint_hessian_grouped(fjac, q, eta, prm, out, qa, d, Gp, Gm, si, n, m):
    """:func:`fd_constraint_hessian` with the columns perturbed in groups (Curtis–Powell–
    Reid, planned by :func:`fastvi.structure.plan` on the pattern of ``Gᵀ G``): two
    Jacobian calls per group instead of per coordinate, products over the pattern of G.

    Row ``a`` of ``Gᵀ η`` depends only on the coordinates that share a constraint with
    ``a``, and a group holds at most one of them: its difference is the one of that
    single column, in the same floating-point operations (the sum over constraints in the
    same order, without its exact zeros), so ``out`` equals the column-by-column result
    bit for bit."""
    gp = si[SI_GPTR]
    gc = si[SI_GCOL]
    cp = si[SI_HC_CPTR]
    cc = si[SI_HC_COLS]
    pp = si[SI_HC_PPTR]
    pr = si[SI_HC_ROWS]
    pb = si[SI_HC_BCOL]
    for c in range(m):
        for a in range(n):
            Gp[c, a] = 0.0
            Gm[c, a] = 0.0
    for a in range(n):
        qa[a] = q[a]
        for b in range(n):
            out[a, b] = 0.0
    for g in range(si[SI_HC_NG]):
        for k in range(si[cp + g], si[cp + g + 1]):
            b = si[cc + k]
            qa[b] = q[b] + _FD_REL * max(1.0, abs(q[b]))
        fjac(ptr(qa), ptr(qa), ptr(prm), ptr(Gp))
        for k in range(si[cp + g], si[cp + g + 1]):
            b = si[cc + k]
            qa[b] = q[b] - _FD_REL * max(1.0, abs(q[b]))
        fjac(ptr(qa), ptr(qa), ptr(prm), ptr(Gm))
        for k in range(si[cp + g], si[cp + g + 1]):
            b = si[cc + k]
            qa[b] = q[b]
        for a in range(n):
            d[a] = 0.0
        for c in range(m):
            e = eta[c]
            for k in range(si[gp + c], si[gp + c + 1]):
                a = si[gc + k]
                d[a] += (Gp[c, a] - Gm[c, a]) * e
        for k in range(si[pp + g], si[pp + g + 1]):
            a = si[pr + k]
            b = si[pb + k]
            out[a, b] = d[a] * (0.5 / (_FD_REL * max(1.0, abs(q[b]))))
    _symmetrize(out, n)


# ----------------------------------------------------------------------------- time
@hot_inline
def _at(md, ws, h, x):
    """Set the time the callbacks read to ``t_k + x h`` (``x = 1``: ``t_{k+1}`` exactly, the
    value the next step starts from). Compiled away for a conservative model
    (:func:`.layout.is_timed`)."""
    if is_timed(md):
        md.prm[md.flags[F_TSLOT]] = ws.time[1] if x == 1.0 else ws.time[0] + x * h


@hot_inline
def _d_dt(md, fn, q, t, out, scratch, k):
    """``out[:k] = ∂f/∂t`` of the callback ``fn(q)`` at time ``t`` by the five-point
    difference (leaves the time entry at ``t``)."""
    slot = md.flags[F_TSLOT]
    prm = md.prm
    dt = FD_T * max(1.0, abs(t))
    for a in range(k):
        out[a] = 0.0
    for sgn, wgt in FD_T_POINTS:
        prm[slot] = t + sgn * dt
        fn(ptr(q), ptr(q), ptr(prm), ptr(scratch))
        for a in range(k):
            out[a] += wgt * scratch[a]
    inv = 1.0 / (12.0 * dt)
    for a in range(k):
        out[a] *= inv
    prm[slot] = t


@hot
def constraint_rate(md, q, t, out, scratch):
    """``out = g_t(t, q)``: the callback, or a five-point difference of the constraint."""
    m = md.flags[F_M]
    if md.flags[F_EX_GT] != 0:
        md.prm[md.flags[F_TSLOT]] = t
        md.fns[GT](ptr(q), ptr(q), ptr(md.prm), ptr(out))
    else:
        _d_dt(md, md.fns[CON], q, t, out, scratch, m)


@hot
def jacobian_rate(md, q, t, out, scratch):
    """``out (m, n) = ∂G/∂t (t, q)``, which is ``∂g_t/∂q``: a five-point difference in time
    of the constraint Jacobian (leaves the time entry at ``t``). ``scratch`` (m, n)."""
    m, n = md.flags[F_M], q.shape[0]
    for c in range(m):
        for a in range(n):
            scratch[c, a] = 0.0  # a callback with a declared pattern writes only its non-zeros
    _d_dt(md, md.fns[CJAC], q, t, out.reshape(m * n), scratch.reshape(m * n), m * n)


# ----------------------------------------------------------------------------- assembly
@hot_inline
def linear_force(md, ws, qk):
    """``ws.Fg = −∇V(q_k)`` for a potential linear in q (else nothing): the kernels then read
    it instead of calling ``potential_grad`` at every quadrature point of every Newton
    iteration. The step calls it at a trajectory's first step (the parameters are fixed for
    a trajectory); callers of :func:`residual` and :func:`assemble` outside a step (tests,
    profiles) call it first."""
    if linear_potential(md):
        Fg = ws.Fg
        md.fns[PGRAD](ptr(qk), ptr(qk), ptr(md.prm), ptr(Fg))
        for a in range(Fg.shape[0]):
            Fg[a] = -Fg[a]


@hot_inline
def _point_force(md, ws, Mi, has_mass, n):
    """At ``(ws.qi, ws.vi)``: ``ws.F = ∂T/∂q − ∇V + F_nc``, ``ws.fa = ∇V`` and, for a mass
    function, ``Mi = M(q_i)``."""
    fns, prm = md.fns, md.prm
    qi, vi, F, fa = ws.qi, ws.vi, ws.F, ws.fa
    if linear_potential(md):
        for a in range(n):
            fa[a] = -ws.Fg[a]
    else:
        fns[PGRAD](ptr(qi), ptr(qi), ptr(prm), ptr(fa))
    if has_mass:
        fns[KGRAD](ptr(qi), ptr(vi), ptr(prm), ptr(F))
        fns[MASS](ptr(qi), ptr(qi), ptr(prm), ptr(Mi))
        for a in range(n):
            F[a] -= fa[a]
    else:
        for a in range(n):
            F[a] = -fa[a]
    if is_timed(md) and md.flags[F_FORCE] != 0:
        fb = ws.fb
        fns[FORCE](ptr(qi), ptr(vi), ptr(prm), ptr(fb))
        for a in range(n):
            F[a] += fb[a]


@hot
def assemble(md_, tabs_, h, qk, pk, ws_, jac):
    """:func:`residual` and, if ``jac``, :func:`newton_matrix` at the unknowns ``ws.X``.

    Leaves ``ws.R``, ``ws.D`` (∂S_u/∂Q^ν), ``ws.G[j]`` (G at the constraint points j ≥ 1)
    and, if ``jac``, ``ws.A``. Returns 0, or ``NONFINITE`` when a callback produced NaN/inf.
    """
    # the residual solves nothing: compiled once for dense and structured plans
    st = residual(md_, tabs_, h, qk, pk, as_loop_view(ws_))
    if st == OK and jac:
        newton_matrix(md_, tabs_, h, qk, ws_)
    return st


def _assemble_entry(md_, tabs_, h, qk_, pk_, ws_, jac):
    return assemble(md_, tabs_, h, own(qk_), own(pk_), ws_, jac)


#: how a caller holds :func:`assemble_function`: pointers to the model, tables and workspace
#: erased (:func:`fastvi._numba.erased`), so that the caller is compiled once for every type
#: of them
ASSEMBLE_SIGNATURE = types.int64(types.voidptr, types.voidptr, types.float64,
                                 types.CPointer(numba.typeof(np.zeros(1))),
                                 types.CPointer(numba.typeof(np.zeros(1))), types.voidptr,
                                 types.boolean)
_ASSEMBLE: dict = {}


def assemble_function(md, tabs, ws):
    """:func:`assemble` for these types of model, tables and workspace as a C function
    (cached on disk), held as :data:`ASSEMBLE_SIGNATURE`: the linearised step calls it
    through its address. numba links a callee's code into its caller and optimises it again
    there; called directly, the residual and the Newton matrix (two fifths of the linearised
    step's code) would be optimised again in the linearised step and in every C function that
    holds it (the per-step hooks of sensitivities, the adjoint's sweep, each sized twin)."""
    key = (_key(md), _key(tabs), _key(ws))
    if key not in _ASSEMBLE:
        P, arg = types.CPointer, numba.typeof
        a1 = P(arg(np.zeros(1)))
        sig = types.int64(P(arg(md)), P(arg(tabs)), types.float64, a1, a1, P(arg(ws)),
                          types.boolean)
        with quiet():
            _ASSEMBLE[key] = CalledAs(cached_cfunc(_assemble_entry, sig), ASSEMBLE_SIGNATURE)
    return _ASSEMBLE[key]


@hot
def assemble_at(md, tabs, h, qk, pk, ws, jac):
    """:func:`assemble` for a caller in Python (the tests, the profiles).

    The kernels hand ``assemble`` its tuples by pointer; called from Python with the tuples
    themselves it would be typed, and compiled, a second time with its residual and Newton
    matrix (half a minute). Passing them on by pointer here reuses the kernels' compile."""
    return assemble(byref(md), byref(tabs), h, qk, pk, byref(ws), jac)


@hot
def residual_dependence(md, tabs, h, qk, pk, ws, dx, R0, P):
    """``P[a, k] |= R_a`` depends on ``X_k``, at the unknowns ``ws.X``, for a caller in
    Python (:func:`fastvi.structure.detect_pattern`): the non-zeros of the Newton matrix
    ``∂R/∂X`` without compiling it.

    Each unknown in turn is moved by ``dx[k]`` and the rows whose residual changes, bit for
    bit, are marked. The residual is evaluated exactly, so a row that does not depend on
    ``X_k`` comes out the same, and a change of order ``dx`` is far above round-off. A
    callback that gives NaN or inf marks its rows too (NaN equals nothing): the pattern
    can only grow. Ends with the residual at ``ws.X`` (``ws.G[1:]`` there) and returns
    its status."""
    md_, tabs_, ws_ = byref(md), byref(tabs), byref(ws)
    n, m, s, _, J = sizes(ws)
    N = s * n + J * m
    X, R = ws.X, ws.R
    residual(md_, tabs_, h, qk, pk, ws_)
    for a in range(N):
        R0[a] = R[a]
    for k in range(N):
        x = X[k]
        X[k] = x + dx[k]
        residual(md_, tabs_, h, qk, pk, ws_)
        for a in range(N):
            if R[a] != R0[a]:
                P[a, k] = True
        X[k] = x
    return residual(md_, tabs_, h, qk, pk, ws_)


@hot_inline
def _jacobian(md, exact, slot, of, kind, q, v, out, s1, s2, s3, n):
    """``out`` (n, n) = the model's callback ``slot`` where it has it (``exact``), else central
    differences (:func:`_fd_vec_jacobian` of ``kind``) of the callback ``of`` it
    differentiates; ``s1 … s3`` (n,) scratch."""
    if exact != 0:
        md.fns[slot](ptr(q), ptr(v), ptr(md.prm), ptr(out))
    else:
        _fd_vec_jacobian(md.fns[of], kind, q, v, md.prm, out, s1, s2, s3, n)


@hot_inline
def _add_row(A, si, xm, r, c0, coef, B, a, lo, hi):
    """``A[r, c0 + c] += coef · B[a, c]`` for ``c`` in ``lo … hi − 1``."""
    for c in range(lo, hi):
        add_entry(A, si, xm, r, c0 + c, coef * B[a, c])


@hot_inline
def _row_span(B, a, n, si, sp):
    """``(lo, hi)``: row ``a`` of the (n, n) block ``B`` is zero outside columns
    ``lo … hi − 1`` (``lo = hi = 0``: all of it). Scanned within the plan's span of that
    row where it has one (``sp``: the offset in ``si`` of the rows' spans, 0: none): O(1)
    a row of a banded model, and no wider than the row's own non-zeros (a damping force's
    diagonal ``F_v`` adds one entry a row, not the coupling's)."""
    lo, hi = (si[sp + 2 * a], si[sp + 2 * a + 1]) if sp != 0 else (0, n)
    while lo < hi and B[a, lo] == 0.0:
        lo += 1
    if lo == hi:
        return 0, 0
    while B[a, hi - 1] == 0.0:
        hi -= 1
    return lo, hi


@hot_inline
def _nonzero(B, n, si, sp):
    """Whether the (n, n) block ``B`` has an entry other than zero (within the rows'
    spans ``si[sp …]`` where ``sp`` is not 0)."""
    if sp != 0:
        for a in range(n):
            for c in range(si[sp + 2 * a], si[sp + 2 * a + 1]):
                if B[a, c] != 0.0:
                    return True
        return False
    for a in range(n):
        for c in range(n):
            if B[a, c] != 0.0:
                return True
    return False


@hot_inline
def add_block(A, r0, c0, coef, B, rows, n, si, sp, xm):
    """``A[r0 + a, c0 + c] += coef · B[a, c]`` for the ``rows`` rows of ``B`` (n columns),
    over their spans ``si[sp …]`` where ``sp`` is not 0, else over all columns; by the map
    ``xm`` where there is one (:func:`.banded.assembly_offset`)."""
    if sp != 0:
        for a in range(rows):
            for c in range(si[sp + 2 * a], si[sp + 2 * a + 1]):
                add_entry(A, si, xm, r0 + a, c0 + c, coef * B[a, c])
    else:
        for a in range(rows):
            for c in range(n):
                add_entry(A, si, xm, r0 + a, c0 + c, coef * B[a, c])


@hot_inline
def _set_block(A, r0, c0, coef, B, rows, n, si, sp, xm):
    """``A[r0 + a, c0 + c] = coef · B[a, c]``, over the spans as :func:`add_block`."""
    if sp != 0:
        for a in range(rows):
            for c in range(si[sp + 2 * a], si[sp + 2 * a + 1]):
                put_entry(A, si, xm, r0 + a, c0 + c, coef * B[a, c])
    else:
        for a in range(rows):
            for c in range(n):
                put_entry(A, si, xm, r0 + a, c0 + c, coef * B[a, c])


@hot_inline
def clear_rows(B, rows, n, spans):
    """``B ← 0`` (rows, n) over each row's span ``spans`` (``(lo, hi)`` pairs; empty: all
    of it). A callback with a declared pattern writes only its non-zeros, and entries
    outside the spans are never written: they keep the zeros of the allocation."""
    if spans.shape[0] > 0:
        for c in range(rows):
            for a in range(spans[2 * c], spans[2 * c + 1]):
                B[c, a] = 0.0
    else:
        for c in range(rows):
            for a in range(n):
                B[c, a] = 0.0


@hot_inline
def _spans(si, sp, rows):
    """The rows' spans at ``si[sp …]`` (:func:`plan_spans`), empty where ``sp`` is 0."""
    return si[sp: sp + 2 * rows] if sp != 0 else si[:0]


@hot
def plan_spans(ws_):
    """``(si[SI_BSPAN], si[SI_GSPAN], si[SI_FSPAN])`` of a structured workspace;
    ``(0, 0, 0)``, a constant, for a small model's (``_numba.only_if``): its assembly then
    compiles to the dense loops alone, as before the spans, and keeps them unrolled in the
    sized step."""
    ws = own(ws_)
    return ws.si[SI_BSPAN], ws.si[SI_GSPAN], ws.si[SI_FSPAN]


plan_spans = only_if(plan_spans, "structured", (0, 0, 0))


@hot
def newton_matrix(md_, tabs_, h, qk, ws_):
    r"""``ws.A = ∂R/∂X`` at the unknowns ``ws.X``: the exact derivative of :func:`residual`
    as it computes ``R``, with ``ws.G[0 … J]`` as it leaves them.

    Rows ``E_ν`` (ν < s) and constraint rows, columns ``ΔQ^μ`` (μ = 1…s) and ``η_j``:

        ∂E_ν/∂ΔQ^μ = (1/h) Am[ν−1, μ−1] M  (row 0: minus the sum over ν ≥ 1; constant M)
                     + Σ_i b_i [h ℓ_ν ℓ_μ ∂F/∂q + ℓ_ν ℓ'_μ (C_qᵀ + F_v) + ℓ'_ν ℓ_μ C_q
                                + ℓ'_ν ℓ'_μ M(q_i)/h]          (at the quadrature points c_i)
                     − Σ_{0<j<J} ℓ_ν(d_j) ℓ_μ(d_j) Σ_c η_{j,c} ∇²g_c(q(d_j)),
        ∂E_ν/∂η_j = −ℓ_ν(d_j) G_jᵀ,     ∂g(q(d_j))/∂ΔQ^μ = ℓ_μ(d_j) G_j,

    with ``∂F/∂q = T_qq − ∇²V + ∂F_nc/∂q``, ``C_q = ∂(M v)/∂q`` and ``F_v = ∂F_nc/∂v``. The
    quadrature terms are formed only for what the model has: a constant mass, a potential
    linear in q and no force leave the mass block and the constraint terms alone.

    With a banded plan (``ws.si[SI_BSPAN]``, :func:`fastvi.structure.plan`) each row of a
    block is formed over its span of the coordinates' coupling (of G's pattern for the
    constraint blocks) alone, and only those spans are zeroed: the rest of ``ws.A`` keeps
    the zeros of its allocation. The assembly then costs O(nnz), not O(N²), and every
    entry it forms is the same, bit for bit.
    """
    md, tabs, ws = own(md_), own(tabs_), own(ws_)
    fns, flags, Mc, prm = md.fns, md.flags, md.Mc, md.prm
    b, L, Ld, Lc = tabs.b, tabs.L, tabs.Ld, tabs.Lc
    X, A, G = ws.X, ws.A, ws.G
    qi, vi, F, Pm, fa = ws.qi, ws.vi, ws.F, ws.Pm, ws.fa
    Aq, Cq, Hc, Ma = ws.Aq, ws.Cq, ws.Hc, ws.Ma
    n, m, s, r, J = sizes(ws)
    has_mass = flags[F_MASSFN] != 0
    diag = flags[F_DIAG] != 0
    has_force = is_timed(md) and flags[F_FORCE] != 0
    sn = s * n
    N = sn + J * m
    inv_h = 1.0 / h
    si = ws.si
    bsp, gsp, fsp = plan_spans(ws_)
    xm = assembly_map(ws_)
    clear_band(A, xm)  # by a map (assembly_offset), then its own rows and columns' spans
    if bsp != 0:
        for nu in range(s):
            for mu in range(s):
                for a in range(n):
                    for c in range(si[bsp + 2 * a], si[bsp + 2 * a + 1]):
                        put_entry(A, si, xm, nu * n + a, mu * n + c, 0.0)
    else:
        for k in range(N):
            for l in range(N):
                put_entry(A, si, xm, k, l, 0.0)

    if not has_mass:
        # the derivative of the residual's quadratic form, row 0 as its sum (as there)
        Am = tabs.Am
        for mu in range(1, s + 1):
            c0 = (mu - 1) * n
            for nu in range(s):
                if nu == 0:
                    cM = 0.0
                    for k in range(1, s + 1):
                        cM -= Am[k - 1, mu - 1] * inv_h
                else:
                    cM = Am[nu - 1, mu - 1] * inv_h
                r0 = nu * n
                if diag:
                    for a in range(n):
                        put_entry(A, si, xm, r0 + a, c0 + a, cM * Mc[a, a])
                else:
                    _set_block(A, r0, c0, cM, Mc, n, n, si, bsp, xm)

    if has_mass or has_force or flags[F_LINPOT] == 0:
        Mi, Fv = ws.Mi, ws.Fv
        # ∂F/∂q = 0 by declaration (a linear potential, a constant mass and a force of v
        # alone: viscous damping): the block is neither formed nor scanned
        q_free = (flags[F_LINPOT] != 0 and not has_mass
                  and not (has_force and flags[F_FORCE_Q0] == 0))
        # a large model's blocks are sparse (a damping force's F_v is diagonal, a chain's
        # Hessians are banded): each row's span of non-zeros, found once and added to
        # every block. Each entry gets its terms in the dense loops' order: ∂F/∂q first,
        # ∂F/∂v last, so F_v goes here only where no mass term comes between; over the
        # declared pattern's spans where there is one, else over those it finds
        sparse_fv = has_force and not has_mass and n > _MASS_ROWS_SMALL
        fv_spans = fsp if sparse_fv else 0
        for i in range(r):
            _at(md, ws, h, tabs.c[i])
            for a in range(n):
                qa = qk[a]
                va = 0.0
                for nu in range(1, s + 1):
                    x = X[(nu - 1) * n + a]
                    qa += L[nu, i] * x
                    va += Ld[nu, i] * x
                qi[a] = qa
                vi[a] = va * inv_h
            # ∂F/∂q = T_qq − V_qq (+ ∂F_nc/∂q); F, Pm, fa are spent scratch of the residual
            if not q_free:
                if flags[F_LINPOT] != 0:
                    clear_rows(Aq, n, n, _spans(si, bsp, n))
                else:
                    _jacobian(md, flags[F_EX_PHESS], PHESS, PGRAD, _FD_HESSIAN, qi, qi, Aq, fa,
                              F, Pm, n)
                # −x exactly, as −0.0 for 0.0
                _set_block(Aq, 0, 0, -1.0, Aq, n, n, si, bsp, None)
            if has_mass:
                fns[MASS](ptr(qi), ptr(qi), ptr(prm), ptr(Mi))
                _jacobian(md, flags[F_EX_KHESS], KHESS, KGRAD, _FD_HESSIAN, qi, vi, Hc, fa, F,
                          Pm, n)
                add_block(Aq, 0, 0, 1.0, Hc, n, n, si, bsp, None)
                if flags[F_EX_MJAC] != 0:
                    fns[MJAC](ptr(qi), ptr(vi), ptr(prm), ptr(Cq))
                else:
                    fd_momentum_jacobian(fns[MASS], qi, vi, prm, Cq, fa, Ma, n)
            if has_force:
                # ∂F_nc/∂q joins the force block, ∂F_nc/∂v the mixed block (docs/method.md §11)
                # with a pattern they write its entries only: what is read is zeroed first
                patterned = flags[F_FJ_PATTERN] != 0
                if flags[F_FORCE_Q0] == 0:
                    if patterned:
                        clear_rows(Hc, n, n, _spans(si, bsp, n))
                    _jacobian(md, flags[F_EX_FJQ], FJQ, FORCE, _FD_Q, qi, vi, Hc, fa, F, Pm, n)
                    add_block(Aq, 0, 0, 1.0, Hc, n, n, si, bsp, None)
                if patterned:
                    clear_rows(Fv, n, n, _spans(si, fv_spans if fv_spans != 0 else bsp, n))
                _jacobian(md, flags[F_EX_FJV], FJV, FORCE, _FD_V, qi, vi, Fv, Pm, fa, F, n)
            # a block of zeros adds nothing: skipping it leaves A as it was
            force_q = not q_free and _nonzero(Aq, n, si, bsp)
            w = h * b[i]
            if n > _MASS_ROWS_SMALL:
                if force_q:
                    for a in range(n):
                        lo, hi = _row_span(Aq, a, n, si, bsp)
                        for nu in range(s):
                            for mu in range(1, s + 1):
                                cA = w * L[nu, i] * L[mu, i]
                                _add_row(A, si, xm, nu * n + a, (mu - 1) * n, cA, Aq, a, lo, hi)
                    force_q = False
                if sparse_fv:
                    for a in range(n):
                        if fv_spans != 0:
                            lo, hi = si[fv_spans + 2 * a], si[fv_spans + 2 * a + 1]
                        else:
                            lo, hi = _row_span(Fv, a, n, si, bsp)
                        for nu in range(s):
                            for mu in range(1, s + 1):
                                cB = b[i] * L[nu, i] * Ld[mu, i]
                                _add_row(A, si, xm, nu * n + a, (mu - 1) * n, cB, Fv, a, lo, hi)
            for nu in range(s):
                for mu in range(1, s + 1):
                    cA = w * L[nu, i] * L[mu, i]
                    r0 = nu * n
                    c0 = (mu - 1) * n
                    if force_q:
                        for a in range(n):
                            for c in range(n):
                                add_entry(A, si, xm, r0 + a, c0 + c, cA * Aq[a, c])
                    if has_mass:
                        # ∂/∂Q^μ of ℓ'_ν M v and of ℓ_ν ∂T/∂q: the mass and mixed terms
                        cM = b[i] * Ld[nu, i] * Ld[mu, i] * inv_h
                        cB = b[i] * L[nu, i] * Ld[mu, i]
                        cC = b[i] * Ld[nu, i] * L[mu, i]
                        if bsp != 0:
                            for a in range(n):
                                for c in range(si[bsp + 2 * a], si[bsp + 2 * a + 1]):
                                    add_entry(A, si, xm, r0 + a, c0 + c,
                                         cM * Mi[a, c] + cB * Cq[c, a] + cC * Cq[a, c])
                        else:
                            for a in range(n):
                                for c in range(n):
                                    add_entry(A, si, xm, r0 + a, c0 + c,
                                         cM * Mi[a, c] + cB * Cq[c, a] + cC * Cq[a, c])
                    if has_force and not sparse_fv:
                        add_block(A, r0, c0, b[i] * L[nu, i] * Ld[mu, i], Fv, n, n, si, bsp, xm)

    if m > 0:
        qd = qi
        for j in range(1, J + 1):
            Gj = G[j]
            row = sn + (j - 1) * m
            for mu in range(1, s + 1):
                cl = Lc[mu, j]
                if cl != 0.0:
                    c0 = (mu - 1) * n
                    _set_block(A, row, c0, cl, Gj, m, n, si, gsp, xm)
            if j < J:
                _at(md, ws, h, tabs.d[j])
                for a in range(n):
                    qa = qk[a]
                    for nu in range(1, s + 1):
                        qa += Lc[nu, j] * X[(nu - 1) * n + a]
                    qd[a] = qa
                eta = X[sn + j * m : sn + (j + 1) * m]
                if flags[F_EX_CHESS] != 0:
                    if flags[F_CH_PATTERN] != 0:  # it writes the shared coordinates' entries
                        clear_rows(Hc, n, n, _spans(si, bsp, n))
                    fns[CHESS](ptr(qd), ptr(eta), ptr(prm), ptr(Hc))
                elif ws.si[SI_HC_NG] != 0:  # large models: columns in groups
                    fd_constraint_hessian_grouped(fns[CJAC], qd, eta, prm, Hc, fa, Pm, ws.Gp,
                                                   ws.Gm, ws.si, n, m)  # Pm: spent scratch
                else:
                    fd_constraint_hessian(fns[CJAC], qd, eta, prm, Hc, fa, ws.Gp, ws.Gm, n, m)
                if n > _MASS_ROWS_SMALL:
                    for a in range(n):
                        lo, hi = _row_span(Hc, a, n, si, bsp)
                        for nu in range(s):
                            for mu in range(1, s + 1):
                                cc = Lc[nu, j] * Lc[mu, j]
                                if cc != 0.0:
                                    _add_row(A, si, xm, nu * n + a, (mu - 1) * n, -cc, Hc, a,
                                             lo, hi)
                else:
                    for nu in range(s):
                        for mu in range(1, s + 1):
                            cc = Lc[nu, j] * Lc[mu, j]
                            if cc != 0.0:
                                r0 = nu * n
                                c0 = (mu - 1) * n
                                for a in range(n):
                                    for c in range(n):
                                        add_entry(A, si, xm, r0 + a, c0 + c, -(cc * Hc[a, c]))
        for j in range(J):
            Gj = G[j]
            col = sn + j * m
            for nu in range(s):
                cl = Lc[nu, j]
                if cl != 0.0:
                    r0 = nu * n
                    if gsp != 0:  # G's rows by their spans: the transposed block by columns
                        for c in range(m):
                            for a in range(si[gsp + 2 * c], si[gsp + 2 * c + 1]):
                                put_entry(A, si, xm, r0 + a, col + c, -cl * Gj[c, a])
                    else:
                        for a in range(n):
                            for c in range(m):
                                put_entry(A, si, xm, r0 + a, col + c, -cl * Gj[c, a])


# ----------------------------------------------------------------------------- predictor, full Newton
@hot_inline
def extrapolate(E, E2, Xp, Xpp, X, Z, s, n, two, h, vk):
    """``X[:s n]`` ← the last step's polynomial (unknowns ``Xp``) extrapolated by ``E`` onto
    this step's nodes; with ``two``, the Hermite polynomial of the last two steps (``Xpp``
    the one before; slope ``h v_k`` at the step's start) by ``E2`` instead
    (:func:`fastvi.tables.hermite_predictor`), where the two guesses agree to
    ``PREDICT_TRUST`` of the last step's displacement (``Z``: (s, n) scratch). Positions
    are increments from each step's start."""
    gap = 0.0
    move = 0.0
    for nu in range(1, s + 1):
        for a in range(n):
            last = Xp[(s - 1) * n + a]
            acc = -last * E[0, nu]  # μ = 0: ΔQ^0 = 0
            for mu in range(1, s + 1):
                acc += (Xp[(mu - 1) * n + a] - last) * E[mu, nu]
            X[(nu - 1) * n + a] = acc
            if two:
                # node τ_{s−1} − 1 of the step before last, relative to q_{k−1}: ΔQ^{s−1} − ΔQ^s
                # of that step; the result relative to q_k = q_{k−1} + ΔQ^s
                back = -Xpp[(s - 1) * n + a]
                if s >= 2:
                    back += Xpp[(s - 2) * n + a]
                acc2 = back * E2[0, nu]
                for mu in range(1, s + 1):  # row 1 (μ = 0): ΔQ^0 = 0
                    acc2 += Xp[(mu - 1) * n + a] * E2[mu + 1, nu]
                acc2 += h * vk[a] * E2[s + 2, nu]
                acc2 -= last
                Z[nu - 1, a] = acc2
                gap = max(gap, abs(acc2 - acc))
                move = max(move, abs(last))
    # The two guesses differ by about the error of the one-step guess. Far below the last
    # step's displacement the extrapolation is in its asymptotic range and the two-step
    # guess is the better one; otherwise (long steps, sudden turns) its higher degree
    # makes it the worse one, and Newton may even find another root from it.
    if two and gap <= PREDICT_TRUST * move:
        for nu in range(s):
            for a in range(n):
                X[nu * n + a] = Z[nu, a]


@hot
def varied_weights(tau, Lw, Ew, hist, h, s, two, Ev, E2v):
    """The weights of :func:`extrapolate` for a step of another length than the last two
    (``hist`` = their lengths h1, h2): ``Ev`` in the place of ``tabs.E`` and, with ``two``,
    ``E2v`` in that of ``tabs.E2`` (columns 1…s; with equal steps they are those tables).

    In the last step's local time τ (length ``h1``), with its control values ``y_μ`` at
    ``τ_μ`` and ``ω(τ) = Π_k (τ − τ_k)``: the one-step guess is the interpolant
    ``P_s(τ) = Σ_μ ℓ_μ(τ) y_μ``; the two-step guess adds ``ω(τ) (α + β (τ − 1))``, with
    ``α = (h1 v_k − P_s'(1)) / ω'(1)`` from the slope at τ = 1 (where ω vanishes,
    ``ω'(1) = 1 / Lw[0, s]``) and ``β`` from the step before's point at
    ``τ_e = (τ_{s−1} − 1) h2 / h1``. Both are evaluated at this step's nodes
    ``x_ν = 1 + (h / h1) τ_ν`` and written as weights of the inputs of :func:`extrapolate`:
    the point ``τ_e`` (row 0 of ``E2v``), the ``y_μ`` and the slope ``h v_k`` (row s + 2).
    The Lagrange weights come from prefix and suffix products (``Ew``: column 0 the point
    τ_e, columns ν the new nodes, row s + 1 ω), so nothing divides but the two constants of
    α and β. Called, not inlined, also by the size-specialized step (only runs of changing
    step length take it: inlined there it made the fixed step ≈ 4 % slower)."""
    h1 = hist[0]
    r = h / h1
    te = (tau[s - 1] - 1.0) * hist[1] / h1
    for col in range(s + 1):
        x = te if col == 0 else 1.0 + r * tau[col]
        pre = 1.0
        for mu in range(s + 1):
            Ew[mu, col] = pre
            pre *= x - tau[mu]
        Ew[s + 1, col] = pre  # ω(x)
        suf = 1.0
        for mu in range(s, -1, -1):
            Ew[mu, col] *= suf * Lw[0, mu]
            suf *= x - tau[mu]
    for mu in range(s + 1):
        for nu in range(s + 1):
            Ev[mu, nu] = Ew[mu, nu]
    if not two:
        return
    we = Ew[s + 1, 0]
    inv_b = 1.0 / (we * (te - 1.0))
    for nu in range(1, s + 1):
        # ω(x_ν) (α + β r τ_ν) = a_ν (h1 v_k − P_s'(1)) / Lw[0, s] … in the inputs' weights
        kappa = Ew[s + 1, nu] * r * tau[nu] * inv_b
        a = (Ew[s + 1, nu] - kappa * we) * Lw[0, s]
        E2v[0, nu] = kappa
        for mu in range(s + 1):
            E2v[mu + 1, nu] = Ew[mu, nu] - a * Lw[1, mu] - kappa * Ew[mu, 0]
        E2v[s + 2, nu] = a / r


@hot
def predict(tabs_, n, m, h, vk, ws_, order):
    """Initial guess of ``order`` 2: the polynomial of degree s + 2 through the last step's
    control points and the nearest one of the step before, with slope ``v_k`` at ``t_k``
    (error O(h^(s+3))), extrapolated onto this step; 1 (or 2 with only one step known): of
    the last step alone (degree s); 0: the straight line with ``v_k``. The impulses are the
    last step's (zero for order 0)."""
    tabs, ws = own(tabs_), own(ws_)
    E, tau = tabs.E, tabs.tau
    _, _, s, _, J = sizes(ws)
    X = ws.X
    Xp = ws.Xprev
    if order == 0:
        # straight line with the initial velocity; impulses start at zero
        for nu in range(1, s + 1):
            for a in range(n):
                X[(nu - 1) * n + a] = h * tau[nu] * vk[a]
        for k in range(s * n, s * n + J * m):
            X[k] = 0.0
        return
    sn = s * n
    two = order >= 2 and ws.hold[H_HIST] >= 2
    if ws.hist[0] != h or (two and ws.hist[1] != h):
        varied_weights(tabs.tau, tabs.Lw, ws.Ew, ws.hist, h, s, two, ws.Ev, ws.E2v)
        extrapolate(ws.Ev, ws.E2v, Xp, ws.Xpp, X, ws.Z, s, n, two, h, vk)
    else:
        extrapolate(E, tabs.E2, Xp, ws.Xpp, X, ws.Z, s, n, two, h, vk)
    for k in range(sn, sn + J * m):
        X[k] = Xp[k]


@hot_inline
def _qscale(qk, n):
    qscale = 1.0
    for a in range(n):
        qscale = max(qscale, abs(qk[a]))
    return qscale


@hot_inline
def _apply_increment(X, R, N, sn, qscale):
    """X −= R; returns the max-norm of the control-point increments over ``qscale``."""
    dn = 0.0
    for k in range(N):
        X[k] -= R[k]
    for k in range(sn):
        dn = max(dn, abs(R[k]))
    return dn / qscale


@hot
def newton_full(md_, tabs_, opts_, h, qk_, pk_, ws_, out_):
    """Newton's method with the exact Newton matrix, from the unknowns in ``ws.X``.

    Stops on the increment of the control points, scaled by ``max(1, |q_k|)``: converged
    when it is below ``tol``, when the contraction estimate ``θ/(1−θ)·|δ|`` predicts the
    remaining error below ``tol``, or at a round-off plateau (``θ ≥ ½`` with ``|δ| ≤ 100
    tol``). A residual test on the momentum rows would leave an error ~tol/h per step.
    Gives up early when the increments grow twice in a row (divergence).

    Converged or not, it ends with the residual at the final unknowns (``ws.R``, ``ws.D``,
    ``ws.G[1:]``: what the end momentum and the diagnostics need) and its max-norm in
    ``out[S_RES]``. The loop has one call of :func:`assemble`, with the Newton matrix while
    iterating and without it for that final residual.
    """
    ws = own(ws_)
    opts, qk, pk, out = own(opts_), own(qk_), own(pk_), own(out_)
    X, R, A, piv = ws.X, ws.R, ws.A, ws.piv
    n, m, s, _, J = sizes(ws)
    sn = s * n
    N = sn + J * m
    tol = opts.tol
    qscale = _qscale(qk, n)
    dprev = np.inf
    grew = 0
    it = 0
    final = False  # the next assembly is the residual at the final unknowns
    status = NEWTON_FAILED
    while True:
        if not final:
            it += 1
            out[S_ITERS] = it
        st = assemble(md_, tabs_, h, qk, pk, ws_, not final)
        if st != OK:
            return st
        if final:
            break
        if ws.si[SI_A] == SOLVE_BANDED:  # large sparse models (banded.py)
            if newton_banded(ws_, N) != 0:
                return SINGULAR
        else:
            if lu_factor(A, piv, N) != 0:
                return SINGULAR
            lu_solve(A, piv, R, N)
        dn = _apply_increment(X, R, N, sn, qscale)
        if not np.isfinite(dn):
            return NONFINITE
        final = it >= opts.max_iter
        if dn <= tol:
            status, final = OK, True
        elif it >= 2:
            theta = dn / dprev
            if theta < 1.0 and theta / (1.0 - theta) * dn <= tol:
                status, final = OK, True
            elif theta >= 0.5 and dn <= 100.0 * tol:
                status, final = OK, True  # round-off plateau
            else:
                grew = grew + 1 if theta > 1.0 else 0
                if grew >= 2:
                    final = True
        dprev = dn
    res = 0.0
    for k in range(N):
        res = max(res, abs(R[k]))
    out[S_RES] = res
    return status


# ----------------------------------------------------------------------------- mechanics matrix
@hot_inline
def _mass_bar(md, qk, ws, n):
    """Prepare ``M̄⁻¹`` for this step: ``1/diag(M)``, or the LU of ``M(q_k)`` (of the
    constant ``M`` once per trajectory; of ``M + Gᵀ W G`` at ``q_k`` for a singular constant
    ``M``, :func:`.linalg.augmented_mass`). Returns a status code."""
    fns, flags, Mc, prm = md.fns, md.flags, md.Mc, md.prm
    Mb = ws.Mb
    if flags[F_AUGMENT] != 0:
        augmented_mass(Mc, ws.G[0], Mb, n, flags[F_M])
    elif flags[F_DIAG] != 0:
        _inverse_diagonal(md, ws, n)
        return OK
    elif flags[F_MASSFN] != 0:
        fns[MASS](ptr(qk), ptr(qk), ptr(prm), ptr(Mb))
    elif ws.hold[H_MBAR] != 0:
        return OK
    else:
        for a in range(n):
            for c in range(n):
                Mb[a, c] = Mc[a, c]
        ws.hold[H_MBAR] = 1
    if lu_factor_small(Mb, ws.pivn, n) != 0:
        return SINGULAR_MASS
    return OK


@hot_inline
def _inverse_diagonal(md, ws, n):
    """``ws.minv = 1 / diag(M)`` of a diagonal constant mass, once per trajectory: the kernels
    multiply by it (a division costs several multiplications)."""
    if ws.hold[H_MBAR] == 0:
        for a in range(n):
            ws.minv[a] = 1.0 / md.Mc[a, a]
        ws.hold[H_MBAR] = 1


@hot_inline
def _minv(md, ws, x, n):
    """x ← M̄⁻¹ x."""
    if md.flags[F_DIAG] != 0 and md.flags[F_AUGMENT] == 0:
        for a in range(n):
            x[a] *= ws.minv[a]
    else:
        lu_solve_small(ws.Mb, ws.pivn, x, n)


@hot_inline
def _mech_rows(md, ws, j, n, m):
    """``ws.Y[j]`` = (M̄⁻¹ G_jᵀ)ᵀ from ``ws.G[j]``."""
    if ws.si[SI_SC] != SOLVE_DENSE:
        mech_rows_sparse(ws, j, m)
        return
    for c in range(m):
        Yc = ws.Y[j, c]
        for a in range(n):
            Yc[a] = ws.G[j, c, a]
        _minv(md, ws, Yc, n)


@hot
def residual(md_, tabs_, h, qk, pk, ws_):
    r"""The step's residual at the unknowns ``ws.X``, into ``ws.R`` (with ``ws.D`` and
    ``ws.G[1:]``): the one residual of both Newton iterations and of the linearised step.

        E_ν = δ_{ν0} p_k + ∂S_u/∂Q^ν − Σ_{j<J} ℓ_ν(d_j) G_jᵀ η_j   (ν < s),
        g(q(d_j)) = 0   (j = 1…J),   ∂S_u/∂Q^ν = Σ_i b_i [h ℓ_ν F + ℓ'_ν M v](c_i).

    The loops are ordered so that the innermost one runs over the coordinates
    independently: tiny reductions over the s control points are bound by the latency of
    their additions. Returns 0, or ``NONFINITE`` when a callback produced NaN/inf.
    """
    md, tabs, ws = own(md_), own(tabs_), own(ws_)
    fns, flags, Mc, prm = md.fns, md.flags, md.Mc, md.prm
    b, L, Ld, Lc = tabs.b, tabs.L, tabs.Ld, tabs.Lc
    X, R, D, G = ws.X, ws.R, ws.D, ws.G
    qi, vi, F, Pm = ws.qi, ws.vi, ws.F, ws.Pm
    n, m, s, r, J = sizes(ws)
    has_mass = flags[F_MASSFN] != 0
    diag = flags[F_DIAG] != 0
    sn = s * n
    N = sn + J * m
    inv_h = 1.0 / h
    Mi = Mc if not has_mass else ws.Mi
    # a constant M: the mass part of D is linear in X with the method's own quadratic form,
    # (1/h) M Σ_μ Am[ν−1, μ−1] ΔQ^μ for ν ≥ 1 and minus their sum for ν = 0 (the same
    # quadrature sums, in another order; a sum so that the rows sum to zero exactly, as
    # the discrete Noether theorem needs: tables._mass_block), and v at the quadrature
    # points is needed only by a velocity-dependent force
    need_v = has_mass or (is_timed(md) and flags[F_FORCE] != 0)
    if has_mass:
        for nu in range(s + 1):
            for a in range(n):
                D[nu, a] = 0.0
    else:
        # the same operations in the same order either way (bit for bit); for a few
        # coordinates one pass over them with the short sums over μ innermost (n s
        # independent chains, no loop of run-time length n for each ν and μ: those cost
        # the generic kernels more than the multiply–adds saved), for many the loops over
        # the coordinates innermost, where they vectorise
        Am = tabs.Am
        if n <= _MASS_ROWS_SMALL:
            for a in range(n):
                d0 = 0.0
                for nu in range(1, s + 1):
                    acc = 0.0
                    for mu in range(s):
                        acc += Am[nu - 1, mu] * X[mu * n + a]
                    acc *= inv_h
                    if diag:
                        acc *= Mc[a, a]
                    D[nu, a] = acc  # without M for a full M: applied below
                    d0 -= acc
                D[0, a] = d0
        else:
            for a in range(n):
                D[0, a] = 0.0
            for nu in range(1, s + 1):
                Dn = D[nu]
                for a in range(n):
                    Dn[a] = 0.0
                for mu in range(s):
                    cm = Am[nu - 1, mu]
                    off = mu * n
                    for a in range(n):
                        Dn[a] += cm * X[off + a]
                for a in range(n):
                    acc = Dn[a] * inv_h
                    if diag:
                        acc *= Mc[a, a]
                    Dn[a] = acc
                    D[0, a] -= acc
        if not diag:
            for nu in range(s + 1):
                for a in range(n):
                    Pm[a] = D[nu, a]
                for a in range(n):
                    acc = 0.0
                    for c in range(n):
                        acc += Mc[a, c] * Pm[c]
                    D[nu, a] = acc
    # a potential linear in q and nothing else at the quadrature points: its part of D is
    # −h Σ_i b_i ℓ_ν(c_i) ∇V, with ∇V evaluated once a trajectory (linear_force)
    if not need_v and linear_potential(md):
        Fg, bL = ws.Fg, tabs.bL
        for nu in range(s + 1):
            w = h * bL[nu]
            for a in range(n):
                D[nu, a] += w * Fg[a]
    else:
        for i in range(r):
            _at(md, ws, h, tabs.c[i])
            for a in range(n):
                qi[a] = qk[a]
                vi[a] = 0.0
            for nu in range(1, s + 1):
                cl = L[nu, i]
                off = (nu - 1) * n
                if need_v:
                    cd = Ld[nu, i] * inv_h
                    for a in range(n):
                        x = X[off + a]
                        qi[a] += cl * x
                        vi[a] += cd * x
                else:
                    for a in range(n):
                        qi[a] += cl * X[off + a]
            _point_force(md, ws, Mi, has_mass, n)
            w = h * b[i]
            if has_mass:
                for a in range(n):
                    Pm[a] = 0.0
                for c in range(n):
                    vc = vi[c]
                    for a in range(n):
                        Pm[a] += Mi[a, c] * vc
                for nu in range(s + 1):
                    cl = w * L[nu, i]
                    cd = b[i] * Ld[nu, i]
                    for a in range(n):
                        D[nu, a] += cl * F[a] + cd * Pm[a]
            else:
                for nu in range(s + 1):
                    cl = w * L[nu, i]
                    for a in range(n):
                        D[nu, a] += cl * F[a]
    for a in range(n):
        R[a] = pk[a] + D[0, a]
    for nu in range(1, s):
        for a in range(n):
            R[nu * n + a] = D[nu, a]
    if m > 0:
        gj = ws.g
        for j in range(1, J + 1):
            _at(md, ws, h, tabs.d[j])
            for a in range(n):
                qi[a] = qk[a]
            for nu in range(1, s + 1):
                cl = Lc[nu, j]
                if cl != 0.0:
                    off = (nu - 1) * n
                    for a in range(n):
                        qi[a] += cl * X[off + a]
            fns[CON](ptr(qi), ptr(qi), ptr(prm), ptr(gj))
            fns[CJAC](ptr(qi), ptr(qi), ptr(prm), ptr(G[j]))
            row = sn + (j - 1) * m
            for c in range(m):
                R[row + c] = gj[c]
        for j in range(J):
            Gj = G[j]
            col = sn + j * m
            for nu in range(s):
                cl = Lc[nu, j]
                if cl == 0.0:
                    continue
                r0 = nu * n
                if ws.si[SI_SC] != SOLVE_DENSE:  # over the pattern of G (banded.py)
                    gt_times(ws.si, Gj, X[col:], R[r0:], -cl, m)
                    continue
                for c in range(m):
                    e = cl * X[col + c]
                    for a in range(n):
                        R[r0 + a] -= Gj[c, a] * e
    for k in range(N):
        if not np.isfinite(R[k]):
            return NONFINITE
    return OK


@hot_inline
def _schur_build(tabs, h, ws, n, m, J):
    """``ws.Sc`` ← the dense Schur complement ``[h W_{jj'} G_j M̄⁻¹ G_{j'}ᵀ]``."""
    G, Y, Sc, W = ws.G, ws.Y, ws.Sc, tabs.W
    for j in range(1, J + 1):
        for jp in range(J):
            w = h * W[j - 1, jp]
            for c in range(m):
                for e in range(m):
                    acc = 0.0
                    if w != 0.0:
                        for a in range(n):
                            acc += G[j, c, a] * Y[jp, e, a]
                    Sc[(j - 1) * m + c, jp * m + e] = w * acc


@hot
def _schur_pivoted(tabs_, h, ws_, n, m, J):
    """The Schur complement rebuilt and inverted with partial pivoting: the rare fallback of
    :func:`_schur`, called rather than inlined (a second build and a pivoted inverse inlined
    into every kernel cost compile time, not speed). Returns a status code."""
    tabs, ws = own(tabs_), own(ws_)
    _schur_build(tabs, h, ws, n, m, J)
    if invert(ws.Sc, ws.pivs, J * m) != 0:
        return SINGULAR
    return OK


@hot
def _schur(tabs_, h, ws_, n, m, J, inverse):
    """Build the Schur complement ``[h W_{jj'} G_j M̄⁻¹ G_{j'}ᵀ]`` on the impulses from
    ``ws.G`` and ``ws.Y``, and factor it, or with ``inverse`` invert it. Returns a status
    code."""
    tabs, ws = own(tabs_), own(ws_)
    if ws.si[SI_SC] != SOLVE_DENSE:  # large sparse models (banded.py)
        if schur_structured(ws_, tabs.W, h, m, J) != 0:
            return SINGULAR
        return OK
    _schur_build(tabs, h, ws, n, m, J)
    if inverse:
        # kept for the whole step: its inverse turns the back substitution of every
        # iteration (a chain of J m dependent divisions and sums) into J m independent
        # dot products; the iteration needs only an approximate inverse of its matrix.
        # Without row interchanges first: with Lobatto constraint points its diagonal
        # blocks h W_{j−1,j−1} G_j M̄⁻¹ G_{j−1}ᵀ keep the pivots away from zero; a small
        # pivot (another placement, a near-singular configuration) rebuilds it for
        # partial pivoting
        if invert_unpivoted(ws.Sc, J * m) != 0:
            return _schur_pivoted(tabs_, h, ws_, n, m, J)
    elif lu_factor_small(ws.Sc, ws.pivs, J * m) != 0:
        return SINGULAR
    return OK


@hot
def _mech_solve(md_, tabs_, h, ws_, n, m, s, J, inverse):
    r"""Overwrite the residual ``ws.R`` with ``K̃⁻¹ R`` for the mechanics matrix

        K̃ = [ (1/h) A ⊗ M̄    −B ]      (B δη)_ν = Σ_{j<J} ℓ_ν(d_j) G_jᵀ δη_j
             [      C          0 ]      (C δQ)_j = Σ_μ ℓ_μ(d_j) G_j δQ^μ

    by block elimination: ``t = h (A⁻¹ ⊗ M̄⁻¹) r_E``, the Schur complement
    ``C K⁻¹ B = [h W_{jj'} G_j M̄⁻¹ G_{j'}ᵀ]`` (from :func:`_schur`: factored, or with
    ``inverse`` inverted) solved for ``δη``, then ``δQ = t + h (A⁻¹ ⊗ M̄⁻¹) B δη``. ``C``
    uses the current ``G_j``. Returns a status code.
    """
    md, tabs, ws = own(md_), own(tabs_), own(ws_)
    R, Z, U, Y, G = ws.R, ws.Z, ws.U, ws.Y, ws.G
    Ainv, Lc = tabs.Ainv, tabs.Lc
    T = ws.fa
    sn = s * n
    for nu in range(s):
        Znu = Z[nu]
        for a in range(n):
            Znu[a] = R[nu * n + a]
        _minv(md, ws, Znu, n)
    for mu in range(s):
        for a in range(n):
            U[mu, a] = 0.0
        for nu in range(s):
            c = h * Ainv[mu, nu]
            for a in range(n):
                U[mu, a] += c * Z[nu, a]
    if m > 0 and ws.si[SI_SC] != SOLVE_DENSE:
        # the same with the pattern of G, not inlined: small models' code stays as it was
        mech_impulses_structured(ws_, Lc, Ainv, h, n, m, s, J)
    elif m > 0:
        Jm = J * m
        for j in range(1, J + 1):
            row = sn + (j - 1) * m
            for a in range(n):
                T[a] = 0.0
            for mu in range(1, s + 1):
                cl = Lc[mu, j]
                if cl != 0.0:
                    for a in range(n):
                        T[a] += cl * U[mu - 1, a]
            for c in range(m):
                acc = 0.0
                for a in range(n):
                    acc += G[j, c, a] * T[a]
                R[row + c] -= acc
        if inverse:
            w, Sc = ws.w, ws.Sc
            for i in range(Jm):
                w[i] = R[sn + i]
            for i in range(Jm):
                acc = 0.0
                for k in range(Jm):
                    acc += Sc[i, k] * w[k]
                R[sn + i] = acc
        else:
            lu_solve_small(ws.Sc, ws.pivs, R[sn:], Jm)
        for nu in range(s):
            for a in range(n):
                Z[nu, a] = 0.0
            for jp in range(J):
                cl = Lc[nu, jp]
                if cl != 0.0:
                    for e in range(m):
                        de = cl * R[sn + jp * m + e]
                        for a in range(n):
                            Z[nu, a] += Y[jp, e, a] * de
        for mu in range(s):
            for nu in range(s):
                c = h * Ainv[mu, nu]
                for a in range(n):
                    U[mu, a] += c * Z[nu, a]
    for mu in range(s):
        for a in range(n):
            R[mu * n + a] = U[mu, a]
    return OK


@hot_inline
def _exact_mechanics(md):
    """Whether the mechanics matrix of an ``s = 1`` step is its exact Newton matrix: no
    Hessian is dropped when the potential is linear in q, the mass constant and there is no
    force (the one impulse of the step acts at q_k, through the fixed G(q_k)), once its
    Schur complement is rebuilt from the current G(q_{k+1}) at every iteration."""
    flags = md.flags
    return (flags[F_LINPOT] != 0 and flags[F_MASSFN] == 0 and flags[F_AUGMENT] == 0
            and not (is_timed(md) and flags[F_FORCE] != 0))


@hot
def newton_mech(md_, tabs_, opts_, h, qk_, pk_, ws_, out_):
    """Newton-like iteration with the mechanics matrix (see :func:`_mech_solve`).

    Stops when the scaled increment of the control points is below ``tol`` (or at the
    round-off plateau), without the contraction-based early exit of :func:`newton_full`:
    this iteration converges linearly, so the error left after an increment is that
    increment times the rate, and a rate estimated from the first increments (which remove
    the predictor's error, mostly in directions the mechanics matrix treats exactly) is far
    too optimistic. An exit at a predicted ``tol`` left errors of ~tol/h in the momentum:
    a drift of 1e-12 in a conserved angular momentum over 5000 steps, 25× the full
    Newton's. Returns ``NEWTON_FAILED`` as soon as the increments shrink by less than
    ``MECH_THETA_MAX`` (the caller then takes the full Newton). ``ws.R`` ends holding the
    last increment and ``out[S_RES]`` the max-norm of the last residual evaluated.

    Where the mechanics matrix is the exact Newton matrix (:func:`_exact_mechanics`: an
    ``s = 1`` step of a conservative model with a linear potential and a constant mass),
    its Schur complement (m × m) is rebuilt at every iteration, the iteration is Newton's
    method, and it stops with the full Newton's early exit: 3.0 iterations a step for
    ``P1L-Q2G`` on the double pendulum, against 5.5 with the Schur complement of the
    predictor's G(q_{k+1}) and the strict stop (docs/decisions/0001-mechanics-newton.md).
    """
    md, ws = own(md_), own(ws_)
    opts, qk, pk, out = own(opts_), own(qk_), own(pk_), own(out_)
    X, R = ws.X, ws.R
    n, m, s, _, J = sizes(ws)
    sn = s * n
    N = sn + J * m
    tol = opts.tol
    qscale = _qscale(qk, n)
    exact = s == 1 and _exact_mechanics(md) and ws.si[SI_SC] == SOLVE_DENSE
    if m > 0:
        # here, not in the step: the step is compiled once for every workspace, and only
        # this stage knows whether G's rows are dense or on a pattern (step_kernel)
        _mech_rows(md, ws, 0, n, m)
    dprev = np.inf
    it = 0
    while it < opts.max_iter:
        it += 1
        out[S_ITERS] = it
        st = residual(md_, tabs_, h, qk, pk, as_loop_view(ws_))
        if st != OK:
            return st
        res = 0.0
        for k in range(N):
            res = max(res, abs(R[k]))
        out[S_RES] = res
        if (it == 1 or exact) and m > 0:
            # the Schur complement from the first iterate's G_j, kept for the step: the
            # constraint rows use the current G_j, so the iteration still converges to the
            # same solution, and later increments barely move the G_j. Where nothing else
            # is dropped (exact) that lag alone made the convergence linear: rebuilt then
            for j in range(1, J):
                _mech_rows(md, ws, j, n, m)
            st = _schur(tabs_, h, ws_, n, m, J, not exact)
            if st != OK:
                return st
        _mech_solve(md_, tabs_, h, ws_, n, m, s, J, not exact)
        dn = _apply_increment(X, R, N, sn, qscale)
        if not np.isfinite(dn):
            return NONFINITE
        if dn <= tol:
            return OK
        if it >= 2:
            theta = dn / dprev
            if exact and theta < 1.0 and theta / (1.0 - theta) * dn <= tol:
                return OK  # Newton's own convergence: the full Newton's early exit
            if theta >= 0.5 and dn <= 100.0 * tol:
                return OK  # round-off plateau
            if theta > MECH_THETA_MAX:
                return NEWTON_FAILED
        dprev = dn
    return NEWTON_FAILED


@hot
def _finish_mech(md_, tabs_, h, qk, ws_, q1, n, m, s, J):
    """After :func:`newton_mech`: q1, g(q1), G(q1) and ``D_s`` at the final unknowns.

    ``ws.D`` was assembled one increment ``δ = ws.R`` earlier; instead of a second full
    residual, its mass part is moved along ``δ`` exactly for a constant ``M`` (to
    O(|δ| h |∂M/∂q|) otherwise): ``D_s −= (1/h) Σ_μ Am[s−1, μ−1] M̄ δQ^μ`` (the last row of
    the residual's own mass block). The force part moves by
    O(h |∂F/∂q| |δ|), below round-off of the momentum. Returns max|g(q1)|.
    """
    md, tabs, ws = own(md_), own(tabs_), own(ws_)
    fns, flags, Mc, prm = md.fns, md.flags, md.Mc, md.prm
    X, R, D, G = ws.X, ws.R, ws.D, ws.G
    Ks = tabs.Am[s - 1]
    inv_h = 1.0 / h
    for a in range(n):
        q1[a] = qk[a] + X[(s - 1) * n + a]
    dv = ws.fa
    for a in range(n):
        acc = 0.0
        for mu in range(s):
            acc += Ks[mu] * R[mu * n + a]
        dv[a] = acc * inv_h
    if flags[F_DIAG] != 0:
        for a in range(n):
            D[s, a] -= Mc[a, a] * dv[a]
    else:
        Mb = Mc if flags[F_MASSFN] == 0 else ws.Mi
        if flags[F_MASSFN] != 0:
            fns[MASS](ptr(qk), ptr(qk), ptr(prm), ptr(Mb))
        for a in range(n):
            acc = 0.0
            for c in range(n):
                acc += Mb[a, c] * dv[c]
            D[s, a] -= acc
    gmax = 0.0
    if m > 0:
        gj = ws.g
        _at(md, ws, h, 1.0)
        fns[CON](ptr(q1), ptr(q1), ptr(prm), ptr(gj))
        fns[CJAC](ptr(q1), ptr(q1), ptr(prm), ptr(G[J]))
        for a in range(m):
            gmax = max(gmax, abs(gj[a]))
    return gmax


# ----------------------------------------------------------------------------- one step
@hot
def step(md_, tabs_, opts_, h, state_, ws_, first, out_, stages_):
    """Advance ``state`` rows (q_k, p_k, v_k) by one step into rows 3–5 (q1, p1, v1).

    ``out`` (float64, ``STEP_OUT_SIZE``) receives the Newton iterations, max|g(q1)|,
    max|G(q1) v1|, the max-norm of the last residual and 1 if the step used the full
    Newton as a fallback. Returns a status code (0 on success).
    """
    md, tabs, ws = own(md_), own(tabs_), own(ws_)
    opts, state, out, stages = own(opts_), own(state_), own(out_), own(stages_)
    fns, prm = md.fns, md.prm
    qk, pk, vk, q1, p1, v1 = state[0], state[1], state[2], state[3], state[4], state[5]
    X, R, D, G = ws.X, ws.R, ws.D, ws.G
    Lc = tabs.Lc
    n, m, s, _, J = sizes(ws)
    sn = s * n
    N = sn + J * m

    if m > 0:
        G0 = G[0]
        if first:
            _at(md, ws, h, 0.0)
            fns[CJAC](ptr(qk), ptr(qk), ptr(prm), ptr(G0))
        else:
            # the previous step ended with G at q(d_J) = q_k, bit for bit, and its
            # end_momentum left it in G0 (a failed step leaves G0 alone: still G(q_k))
            pass
    if first or ws.hold[H_FG] == 0:
        linear_force(md, ws, qk)
        ws.hold[H_FG] = 1
    out[S_FULL] = 0.0
    full = opts.mode == NEWTON_FULL or ws.hold[H_FULL] > 0 or not tabs.mech
    if full and stages.full == 0:
        return NEEDS_FULL_NEWTON
    if ws.hold[H_FULL] > 0:
        ws.hold[H_FULL] -= 1
    used = 0.0
    gmax = 0.0
    if not full:
        st = _mass_bar(md, qk, ws, n)
        if st == OK:
            predict(tabs_, n, m, h, vk, ws_, 0 if first else ws.hold[H_HIST])
            st = stages.newton_mech(md_, tabs_, opts_, h, byref(qk), byref(pk), ws_, out_)
        if st == OK:
            gmax = _finish_mech(md_, tabs_, h, qk, ws_, q1, n, m, s, J)
        else:
            if stages.full == 0:
                return NEEDS_FULL_NEWTON  # before anything of this step is kept
            # too slow a contraction (stiff forces) or a failure: the full Newton, which
            # then stays on for a while rather than paying this detour at every step
            used = out[S_ITERS]
            full = True
            ws.hold[H_FULL] = FULL_HOLD
            out[S_FULL] = 1.0
    if full:
        order = 0 if first else ws.hold[H_HIST]
        while True:
            # An extrapolated polynomial can be far off (stiff oscillations with ωh > 1, a
            # sudden turn, a long step: the two-step one first): start again from a guess
            # of lower degree, down to the straight line through q_k with velocity v_k.
            # (One call site of newton_full: the sized step inlines it, assembly and all.)
            predict(tabs_, n, m, h, vk, ws_, order)
            st = stages.newton_full(md_, tabs_, opts_, h, byref(qk), byref(pk), ws_, out_)
            if st == OK or order == 0:
                break
            used += out[S_ITERS]
            order -= 1
        out[S_ITERS] += used
        if st != OK:
            return st
        # newton_full ended with the residual at the converged unknowns: exact D_s for the
        # momentum, and g(q1)
        for a in range(n):
            q1[a] = qk[a] + X[(s - 1) * n + a]
        for a in range(m):
            gmax = max(gmax, abs(R[sn + (J - 1) * m + a]))

    # P = D_s − Σ_{j<J} ℓ_s(d_j) G_jᵀ η_j
    P = ws.P
    for a in range(n):
        P[a] = D[s, a]
    for j in range(1, J):
        cl = Lc[s, j]
        if cl != 0.0:
            for a in range(n):
                acc = 0.0
                for c in range(m):
                    acc += G[j, c, a] * X[sn + j * m + c]
                P[a] -= cl * acc
    G1 = G[J]
    st = stages.end_momentum(md_, byref(q1), byref(P), byref(p1), byref(v1), byref(G1), ws_, out_)
    if st != OK:
        return st
    out[S_G] = gmax
    out[S_WORK] = 0.0
    out[S_WORK_F] = 0.0
    if is_timed(md):
        out[S_WORK] = stages.step_work(md_, tabs_, h, byref(qk), byref(q1), ws_, n, m, s, J,
                                       out_)
    # keep this step's unknowns (and the last step's) for the next predictor
    Xp, Xpp = ws.Xprev, ws.Xpp
    for k in range(N):
        Xpp[k] = Xp[k]
        Xp[k] = X[k]
    ws.hold[H_HIST] = 1 if first else min(ws.hold[H_HIST] + 1, 2)
    ws.hist[1] = ws.hist[0]
    ws.hist[0] = h
    return OK


@hot_inline
def velocity_residual(G1, v1, n, m):
    """max_a |(G v)_a|."""
    gv = 0.0
    for a in range(m):
        acc = 0.0
        for c in range(n):
            acc += G1[a, c] * v1[c]
        gv = max(gv, abs(acc))
    return gv


@hot_inline
def hidden_residual(G1, v1, gt, n, m):
    """max_a |(G v + g_t)_a|: the hidden constraint of a (possibly rheonomic) constraint."""
    gv = 0.0
    for a in range(m):
        acc = gt[a]
        for c in range(n):
            acc += G1[a, c] * v1[c]
        gv = max(gv, abs(acc))
    return gv


@hot
def _step_work(md_, tabs_, h, qk_, q1_, ws_, n, m, s, J, out_):
    r"""The work done on the system over the step (``docs/method.md`` §11, energy balance)::

        W = h Σ_i b_i [F(t_i, q_i, v_i)·v_i + ∂V/∂t(t_i, q_i)] + Σ_{j≤J} η_j·g_t(t_j, q(d_j))

    on the converged step polynomial, with the action's quadrature for the forces and the
    time-dependent potential, and the constraint impulses (``η_J`` the projection's) for
    driving constraints: the constraint force ``−Gᵀλ`` has power ``−λ·Gv = λ·g_t``. The
    first term alone, the work of the applied forces, goes to ``out[S_WORK_F]`` (summed
    apart, so that the total is the same sum as ever).
    """
    md, tabs, ws = own(md_), own(tabs_), own(ws_)
    qk, out = own(qk_), own(out_)
    fns, flags, prm = md.fns, md.flags, md.prm
    b, L, Ld, Lc = tabs.b, tabs.L, tabs.Ld, tabs.Lc
    X, qi, vi, fb = ws.X, ws.qi, ws.vi, ws.fb
    timed = flags[F_TIME] != 0
    inv_h = 1.0 / h
    w = 0.0
    wf = 0.0
    r = sizes(ws)[3]
    for i in range(r):
        ti = ws.time[0] + tabs.c[i] * h
        for a in range(n):
            qi[a] = qk[a]
            vi[a] = 0.0
        for nu in range(1, s + 1):
            cl = L[nu, i]
            cd = Ld[nu, i] * inv_h
            off = (nu - 1) * n
            for a in range(n):
                x = X[off + a]
                qi[a] += cl * x
                vi[a] += cd * x
        p = 0.0
        if flags[F_FORCE] != 0:
            prm[flags[F_TSLOT]] = ti
            fns[FORCE](ptr(qi), ptr(vi), ptr(prm), ptr(fb))
            for a in range(n):
                p += fb[a] * vi[a]
            wf += h * b[i] * p
        if timed:
            _d_dt(md, fns[POT], qi, ti, fb, ws.fa, 1)
            p += fb[0]
        w += h * b[i] * p
    if timed and m > 0:
        sn = s * n
        gt = ws.Gp[0]  # (n,) row of scratch, m ≤ n entries used
        for j in range(J):
            for a in range(n):
                qi[a] = qk[a]
            for nu in range(1, s + 1):
                cl = Lc[nu, j]
                if cl != 0.0:
                    off = (nu - 1) * n
                    for a in range(n):
                        qi[a] += cl * X[off + a]
            constraint_rate(md, qi, ws.time[0] + tabs.d[j] * h, gt, ws.g)
            for c in range(m):
                w += X[sn + j * m + c] * gt[c]
        for c in range(m):
            w += ws.etaJ[c] * ws.gt[c]
    out[S_WORK_F] = wf
    return w


@hot
def end_momentum(md_, q1_, P_, p1_, v1_, G1_, ws_, out_):
    """p1 = P − G1ᵀ η with (G M⁻¹ Gᵀ) η = G M⁻¹ P (+ g_t at t_{k+1} for a rheonomic
    constraint), and v1 = M⁻¹ p1: the hidden constraint G v1 + g_t = 0.

    Also, once the step has succeeded: ``out[S_GV]`` = max|G1 v1 + g_t| and
    ``ws.G[0]`` = G1, where the next step starts. In the structured path both run over the
    pattern of G inside :func:`.banded.project_structured` (O(nnz), not O(m n)), so a small
    model's step has no code for it (a branch and a call for it in the step cost the
    generic double-pendulum step 9–19 %, measured side by side)."""
    md, ws = own(md_), own(ws_)
    q1, P, p1, v1, G1, out = own(q1_), own(P_), own(p1_), own(v1_), own(G1_), own(out_)
    fns, flags, Mc, prm = md.fns, md.flags, md.Mc, md.prm
    n, m, _, _, _ = sizes(ws)
    if ws.si[SI_S] != SOLVE_DENSE:  # large sparse models, diagonal mass (banded.py)
        rheonomic = is_timed(md) and flags[F_TIME] != 0
        if rheonomic:
            constraint_rate(md, q1, ws.time[1], ws.gt, ws.g)
        return project_structured(Mc, q1, P, p1, v1, G1, ws_, n, m, rheonomic, out)
    Mlu = ws.Ma
    pivn = ws.pivp
    Y = ws.Gp
    S = ws.S
    pivm = ws.pivm
    diag = flags[F_DIAG] != 0 and flags[F_AUGMENT] == 0  # M⁻¹ elementwise
    minv = ws.minv
    if diag:
        _inverse_diagonal(md, ws, n)
        for a in range(n):
            v1[a] = P[a] * minv[a]  # z = M⁻¹ P
    else:
        if flags[F_MASSFN] != 0:
            fns[MASS](ptr(q1), ptr(q1), ptr(prm), ptr(Mlu))
        elif flags[F_AUGMENT] != 0:
            augmented_mass(Mc, G1, Mlu, n, m)
        else:
            for a in range(n):
                for c in range(n):
                    Mlu[a, c] = Mc[a, c]
        if lu_factor_small(Mlu, pivn, n) != 0:
            return SINGULAR_MASS
        for a in range(n):
            v1[a] = P[a]
        lu_solve_small(Mlu, pivn, v1, n)  # z = M⁻¹ P
    if m > 0:
        for c in range(m):
            Yc = Y[c]
            for a in range(n):
                Yc[a] = G1[c, a]
            if diag:
                for a in range(n):
                    Yc[a] *= minv[a]
            else:
                lu_solve_small(Mlu, pivn, Yc, n)  # row c of (M⁻¹ Gᵀ)ᵀ
        eta = ws.etaJ
        rheonomic = is_timed(md) and flags[F_TIME] != 0
        if rheonomic:
            # G v1 + g_t = 0 at t_{k+1}: (G M⁻¹ Gᵀ) η = G M⁻¹ P + g_t (docs/method.md §11)
            constraint_rate(md, q1, ws.time[1], ws.gt, ws.g)
        for c in range(m):
            acc = ws.gt[c] if rheonomic else 0.0
            for a in range(n):
                acc += G1[c, a] * v1[a]
            eta[c] = acc
            for d in range(m):
                acc = 0.0
                for a in range(n):
                    acc += G1[c, a] * Y[d, a]
                S[c, d] = acc
        if lu_factor_small(S, pivm, m) != 0:
            return SINGULAR_CONSTRAINTS
        lu_solve_small(S, pivm, eta, m)
        for a in range(n):
            acc = 0.0
            acc2 = 0.0
            for c in range(m):
                acc += G1[c, a] * eta[c]
                acc2 += Y[c, a] * eta[c]
            p1[a] = P[a] - acc
            v1[a] -= acc2
        if flags[F_AUGMENT] != 0:
            # v1 is that of M itself, and its momentum M v1 = P − G1ᵀ(η − W g_t): the
            # multiplier of M̄ differs by W g_t for a rheonomic constraint
            for a in range(n):
                acc = 0.0
                for c in range(n):
                    acc += Mc[a, c] * v1[c]
                p1[a] = acc
    else:
        for a in range(n):
            p1[a] = P[a]
    for a in range(n):
        if not (np.isfinite(p1[a]) and np.isfinite(v1[a])):
            return NONFINITE
    out[S_GV] = hidden_residual(G1, v1, ws.gt, n, m)
    G0 = ws.G[0]
    for c in range(m):
        for a in range(n):
            G0[c, a] = G1[c, a]
    return OK


# ----------------------------------------------------------------------------- entry point
#: the compiled step of each kernel type — (model, options, sizes) as :func:`step_kernel`
#: keys them: one step for small and large models alike
_STEPS: dict = {}
#: the stages of a kernel type and plan (dense or structured) compiled so far:
#: ((kernel type, structured), stage name) -> C function; "base" -> the :class:`Stages`
#: with placeholders in the optional ones
_OPTIONAL: dict = {}
#: the sized stages looked up in numba's disk cache and not found there, in this process
_NOT_CACHED: set = set()


#: the step's three large stages, compiled as C functions and called by address from the
#: step's entry point (:func:`step_kernel`): each compiled once, not again inside its caller
#: (``full``: 1, or 0 while ``newton_full`` is a placeholder that no step calls — a step
#: that needs it returns ``NEEDS_FULL_NEWTON`` first)
#: ``step_work``, the work of forces and time over a step, is compiled only for a model
#: with forces or time (a placeholder that no conservative step calls otherwise).
Stages = namedtuple("Stages", ["newton_mech", "newton_full", "end_momentum", "step_work",
                               "full"])


def _no_full_newton(md_, tabs_, opts_, h, qk_, pk_, ws_, out_):
    return NEEDS_FULL_NEWTON


def _no_work(md_, tabs_, h, qk_, q1_, ws_, n, m, s, J, out_):
    return 0.0


def cached_cfunc(fn, sig, compile=True, allocates=False):
    """``fn`` as a C function of signature ``sig``, cached on disk; with ``compile`` false,
    only if numba's disk cache holds it (else None, and nothing is compiled). Without
    numba's reference counting unless ``allocates`` (a function that allocates its own
    arrays needs it to free them).

    What ``numba.cfunc(sig, cache=True)`` does, with its cache lookup apart (numba's
    ``CFunc.compile`` takes the same steps)."""
    cf = CFunc(fn, sigutils.normalize_signature(sig), locals={},
               options=dict(error_model="numpy", boundscheck=False, _nrt=allocates))
    cf.enable_caching()
    if compile:
        cf.compile()
        return cf
    try:
        cres = cf._cache.load_overload(cf._sig, cf._targetdescr.target_context)
    except Exception:  # noqa: BLE001 - an unreadable cache is a cache miss
        cres = None
    if cres is None:
        return None
    cf._library = cres.library
    cf._wrapper_name = cres.fndesc.llvm_cfunc_wrapper_name
    cf._wrapper_address = cf._library.get_pointer_to_function(cf._wrapper_name)
    return cf


class _TwinStage(CalledAs):
    """A stage compiled for a twin of the workspace type the step is compiled for, called
    through the step's own stage signature: the size-specialized twin
    (:func:`.layout.specialize`) or the structured one (a plan with banded or sparse
    solves, :func:`.layout.loop_view`).

    numba types it as the generic stage (a first-class function of that signature), so the
    step and the time loops that hold it are not compiled again for it. The twins have the
    workspace's layout, field for field (``tests/test_sparse.py`` compares the offsets): the
    sizes and the plan's kind are read from the type, never from memory, so a pointer to
    the generic workspace serves the twin's code as it is."""


#: the stages compiled for a workspace's sizes where :func:`step_kernel` is asked to
#: (``sized``): the mechanics iteration and the end projection, where a small model's
#: step spends its time in loops of 2–12 iterations — or, for a run that always takes the
#: full Newton (``newton="full"``, a method without the mechanics matrix), the full Newton
#: in place of the mechanics iteration. The step itself and the time loops stay generic:
#: sizing the step too saved 8–10 % for 3 s more of compiling per size
#: (``docs/decisions/0012-sized-stages.md``).
SIZED_STAGES = ("newton_mech", "end_momentum")
SIZED_STAGES_FULL = ("newton_full", "end_momentum")


def _stage_signatures(md, tabs, opts, ws):
    """The C signatures of the stages for workspaces of the type of ``ws``."""
    P, arg, i64, f64 = types.CPointer, numba.typeof, types.int64, types.float64
    tmd, ttabs, topts, tws = P(arg(md)), P(arg(tabs)), P(arg(opts)), P(arg(ws))
    a1, a2 = P(arg(np.zeros(1))), P(arg(np.zeros((1, 1))))
    return dict(newton_mech=i64(tmd, ttabs, topts, f64, a1, a1, tws, a1),
                newton_full=i64(tmd, ttabs, topts, f64, a1, a1, tws, a1),
                end_momentum=i64(tmd, a1, a1, a1, a1, a2, tws, a1),
                step_work=f64(tmd, ttabs, f64, a1, a1, tws, i64, i64, i64, i64, a1))


def _sized(key, md, tabs, opts, ws, stages, compile):
    """``stages`` with :data:`SIZED_STAGES` (or :data:`SIZED_STAGES_FULL`) compiled for the
    sizes of ``ws``: compiled now with ``compile``, else only if in this process or numba's
    disk cache; else None."""
    names = SIZED_STAGES_FULL if opts.mode == NEWTON_FULL or not tabs.mech else SIZED_STAGES
    skey = (key, "sized", _key(layout_specialize(ws).dims), names)
    if skey not in _OPTIONAL and not compile and skey in _NOT_CACHED:
        return None  # looked up once in this process: a lookup costs a few ms a call
    if skey not in _OPTIONAL:
        generic = _stage_signatures(md, tabs, opts, ws)
        sized = _stage_signatures(md, tabs, opts, layout_specialize(ws))
        fns = dict(newton_mech=newton_mech, newton_full=newton_full, end_momentum=end_momentum)
        entries = {}
        for name in names:
            cf = cached_cfunc(fns[name].py_func, sized[name], compile)
            if cf is None:
                _NOT_CACHED.add(skey)
                return None
            entries[name] = _TwinStage(cf, generic[name])
        _OPTIONAL[skey] = entries
    return stages._replace(**_OPTIONAL[skey])


def step_kernel(md, tabs, opts, ws, full=False, sized=False):
    """The step for these kinds of model, method, options and workspace, compiled once as a
    C function (cached on disk) that the time loops call through its address; and the
    :class:`Stages` it calls. Returns ``(step, stages)``.

    The step's arguments are pointers (:func:`fastvi._numba.byref`) to ``md``, ``tabs``,
    ``opts``, ``state``, ``ws``, ``out`` and ``stages``, with ``h`` and ``first`` by value;
    it returns the step's status code. Every time loop — :func:`.drive.run`, the ensemble's
    members, a recovery's substeps — calls this one compiled step: numba links a callee's
    code into each of its callers and optimises it again there, so a step called directly
    would be compiled once more in every loop, and so would its stages inside the step. The
    workspace's sizes (integers, or size markers with ``specialize=True``) are part of its
    type: one generic step serves every model.

    Whether the plan is structured (banded or sparse solves, a large model's) is not: the
    step and the time loops take the workspace's loop view (:func:`.layout.loop_view`, which
    callers pass them), and only the stages that solve — the mechanics iteration, the full
    Newton, the end projection — are compiled for the structured workspace, as twins
    (:class:`_TwinStage`) that the same step calls. A process that runs small and large
    models compiles the step and its time loops once.

    The full Newton is compiled only when ``full`` is true, ``opts`` asks for it or the
    method's mechanics matrix is singular (or it is compiled already, for a workspace that
    has its fields): most runs never take it, and its assembly is a fifth of the step's
    code. Stages that take it allocate the fields a workspace made without them
    (:func:`.layout.fit_newton_fields`). Until then a step that would need it
    returns ``NEEDS_FULL_NEWTON`` with nothing kept, and the driver asks again with
    ``full=True`` and retakes the step — the same trajectory, bit for bit. The work of forces
    and time over a step is compiled only for a model with forces or time.

    ``sized``: ``True`` compiles the stages of :data:`SIZED_STAGES` for the sizes of ``ws``
    (compile-time constants, :func:`.layout.specialize`) and puts them in ``stages``;
    ``"cached"`` does so only if they are compiled already (in this process or in numba's
    disk cache); ``False`` keeps the generic stages. The sized stages do the same
    arithmetic in the same order: the trajectory is the same bit for bit. A structured plan
    keeps the generic stages.
    """
    key = (_key(md), _key(opts), _key(ws.dims))
    plan = (key, ws.structured is not None)
    # compiled already, the full Newton is taken from the start — but not by a workspace
    # made without its fields (layout.unused_fields): that one gets it on a step's first
    # need, the same trajectory, and holds its memory only if a step takes it
    compiled = (plan, "newton_full") in _OPTIONAL and ws.A.size > 0
    full = full or opts.mode == NEWTON_FULL or not tabs.mech or compiled
    timed = md.flags[F_FORCE] != 0 or md.flags[F_TIME] != 0
    # the work of forces and time solves nothing: one stage for both plans
    wanted = [(where, name) for where, name, want in ((plan, "newton_full", full),
                                                      ((key, False), "step_work", timed))
              if want and (where, name) not in _OPTIONAL]
    if key not in _STEPS or (plan, "base") not in _OPTIONAL or wanted:
        with quiet():  # typing the callbacks draws numba's first-class-function note
            _compile(key, plan, md, tabs, opts, ws, wanted)
    stepk, stages = _STEPS[key], _OPTIONAL[(plan, "base")]
    if full:
        stages = stages._replace(newton_full=_OPTIONAL[(plan, "newton_full")], full=1)
        fit_newton_fields(ws, md.flags)  # of a workspace made without them (layout.unused_fields)
    if timed:
        stages = stages._replace(step_work=_OPTIONAL[((key, False), "step_work")])
    if sized and ws.structured is None:
        with quiet():
            stages = _sized(key, md, tabs, opts, ws, stages, sized is True) or stages
    return stepk, stages


def _compile(key, plan, md, tabs, opts, ws, wanted):
    """The step of kernel type ``key`` (if not compiled yet), the base :class:`Stages` of
    ``plan`` (if not compiled yet) and the optional stages ``wanted`` (``(where, name)``
    pairs), into :data:`_STEPS` and :data:`_OPTIONAL`."""
    P, arg, i64, f64 = types.CPointer, numba.typeof, types.int64, types.float64
    view = loop_view(ws)
    sigs = _stage_signatures(md, tabs, opts, view)
    twin = _stage_signatures(md, tabs, opts, ws) if plan[1] else None

    def stage(fn, name):
        if twin is None:
            return cached_cfunc(fn.py_func, sigs[name])
        return _TwinStage(cached_cfunc(fn.py_func, twin[name]), sigs[name])

    if (plan, "base") not in _OPTIONAL:
        _OPTIONAL[(plan, "base")] = Stages(stage(newton_mech, "newton_mech"),
                                           cached_cfunc(_no_full_newton, sigs["newton_full"]),
                                           stage(end_momentum, "end_momentum"),
                                           cached_cfunc(_no_work, sigs["step_work"]), 0)
    if key not in _STEPS:
        # typed by the stages' signatures alone: every plan's stages fit the one step
        stages = Stages(*(CalledAs(None, sigs[name]) for name in Stages._fields[:-1]), 0)
        # the step's own body becomes the C function (not a call of the njit `step`, whose
        # code numba would compile once more into the wrapper)
        sig = i64(P(arg(md)), P(arg(tabs)), P(arg(opts)), f64, P(arg(np.zeros((1, 1)))),
                  P(arg(view)), types.boolean, P(arg(np.zeros(1))), P(arg(stages)))
        _STEPS[key] = cached_cfunc(step.py_func, sig)
    for where, name in wanted:
        if name == "newton_full":
            _OPTIONAL[(where, name)] = stage(newton_full, name)
        else:
            _OPTIONAL[(where, name)] = cached_cfunc(_step_work.py_func, sigs[name])


@hot
def take_step(md, tabs, opts, h, state, ws, first, out, stepk, stages):
    """One step through the compiled entry point ``stepk`` and its ``stages``
    (:func:`step_kernel`), for callers other than the time loops: tests and profiles, from
    Python or from their own compiled loops. Arguments as :func:`step`, by value; ``ws``
    as the time loops take it (:func:`.layout.loop_view`)."""
    return stepk(byref(md), byref(tabs), byref(opts), h, byref(state), byref(ws), first,
                 byref(out), byref(stages))


def step_once(md, tabs, opts, h, state, ws, first, out):
    """:func:`take_step` from Python with the kernels of :func:`step_kernel` (the full Newton
    included): advance ``state`` rows (q, p, v) by one step into rows 3–5; returns the
    status code."""
    with quiet():
        return take_step(md, tabs, opts, h, state, loop_view(ws), first, out,
                         *step_kernel(md, tabs, opts, ws, full=True))
