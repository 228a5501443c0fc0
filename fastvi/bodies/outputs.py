r"""What a mechanism's trajectory means: poses, velocities, energies, momenta, reactions.

Every function takes the model built by :meth:`fastvi.bodies.Mechanism.build` and either a
:class:`fastvi.Result` or arrays ``q`` (and ``v`` where velocities enter), one state ``(n,)``
or one per row ``(K, n)``; the result has the matching leading shape. Body frames are the
user's (the principal frame of the directors is turned back: ``R = [d₁ d₂ d₃] Pᵀ``).

===========================  =============================================================
function                     value
===========================  =============================================================
:func:`position`             ``x = φ + X_I d_I`` of a body point (default: the centre of mass)
:func:`rotation`             ``R`` (body frame → world)
:func:`angular_velocity`     ``ω = ½ Σ_I d_I × ḋ_I`` (world) or ``Ω = Rᵀ ω`` (body frame)
:func:`kinetic_energy`       ``½ vᵀ M v``
:func:`potential_energy`     ``V(t, q)``: gravity and springs
:func:`linear_momentum`      ``Σ m φ̇``
:func:`angular_momentum`     ``Σ m (φ − o) × φ̇ + Σ_I E_I d_I × ḋ_I`` about a point ``o``
:func:`joint_coordinate`     a revolute joint's angle, a prismatic joint's displacement
:func:`reactions`            force and torque a joint exerts on its body ``b``
===========================  =============================================================

**Reactions.** :class:`fastvi.Result` does not carry the step's multipliers, so
:func:`reactions` computes the multipliers of the *continuous* equations of motion at each
sampled state, from the saddle-point system

.. math::

    \begin{pmatrix} M & G^T \\ G & 0 \end{pmatrix}
    \begin{pmatrix} a \\ λ \end{pmatrix} =
    \begin{pmatrix} -∇V + F \\ -γ \end{pmatrix}, \qquad
    γ = \ddot g - G a \;\;(\text{the constraints' second derivative at } a = 0),

and maps the joint's rows through ``−G_jᵀ λ_j`` to a force and a torque on its body (a
generalized force ``f_I`` on director ``d_I`` is the torque ``Σ_I d_I × f_I``). With redundant
rows dropped, the reactions are *one* of the many that balance the mechanism (Wojtyra 2005):
the dropped rows carry none.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from . import packing as pk
from .rigid import Body, Ground

__all__ = ["position", "rotation", "angular_velocity", "kinetic_energy", "potential_energy",
           "linear_momentum", "angular_momentum", "joint_coordinate", "reactions"]


def _assembly(model):
    asm = getattr(model, "assembly", None)
    if asm is None:
        raise TypeError("`model` must be built by fastvi.bodies.Mechanism.build (it has no `assembly`)")
    return asm


def _states(model, data, v=None, need_v=False, t=None):
    """``(q, v, t, single)``: the samples of a Result, or the given arrays as (K, n) (at the
    times ``t``, default 0)."""
    if hasattr(data, "q") and hasattr(data, "t"):
        q, v, t = data.q, data.v, data.t
        single = False
    else:
        q = np.asarray(data, dtype=float)
        single = q.ndim == 1
        q = np.atleast_2d(q)
        v = None if v is None else np.atleast_2d(np.asarray(v, dtype=float))
        t = np.broadcast_to(np.asarray(0.0 if t is None else t, dtype=float), (q.shape[0],))
    if q.shape[-1] != model.n:
        raise ValueError(f"`q` must have n = {model.n} columns, got shape {q.shape}")
    if need_v:
        if v is None:
            raise ValueError("this output needs the velocities: pass a Result or `v`")
        if v.shape != q.shape:
            raise ValueError(f"`v` must have the shape of `q` {q.shape}, got {v.shape}")
    return q, v, t, single


def _out(x, single):
    return x[0] if single else x


def _directors(q, o):
    """``D`` (K, 3, 3): the directors as columns."""
    return np.stack([q[:, o + 3: o + 6], q[:, o + 6: o + 9], q[:, o + 9: o + 12]], axis=-1)


def _rigid(asm, body, what):
    b = asm.body(body)
    if not isinstance(b, Body):
        raise ValueError(f"{what} needs a rigid body; {b.name!r} is a point mass")
    return b


def position(model, data, body, point=None):
    """World position of ``point`` (body frame; default the centre of mass) of ``body``."""
    asm = _assembly(model)
    q, _, _, single = _states(model, data)
    b = asm.body(body)
    o = asm.offsets[b]
    x = q[:, o: o + 3].copy()
    if point is not None:
        if not isinstance(b, Body):
            raise ValueError(f"point mass {b.name!r} has no body frame: give no `point`")
        x += _directors(q, o) @ b.to_principal(point)
    return _out(x, single)


def rotation(model, data, body):
    """``R`` (…, 3, 3): the body frame in the world (columns: the body's axes)."""
    asm = _assembly(model)
    q, _, _, single = _states(model, data)
    b = _rigid(asm, body, "rotation")
    return _out(_directors(q, asm.offsets[b]) @ b.axes.T, single)


def angular_velocity(model, data, body, v=None, frame: str = "space"):
    r"""``ω = ½ Σ_I d_I × ḋ_I`` (``frame="space"``) or ``Ω = Rᵀ ω`` (``frame="body"``)."""
    if frame not in ("space", "body"):
        raise ValueError(f"`frame` must be 'space' or 'body', got {frame!r}")
    asm = _assembly(model)
    q, v, _, single = _states(model, data, v, need_v=True)
    b = _rigid(asm, body, "angular_velocity")
    o = asm.offsets[b]
    w = 0.5 * sum(np.cross(q[:, o + 3 * i: o + 3 * i + 3], v[:, o + 3 * i: o + 3 * i + 3])
                  for i in (1, 2, 3))
    if frame == "body":
        R = _directors(q, o) @ b.axes.T
        w = np.einsum("kji,kj->ki", R, w)
    return _out(w, single)


def _mass_diag(model):
    return np.diag(model.mass_matrix_constant)


def kinetic_energy(model, data, v=None):
    """``T = ½ vᵀ M v``."""
    q, v, _, single = _states(model, data, v, need_v=True)
    return _out(0.5 * np.einsum("ki,i,ki->k", v, _mass_diag(model), v), single)


def potential_energy(model, data, t=None):
    """``V(t, q)``: gravity and springs."""
    q, _, ts, single = _states(model, data, t=t)
    return _out(np.array([model.potential_energy(qk, t=float(tk)) for qk, tk in zip(q, ts)]), single)


def linear_momentum(model, data, v=None):
    """``Σ_b m_b φ̇_b`` (…, 3)."""
    asm = _assembly(model)
    q, v, _, single = _states(model, data, v, need_v=True)
    total = sum(b.mass * v[:, asm.offsets[b]: asm.offsets[b] + 3] for b in asm.bodies)
    return _out(total, single)


def angular_momentum(model, data, v=None, about=(0.0, 0.0, 0.0)):
    r"""``L = Σ_b m_b (φ_b − o) × φ̇_b + Σ_I E_I d_I × ḋ_I`` about the point ``o`` (…, 3);
    the second sum is ``J ω`` of each rigid body about its centre of mass."""
    asm = _assembly(model)
    q, v, _, single = _states(model, data, v, need_v=True)
    o_pt = np.asarray(about, dtype=float)
    L = np.zeros((q.shape[0], 3))
    for b in asm.bodies:
        o = asm.offsets[b]
        L += b.mass * np.cross(q[:, o: o + 3] - o_pt, v[:, o: o + 3])
        if isinstance(b, Body):
            for i in range(3):
                s = slice(o + 3 + 3 * i, o + 6 + 3 * i)
                L += b.second_moments[i] * np.cross(q[:, s], v[:, s])
    return _out(L, single)


def _world_dir(q, body, asm, u):
    if isinstance(body, Ground):
        return np.broadcast_to(u, (q.shape[0], 3))
    return _directors(q, asm.offsets[body]) @ u


def _world_point(q, body, asm, X):
    if isinstance(body, Ground):
        return np.broadcast_to(X, (q.shape[0], 3))
    o = asm.offsets[body]
    x = q[:, o: o + 3]
    return x + _directors(q, o) @ X if isinstance(body, Body) else x


def joint_coordinate(model, data, joint):
    r"""A joint's coordinate from the configuration: the angle ``atan2(b₁·n₂, b₁·n₁)`` of a
    revolute (or driven revolute) joint, the displacement ``a·(x_B − x_A)`` of a prismatic
    joint, both ``(θ, s)`` of a cylindrical joint; measured from the reference configuration."""
    asm = _assembly(model)
    q, _, _, single = _states(model, data)
    j = asm.joint(joint)
    angle = shift = None
    if j.kind in ("revolute", "driven_revolute", "cylindrical"):
        b1 = _world_dir(q, j.b, asm, j.frame_b[:, 1])
        n1 = _world_dir(q, j.a, asm, j.frame_a[:, 1])
        n2 = _world_dir(q, j.a, asm, j.frame_a[:, 2])
        angle = np.arctan2(np.einsum("ki,ki->k", b1, n2), np.einsum("ki,ki->k", b1, n1))
    if j.kind in ("prismatic", "driven_prismatic", "cylindrical"):
        a = _world_dir(q, j.a, asm, j.frame_a[:, 0])
        r = _world_point(q, j.b, asm, j.point_b) - _world_point(q, j.a, asm, j.point_a)
        shift = np.einsum("ki,ki->k", a, r)
    if angle is None and shift is None:
        raise ValueError(f"joint_coordinate: the {j.kind} joint {j.name!r} has no single coordinate "
                         "(revolute, prismatic and cylindrical joints have)")
    value = np.stack([angle, shift], axis=-1) if angle is not None and shift is not None else (
        angle if angle is not None else shift)
    return _out(value, single)


# ----------------------------------------------------------------------------- reactions
def _row_values(records, q, v):
    """Per row and term: ``U, W`` at ``q`` and their rates ``U̇, Ẇ`` (vectorized over rows)."""
    m = records.shape[0]
    cols = np.full((m, pk.SLOTS), -1, dtype=int)
    for j in range(pk.SLOTS):
        off = records[:, pk.R_OFFA] if j < 4 else records[:, pk.R_OFFB]
        count = records[:, pk.R_NA] if j < 4 else records[:, pk.R_NB]
        ok = (j % 4) < count
        cols[ok, j] = off[ok].astype(int) + 3 * (j % 4)
    safe = np.where(cols >= 0, cols, 0)
    gather = safe[:, :, None] + np.arange(3)
    Q = np.where(cols[:, :, None] >= 0, q[gather], 0.0)  # (m, 8, 3)
    V = np.where(cols[:, :, None] >= 0, v[gather], 0.0)

    def ev(base):
        w = records[:, base: base + pk.SLOTS]
        c = records[:, base + pk.SLOTS: base + pk.EXPR]
        return np.einsum("aj,ajc->ac", w, Q) + c, np.einsum("aj,ajc->ac", w, V)

    return [ev(b) for b in (pk.R_U1, pk.R_W1, pk.R_U2, pk.R_W2)]


def _gamma(asm, records, q, v, t):
    r"""``γ = g̈ − G a``: for a term ``f(t) U·W``, ``2 f U̇·Ẇ + 2 ḟ (U̇·W + U·Ẇ) + f̈ U·W``; a
    shift ``s(t)`` adds ``−s̈``."""
    (U1, dU1), (W1, dW1), (U2, dU2), (W2, dW2) = _row_values(records, q, v)
    gam = 2.0 * np.einsum("ac,ac->a", dU1, dW1)  # f = 1: a static row or a driven shift
    for a in np.flatnonzero(records[:, pk.R_KIND] != pk.STATIC):
        prof = asm.joints[asm.row_joint[a]].drive
        th, d1, d2 = float(prof(t)), float(prof.derivative(t)), float(prof.second_derivative(t))
        if records[a, pk.R_KIND] == pk.DRIVE_SHIFT:
            gam[a] -= d2
            continue
        c, s = np.cos(th), np.sin(th)
        gam[a] = 0.0
        for f, df, ddf, U, dU, W, dW in (
                (c, -s * d1, -c * d1 * d1 - s * d2, U1[a], dU1[a], W1[a], dW1[a]),
                (-s, -c * d1, s * d1 * d1 - c * d2, U2[a], dU2[a], W2[a], dW2[a])):
            gam[a] += 2.0 * f * (dU @ dW) + 2.0 * df * (dU @ W + U @ dW) + ddf * (U @ W)
    return gam


def reactions(model, data, joint, v=None, t=None):
    r"""Force and torque the joint exerts on its body ``b`` (by body ``a``), at the joint point.

    Parameters
    ----------
    model : fastvi.Model
    data : fastvi.Result or ndarray (K, n) / (n,)
        The states; with arrays, ``v`` too, and ``t`` (default 0) for a driven mechanism.
    joint : str, int or Joint

    Returns
    -------
    force, torque : ndarray (…, 3)
        World frame; the torque is about the joint point ``x_B(X^B)``. On ``b`` = the ground,
        the reaction of the ground (minus that on ``a``).

    Notes
    -----
    The multipliers are those of the continuous equations of motion at each sample (the
    module docstring): the saddle-point system is solved densely, so this is a
    post-processing tool for mechanisms of moderate size.
    """
    asm = _assembly(model)
    q, v, t, single = _states(model, data, v, need_v=True, t=t)
    j = asm.joint(joint)
    rows = asm.rows_of(j)
    records = pk.rows_of(model.params).copy()
    Mdiag = _mass_diag(model)
    n, m = model.n, model.m
    on_b = not isinstance(j.b, Ground)
    body = j.b if on_b else j.a
    o = asm.offsets[body]
    F = np.zeros((q.shape[0], 3))
    T = np.zeros((q.shape[0], 3))
    for k in range(q.shape[0]):
        tk = float(t[k])
        G = model.constraint_jacobian_value(q[k], t=tk)
        rhs = np.zeros(n + m)
        rhs[:n] = model.force_value(tk, q[k], v[k]) - _grad_V(model, q[k], tk)
        rhs[n:] = -_gamma(asm, records, q[k], v[k], tk)
        K = np.zeros((n + m, n + m))
        K[:n, :n] = np.diag(Mdiag)
        K[:n, n:] = G.T
        K[n:, :n] = G
        lam = sla.solve(K, rhs, assume_a="sym")[n:]
        gen = -G[rows].T @ lam[rows]  # the joint's generalized force on every coordinate
        f = gen[o: o + 3]
        x = q[k, o: o + 3]
        tq = np.zeros(3)
        if isinstance(body, Body):
            for i in range(3):
                tq += np.cross(q[k, o + 3 + 3 * i: o + 6 + 3 * i], gen[o + 3 + 3 * i: o + 6 + 3 * i])
        X = j.point_b if on_b else j.point_a
        xj = _world_point(q[k: k + 1], body, asm, X)[0]
        tq = tq + np.cross(x - xj, f)  # about the joint point
        F[k], T[k] = (f, tq) if on_b else (-f, -tq)
    return _out(F, single), _out(T, single)


def _grad_V(model, q, t):
    from . import callbacks as cb

    out = np.zeros(model.n)
    cb._potential_grad(q, model.params, out)
    return out
