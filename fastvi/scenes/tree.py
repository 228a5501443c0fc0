r"""Planar tree of point masses on rigid massless links: a hub with branches.

Body 0, the hub, hangs from the origin (the pivot) on link 0; ``b`` branches of ``L``
bodies each hang from the hub, each body of a branch from the previous one. In ``q`` the
hub comes first, then branch 0 from the hub outward, branch 1, …: ``N = 1 + b L`` bodies,
``q = (x0, y0, …, x_{N−1}, y_{N−1})``, and the N constraints

    g_i = ½ (|r_i − r_{π(i)}|² − l_i²),   i = 0 … N − 1,

with ``π(i)`` the body body ``i`` hangs from (``r_{π(0)} = 0``, the pivot). Gravity ``−g ŷ``,
``M = diag(m_0, m_0, …)`` constant, ``V = g Σ_i m_i y_i`` linear. Jacobian rows:
``∂g_i/∂r_i = r_i − r_{π(i)} = −∂g_i/∂r_{π(i)}``; the contracted Hessian ``Σ_i η_i ∇²g_i``
is the graph Laplacian of the tree weighted by ``η`` with 2×2 identity blocks.

This is the scene of the sparse-solve benchmarks: the ``b + 1`` constraints at the hub
share its coordinates, so ``G M⁻¹ Gᵀ`` holds a dense ``(b + 1)``-clique and, in any order,
a band at least ``b`` wide — while eliminating the branches from their tips inward creates
no fill at all. ``tree(1, L)`` is ``chain(L + 1)``.

``params = (m_0 … m_{N−1}, l_0 … l_{N−1}, g, π(0) … π(N−1))`` with ``π(0) = −1``: one set of
module-level callbacks serves every tree (they read ``N`` from ``len(q) // 2``), and the
potential's are the chain's (the same layout up to ``g``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..model import Model
from . import damping as damping_
from ..drawing import cartesian
from ._common import attach, check_positive
from .chain import per_link, potential as _V, potential_grad as _dV


@njit(inline="always", cache=True)
def _link(q, p, nb, i):
    """The body link ``i`` hangs from (−1: the pivot) and ``r_i − r_{π(i)}``."""
    k = int(p[2 * nb + 1 + i])
    dx = q[2 * i] - (q[2 * k] if k >= 0 else 0.0)
    dy = q[2 * i + 1] - (q[2 * k + 1] if k >= 0 else 0.0)
    return k, dx, dy


def _g(q, p, out):
    nb = q.shape[0] // 2
    for i in range(nb):
        _, dx, dy = _link(q, p, nb, i)
        li = p[nb + i]
        out[i] = 0.5 * (dx * dx + dy * dy - li * li)


def _G(q, p, out):
    # only the entries of `pattern`: the kernels hand `out` zeroed outside it
    nb = q.shape[0] // 2
    for i in range(nb):
        k, dx, dy = _link(q, p, nb, i)
        out[i, 2 * i] = dx
        out[i, 2 * i + 1] = dy
        if k >= 0:
            out[i, 2 * k] = -dx
            out[i, 2 * k + 1] = -dy


def _ddg(q, eta, p, out):
    # the entries of coordinates that share a link alone: handed zeroed (G's pattern)
    nb = q.shape[0] // 2
    for i in range(nb):
        k = int(p[2 * nb + 1 + i])
        e = eta[i]
        for d in range(2):
            out[2 * i + d, 2 * i + d] += e
            if k >= 0:
                out[2 * k + d, 2 * k + d] += e
                out[2 * i + d, 2 * k + d] -= e
                out[2 * k + d, 2 * i + d] -= e


def parents(branches: int, links: int) -> np.ndarray:
    """``π(i)`` for every body of ``tree(branches, links)`` (−1: the pivot)."""
    par = [-1]
    for b in range(branches):
        for k in range(links):
            par.append(0 if k == 0 else 1 + b * links + k - 1)
    return np.array(par, dtype=np.int64)


def pattern(branches: int, links: int):
    """``(rows, cols)`` of the non-zeros of the tree's ``G`` (m = N, n = 2N)."""
    rows, cols = [], []
    for i, k in enumerate(parents(branches, links)):
        for a in ((2 * k, 2 * k + 1, 2 * i, 2 * i + 1) if k >= 0 else (2 * i, 2 * i + 1)):
            rows.append(i)
            cols.append(a)
    return np.array(rows), np.array(cols)


def _count(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"`{name}` must be an integer, got {value!r}")
    if value < 1:
        raise ValueError(f"`{name}` must be >= 1, got {value}")
    return int(value)


def tree(branches: int = 3, links: int = 3, m=1.0, l=1.0, g: float = 9.81, damping: float = 0.0) -> Model:
    r"""Planar tree: a hub on a link from the origin and ``branches`` chains of ``links``
    bodies hanging from it (``N = 1 + branches·links`` bodies, n = 2N, m = N).

    Parameters
    ----------
    branches, links : int, default 3
        Number of branches at the hub (≥ 1) and of bodies in each (≥ 1).
    m, l : float or sequence of N floats, default 1
        Point masses (kg) and link lengths (m), in body order (hub first, then branch by
        branch from the hub outward); link ``i`` joins body ``i`` to the body it hangs from.
    g : float, default 9.81
        Gravitational acceleration along ``−y`` (m/s²).
    damping : float, default 0
        Viscous damping ``c`` (N s/m) on every mass (:mod:`fastvi.scenes.damping`).

    Returns
    -------
    Model
        With exact second derivatives, its declared pattern of ``G``,
        ``initial_state(thetas, omegas=None) -> (q0, v0)`` (link angles from the downward
        vertical in body order, a consistent state), ``angles(q) -> thetas`` (..., N) and a
        ``drawing`` (the pivot, then the bodies).

    Notes
    -----
    The ``branches + 1`` constraints at the hub share its coordinates, so no narrow band
    fits ``G M⁻¹ Gᵀ``, while eliminating the branches from their tips creates no fill: the
    scene where the sparse LU beats the banded one (``docs/decisions/0004-sparse-lu.md``).
    ``tree(1, L)`` is ``chain(L + 1)``. The pattern of ``G`` is
    ``fastvi.scenes.tree.pattern(b, L)``, the body each body hangs from
    ``fastvi.scenes.tree.parents(b, L)``.
    """
    branches = _count("branches", branches)
    links = _count("links", links)
    N = 1 + branches * links
    ms = per_link("m", m, N)
    ls = per_link("l", l, N)
    check_positive(g=g)
    c = damping_.check(damping)
    par = parents(branches, links)
    model = Model(
        2 * N, N, params=(*ms, *ls, g, *par.astype(float)) + ((c,) if c else ()),
        mass=np.repeat(ms, 2), potential=_V, potential_grad=_dV, potential_hessian=0,
        constraint=_g, constraint_jacobian=_G, constraint_hessian=_ddg,
        constraint_jacobian_pattern=pattern(branches, links),
        name=f"tree{branches}x{links}" + ("-damped" if c else ""), **damping_.options(c, 2 * N),
        param_derivatives=damping_.param_derivatives(c),
        param_patterns=damping_.param_patterns(c, 3 * N + 1 + (1 if c else 0), 2 * N),
        fixed_params=range(2 * N + 1, 3 * N + 1),  # the parents: the tree's shape, not a quantity
        mass_params=range(N),
    )
    lengths = np.array(ls)

    def initial_state(thetas, omegas=None):
        th = np.atleast_1d(np.asarray(thetas, dtype=float))
        if th.shape != (N,):
            raise ValueError(f"`thetas` must have N = {N} entries, got shape {th.shape}")
        om = np.zeros(N) if omegas is None else np.atleast_1d(np.asarray(omegas, dtype=float))
        if om.shape != (N,):
            raise ValueError(f"`omegas` must have N = {N} entries, got shape {om.shape}")
        if not (np.all(np.isfinite(th)) and np.all(np.isfinite(om))):
            raise ValueError("`thetas` and `omegas` must be finite")
        q = np.zeros(2 * N)
        v = np.zeros(2 * N)
        for i, k in enumerate(par):  # a parent always precedes its child
            base_q = q[2 * k:2 * k + 2] if k >= 0 else 0.0
            base_v = v[2 * k:2 * k + 2] if k >= 0 else 0.0
            s, co = np.sin(th[i]), np.cos(th[i])
            q[2 * i:2 * i + 2] = base_q + lengths[i] * np.array([s, -co])
            v[2 * i:2 * i + 2] = base_v + lengths[i] * om[i] * np.array([co, s])
        return q, v

    def angles(q):
        q = np.asarray(q, dtype=float)
        x, y = q[..., 0::2], q[..., 1::2]
        px = np.where(par >= 0, x[..., np.maximum(par, 0)], 0.0)
        py = np.where(par >= 0, y[..., np.maximum(par, 0)], 0.0)
        return np.arctan2(x - px, -(y - py))

    kw = dict(branches=branches, links=links, m=ms if len(set(ms)) > 1 else ms[0],
              l=ls if len(set(ls)) > 1 else ls[0], g=g, damping=c)
    # point 0 is the pivot, point i + 1 body i
    drawing = cartesian(2 * N, [(k + 1, i + 1) for i, k in enumerate(par)], before=[(0.0, 0.0)])
    return attach(model, "tree", kw, drawing=drawing, initial_state=initial_state, angles=angles)
