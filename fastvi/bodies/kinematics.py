r"""Consistent initial data from joint coordinates: :func:`initial_state`.

The joints of a tree of bodies (an open chain, a top, a governor's arms) are walked outward
from the ground; each places its body ``B`` from the body ``A`` it hangs on:

.. math::

    D_B = D_A F^A R(θ) F^{B\,T}, \qquad
    x_B(X^B) = x_A(X^A) + D_A F^A t(θ), \qquad
    ω_B = ω_A + D_A F^A ω_\text{rel}(θ, θ̇),

with ``D`` the world directors, ``F`` the joint frames of :mod:`fastvi.bodies.joints`, and the
joint's relative rotation ``R``, translation ``t`` and angular velocity ``ω_rel``:

===================  ============================  ==========================================
joint                coordinates                   ``R``, ``t``, ``ω_rel``
===================  ============================  ==========================================
revolute             angle θ                       ``Rot(e₁, θ)``, 0, ``θ̇ e₁``
prismatic            shift s                       1, ``s e₁``, 0
cylindrical          (θ, s)                        ``Rot(e₁, θ)``, ``s e₁``, ``θ̇ e₁``
universal            (θ₁, θ₂)                      ``Rot(e₁, θ₁) Rot(e₂, θ₂)``,
                                                   0, ``θ̇₁ e₁ + θ̇₂ Rot(e₁, θ₁) e₂``
spherical            rotation vector ρ (A's        ``exp(ρ̂)``, 0, the given relative angular
                     frame)                        velocity (A's frame)
driven               ``θ(t)``, ``θ'(t)`` of its    as revolute / prismatic
                     profile
fixed, distance      none                          as at the reference configuration
                                                   (relative to A)
===================  ============================  ==========================================

Bodies not connected to the ground keep their reference pose and velocity and carry their
subtree. Joints that close a loop take no coordinates. The state is then made consistent —
the nearest one in the metric of the mass matrix that satisfies every constraint and keeps
the given coordinates and rates of revolute, prismatic and cylindrical joints exactly
(Gauss–Newton on positions, a linear solve for velocities) — so that the given joints of a
loop (a crank's angle and speed) determine the rest. For a tree this changes nothing; a
move of the configuration is warned about.
"""

from __future__ import annotations

import warnings

import numpy as np

from .coordinates import HAS_COORDINATES, joint_coordinates
from .rigid import Body, Ground, PointMass, expm_so3

__all__ = ["initial_state"]

#: a residual below this (relative to the configuration's scale) needs no projection
_CONSISTENT = 1e-13
_MAX_ITER = 50


def _rot(axis: int, angle: float) -> np.ndarray:
    return expm_so3(np.eye(3)[axis] * angle)


def _motion(joint, value, rate, t):
    """``(R, t, ω_rel, ṫ)`` of the joint in its frame on A."""
    kind = joint.kind
    zero = np.zeros(3)
    e1 = np.eye(3)[0]
    if kind in ("driven_revolute", "driven_prismatic"):
        value, rate = float(joint.drive(t)), float(joint.drive.derivative(t))
        kind = kind.split("_")[1]
    if kind == "revolute":
        return _rot(0, value), zero, rate * e1, zero
    if kind == "prismatic":
        return np.eye(3), value * e1, zero, rate * e1
    if kind == "cylindrical":
        return _rot(0, value[0]), value[1] * e1, rate[0] * e1, rate[1] * e1
    if kind == "universal":
        R1 = _rot(0, value[0])
        return R1 @ _rot(1, value[1]), zero, rate[0] * e1 + rate[1] * (R1 @ np.eye(3)[1]), zero
    if kind == "spherical":
        return expm_so3(value), zero, np.asarray(rate, dtype=float), zero
    if kind == "distance":  # the rod keeps its reference direction in A
        return np.eye(3), joint.offset, zero, zero
    return np.eye(3), zero, zero, zero  # fixed


def _coordinates_of(joint, given, what):
    names = joint.coordinates
    if given is None:
        return 0.0 if len(names) == 1 else np.zeros(len(names))
    if joint.drive is not None:
        raise ValueError(f"joint {joint.name!r} is driven: its {what} follows from its profile; "
                         "do not give it")
    arr = np.atleast_1d(np.asarray(given, dtype=float))
    if arr.shape != (len(names),) or not np.all(np.isfinite(arr)):
        raise ValueError(f"the {what} of {joint.kind} joint {joint.name!r} must be {len(names)} finite "
                         f"number(s) ({', '.join(names) or 'none'}), got {given!r}")
    return float(arr[0]) if len(names) == 1 else arr


def _keyed(asm, mapping, what) -> dict:
    out = {}
    for key, val in (mapping or {}).items():
        try:
            j = asm.joint(key)
        except KeyError as exc:
            raise ValueError(f"`{what}`: {exc.args[0]}") from None
        out[j] = val
    return out


def initial_state(model, values=None, rates=None, *, t: float = 0.0):
    r"""A consistent ``(q0, v0)`` from joint coordinates and rates.

    Parameters
    ----------
    model : fastvi.Model
        Built by :meth:`fastvi.bodies.Mechanism.build`.
    values, rates : mapping, optional
        Joint (name, index or object) → its coordinates and their rates (see the module
        docstring; a number for a one-coordinate joint). Neither given, and no drives: the
        bodies' own reference poses and velocities, made consistent. Otherwise joints not
        given stay at 0 (the reference configuration) at rest relative to their parent, and
        driven joints at ``θ(t)`` moving at ``θ'(t)``; a body not connected to the ground
        keeps its reference pose and velocity.
    t : float, default 0
        The time of the state (the drives' ``θ(t)``, ``θ'(t)``).

    Returns
    -------
    q0, v0 : ndarray (n,)
        ``g(t, q0) = 0`` and ``G v0 + g_t = 0`` at round-off.

    Raises
    ------
    ValueError
        An unknown joint, the wrong number of coordinates, coordinates for a driven joint or
        a joint that closes a loop.
    """
    asm = model.assembly
    if not values and not rates and not any(j.drive is not None for j in asm.joints):
        return _made_consistent(model, asm.q_ref.copy(), asm.v_ref.copy(), t, [])
    vals, rts = _keyed(asm, values, "values"), _keyed(asm, rates, "rates")
    pose = {}  # body -> (D, φ, ω, φ̇)
    for b in asm.bodies:  # roots keep their reference state
        if isinstance(b, Body):
            pose[b] = (b.directors(), b.position.copy(), b.omega.copy(), b.velocity.copy())
        else:
            pose[b] = (np.eye(3), b.position.copy(), np.zeros(3), b.velocity.copy())
    ground = (np.eye(3), np.zeros(3), np.zeros(3), np.zeros(3))
    tree, placed = [], set()
    pending = list(asm.joints)
    while True:
        progress = False
        for j in list(pending):
            a_known = isinstance(j.a, Ground) or j.a in placed
            b_known = isinstance(j.b, Ground) or j.b in placed
            if a_known and not b_known:
                tree.append((j, True))
                placed.add(j.b)
            elif b_known and not a_known:
                tree.append((j, False))
                placed.add(j.a)
            else:
                continue
            pending.remove(j)
            progress = True
        if not progress:
            # a body the ground does not reach: it is a root; continue from it
            roots = [b for b in asm.bodies if b not in placed]
            if not roots or not pending:
                break
            placed.add(roots[0])
    for j in pending:  # loop closures
        if j in vals or j in rts:
            raise ValueError(f"joint {j.name!r} closes a loop: its coordinates follow from the other "
                             "joints'; give values for the joints of a spanning tree only")
    for j, forward in tree:
        val = _coordinates_of(j, vals.get(j), "values")
        rate = _coordinates_of(j, rts.get(j), "rates")
        R, tr, w_rel, tr_dot = _motion(j, val, rate, t)
        if forward:
            DA, phiA, wA, vA = ground if isinstance(j.a, Ground) else pose[j.a]
            FA = DA @ j.frame_a  # the joint frame on A, world
            D = FA @ R @ j.frame_b.T
            xj = phiA + DA @ j.point_a + FA @ tr
            vj = vA + np.cross(wA, DA @ j.point_a) + np.cross(wA, FA @ tr) + FA @ tr_dot
            w = wA + FA @ w_rel
            pose[j.b] = _placed(j.b, D, xj, vj, w, j.point_b)
        else:
            DB, phiB, wB, vB = ground if isinstance(j.b, Ground) else pose[j.b]
            D = DB @ j.frame_b @ R.T @ j.frame_a.T
            FA = D @ j.frame_a
            xjb = phiB + DB @ j.point_b
            vjb = vB + np.cross(wB, DB @ j.point_b)
            w = wB - FA @ w_rel
            xj = xjb - FA @ tr
            vj = vjb - np.cross(w, FA @ tr) - FA @ tr_dot
            pose[j.a] = _placed(j.a, D, xj, vj, w, j.point_a)
    n = model.n
    q, v = np.zeros(n), np.zeros(n)
    for b in asm.bodies:
        D, phi, w, vphi = pose[b]
        s = asm.slice(b)
        if isinstance(b, Body):
            q[s] = np.concatenate([phi, D[:, 0], D[:, 1], D[:, 2]])
            Dd = np.cross(w, D.T)
            v[s] = np.concatenate([vphi, Dd[0], Dd[1], Dd[2]])
        else:
            q[s], v[s] = phi, vphi
    return _made_consistent(model, q, v, t, [j.name for j in pending], vals, rts)


def _placed(body, D, xj, vj, w, X):
    """The state of ``body`` whose joint point ``X`` is at ``xj`` moving with ``vj``."""
    if isinstance(body, PointMass):
        return np.eye(3), xj, np.zeros(3), vj
    arm = D @ X
    return D, xj - arm, w, vj - np.cross(w, arm)


def _selected(asm, given, what):
    """``[(joint, k, target)]``: the given coordinates the projection holds (the joints with
    coordinate functions, :mod:`fastvi.bodies.coordinates`)."""
    out = []
    for j, val in given.items():
        if j.kind in HAS_COORDINATES and j.drive is None:
            arr = np.atleast_1d(np.asarray(val, dtype=float))
            out.extend((j, k, float(arr[k])) for k in range(arr.size))
    return out


def _rows(asm, q, sel):
    """Values and gradients of the selected joint coordinates at ``q``."""
    if not sel:
        return np.zeros(0), np.zeros((0, q.shape[0]))
    vals, grads = [], []
    for j, k, _ in sel:
        v, g = joint_coordinates(asm, j, q)
        vals.append(v[k])
        grads.append(g[k])
    return np.array(vals), np.array(grads)


def _step(C, w, F, what):
    """The smallest step in the metric ``diag(1/w)`` with ``C Δ = −F``."""
    S = (C * w) @ C.T
    try:
        return -(w * (C.T @ np.linalg.solve(S, F)))
    except np.linalg.LinAlgError:
        raise ValueError(f"the {what} given do not determine a state: the constraints and the given "
                         "joint coordinates are dependent (give coordinates of independent joints, at "
                         "most as many as the mechanism's degrees of freedom)") from None


def _made_consistent(model, q, v, t, loops, vals=None, rts=None):
    """The nearest state (metric of the mass matrix) with ``g = 0``, ``G v + g_t = 0`` and the
    given joint coordinates and rates held."""
    if model.m == 0:
        return q, v
    asm = model.assembly
    mdiag = np.diag(model.mass_matrix_constant)
    w = 1.0 / np.maximum(mdiag, 1e-12 * mdiag.max())  # a lamina's E = 0 still gets a metric
    sel_q, sel_v = _selected(asm, vals or {}, "values"), _selected(asm, rts or {}, "rates")
    scale = max(1.0, float(np.abs(q).max()))
    q0, v0 = q.copy(), v.copy()
    for _ in range(_MAX_ITER):
        c, C = _rows(asm, q, sel_q)
        F = np.concatenate([model.constraint_value(q, t=t),
                            np.angle(np.exp(1j * (c - [x for _, _, x in sel_q])))])
        if np.abs(F).max() <= _CONSISTENT * scale:
            break
        dq = _step(np.vstack([model.constraint_jacobian_value(q, t=t), C]), w, F, "values")
        q = q + dq
    else:
        raise ValueError(f"model {model.name!r}: no consistent configuration found near the given "
                         f"joint coordinates (max residual {np.abs(F).max():.2e}); give values closer "
                         "to an assembly of the mechanism")
    G = model.constraint_jacobian_value(q, t=t)
    _, Cv = _rows(asm, q, sel_v)
    A = np.vstack([G, Cv])
    rhs = np.concatenate([-model.constraint_time_derivative_value(q, t=t), [x for _, _, x in sel_v]])
    for _ in range(2):  # the second pass removes the round-off of the first
        v = v + _step(A, w, A @ v - rhs, "rates")
    moved, changed = float(np.abs(q - q0).max()), float(np.abs(v - v0).max())
    vscale = max(1.0, float(np.abs(v0).max()))
    where = f" (the loop joint(s) {', '.join(map(repr, loops))})" if loops else ""
    if moved > 1e-8 * scale and not (vals and loops):  # given coordinates move a loop's others
        warnings.warn(f"model {model.name!r}: the initial configuration does not satisfy every "
                      f"constraint{where}; it was moved by up to {moved:.2e} onto them",
                      RuntimeWarning, stacklevel=3)
    if changed > 1e-8 * vscale and not loops:
        warnings.warn(f"model {model.name!r}: the initial velocities do not satisfy every constraint; "
                      f"they were changed by up to {changed:.2e} (give each body the velocity its "
                      "joints allow, e.g. φ̇ = ω × (φ − fixed point), or use joint rates)",
                      RuntimeWarning, stacklevel=3)
    return q, v
