r"""Planar chain of N point masses on rigid massless links, hanging from the origin.

``q = (x1, y1, …, xN, yN)``; point mass ``m_i`` at ``r_i = (x_i, y_i)``, link ``i`` of length
``l_i`` joins ``r_{i−1}`` and ``r_i`` with ``r_0 = 0`` (the pivot); gravity ``−g ŷ``. The
mass matrix ``M = diag(m1, m1, …, mN, mN)`` is constant, the potential
``V = g Σ_i m_i y_i`` is linear, and the N constraints are

    g_i = ½ (|r_i − r_{i−1}|² − l_i²),   i = 1 … N.

Jacobian rows: ``∂g_i/∂r_i = r_i − r_{i−1} = −∂g_i/∂r_{i−1}``. The contracted Hessian
``Σ_i η_i ∇²g_i`` is block tridiagonal with 2×2 identity blocks: diagonal
``η_i + η_{i+1}`` (``η_{N+1} = 0``) and off-diagonal ``−η_{i+1}`` between bodies ``i`` and
``i + 1``.

This is the cost-growth scene of the benchmarks (``n = 2N`` coordinates, ``m = N``
constraints): the Newton matrix of ``P<s>L-…`` with ``J`` constraint points has
``s·2N + J·N`` rows, and fastvi factors it densely. ``chain(2)`` is the double pendulum
and ``chain(3)`` the triple pendulum, term for term.

``params = (m1 … mN, l1 … lN, g)``; the functions read ``N`` from ``len(q) // 2``, so one
set of module-level functions serves every N.
"""

from __future__ import annotations

import numpy as np
from numba.extending import register_jitable

from ..model import Model
from . import damping as damping_
from ..drawing import cartesian
from ._common import attach, check_positive

#: the smallest chain (a single link is :func:`fastvi.scenes.pendulum`)
MIN_LINKS = 1


def potential(q, p):
    """``V = g Σ_i m_i y_i`` (``params = (m_1 … m_N, l_1 … l_N, g)``)."""
    nb = q.shape[0] // 2
    acc = 0.0
    for i in range(nb):
        acc += p[i] * q[2 * i + 1]
    return p[2 * nb] * acc


def potential_grad(q, p, out):
    """``∇V``: ``g m_i`` at each ``y_i``, zero at each ``x_i``."""
    nb = q.shape[0] // 2
    for i in range(nb):
        out[2 * i] = 0.0
        out[2 * i + 1] = p[2 * nb] * p[i]


@register_jitable
def _link(q, i):
    """``r_i − r_{i−1}`` of link ``i`` (``r_{−1}``: the pivot at the origin)."""
    if i == 0:
        return q[0], q[1]
    return q[2 * i] - q[2 * i - 2], q[2 * i + 1] - q[2 * i - 1]


def constraint(q, p, out):
    """``g_i = ½ (|r_i − r_{i−1}|² − l_i²)``, link i from body i − 1 (the origin for i = 0)."""
    nb = q.shape[0] // 2
    for i in range(nb):
        dx, dy = _link(q, i)
        li = p[nb + i]
        out[i] = 0.5 * (dx * dx + dy * dy - li * li)


def constraint_jacobian(q, p, out):
    """``G``: row i is ``(r_i − r_{i−1})ᵀ`` at body i and its negative at body i − 1."""
    # only the entries of `pattern(N)`: the kernels hand `out` zeroed outside it
    for i in range(q.shape[0] // 2):
        dx, dy = _link(q, i)
        out[i, 2 * i] = dx
        out[i, 2 * i + 1] = dy
        if i > 0:
            out[i, 2 * i - 2] = -dx
            out[i, 2 * i - 1] = -dy


def constraint_hessian(q, eta, p, out):
    """``Σ_i η_i ∇²g_i``: block tridiagonal, ``(η_i + η_{i+1}) I`` on the diagonal blocks and
    ``−η_{i+1} I`` beside them."""
    # also the closed chain's (fastvi.scenes.closed_chain): its last link ties the last body
    # to a fixed point, so η has one entry more than there are bodies
    # only the entries of coordinates that share a link: the kernels hand `out` zeroed there
    # (the pattern G's implies) and never read the rest, so no O(n²) fill
    nb = q.shape[0] // 2
    m = eta.shape[0]
    for i in range(nb):
        d = eta[i] + (eta[i + 1] if i + 1 < m else 0.0)
        out[2 * i, 2 * i] = d
        out[2 * i + 1, 2 * i + 1] = d
        if i + 1 < nb:
            e = -eta[i + 1]
            out[2 * i, 2 * i + 2] = e
            out[2 * i + 2, 2 * i] = e
            out[2 * i + 1, 2 * i + 3] = e
            out[2 * i + 3, 2 * i + 1] = e


# the derivatives by θ write only the entries of `param_patterns`: a dense (k, n) output
# would cost O(N²) a call
def potential_grad_by_params(q, p, out):
    """``∂(∇V)/∂θ``: at each ``y_i``, ``g`` by ``m_i`` and ``m_i`` by ``g``; zero by the
    lengths (and by a damping coefficient after ``g``)."""
    nb = q.shape[0] // 2
    for i in range(nb):
        out[i, 2 * i + 1] = p[2 * nb]
        out[2 * nb, 2 * i + 1] = p[i]


def constraint_by_params(q, p, out):
    """``∂g/∂θ``: ``∂g_i/∂l_i = −l_i``, zero otherwise."""
    nb = q.shape[0] // 2
    for i in range(nb):
        out[nb + i, i] = -p[nb + i]


def param_derivatives(damping: float = 0.0) -> dict:
    """The chain's derivatives by ``params = (m_1 … m_N, l_1 … l_N, g[, c])`` (``Model``'s
    ``param_derivatives``, with :func:`param_patterns`): the constant mass matrix is data,
    ``G`` does not depend on θ."""
    return dict(potential_grad=potential_grad_by_params, constraint=constraint_by_params,
                constraint_jacobian=0, **damping_.param_derivatives(damping))


def param_patterns(N: int, damping: float = 0.0) -> dict:
    """``(l, entry)`` of the non-zeros of :func:`param_derivatives` (``Model``'s
    ``param_patterns``): ``∂(∇V)/∂θ`` at ``y_i`` by ``m_i`` and by ``g``, ``∂g_i/∂l_i``,
    and ``∂F/∂c`` everywhere."""
    i = np.arange(N)
    k = 2 * N + 1 + (1 if damping else 0)
    return dict(potential_grad=(np.concatenate([i, np.full(N, 2 * N)]), np.tile(2 * i + 1, 2)),
                constraint=(N + i, i), **damping_.param_patterns(damping, k, 2 * N))


def pattern(N: int):
    """``(rows, cols)`` of the non-zeros of the chain's ``G`` (m = N, n = 2N): link i joins
    body i − 1 (the origin for i = 0) to body i."""
    rows, cols = [], []
    for i in range(N):
        for a in range(max(0, 2 * i - 2), 2 * i + 2):
            rows.append(i)
            cols.append(a)
    return np.array(rows), np.array(cols)


def drawing(N: int):
    """The chain's :class:`fastvi.drawing.Drawing`: the pivot, then the N bodies, each link a bar."""
    return cartesian(2 * N, [(i, i + 1) for i in range(N)], before=[(0.0, 0.0)])


def state_from_angles(thetas, omegas=None, lengths=None):
    r"""Cartesian ``(q, v)`` of a chain from link angles measured from the downward vertical.

    ``r_i = r_{i−1} + l_i (sin θ_i, −cos θ_i)`` and ``ṙ_i = ṙ_{i−1} + l_i ω_i (cos θ_i, sin θ_i)``.

    Parameters
    ----------
    thetas : array_like (N,)
        Link angles (rad).
    omegas : array_like (N,), optional
        Angular velocities (rad/s); default at rest.
    lengths : array_like (N,), optional
        Link lengths; default 1.

    Returns
    -------
    q, v : ndarray (2N,)
    """
    th = np.atleast_1d(np.asarray(thetas, dtype=float))
    if th.ndim != 1 or th.size < MIN_LINKS:
        raise ValueError(f"`thetas` must be a non-empty 1-D sequence of angles, got shape {th.shape}")
    om = np.zeros_like(th) if omegas is None else np.atleast_1d(np.asarray(omegas, dtype=float))
    if om.shape != th.shape:
        raise ValueError(f"`omegas` must have the shape of `thetas` {th.shape}, got {om.shape}")
    ls = np.ones_like(th) if lengths is None else np.atleast_1d(np.asarray(lengths, dtype=float))
    if ls.shape != th.shape:
        raise ValueError(f"`lengths` must have the shape of `thetas` {th.shape}, got {ls.shape}")
    if not (np.all(np.isfinite(th)) and np.all(np.isfinite(om))):
        raise ValueError("`thetas` and `omegas` must be finite")
    s, c = np.sin(th), np.cos(th)
    q = np.empty(2 * th.size)
    v = np.empty(2 * th.size)
    q[0::2] = np.cumsum(ls * s)
    q[1::2] = np.cumsum(-ls * c)
    v[0::2] = np.cumsum(ls * c * om)
    v[1::2] = np.cumsum(ls * s * om)
    return q, v


def angles(q):
    """Link angles ``θ_i`` (..., N) from the downward vertical of configurations ``q`` (..., 2N)."""
    q = np.asarray(q, dtype=float)
    x = q[..., 0::2]
    y = q[..., 1::2]
    zero = np.zeros(x.shape[:-1] + (1,))
    dx = np.diff(np.concatenate((zero, x), axis=-1), axis=-1)
    dy = np.diff(np.concatenate((zero, y), axis=-1), axis=-1)
    return np.arctan2(dx, -dy)


def per_link(name: str, value, N: int) -> tuple[float, ...]:
    """A scalar broadcast to N links, or a sequence of N positive numbers."""
    if np.ndim(value) == 0:
        check_positive(**{name: value})
        return (float(value),) * N
    vals = tuple(value)
    if len(vals) != N:
        raise ValueError(f"`{name}` must be a number or have N = {N} entries, got {len(vals)}")
    for i, x in enumerate(vals):
        check_positive(**{f"{name}[{i}]": x})
    return tuple(float(x) for x in vals)


def chain(N: int, m=1.0, l=1.0, g: float = 9.81, damping: float = 0.0) -> Model:
    r"""Planar chain of ``N`` point masses on rigid links from the origin (n = 2N, m = N).

    Parameters
    ----------
    N : int
        Number of links (and bodies), ``N >= 1``.
    m : float or sequence of N floats, default 1
        Point masses (kg).
    l : float or sequence of N floats, default 1
        Link lengths (m), origin to body 1, body 1 to body 2, …
    g : float, default 9.81
        Gravitational acceleration along ``−y`` (m/s²).
    damping : float, default 0
        Viscous damping ``c`` (N s/m): a force ``−c ṙ_i`` on every mass
        (:mod:`fastvi.scenes.damping`; ``params`` then end with ``c``). Zero: a
        conservative model without any force callback.

    Returns
    -------
    Model
        With exact second derivatives, ``initial_state(thetas, omegas=None) -> (q0, v0)``
        (angles from the downward vertical; a consistent state: ``g(q0) = 0``,
        ``G(q0) v0 = 0`` to round-off), ``angles(q) -> thetas`` (..., N) and a ``drawing``
        (the pivot, then the bodies).

    Notes
    -----
    ``chain(2, m=(m1, m2), l=(l1, l2))`` integrates the same equations, with the same
    operations up to round-off, as :func:`fastvi.scenes.double_pendulum`.
    """
    if isinstance(N, bool) or not isinstance(N, (int, np.integer)):
        raise TypeError(f"`N` must be an integer number of links, got {N!r}")
    if N < MIN_LINKS:
        raise ValueError(f"`N` must be >= {MIN_LINKS}, got {N}")
    N = int(N)
    ms = per_link("m", m, N)
    ls = per_link("l", l, N)
    check_positive(g=g)
    c = damping_.check(damping)
    model = Model(
        2 * N, N, params=(*ms, *ls, g) + ((c,) if c else ()), mass=np.repeat(ms, 2),
        potential=potential, potential_grad=potential_grad, potential_hessian=0,
        constraint=constraint, constraint_jacobian=constraint_jacobian,
        constraint_hessian=constraint_hessian, constraint_jacobian_pattern=pattern(N),
        name=f"chain{N}" + ("-damped" if c else ""), param_derivatives=param_derivatives(c),
        param_patterns=param_patterns(N, c), mass_params=range(N),
        **damping_.options(c, 2 * N),
    )
    lengths = np.array(ls)

    def initial_state(thetas, omegas=None):
        th = np.atleast_1d(np.asarray(thetas, dtype=float))
        if th.shape != (N,):
            raise ValueError(f"`thetas` must have N = {N} entries, got shape {th.shape}")
        return state_from_angles(th, omegas, lengths)

    kw = dict(N=N, m=ms if len(set(ms)) > 1 else ms[0], l=ls if len(set(ls)) > 1 else ls[0], g=g,
              damping=c)
    return attach(model, "chain", kw, drawing=drawing(N), initial_state=initial_state, angles=angles)
