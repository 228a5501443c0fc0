r"""SciPy's ``solve_ivp`` on the index-1 right-hand side of a :class:`~fastvi.Model`.

The right-hand side ``y = (q, v) ↦ (v, a(q, v))`` is the compiled
:func:`fastvi.baselines.rk4.acceleration` (the same callbacks as the variational integrator
and the RK4 baseline), so the physics is identical and only the time stepping differs.
SciPy calls it from Python once per stage; that call overhead, not the model, dominates
the cost of this baseline.
"""

from __future__ import annotations

import time
import weakref

import numba as nb
import numpy as np
import scipy.integrate

from .. import _validate as check
from .._numba import njit, quiet
from ..model import Model
from ..status import Status
from ..kernels.layout import F_N
from .rk4 import OBS_G, OBS_GV, OBS_H, OBS_SIZE, BaselineResult, acceleration, observe, workspace

__all__ = ["solve_ivp"]

_METHODS = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")


@njit
def _rhs(fns, flags, Mc, prm, y, dy, ws):
    n = flags[F_N]
    q = y[:n]
    v = y[n:]
    for i in range(n):
        dy[i] = v[i]
    return acceleration(fns, flags, Mc, prm, q, v, dy[n:], ws)


_BOUND = weakref.WeakKeyDictionary()


def _bound_rhs(model: Model):
    """The jitted right-hand side and observation loop with this model's cfuncs frozen in.

    Passing the tuple of cfuncs from Python costs ~0.4 ms per call (numba types every
    first-class function argument on each call), which would swamp SciPy's per-stage calls
    (and, one call per output sample, the energies of a long run); freezing them into a
    closure costs one compile per model (a few seconds, not cached) and then ~5 µs per call.
    """
    if model not in _BOUND:
        (f0, f1, f2, f3, f4, f5, f6, f7, f8, f9, f10, f11, f12,
         f13) = model.kernel_arguments()[0]

        @nb.njit
        def rhs(flags, Mc, prm, y, dy, ws):
            return _rhs((f0, f1, f2, f3, f4, f5, f6, f7, f8, f9, f10, f11, f12, f13), flags, Mc,
                        prm, y, dy, ws)

        @nb.njit
        def observe_all(flags, Mc, prm, Y, out, ws):
            fns = (f0, f1, f2, f3, f4, f5, f6, f7, f8, f9, f10, f11, f12, f13)
            n = flags[F_N]
            q = np.empty(n)
            v = np.empty(n)
            for j in range(Y.shape[0]):
                for i in range(n):
                    q[i] = Y[j, i]
                    v[i] = Y[j, n + i]
                observe(fns, flags, Mc, prm, q, v, ws, out[j])

        _BOUND[model] = (rhs, observe_all)
    return _BOUND[model]


def solve_ivp(model: Model, q0, v0, *, t_end: float, method: str = "DOP853", rtol: float = 1e-10,
              atol: float = 1e-12, n_samples: int = 1001, t_eval=None, params=None,
              **options) -> BaselineResult:
    r"""Integrate ``model`` with :func:`scipy.integrate.solve_ivp` on its index-1 form.

    Parameters
    ----------
    model : Model
    q0, v0 : array_like (n,)
        Initial state; projected onto ``g = 0``, ``G v = 0`` as by :func:`fastvi.integrate`.
    t_end : float
        Final time.
    method : str, default "DOP853"
        Any explicit or implicit method of ``solve_ivp``.
    rtol, atol : float
        SciPy's tolerances.
    n_samples : int, default 1001
        Number of equally spaced output times on ``[0, t_end]`` (ignored if ``t_eval``).
    t_eval : array_like, optional
        Output times.
    params : array_like (k,), optional
    **options
        Passed to ``solve_ivp`` (e.g. ``max_step``).

    Returns
    -------
    BaselineResult
        ``h`` is ``nan`` (adaptive steps); ``stats["steps"]`` and
        ``stats["rhs_evaluations"]`` both hold SciPy's ``nfev`` (it does not report
        accepted steps); ``stats["wall_time"]`` and ``stats["cpu_time"]`` (CPU time of the
        calling thread) time ``scipy.integrate.solve_ivp`` alone, not the energies and
        residuals evaluated afterwards.
    """
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    if method not in _METHODS:
        raise ValueError(f"`method` must be one of {', '.join(_METHODS)}, got {method!r}")
    n = model.n
    q0 = check.vector(q0, "q0", n)
    v0 = check.vector(v0, "v0", n)
    prm = check.params(params, model)
    check.conservative(model, "solve_ivp")
    if isinstance(t_end, bool) or not isinstance(t_end, (int, float, np.integer, np.floating)) \
            or not (np.isfinite(t_end) and t_end > 0):
        raise ValueError(f"`t_end` must be positive and finite, got {t_end!r}")
    if t_eval is None:
        n_samples = check.count(n_samples, "n_samples", 2)
        t_eval = np.linspace(0.0, float(t_end), n_samples)
    q0, v0 = check.initial_state(model, q0, v0, prm)
    _, flags, Mc = model.kernel_arguments()
    ws = workspace(model, prm)  # large models: G M⁻¹ Gᵀ over the pattern of G
    failure = []
    with quiet():
        fast_rhs, observe_all = _bound_rhs(model)
        fast_rhs(flags, Mc, prm, np.concatenate((q0, v0)), np.empty(2 * n), ws)  # compile outside the timing

    def rhs(t, y):
        dy = np.empty(2 * n)
        st = fast_rhs(flags, Mc, prm, np.ascontiguousarray(y), dy, ws)
        if st != 0 and not failure:
            failure.append(st)
        return dy

    y0 = np.concatenate((q0, v0))
    w0, c0 = time.perf_counter(), time.thread_time()
    sol = scipy.integrate.solve_ivp(rhs, (0.0, float(t_end)), y0, method=method, rtol=rtol,
                                    atol=atol, t_eval=t_eval, **options)
    wall, cpu = time.perf_counter() - w0, time.thread_time() - c0
    Y = np.ascontiguousarray(sol.y.T)
    obs = np.zeros((Y.shape[0], OBS_SIZE))
    with quiet():
        observe_all(flags, Mc, prm, Y, obs, ws)
    status = Status(failure[0]) if failure else (Status.SUCCESS if sol.success else Status.NONFINITE)
    return BaselineResult(
        t=sol.t.copy(), q=Y[:, :n].copy(), v=Y[:, n:].copy(), energy=obs[:, OBS_H].copy(),
        constraint_residual=obs[:, OBS_G].copy(), velocity_residual=obs[:, OBS_GV].copy(),
        stats=dict(steps=int(sol.nfev), rhs_evaluations=int(sol.nfev), wall_time=wall,
                   cpu_time=cpu, message=sol.message),
        status=status, name=f"SciPy {method}", h=float("nan"), model_name=model.name,
    )
