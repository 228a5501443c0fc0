r"""Consistent initial data for any model: :func:`consistent_state`.

A constrained model needs ``g(q0) = 0`` and ``G(q0) v0 = 0`` (``docs/method.md`` §1), and
:func:`fastvi.integrate` only projects data that are off by less than ``1e-6``. Deriving a
consistent state by hand is much of the work of writing a model with redundant coordinates;
:func:`consistent_state` does it from a rough guess, keeping the coordinates the user chose
(e.g. a crank angle and its speed) exactly as given.
"""

from __future__ import annotations

import math

import numpy as np

from . import _validate as valid
from .model import Model

__all__ = ["consistent_state"]

_EPS = np.finfo(float).eps
#: Smallest singular value of the free columns of G, relative to |G|, that counts as rank.
_RANK_RTOL = 1e-10
_MAX_ITER = 50


def consistent_state(model: Model, q, v, *, fixed=(), t: float = 0.0, params=None,
                     max_iter: int = _MAX_ITER):
    r"""The consistent state ``(q0, v0)`` nearest to a guess ``(q, v)``, keeping ``fixed`` entries.

    Positions: Gauss–Newton on ``g(q) = 0`` changing only the free coordinates ``F`` (those
    not in ``fixed``), each step the smallest one in the metric of the mass matrix,

    .. math::

        \min_{\Delta q_F} \tfrac12 \Delta q_F^T M_{FF} \Delta q_F \quad\text{s.t.}\quad
        g(q) + G_F \Delta q_F = 0
        \;\Longrightarrow\;
        \Delta q_F = -M_{FF}^{-1} G_F^T \left(G_F M_{FF}^{-1} G_F^T\right)^{-1} g(q),

    with ``G_F`` the columns of ``G = ∂g/∂q`` of the free coordinates and ``M_FF`` the free
    block of ``M(q)`` (re-evaluated at each iterate), halving a step that does not reduce
    ``|g|``; iterations stop when the step is at round-off. Velocities: the fixed entries
    are kept and the free ones changed least in the same metric so that ``G v = 0``,

    .. math::

        v_F \leftarrow v_F - M_{FF}^{-1} G_F^T \left(G_F M_{FF}^{-1} G_F^T\right)^{-1}
        \left(G v + g_t\right),

    solved twice (the second pass removes the round-off of the first). ``g_t = ∂g/∂t`` is
    zero unless the model is ``time_dependent`` (a driven constraint).

    Parameters
    ----------
    model : Model
    q, v : array_like (n,)
        The guess; the entries listed in ``fixed`` are kept bit for bit.
    fixed : sequence of int, default ()
        Coordinate indices (0 … n−1) whose position and velocity are prescribed, e.g. the
        two coordinates of a crank pin to set its angle and speed.
    t : float, default 0.0
        The time of the state. It matters only to a ``time_dependent`` model: the
        constraints are solved at ``t``, and the velocities so that ``G v + g_t = 0``.
    params : array_like (k,), optional
        Parameters (default: the model's).
    max_iter : int, default 50
        Gauss–Newton iterations before giving up.

    Returns
    -------
    q0, v0 : ndarray (n,)
        ``|g(q0)|`` and ``|G(q0) v0|`` at round-off; ``q0[fixed] == q[fixed]`` and
        ``v0[fixed] == v[fixed]`` exactly.

    Raises
    ------
    ValueError
        When the fixed coordinates leave the system singular (``G_F`` loses rank: e.g.
        fixing a coordinate the constraints determine), naming them; when the iteration
        does not converge (naming the residual reached); for bad arguments.
    fastvi.ModelCheckError
        When a callback writes outside its declared output (checked first, once per model,
        as :func:`fastvi.integrate` does).

    Examples
    --------
    >>> import numpy as np, fastvi
    >>> dp = fastvi.scenes.double_pendulum()
    >>> q0, v0 = fastvi.consistent_state(dp, [0.5, -0.9, 1.2, -1.5], [1.0, 0.0, 0.0, 0.0], fixed=[0])
    >>> bool(np.abs(dp.constraint_value(q0)).max() < 1e-13), q0[0]
    (True, np.float64(0.5))
    """
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    n, m = model.n, model.m
    q = valid.vector(q, "q", n).copy()
    v = valid.vector(v, "v", n).copy()
    prm = valid.params(params, model)
    if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not math.isfinite(t):
        raise ValueError(f"`t` must be a finite float, got {t!r}")
    iters = valid.max_iter(max_iter)
    fix = _fixed_indices(fixed, n)
    free = np.array([i for i in range(n) if i not in set(fix)], dtype=np.int64)
    if m == 0:
        return q, v
    if not model.checked:  # our evaluations below use the plain (unguarded) buffers
        from .check import check_sizes

        check_sizes(model, q, v, params=prm, t=t)
    if free.size < m:
        raise ValueError(
            f"`fixed` leaves {free.size} free coordinate(s) for m = {m} constraints: fixing "
            f"{_names(fix)} over-determines the system; fix at most {n - m} coordinate(s)")

    scale = max(1.0, float(np.abs(q).max()))
    g = _constraint(model, q, t, prm)
    step_size, done, it = np.inf, False, 0
    for it in range(iters + 1):
        gnorm = float(np.linalg.norm(g))
        done = gnorm == 0.0 or step_size <= 4.0 * _EPS * scale
        if done or it == iters:
            break
        G = _jacobian(model, q, t, prm)
        W, S = _reduced(model, q, prm, G, free, fix)
        dq = -W @ np.linalg.solve(S, g)
        lam = 1.0
        while True:  # halve a step that does not reduce |g| (far from the solution)
            trial = q.copy()
            trial[free] += lam * dq
            g_trial = _constraint(model, trial, t, prm)
            ok = np.all(np.isfinite(g_trial))
            if ok and (np.linalg.norm(g_trial) < gnorm or lam * np.abs(dq).max() <= 1e3 * _EPS * scale):
                break
            lam *= 0.5
            if lam < 1e-6:
                raise ValueError(_not_converged(model, q, g, it, "no step along the Gauss–Newton "
                                                "direction reduces |g|", fix))
        q, g = trial, g_trial
        step_size = lam * float(np.abs(dq).max())
    G = _jacobian(model, q, t, prm)
    gmax = float(np.abs(g).max())
    # converged: the last step at round-off and |g| at the round-off of its terms (|G|·|q|)
    gtol = 1e-12 * max(1.0, float(np.abs(G).max()) * scale)
    if gmax > gtol or not (done or step_size <= 1e-10 * scale):
        raise ValueError(_not_converged(model, q, g, it, f"the last step was {step_size:.1e}", fix))

    W, S = _reduced(model, q, prm, G, free, fix)
    g_t = _constraint_time_derivative(model, q, t, prm)
    for _ in range(2):
        v[free] -= W @ np.linalg.solve(S, G @ v + g_t)
    return q, v


# ----------------------------------------------------------------------------- g(t, q) and g_t
def _constraint(model: Model, q: np.ndarray, t: float, prm: np.ndarray) -> np.ndarray:
    """``g(t, q)`` (``t`` is ignored by a model that is not ``time_dependent``)."""
    g = model.constraint_value(q, prm, t)
    if not np.all(np.isfinite(g)):
        raise ValueError(f"callback `constraint` returned non-finite values at q = {q}: {g}")
    return g


def _constraint_time_derivative(model: Model, q: np.ndarray, t: float, prm: np.ndarray) -> np.ndarray:
    """``g_t = ∂g/∂t`` at ``(t, q)``: the callback, a difference in ``t``, or zero for
    constraints that do not depend on time."""
    gt = model.constraint_time_derivative_value(q, prm, t)
    if not np.all(np.isfinite(gt)):
        raise ValueError(f"∂g/∂t is not finite at t = {t}, q = {q}: {gt}")
    return gt


# ----------------------------------------------------------------------------- helpers
def _jacobian(model: Model, q: np.ndarray, t: float, prm: np.ndarray) -> np.ndarray:
    G = model.constraint_jacobian_value(q, prm, t)
    if not np.all(np.isfinite(G)):
        raise ValueError(f"callback `constraint_jacobian` returned non-finite values at q = {q}: {G}")
    return G


def _reduced(model, q, prm, G, free, fix):
    """``W = M_FF⁻¹ G_Fᵀ`` and ``S = G_F W`` at ``q``, refusing a rank-deficient ``G_F``."""
    GF = G[:, free]
    sv = np.linalg.svd(GF, compute_uv=False)
    gscale = float(np.abs(G).max())
    if sv[-1] <= _RANK_RTOL * max(gscale, 1e-300):
        raise ValueError(_singular(G, free, fix, q, sv))
    M = valid.mass_metric(model.mass_matrix(q, prm), G)
    MFF = M[np.ix_(free, free)]
    try:
        L = np.linalg.cholesky(0.5 * (MFF + MFF.T))
    except np.linalg.LinAlgError:
        raise ValueError(f"the mass matrix at q = {q} is not positive definite on the free "
                         f"coordinates {_names(free)}") from None
    W = np.linalg.solve(L.T, np.linalg.solve(L, GF.T))
    return W, GF @ W


def _singular(G, free, fix, q, sv) -> str:
    tol = _RANK_RTOL * max(float(np.abs(G).max()), 1e-300)
    rank = int(np.sum(sv > tol))
    m = G.shape[0]
    # the fixed coordinates the constraints determine: freeing one of them restores rank
    culprits = [i for i in fix if np.linalg.matrix_rank(G[:, list(free) + [i]], tol=tol) > rank]
    if culprits:
        return (f"`fixed` leaves the constraints singular: with {_names(fix)} fixed, the constraint "
                f"Jacobian on the free coordinates has rank {rank} < m = {m} at q = {q}. The "
                f"constraints determine {_names(culprits)}: do not fix "
                f"{'it' if len(culprits) == 1 else 'all of them'}")
    return (f"the constraint Jacobian has rank {rank} < m = {m} at q = {q} even with no coordinate "
            "fixed (a singular position of the mechanism, or redundant constraints): start from a "
            "guess away from it")


def _not_converged(model, q, g, iters, why, fix) -> str:
    kept = f" with {_names(fix)} fixed" if fix else ""
    return (f"consistent_state did not converge for model {model.name!r}{kept}: max|g| = "
            f"{float(np.abs(g).max()):.3e} after {iters} iteration(s) ({why}), at q = {q}. Start from "
            "a better guess (closer to the constraints), or check that the fixed values are "
            "reachable (e.g. a crank pin within the crank's radius)")


def _names(idx) -> str:
    idx = [int(i) for i in idx]
    return ("coordinate " if len(idx) == 1 else "coordinates ") + ", ".join(f"q[{i}]" for i in idx)


def _fixed_indices(fixed, n: int) -> list[int]:
    try:
        items = list(np.asarray(fixed).ravel()) if not isinstance(fixed, (list, tuple, range)) else list(fixed)
    except Exception:  # noqa: BLE001 - anything that is not a sequence
        raise TypeError(f"`fixed` must be a sequence of coordinate indices, got {fixed!r}") from None
    out = []
    for i in items:
        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)):
            raise TypeError(f"`fixed` must hold coordinate indices (integers), got {i!r} in {fixed!r}")
        if not 0 <= i < n:
            raise ValueError(f"`fixed` index {int(i)} is out of range for n = {n} coordinates (0 … {n - 1})")
        if int(i) not in out:
            out.append(int(i))
    return sorted(out)
