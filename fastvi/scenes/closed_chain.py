r"""Planar closed chain: N equal rigid links between two ground pivots, N − 1 point masses.

The links join ``A = (0, 0)``, the bodies ``r_1 … r_{N−1}`` and ``D = (d, 0)``; gravity ``−g ŷ``.
``q = (x1, y1, …, x_{N−1}, y_{N−1})`` (n = 2N − 2), N constraints

    g_i = ½ (|r_i − r_{i−1}|² − l²),   i = 1 … N,   r_0 = A, r_N = D,

so N − 2 degrees of freedom (N ≥ 3). The loop closes through the ground: the last
constraint couples the last body to a fixed point, and the Newton matrix stays banded in
body order (bandwidth independent of N). When ``d = N l`` the loop is stretched straight
and every configuration is singular; for ``d`` close to ``N l`` the loop is nearly taut.
Constant diagonal mass, linear potential, exact second derivatives.

``params = (m, l, d, g)`` (equal masses and lengths); the functions read the number of bodies
from ``len(q) // 2``. The model has exact derivatives by its parameters
(``Model(param_derivatives=...)``): ``∇V`` by ``m`` and ``g``, every constraint by ``l``, the
last by ``d`` (with ``param_patterns``: O(N) entries), and ``G`` by ``d`` (one entry, but
``∂G/∂θ`` has no pattern: the kernels read its k·m·n entries, O(N²) a call).
"""

from __future__ import annotations

import numpy as np
from numba.extending import register_jitable

from ..model import Model
from ..drawing import cartesian
from ._common import attach, check_positive
# Σ η_i ∇²g_i: block tridiagonal as for the open chain
from .chain import constraint_hessian as _ddg

MIN_LINKS = 3


def _V(q, p):
    acc = 0.0
    for i in range(q.shape[0] // 2):
        acc += q[2 * i + 1]
    return p[0] * p[3] * acc


def _dV(q, p, out):
    for i in range(q.shape[0] // 2):
        out[2 * i] = 0.0
        out[2 * i + 1] = p[0] * p[3]


@register_jitable
def _link(q, p, i):
    """``r_i − r_{i−1}`` of link ``i`` (``r_{−1} = A = (0, 0)``, ``r_{N−1} = D = (d, 0)``)."""
    nb = q.shape[0] // 2
    x = q[2 * i] if i < nb else p[2]
    y = q[2 * i + 1] if i < nb else 0.0
    if i == 0:
        return x, y
    return x - q[2 * i - 2], y - q[2 * i - 1]


def _g(q, p, out):
    for i in range(q.shape[0] // 2 + 1):
        dx, dy = _link(q, p, i)
        out[i] = 0.5 * (dx * dx + dy * dy - p[1] * p[1])


def _G(q, p, out):
    # only the entries of `pattern(N)`: the kernels hand `out` zeroed outside it
    nb = q.shape[0] // 2
    for i in range(nb + 1):
        dx, dy = _link(q, p, i)
        if i < nb:
            out[i, 2 * i] = dx
            out[i, 2 * i + 1] = dy
        if i > 0:
            out[i, 2 * i - 2] = -dx
            out[i, 2 * i - 1] = -dy


# the derivatives by θ = (m, l, d, g) write only the entries of `param_patterns`
# (the kernels hand them `out` zeroed there and read nothing else); the constant mass
# matrix is data
def _dV_by_params(q, p, out):
    """``∂(∇V)/∂θ``: at each ``y_i``, ``g`` by ``m`` and ``m`` by ``g``; zero by ``l``, ``d``."""
    for i in range(q.shape[0] // 2):
        out[0, 2 * i + 1] = p[3]
        out[3, 2 * i + 1] = p[0]


def _g_by_params(q, p, out):
    """``∂g/∂θ``: ``∂g_i/∂l = −l`` for every link, and ``∂g_N/∂d = d − x_{N−1}`` for the
    last (D = (d, 0) moves with d); zero by ``m`` and ``g``."""
    nb = q.shape[0] // 2
    for i in range(nb + 1):
        out[1, i] = -p[1]
    out[2, nb] = p[2] - q[2 * nb - 2]


def _G_by_params(q, p, out):
    """``∂G/∂θ`` (k, m, n): only the last row's ``∂g_N/∂x_{N−1} = x_{N−1} − d`` moves,
    ``∂/∂d = −1``. Dense: the kernels read all k·m·n entries (no pattern by θ for ``G``)."""
    nb = q.shape[0] // 2
    out[:, :, :] = 0.0
    out[2, nb, 2 * nb - 2] = -1.0


def param_patterns(N: int) -> dict:
    """``(l, entry)`` of the non-zeros of the derivatives by θ (``Model``'s
    ``param_patterns``): ``∂(∇V)/∂θ`` at every ``y_i`` by ``m`` and by ``g``, ``∂g_i/∂l``
    at every link and ``∂g_N/∂d`` at the last."""
    nb = N - 1
    i = np.arange(nb)
    return dict(potential_grad=(np.repeat([0, 3], nb), np.tile(2 * i + 1, 2)),
                constraint=(np.r_[np.ones(N, dtype=np.int64), 2], np.r_[np.arange(N), N - 1]))


def pattern(N: int):
    """``(rows, cols)`` of the non-zeros of ``G`` (m = N, n = 2N − 2): link i joins body
    i − 1 (pivot A for i = 0) to body i (pivot D for i = N − 1)."""
    nb = N - 1
    rows, cols = [], []
    for i in range(N):
        lo = max(0, 2 * i - 2)
        hi = min(2 * nb, 2 * i + 2)
        rows += [i] * (hi - lo)
        cols += range(lo, hi)
    return np.array(rows), np.array(cols)


def _arc(N: int, l: float, d: float) -> np.ndarray:
    """Vertices of N equal chords of length l on a circular arc from (0, 0) to (d, 0),
    sagging below the ground line (d < N l)."""
    # half-angle α of one chord: l = 2R sin α, d = 2R sin(N α) → sin(Nα)/sin(α) = d/l
    ratio = d / l
    lo, hi = 1e-12, np.pi / N
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if np.sin(N * mid) / np.sin(mid) > ratio:
            lo = mid
        else:
            hi = mid
    a = 0.5 * (lo + hi)
    R = l / (2.0 * np.sin(a))
    cx, cy = 0.5 * d, R * np.cos(N * a)  # centre above the chord line
    phi0 = np.arctan2(0.0 - cy, 0.0 - cx)
    ang = phi0 + 2.0 * a * np.arange(1, N)
    return np.column_stack((cx + R * np.cos(ang), cy + R * np.sin(ang)))


def closed_chain(N: int = 8, m: float = 1.0, l: float = 1.0, d: float | None = None,
                 g: float = 9.81) -> Model:
    r"""Closed planar chain of ``N`` equal links pinned at ``(0, 0)`` and ``(d, 0)``
    (n = 2N − 2, m = N, N − 2 degrees of freedom).

    Parameters
    ----------
    N : int, default 8
        Number of links, ``N >= 3``.
    m, l : float
        Mass of each of the N − 1 bodies and length of each link.
    d : float, optional
        Distance between the pivots, ``0 < d < N l``; default ``0.7 N l``.
    g : float
        Gravity along ``−y``.

    Returns
    -------
    Model
        With exact derivatives by its parameters, ``initial_state() -> (q0, v0)``: at rest
        on a circular arc through both pivots (consistent: ``g(q0) = 0`` to round-off), and
        a ``drawing`` (pivot A, the bodies, pivot D).
    """
    if isinstance(N, bool) or not isinstance(N, (int, np.integer)) or N < MIN_LINKS:
        raise ValueError(f"`N` must be an integer >= {MIN_LINKS}, got {N!r}")
    N = int(N)
    d = 0.7 * N * l if d is None else d
    check_positive(m=m, l=l, d=d, g=g)
    if not d < N * l:
        raise ValueError(f"`d` must be below N·l = {N * l:g} (the loop would be stretched), got {d!r}")
    n = 2 * (N - 1)
    model = Model(n, N, params=(m, l, d, g), mass=np.full(n, float(m)) * np.eye(n), potential=_V,
                  potential_grad=_dV, potential_hessian=0, constraint=_g,
                  constraint_jacobian=_G, constraint_hessian=_ddg,
                  constraint_jacobian_pattern=pattern(N), mass_params=(0,),
                  name=f"closed_chain{N}",
                  param_derivatives=dict(potential_grad=_dV_by_params, constraint=_g_by_params,
                                         constraint_jacobian=_G_by_params),
                  param_patterns=param_patterns(N))

    def initial_state():
        return _arc(N, l, d).ravel(), np.zeros(n)

    drawing = cartesian(n, [(i, i + 1) for i in range(N)], before=[(0.0, 0.0)], after=[(d, 0.0)])
    return attach(model, "closed_chain", dict(N=N, m=m, l=l, d=d, g=g), drawing=drawing,
                  initial_state=initial_state)
