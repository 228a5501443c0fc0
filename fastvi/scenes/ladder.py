r"""A ladder of N parallelogram four-bar cells: a large closed-loop mechanism with singular
positions (issue 12).

Two rails of N links of length ``a`` hang from the ground pivots ``B_0 = (0, 0)`` and
``C_0 = (L, 0)``; at every level ``i = 1 … N`` a rung of length ``L`` joins the rail nodes
``B_i`` and ``C_i``, each a point mass ``m``; gravity ``−g ŷ``. ``q = (B_1, C_1, B_2, C_2, …)``
(n = 4N, ordered by level, so the Newton matrix is banded) and 3N constraints, per level

    ½ (|B_i − B_{i−1}|² − a²),   ½ (|C_i − C_{i−1}|² − a²),   ½ (|C_i − B_i|² − L²),

so each cell is a four-bar linkage whose rung is its coupler: N degrees of freedom. On the
parallelogram branch every rung stays parallel to the ground, ``C_i = B_i + (L, 0)``, and the
ladder moves like an N-link pendulum of rail angles θ_i (from the +x axis). Cell ``i`` is
**singular** when its rails are aligned with its rungs (``sin θ_i = 0``): its three
constraint gradients then have no y-components at level i, and ``G`` loses rank, exactly
as for :func:`fastvi.scenes.four_bar`. Released at rest from rails raised above the
horizontal, every cell swings down through that position.

Constant diagonal mass, linear potential, exact second derivatives, and the declared pattern
of ``G`` (:func:`pattern`: the callback writes only those entries).

``params = (m, a, L, g)``; the functions read N from ``len(q) // 4``.
"""

from __future__ import annotations

import numpy as np

from .._numba import njit
from ..model import Model
from ..drawing import cartesian
from ._common import attach, check_positive

MIN_CELLS = 1


def _V(q, p):
    acc = 0.0
    for i in range(q.shape[0] // 4):
        acc += q[4 * i + 1] + q[4 * i + 3]
    return p[0] * p[3] * acc


def _dV(q, p, out):
    for i in range(q.shape[0] // 4):
        out[4 * i] = 0.0
        out[4 * i + 1] = p[0] * p[3]
        out[4 * i + 2] = 0.0
        out[4 * i + 3] = p[0] * p[3]


def _g(q, p, out):
    a, L = p[1], p[2]
    bx, by, cx, cy = 0.0, 0.0, L, 0.0
    for i in range(q.shape[0] // 4):
        o = 4 * i
        dbx, dby = q[o] - bx, q[o + 1] - by
        dcx, dcy = q[o + 2] - cx, q[o + 3] - cy
        rx, ry = q[o + 2] - q[o], q[o + 3] - q[o + 1]
        out[3 * i] = 0.5 * (dbx * dbx + dby * dby - a * a)
        out[3 * i + 1] = 0.5 * (dcx * dcx + dcy * dcy - a * a)
        out[3 * i + 2] = 0.5 * (rx * rx + ry * ry - L * L)
        bx, by, cx, cy = q[o], q[o + 1], q[o + 2], q[o + 3]


def _G(q, p, out):
    # only the entries of `pattern(N)`: the kernels hand `out` zeroed outside it
    bx, by, cx, cy = 0.0, 0.0, p[2], 0.0
    for i in range(q.shape[0] // 4):
        o = 4 * i
        dbx, dby = q[o] - bx, q[o + 1] - by
        dcx, dcy = q[o + 2] - cx, q[o + 3] - cy
        rx, ry = q[o + 2] - q[o], q[o + 3] - q[o + 1]
        c = 3 * i
        out[c, o] = dbx
        out[c, o + 1] = dby
        out[c + 1, o + 2] = dcx
        out[c + 1, o + 3] = dcy
        if i > 0:
            out[c, o - 4] = -dbx
            out[c, o - 3] = -dby
            out[c + 1, o - 2] = -dcx
            out[c + 1, o - 1] = -dcy
        out[c + 2, o] = -rx
        out[c + 2, o + 1] = -ry
        out[c + 2, o + 2] = rx
        out[c + 2, o + 3] = ry
        bx, by, cx, cy = q[o], q[o + 1], q[o + 2], q[o + 3]


@njit
def _link_hessian(out, x, y, e):
    """Add ``e ∇²(½|X − Y|²)`` for the coordinates x, y (first of two) of X and Y (y < 0:
    a ground pivot)."""
    for k in range(2):
        out[x + k, x + k] += e
        if y >= 0:
            out[y + k, y + k] += e
            out[x + k, y + k] -= e
            out[y + k, x + k] -= e


def _ddg(q, eta, p, out):
    # the entries of coordinates that share a constraint alone: handed zeroed (G's pattern)
    for i in range(q.shape[0] // 4):
        o = 4 * i
        c = 3 * i
        _link_hessian(out, o, o - 4 if i > 0 else -1, eta[c])
        _link_hessian(out, o + 2, o - 2 if i > 0 else -1, eta[c + 1])
        _link_hessian(out, o + 2, o, eta[c + 2])


def pattern(N: int):
    """``(rows, cols)`` of the non-zeros of ``G`` (m = 3N, n = 4N)."""
    rows, cols = [], []
    for i in range(N):
        o, c = 4 * i, 3 * i
        below = (o - 4, o - 3) if i > 0 else ()
        rows += [c] * (2 + len(below))
        cols += [*below, o, o + 1]
        below = (o - 2, o - 1) if i > 0 else ()
        rows += [c + 1] * (2 + len(below))
        cols += [*below, o + 2, o + 3]
        rows += [c + 2] * 4
        cols += [o, o + 1, o + 2, o + 3]
    return np.array(rows), np.array(cols)


def state_from_angles(thetas, omegas, a: float, L: float):
    """Consistent ``(q, v)`` on the parallelogram branch from the rail angles θ_i (from +x)
    and their rates: ``B_i = B_{i−1} + a (cos θ_i, sin θ_i)``, ``C_i = B_i + (L, 0)``."""
    th = np.asarray(thetas, dtype=float)
    om = np.zeros_like(th) if omegas is None else np.asarray(omegas, dtype=float)
    N = th.size
    q = np.empty(4 * N)
    v = np.empty(4 * N)
    bx = by = ux = uy = 0.0
    for i in range(N):
        bx += a * np.cos(th[i])
        by += a * np.sin(th[i])
        ux -= a * om[i] * np.sin(th[i])
        uy += a * om[i] * np.cos(th[i])
        q[4 * i:4 * i + 4] = bx, by, bx + L, by
        v[4 * i:4 * i + 4] = ux, uy, ux, uy
    return q, v


def rail_sines(q, a: float):
    """``sin θ_i`` of the left rail links, (..., N): zero where cell i is singular."""
    q = np.asarray(q, dtype=float)
    y = q[..., 1::4]
    below = np.concatenate([np.zeros(y.shape[:-1] + (1,)), y[..., :-1]], axis=-1)
    return (y - below) / a


def rung_tilts(q):
    """``yC_i − yB_i``, (..., N): zero on the parallelogram branch."""
    q = np.asarray(q, dtype=float)
    return q[..., 3::4] - q[..., 1::4]


def ladder(N: int = 8, m: float = 1.0, a: float = 1.0, L: float = 1.0, g: float = 9.81) -> Model:
    r"""A ladder of ``N`` parallelogram four-bar cells hanging from two ground pivots
    (n = 4N, m = 3N, N degrees of freedom); see the module docstring.

    Parameters
    ----------
    N : int, default 8
        Number of cells (rungs), ``N >= 1``.
    m : float, default 1
        Mass of each rail node (kg).
    a, L : float, default 1
        Rail link length and rung (and ground) length (m).
    g : float, default 9.81
        Gravity along ``−y`` (m/s²).

    Returns
    -------
    Model
        With ``initial_state(thetas, omegas=None) -> (q0, v0)`` (rail angles from the +x
        axis, consistent on the parallelogram branch), ``rail_sines(q)`` (zero at a cell's
        singular position), ``rung_tilts(q)`` (zero on the parallelogram branch) and a
        ``drawing`` (the ground pivots, then B_i, C_i level by level).
    """
    if isinstance(N, bool) or not isinstance(N, (int, np.integer)) or N < MIN_CELLS:
        raise ValueError(f"`N` must be an integer >= {MIN_CELLS}, got {N!r}")
    N = int(N)
    check_positive(m=m, a=a, L=L, g=g)
    n = 4 * N
    model = Model(n, 3 * N, params=(m, a, L, g), mass=float(m) * np.eye(n), potential=_V,
                  potential_grad=_dV, potential_hessian=0, constraint=_g, constraint_jacobian=_G,
                  constraint_hessian=_ddg, constraint_jacobian_pattern=pattern(N), mass_params=(0,),
                  name=f"ladder{N}")

    def initial_state(thetas, omegas=None):
        th = np.atleast_1d(np.asarray(thetas, dtype=float))
        if th.shape != (N,):
            raise ValueError(f"`thetas` must have N = {N} entries, got shape {th.shape}")
        return state_from_angles(th, omegas, a, L)

    # points B_0, C_0 (the ground pivots), B_1, C_1, …: B_i is point 2i, C_i point 2i + 1
    bars = [(2 * i + s, 2 * i + 2 + s) for i in range(N) for s in (0, 1)]  # the rails
    bars += [(2 * i, 2 * i + 1) for i in range(1, N + 1)]  # the rungs
    drawing = cartesian(n, bars, before=[(0.0, 0.0), (L, 0.0)])
    return attach(model, "ladder", dict(N=N, m=m, a=a, L=L, g=g), drawing=drawing,
                  initial_state=initial_state, rail_sines=lambda q: rail_sines(q, a),
                  rung_tilts=rung_tilts)
