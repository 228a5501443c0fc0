r"""Periodic orbits of the discrete flow by shooting, and their Floquet multipliers:
:func:`periodic_orbit`.

Newton's method on the closing condition ``Φ^N(x) = x`` of the integrator's own map, with the
exact derivatives of :func:`fastvi.sensitivity`, in coordinates of the tangent space of the
constrained phase space (:func:`fastvi.tangent_space`); ``docs/sensitivities.md``. An
autonomous model's orbits need a phase condition; a periodically forced model's (a driven
constraint, a time-dependent potential or force) have their time origin fixed by the drive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import _validate as valid
from ._discrete import momentum, momentum_mass, velocity
from .consistent import consistent_state
from .integrate import IntegrationError, Result, integrate
from .sensitivity import sensitivity, tangent_space

__all__ = ["periodic_orbit", "PeriodicOrbit", "PeriodicOrbitError"]

#: halvings of a Newton step that does not reduce the closing residual before giving up
_MAX_HALVINGS = 8
#: relative step of the central differences of ``M(q) v`` in ``q`` (a q-dependent mass only)
_FD_STEP = 1e-6
#: fractions of the period at which a force is compared with its value at ``t0`` to tell
#: whether it changes in time: not simple fractions, so that a force of period ``T / k``
#: shows it too
_PROBES = (0.1372, 0.3718, 0.5, 0.7291)
#: the callbacks that take the time in a ``time_dependent`` model
_TIMED_SLOTS = ("potential", "potential_grad", "constraint", "constraint_jacobian")
#: how far (relative) the model's time-dependent callbacks may differ between ``t0`` and
#: ``t0 + period`` at the guess: round-off in the drive's phase, far below a wrong period's
_PERIODIC_RTOL = 1e-8


@dataclass
class PeriodicOrbit:
    r"""A periodic orbit of the discrete flow, found by :func:`periodic_orbit`.

    Attributes
    ----------
    q0, v0 : ndarray (n,)
        The initial state: consistent, and returned to after ``n_steps`` steps.
    period : float
        ``n_steps · h``.
    h : float
    n_steps : int
    result : Result
        The trajectory over one period from ``(q0, v0)`` (every ``save_every``-th step).
    basis : ndarray (2n, 2(n − m))
        ``Z``: the orthonormal basis of the tangent space at ``(q0, p0)``, in ``(δq, δp)``,
        in which :attr:`monodromy` is written.
    monodromy : ndarray (2(n − m), 2(n − m))
        ``Zᵀ DΦ^N(x0) Z``: the tangent map of one period in the coordinates of ``Z``.
    multipliers : ndarray (2(n − m),), complex
        The eigenvalues of :attr:`monodromy`, farthest from 1 first: for an orbit of an
        autonomous conservative model the last two are the trivial pair ≈ 1 (the directions
        along the flow and across the energies); a forced model's have no trivial pair.
    residual : float
        ``max |(q, v)(period) − (q0, v0)|`` of :attr:`result`.
    iterations : int
        Newton iterations taken.
    method : str
    t0 : float
        The time of ``(q0, v0)``: for a forced model, the phase of the drive the orbit
        starts at.
    forced : bool
        Whether the model is forced (time-dependent, or with a force that changes in time),
        so that the orbit was sought without a phase condition.
    """

    q0: np.ndarray
    v0: np.ndarray
    period: float
    h: float
    n_steps: int
    result: Result = field(repr=False)
    basis: np.ndarray = field(repr=False)
    monodromy: np.ndarray = field(repr=False)
    multipliers: np.ndarray
    residual: float
    iterations: int
    method: str
    t0: float = 0.0
    forced: bool = False


class PeriodicOrbitError(RuntimeError):
    """Newton's method of :func:`periodic_orbit` did not converge, or found an equilibrium.

    Attributes
    ----------
    residual : float
        The closing residual ``max |(q, v)(period) − (q0, v0)|`` reached.
    iterations : int
        Newton iterations taken.
    q, v : ndarray (n,)
        The last iterate: a starting point for another try.
    """

    def __init__(self, message, *, residual, iterations, q, v):
        super().__init__(message)
        self.residual = residual
        self.iterations = iterations
        self.q = q
        self.v = v


def periodic_orbit(model, q0, v0, *, period: float, n_steps: int | None = None,
                   h: float | None = None, method="P2L-Q3G", phase="auto",
                   tol: float = 1e-12, max_iter: int = 20, params=None,
                   save_every: int = 1, t0: float = 0.0) -> PeriodicOrbit:
    r"""A periodic orbit of the discrete flow through a guess, and its Floquet multipliers.

    Finds a consistent state ``x0 = (q0, p0)`` that the integrator's map ``Φ`` (one step
    ``h``) brings back to itself after ``N`` steps, ``period = N h``:

    .. math:: F(x_0) = Φ^N(x_0) - x_0 = 0, \qquad φ(x_0) = 0,

    with ``φ`` a phase condition. Each Newton iteration works in the chart
    ``x = P(x_k + Z_k ξ)`` at the current iterate ``x_k``: ``Z_k`` (2n × 2d, ``d = n − m``)
    is the orthonormal basis of the tangent space of the constrained phase space
    (:func:`fastvi.tangent_space`) and ``P`` the projection onto the constraints
    (:func:`fastvi.consistent_state`). :func:`fastvi.sensitivity` propagates the columns of
    ``Z_k`` over the period (exact derivatives of the discrete map), giving
    ``Y_k = DΦ^N(x_k) Z_k``, and the step ``ξ`` is the least-squares solution of the
    ``2d + 1`` linear equations in ``2d`` unknowns

    .. math::

        \begin{pmatrix} Z_k^T Y_k - I \\ \nabla φ\, Z_k \end{pmatrix} ξ
        = -\begin{pmatrix} Z_k^T F(x_k) \\ φ(x_k) \end{pmatrix},

    halved while it does not reduce ``|F|² + φ²``. Why one more equation than unknowns is
    right: an autonomous conservative system has its periodic orbits in a two-parameter
    family, along the flow and across the energies. With the period fixed, energy is fixed
    too (where the period changes with the energy), and the phase condition picks one point
    of the orbit; ``Z^T Y − I`` then has rank ``2d − 1``, the component of ``F`` it misses
    (the energy's) vanishes by conservation, and the ``2d + 1`` equations are consistent
    with a full-rank matrix. The discrete map conserves a modified energy (to far below
    round-off over a period), so the same holds for it.

    **Monodromy and multipliers.** At the solution the orbit closes, so the tangent space
    at the end is the one at the start, and one basis ``Z`` of it serves at both ends: the
    monodromy matrix is

    .. math:: \mathcal{M} = Z^T DΦ^N(x_0)\, Z \qquad (2d × 2d),

    the tangent map of one period in the coordinates ``ξ`` of ``δx = Z ξ``. Another basis
    ``Z' = Z A`` (``A`` invertible: the coordinates of another chart, or minimal
    coordinates such as angles) gives ``A⁻¹ \mathcal{M} A``, a similar matrix: the
    eigenvalues, the *Floquet multipliers*, do not depend on the basis. The discrete map of
    a conservative model is symplectic on the constrained phase space, so ``\mathcal{M}``
    preserves the symplectic form restricted to the tangent space: its multipliers come in
    reciprocal pairs ``(λ, 1/λ)`` and, being real, in conjugate pairs, and ``det = 1``. Two
    of them are ≈ 1: the direction along the orbit (an eigenvector) and across the energies
    (a Jordan chain: a change of energy changes the period). The others decide linear
    stability: all on the unit circle (elliptic, ``λ = e^{±iθ}``), or a pair ``|λ| > 1``
    (unstable). They are those of the discrete map and differ from the exact flow's by the
    method's error, ``O(h^{2s})``.

    **Forced models.** A model whose constraints or potential depend on time
    (``time_dependent``), or whose force changes in time at the guess, is *forced*: its map
    over a period of the drive depends on where in the drive the orbit starts, ``t0``, and
    its periodic orbits (of the drive's period or a multiple of it) are isolated. There is
    no phase condition then: Newton solves the ``2d`` equations ``Z_kᵀ F(x_k) = 0`` in the
    ``2d`` unknowns ``ξ``. An equilibrium of the drive's period map — the inverted position
    of a pendulum on a vibrating pivot, say — is such an orbit and is returned. Where the
    model is conservative the multipliers still come in reciprocal pairs (the map is
    symplectic), none of them trivial; with damping their product is the contraction of
    phase-space volume over a period.

    Parameters
    ----------
    model : Model
        An autonomous conservative model (its periodic orbits come in families; a damped
        autonomous model has none, and Newton fails with :class:`PeriodicOrbitError`), or
        a forced one: time-dependent constraints or potential, or a force that changes in
        time, periodic with a period that divides ``period``.
    q0, v0 : array_like (n,)
        The guess, e.g. a linear normal mode; projected onto the constraints first.
    period : float
        The period sought, ``n_steps · h``. For a forced model, a period of its time
        dependence (that of the drive or a multiple of it): its callbacks are compared at
        ``t0`` and ``t0 + period`` at the guess, and a difference is an error.
    n_steps, h :
        Give one: the steps per period (then ``h = period / n_steps``), or the step size
        (then ``period`` must be a whole number of steps).
    method : str or Method, default "P2L-Q3G"
        As :func:`fastvi.integrate`.
    phase : "auto", "section", ("q", i), ("v", i) or None; default "auto"
        The phase condition. ``"section"``: ``x0`` lies on the hyperplane through the guess
        orthogonal to the direction of the flow there (in ``(q, p)``). ``("q", i)``,
        ``("v", i)``: ``q0[i]`` (``v0[i]``) keeps its value in the guess — e.g.
        ``("v", i)`` with ``v0[i] = 0`` starts at a turning point of coordinate ``i``.
        The coordinate must move along the orbit there. ``None``: no phase condition, for a
        forced model only (the drive fixes the time origin). ``"auto"``: ``"section"`` for
        an autonomous model, ``None`` for a forced one.
    tol : float, default 1e-12
        Converged when ``max |(q, v)(period) − (q0, v0)| ≤ tol · max(1, |q0|, |v0|)`` and
        the phase condition holds as closely; one more Newton step is then taken if it
        lowers the residual further (to round-off, for the price of one more run).
    max_iter : int, default 20
        Newton iterations before :class:`PeriodicOrbitError`.
    params : array_like (k,), optional
        Parameters (default: the model's).
    save_every : int, default 1
        Sampling of :attr:`PeriodicOrbit.result`; must divide ``n_steps``.
    t0 : float, default 0.0
        The time of the guess and of the orbit's start (the drive's phase for a forced
        model).

    Returns
    -------
    PeriodicOrbit
        The state ``(q0, v0)``, the trajectory, the monodromy matrix, the multipliers, the
        closing residual and the iterations.

    Raises
    ------
    PeriodicOrbitError
        Newton did not converge in ``max_iter`` iterations, or a step could not reduce the
        residual (no periodic orbit of that period near the guess), or, for an autonomous
        model, it converged to an equilibrium (which closes for any period); carries the
        last iterate.
    ValueError, TypeError
        Bad arguments, naming them: among them a ``period`` that is not a period of a forced
        model's time dependence, a phase condition for a forced model and none for an
        autonomous one.
    fastvi.IntegrationError
        The run from the guess itself fails.

    References
    ----------
    R. Seydel, *Practical Bifurcation and Stability Analysis*, 3rd ed., Springer (2010),
    ch. 7 (shooting and phase conditions, monodromy and multipliers).
    E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, 2nd ed., Springer
    (2006), ch. IX (modified energy of symplectic integrators).

    Examples
    --------
    >>> import numpy as np, fastvi
    >>> dp = fastvi.scenes.double_pendulum()          # the in-phase linear mode, larger
    >>> q0, v0 = dp.initial_state(0.3, 0.3 * np.sqrt(2))
    >>> T = 2 * np.pi / np.sqrt(9.81 * (2 - np.sqrt(2)))
    >>> orbit = fastvi.periodic_orbit(dp, q0, v0, period=1.02 * T, n_steps=200,
    ...                               phase=("v", 0))
    >>> bool(orbit.residual < 1e-12), orbit.multipliers.shape
    (True, (4,))

    The inverted position of Kapitza's pendulum, over one period of its pivot:

    >>> kp = fastvi.scenes.kapitza_pendulum()             # a ω = 7.5 m/s: stable
    >>> q0, v0 = kp.initial_state(np.pi + 0.05)
    >>> up = fastvi.periodic_orbit(kp, q0, v0, period=2 * np.pi / 150.0, n_steps=40)
    >>> bool(abs(kp.angle(up.q0, 0.0)) > 3.14159), bool(np.abs(np.abs(up.multipliers) - 1).max() < 1e-12)
    (True, True)
    """
    n = model.n
    period, h, N = _steps(period, n_steps, h)
    t0 = valid.start_time(t0)
    every = valid.count(save_every, "save_every", 1)
    if N % every:
        raise ValueError(f"`save_every` = {every} must divide the {N} steps of a period, so that "
                         "the trajectory ends at the period")
    tol = valid.tolerance(tol)
    iters = valid.max_iter(max_iter)
    prm = valid.params(params, model)
    run = dict(h=h, n_steps=N, method=method, params=prm, save_every=every, t0=t0)
    q, v = consistent_state(model, valid.vector(q0, "q0", n), valid.vector(v0, "v0", n),
                            params=prm, t=t0)
    forced = _forced(model, q, v, prm, t0, period)
    phi = _phase(model, phase, q, v, prm, run, forced)

    Z, A, S = _linearise(model, q, v, prm, run)
    polished = False
    for it in range(iters + 1):
        close, scale = _closing(S), max(1.0, np.abs(q).max(), np.abs(v).max())
        converged = close <= tol * scale and (phi is None or abs(phi.value(S)) <= tol * scale)
        if converged and (polished or it == iters):
            break
        if not converged and it == iters:
            raise PeriodicOrbitError(
                f"periodic_orbit did not converge in `max_iter` = {iters} iterations: closing "
                f"residual {close:.2e} > `tol` · scale = {tol * scale:.1e}. Raise `max_iter` or "
                "`tol`, or start from a better guess", residual=close, iterations=iters, q=q, v=v)
        # once converged, one more full step takes the residual from `tol` to round-off
        new = _newton_step(model, S, Z, A, phi, prm, run, 0 if converged else _MAX_HALVINGS)
        if new is None and converged:
            break
        if new is None:
            raise PeriodicOrbitError(
                f"periodic_orbit: no Newton step reduces the closing residual "
                f"({close:.2e} after {it} iteration(s)): there is no periodic orbit of period "
                f"{period:g} near the guess, or the guess is too far from one. Start from a "
                "better guess (a linear normal mode, a period nearer the linear one), or use "
                "another `phase` condition", residual=close, iterations=it, q=q, v=v)
        (q, v), Z, A, S = new
        polished = converged
    if not forced and _flow(model, q, v, prm, run)[1] is None:
        raise PeriodicOrbitError(
            "periodic_orbit converged to an equilibrium (the state does not move), not to an "
            f"orbit of period {period:g}: start from a guess with more motion, or with a period "
            "nearer the linear one", residual=close, iterations=it, q=q, v=v)
    return _orbit(S, Z, A, q, v, period, h, N, _closing(S), it, method, t0, forced)


# ----------------------------------------------------------------------------- arguments
def _steps(period, n_steps, h):
    """``(period, h, N)`` from the period and one of ``n_steps``, ``h``."""
    if isinstance(period, bool) or not isinstance(period, (int, float, np.integer, np.floating)):
        raise TypeError(f"`period` must be a float, got {period!r}")
    period = float(period)
    if not (period > 0.0 and math.isfinite(period)):
        raise ValueError(f"`period` must be positive and finite, got {period}")
    if (n_steps is None) == (h is None):
        raise ValueError("give exactly one of `n_steps` (steps per period) and `h` (step size)")
    if n_steps is not None:
        N = valid.count(n_steps, "n_steps", 1)
        return period, period / N, N
    h = valid.step_size(h)
    N = int(round(period / h))
    if N < 1 or abs(N * h - period) > 1e-9 * period:
        raise ValueError(f"`period` = {period:g} is not a whole number of steps `h` = {h:g} "
                         f"({period / h:.6g} steps): pass `n_steps=` instead of `h`, or "
                         "h = period / N")
    return period, h, N


@dataclass
class _Phase:
    """A phase condition: its value at the start of a run and its derivative along the
    run's directions (a row over the columns of the sensitivity)."""

    kind: str
    index: int
    target: float
    normal: np.ndarray = None

    def value(self, S) -> float:
        if self.kind == "section":
            x = np.concatenate([S.result.q[0], S.result.p[0]])
            return float(self.normal @ x) - self.target
        return float((S.result.q if self.kind == "q" else S.result.v)[0][self.index]) - self.target

    def row(self, S) -> np.ndarray:
        if self.kind == "section":
            return self.normal @ np.vstack([S.dq[0], S.dp[0]])
        return (S.dq if self.kind == "q" else S.dv)[0][self.index]


def _at(model, slot, q, v, prm, t):
    """The callback ``slot`` at ``(t, q, v)``, or ``None`` where the model has none."""
    try:
        return np.asarray(model.callback_value(slot, q, v, params=prm, t=t), dtype=np.float64)
    except ValueError:
        return None


def _forced(model, q, v, prm, t0, period) -> bool:
    """Whether the model is forced (time-dependent, or a force that changes in time at the
    guess); if so, checks at the guess that ``period`` is a period of its time dependence."""
    slots = list(_TIMED_SLOTS) if model.time_dependent else []
    if model.has_force:
        f0 = _at(model, "force", q, v, prm, t0)
        if any(not np.array_equal(_at(model, "force", q, v, prm, t0 + c * period), f0)
               for c in _PROBES):
            slots.append("force")
    if not slots:
        return False
    for slot in slots:
        a, b = _at(model, slot, q, v, prm, t0), _at(model, slot, q, v, prm, t0 + period)
        if a is None:
            continue
        gap = float(np.abs(b - a).max(initial=0.0))
        if gap > _PERIODIC_RTOL * max(1.0, float(np.abs(a).max(initial=0.0))):
            raise ValueError(
                f"`period` = {period:g} is not a period of the model's time dependence: its "
                f"`{slot}` at the guess differs by {gap:.2e} between t0 = {t0:g} and "
                f"t0 + period. Pass the drive's period or a multiple of it")
    return True


def _phase(model, phase, q, v, prm, run, forced) -> _Phase | None:
    n = model.n
    if isinstance(phase, str) and phase == "auto":
        phase = None if forced else "section"
    if forced and phase is not None:
        raise ValueError(
            f"`phase` = {phase!r}: the model is forced (time-dependent, or a force that changes "
            "in time), and the drive fixes where its orbit starts; pass `phase=None` (or "
            "'auto') and choose the start with `t0`")
    if phase is None:
        if not forced:
            raise ValueError("`phase` = None is for a forced model: an autonomous model's "
                             "orbits need a phase condition ('section', ('q', i) or ('v', i))")
        return None
    if isinstance(phase, str) and phase == "section":
        x, f = _flow(model, q, v, prm, run)
        if f is None:
            raise ValueError("`phase` = 'section' needs motion: the guess is an equilibrium "
                             "(no flow direction); start from a moving state, e.g. a linear "
                             "normal mode")
        normal = f / np.linalg.norm(f)
        return _Phase("section", -1, float(normal @ x), normal)
    ok = (isinstance(phase, tuple) and len(phase) == 2 and phase[0] in ("q", "v")
          and isinstance(phase[1], (int, np.integer)) and not isinstance(phase[1], bool))
    if not ok:
        raise ValueError(f"`phase` must be 'auto', 'section', ('q', i), ('v', i) with an "
                         f"integer i, or None, got {phase!r}")
    i = int(phase[1])
    if not 0 <= i < n:
        raise ValueError(f"`phase` index {i} is out of range for n = {n} coordinates (0 … {n - 1})")
    return _Phase(phase[0], i, float((q if phase[0] == "q" else v)[i]))


def _flow(model, q, v, prm, run):
    """``x = (q, p)`` and the direction of the flow there, ``Φ(x) − x`` (one step), or
    ``None`` at an equilibrium (a step that moves by round-off only)."""
    one = integrate(model, q, v, h=run["h"], n_steps=1, method=run["method"], params=prm,
                    t0=run["t0"])
    x = np.concatenate([one.q[0], one.p[0]])
    f = np.concatenate([one.q[1], one.p[1]]) - x
    return x, (f if np.abs(f).max() > 1e-12 * max(1.0, np.abs(x).max()) else None)


# ----------------------------------------------------------------------------- Newton
def _state(model, q, v, prm, t) -> np.ndarray:
    """``(q, p)`` of a state at time ``t``."""
    return np.concatenate([q, momentum(model, q, v, prm, t)])


def _closing(S) -> float:
    """``max |(q, v)(end) − (q, v)(start)|`` of a run."""
    r = S.result
    return float(max(np.abs(r.q[-1] - r.q[0]).max(), np.abs(r.v[-1] - r.v[0]).max()))


def _ends(model, S, prm):
    """``(q, p)`` at the start and at the end of the run ``S``."""
    r = S.result
    return (_state(model, r.q[0], r.v[0], prm, r.t[0]),
            _state(model, r.q[-1], r.v[-1], prm, r.t[-1]))


def _merit(model, S, phi, prm) -> float:
    x, xN = _ends(model, S, prm)
    d = xN - x
    return float(d @ d + (0.0 if phi is None else phi.value(S) ** 2))


def _chart(model, x, Z, xi, prm, t):
    """The consistent state nearest to ``x + Z ξ`` at time ``t`` (``None`` where the
    projection fails: a step too long)."""
    n = model.n
    y = x + Z @ xi
    q = y[:n]
    try:
        v = velocity(model, q, y[n:], prm, t)
        return consistent_state(model, q, v, params=prm, t=t)
    except (ValueError, np.linalg.LinAlgError):
        return None


def _newton_step(model, S, Z, A, phi, prm, run, halvings):
    """The next iterate ``(state, Z, A, run)`` from the run ``S`` at the current one: the
    least-squares Newton step, halved up to ``halvings`` times until ``|F|² + φ²`` drops;
    ``None`` if it never does."""
    x, xN = _ends(model, S, prm)
    Ainv = np.linalg.inv(A)
    Y = np.vstack([S.dq[-1], S.dp[-1]])
    lhs, rhs = Z.T @ Y @ Ainv - np.eye(Z.shape[1]), -(Z.T @ (xN - x))
    if phi is not None:
        lhs = np.vstack([lhs, phi.row(S) @ Ainv])
        rhs = np.concatenate([rhs, [-phi.value(S)]])
    xi = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    merit = _merit(model, S, phi, prm)
    for j in range(halvings + 1):
        trial = _chart(model, x, Z, 0.5 ** j * xi, prm, run["t0"])
        if trial is None:
            continue
        try:
            Zt, At, St = _linearise(model, *trial, prm, run)
        except IntegrationError:  # a step too long: the run from the trial state failed
            continue
        if _merit(model, St, phi, prm) < merit:
            return trial, Zt, At, St
    return None


def _linearise(model, q, v, prm, run):
    """The basis ``Z`` at ``(q, v)``, the run over one period with the columns of ``Z`` as
    directions, and ``A = Zᵀ (δq, δp)(0)``: the coordinates in ``Z`` of the tangent vectors
    the directions became (``I`` up to the difference quotients of ``C_q``)."""
    n, k, t = model.n, prm.shape[0], run["t0"]
    Z = tangent_space(model, q, v, params=prm, t=t)
    M = momentum_mass(model, q, prm, t)
    dv = np.linalg.solve(M, Z[n:] - _momentum_derivative(model, q, v, prm, t) @ Z[:n])
    D = np.vstack([Z[:n], dv, np.zeros((k, Z.shape[1]))])
    S = sensitivity(model, q, v, wrt=D, **run)
    A = Z.T @ np.vstack([S.dq[0], S.dp[0]])
    return Z, A, S


def _momentum_derivative(model, q, v, prm, t) -> np.ndarray:
    """``C_q = ∂p/∂q`` at fixed ``v`` by central differences, ``p`` the
    :func:`fastvi._discrete.momentum` (zero for a constant invertible mass matrix; it depends
    on ``q`` through ``G`` for a singular one). Its error only moves the directions within
    the tangent space: ``A`` accounts for it."""
    n = model.n
    if model.mass_matrix_constant is not None and not model.mass_singular:
        return np.zeros((n, n))
    C = np.empty((n, n))
    for j in range(n):
        e = np.zeros(n)
        e[j] = _FD_STEP * max(1.0, abs(q[j]))
        C[:, j] = (momentum(model, q + e, v, prm, t) - momentum(model, q - e, v, prm, t)) / (2 * e[j])
    return C


def _orbit(S, Z, A, q, v, period, h, N, close, iterations, method, t0, forced) -> PeriodicOrbit:
    Y = np.vstack([S.dq[-1], S.dp[-1]])
    mono = Z.T @ Y @ np.linalg.inv(A)
    lam = np.linalg.eigvals(mono)
    lam = lam[np.argsort(-np.abs(lam - 1.0), kind="stable")]
    name = method if isinstance(method, str) else getattr(method, "name", str(method))
    return PeriodicOrbit(q.copy(), v.copy(), period, h, N, S.result, Z, mono, lam, close,
                         iterations, name, t0, forced)
