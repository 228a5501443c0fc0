"""The Python driver: validate, allocate, call the compiled loop, build the :class:`Result`."""

from __future__ import annotations

import sys
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from . import _validate as valid
from ._numba import quiet
from .kernels import drive
from .kernels.step import make_workspace, velocity_residual
from .model import Model
from .status import MESSAGES, Status
from .tables import Method

__all__ = ["integrate", "Result", "IntegrationError"]

_PROGRESS_CHUNKS = 50  # progress lines per run when progress=True
#: growth of the energy error (last tenth of the samples over the first) that no bounded,
#: oscillating error reaches: round-off grows like √steps, chaos by a small factor, while a
#: step beyond a method's stability limit grows exponentially (docs/robustness.md)
ENERGY_GROWTH_ALARM = 1e6


@dataclass
class Result:
    """Trajectory of :func:`integrate` at the saved steps.

    Attributes
    ----------
    t : ndarray (K,)
        Times of the samples; ``t[0] = 0`` is the (projected) initial state.
    q, v, p : ndarray (K, n)
        Positions, velocities ``v = M⁻¹p`` and momenta.
    energy : ndarray (K,)
        ``H = ½ vᵀ M v + V``.
    constraint_residual, velocity_residual : ndarray (K,)
        ``max |g(q_k)|`` and ``max |G(q_k) v_k|`` over the steps since the previous sample.
    newton_iterations : ndarray (K,)
        Newton iterations spent since the previous sample.
    stats : dict
        ``steps``, ``newton_iterations`` (total), ``wall_time`` (s), ``max_residual``.
    status : Status
        ``Status.SUCCESS`` or the reason the run stopped early.
    method : Method
    h : float
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    p: np.ndarray
    energy: np.ndarray
    constraint_residual: np.ndarray
    velocity_residual: np.ndarray
    newton_iterations: np.ndarray
    stats: dict
    status: Status
    method: Method
    h: float
    failed_step: int | None = None
    model_name: str = field(default="model")

    @property
    def success(self) -> bool:
        return self.status >= 0

    @property
    def message(self) -> str:
        return MESSAGES[self.status]

    @property
    def energy_error(self) -> np.ndarray:
        """``H(t) − H(0)``."""
        return self.energy - self.energy[0]

    def summary(self) -> str:
        """One line per figure a user checks first."""
        return (
            f"{self.model_name}: method {self.method.name}, h = {self.h:g}, "
            f"steps = {self.stats['steps']}, wall time = {self.stats['wall_time']:.3f} s, "
            f"max |ΔH| = {np.max(np.abs(self.energy_error)):.3e}, "
            f"max |g| = {np.max(self.constraint_residual):.3e}, "
            f"max |Gv| = {np.max(self.velocity_residual):.3e}, "
            f"Newton iterations/step = {self.stats['newton_iterations'] / max(1, self.stats['steps']):.2f}"
        )

    def save(self, path) -> None:
        """Write the arrays and stats to a ``.npz`` file (read back with ``numpy.load``)."""
        np.savez_compressed(
            path, t=self.t, q=self.q, v=self.v, p=self.p, energy=self.energy,
            constraint_residual=self.constraint_residual, velocity_residual=self.velocity_residual,
            newton_iterations=self.newton_iterations, h=self.h, method=self.method.name,
            status=int(self.status), **{f"stats_{k}": v for k, v in self.stats.items()},
        )

    def plot(self, path=None):
        """Energy error and constraint residual against time (needs matplotlib)."""
        import matplotlib

        if path is not None:
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, (a1, a2) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
        a1.plot(self.t, self.energy_error)
        a1.set_ylabel("H(t) − H(0)")
        a2.semilogy(self.t[1:], np.maximum(self.constraint_residual[1:], 1e-300), label="max|g|")
        a2.semilogy(self.t[1:], np.maximum(self.velocity_residual[1:], 1e-300), label="max|Gv|")
        a2.set_xlabel("t")
        a2.legend()
        a1.set_title(f"{self.model_name}, {self.method.name}, h = {self.h:g}")
        fig.tight_layout()
        if path is not None:
            fig.savefig(path, dpi=120)
            plt.close(fig)
        return fig


class IntegrationError(RuntimeError):
    """The integration could not continue (see :class:`fastvi.Status`).

    Attributes
    ----------
    status : Status
    step : int
        Index of the step that failed (0-based: the step from ``t = step·h``).
    time : float
        Time at the start of that step.
    residual : float
        Max-norm of the Newton residual at the last iterate.
    result : Result
        The trajectory up to the last good step.
    """

    def __init__(self, status: Status, step: int, time: float, residual: float, result: Result,
                 detail: str | None = None):
        self.status, self.step, self.time, self.residual, self.result = status, step, time, residual, result
        self.detail = detail
        super().__init__(
            f"{MESSAGES[status]} (status {int(status)} {status.name}, at step {step}, t = {time:.6g}, "
            f"residual {residual:.3e}, method {result.method.name}, h = {result.h:g})"
            + (f": {detail}" if detail else "")
        )


def _alloc(K: int, n: int):
    return (np.zeros(K), np.zeros((K, n)), np.zeros((K, n)), np.zeros((K, n)), np.zeros(K),
            np.zeros(K), np.zeros(K), np.zeros(K))


def integrate(
    model: Model,
    q0,
    v0,
    *,
    h: float,
    t_end: float | None = None,
    n_steps: int | None = None,
    method: str | Method = "P2L-Q3G",
    save_every: int = 1,
    tol: float = valid.DEFAULT_TOL,
    max_iter: int = valid.DEFAULT_MAX_ITER,
    params=None,
    progress: bool = False,
    on_failure: str = "raise",
    recover: int = 0,
    check: bool = True,
) -> Result:
    r"""Integrate a constrained mechanical system with a Galerkin variational integrator.

    Each step solves the discrete Euler–Lagrange equations of ``docs/method.md`` for the
    control points ``Q^1 … Q^s`` and the constraint impulses by Newton's method, then
    updates the momentum explicitly and projects it onto the hidden constraint
    ``G(q) M⁻¹ p = 0`` (RATTLE pattern). The map ``(q_k, p_k) → (q_{k+1}, p_{k+1})`` is
    symplectic on the constrained phase space; constraints hold at every constraint point
    to Newton tolerance.

    Parameters
    ----------
    model : Model
    q0, v0 : array_like (n,)
        Initial configuration and velocity. Slightly inconsistent data are projected onto
        ``g = 0``, ``G v = 0`` (with a warning when the move exceeds round-off); data off by
        more than 1e-6 raise.
    h : float
        Step size.
    t_end, n_steps :
        Exactly one: final time (a whole number of steps) or number of steps.
    method : str or Method, default "P2L-Q3G"
        See :mod:`fastvi.tables`. ``P<s>L-Q<r>G`` is order ``2s`` for ``r >= s``.
    save_every : int, default 1
        Keep every k-th step (and the last); residuals are maxima over the skipped steps.
    tol : float, default 1e-14
        Newton stops when the predicted error of the control points, relative to
        ``max(1, |q_k|)``, is below ``tol`` (increment-based: residual tolerances on the
        momentum rows would leave an error of order ``tol/h`` per step).
    max_iter : int, default 30
        Newton iterations per step before giving up.
    params : array_like (k,), optional
        Parameters for this run (default: the model's).
    progress : bool, default False
        Print progress lines to stderr (the run is split into chunks; results are identical).
    on_failure : {"raise", "return"}
        On a failed step raise :class:`IntegrationError` (carrying the partial result), or
        return the partial :class:`Result` with its ``status`` set.
    recover : int, default 0
        Opt-in recovery: a step whose Newton iteration fails is retaken as 2, 4, …,
        ``2**recover`` substeps of ``h/2**j`` before giving up. The saved time grid stays
        ``k·h``; the map over a recovered step is a composition of variational steps (still
        symplectic and constraint-preserving) but of a different method than its
        neighbours, so the modified energy may jump slightly there. Recovered steps are
        listed in ``stats["recovered_steps"]`` as (step, substeps).
    check : bool, default True
        The first time a model is integrated, run :func:`fastvi.check.check_model` at ``q0``
        and one nearby state (a few milliseconds): first every callback is evaluated once
        into guarded buffers, so one that writes past its declared output shape, into its
        inputs, or leaves an entry unset raises :class:`fastvi.ModelCheckError` instead of
        corrupting memory in the kernels; then its derivative callbacks are compared with
        finite differences. Models that passed once (or passed :meth:`Model.check`) are not
        checked again. ``check=False`` skips both, at your own risk: a callback with a size
        mistake then writes out of bounds (crashes, or silently wrong results).

    Returns
    -------
    Result

    References
    ----------
    Paper A: variational integrators in holonomic mechanics (constraint points, split
    action). Paper B: higher-order variational Galerkin integrators for multibody systems
    with constraints. Both in ``shared/seeds``; the method is written out in
    ``docs/method.md``.
    """
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    if on_failure not in ("raise", "return"):
        raise ValueError(f"`on_failure` must be 'raise' or 'return', got {on_failure!r}")
    n = model.n
    q0 = valid.vector(q0, "q0", n)
    v0 = valid.vector(v0, "v0", n)
    prm = valid.params(params, model)
    h = valid.step_size(h)
    total = valid.step_count(h, t_end, n_steps)
    every = valid.save_every(save_every)
    tol = valid.tolerance(tol)
    iters = valid.max_iter(max_iter)
    recover = valid.recover(recover)
    meth = valid.method(method)
    if check and not model._checked:  # before the projection, which trusts G(q)
        model.check(q0, v0, params=prm, n_random=1)
    q0, v0 = valid.initial_state(model, q0, v0, prm)

    fns, flags, Mc = model.kernel_arguments()
    M0 = model.mass_matrix(q0, prm)
    state = np.zeros((6, n))
    state[0], state[1], state[2] = q0, M0 @ v0, v0
    ws = make_workspace(n, model.m, meth.s, meth.r, meth.J)
    K = total // every + 1 + (1 if total % every else 0)
    outs = _alloc(K, n)
    T, Qs, Vs, Ps, En, Gr, GVr, It = outs
    Qs[0], Vs[0], Ps[0] = q0, v0, state[1]
    En[0] = 0.5 * v0 @ state[1] + model.potential_energy(q0, prm)
    if model.m:
        Gr[0] = np.max(np.abs(model.constraint_value(q0, prm)))
        GVr[0] = velocity_residual(model.constraint_jacobian_value(q0, prm), v0, n, model.m)
    info = np.zeros(drive.INFO_SIZE)
    info[drive.I_SLOT] = 1
    info[drive.I_FIRST] = 1
    tabs = meth.kernel_tables

    chunk = total if not progress else max(1, total // _PROGRESS_CHUNKS)
    t0 = time.perf_counter()
    status = 0
    recovered = []
    while info[drive.I_STEPS] < total:
        with quiet():
            status = drive.run(fns, flags, Mc, prm, tabs, h, tol, iters, state, ws, chunk, total,
                               every, outs, info)
        if status != 0 and recover:
            sub = _retry_in_substeps(model, meth, h, tol, iters, prm, state, recover, total, every,
                                     outs, info, ws)
            if sub:
                recovered.append((int(info[drive.I_STEPS]) - 1, sub))
                status = 0
                continue
        if progress:
            done = int(info[drive.I_STEPS])
            el = time.perf_counter() - t0
            print(f"fastvi: {done}/{total} steps ({100 * done / total:.0f}%), t = {done * h:.6g}, "
                  f"{el:.1f} s elapsed, {done / max(el, 1e-9):.3g} steps/s", file=sys.stderr, flush=True)
        if status != 0:
            break
    wall = time.perf_counter() - t0
    J = int(info[drive.I_SLOT])
    status = Status(status)
    result = Result(
        t=T[:J].copy(), q=Qs[:J].copy(), v=Vs[:J].copy(), p=Ps[:J].copy(), energy=En[:J].copy(),
        constraint_residual=Gr[:J].copy(), velocity_residual=GVr[:J].copy(),
        newton_iterations=It[:J].copy(),
        stats=dict(steps=int(info[drive.I_STEPS]), newton_iterations=int(info[drive.I_ITERS]),
                   wall_time=wall, max_residual=float(info[drive.I_MAXRES]),
                   recovered_steps=recovered),
        status=status, method=meth, h=h, model_name=model.name,
        failed_step=None if status == 0 else int(info[drive.I_FAILED]),
    )
    _warn_if_energy_explodes(result)
    if status != 0 and on_failure == "raise":
        k = int(info[drive.I_FAILED])
        culprit = _nonfinite_callback(model, prm, state, ws) if status == Status.NONFINITE else None
        raise IntegrationError(status, k, k * h, float(info[drive.I_RES]), result, culprit)
    return result


def _warn_if_energy_explodes(result: Result) -> None:
    """Warn when the energy error grows by ``ENERGY_GROWTH_ALARM`` over the run.

    A variational integrator's energy error stays bounded; exponential growth means the
    step is beyond the method's stability limit (e.g. ``P1L-Q2G`` with ``ωh > √12`` on a
    stiff spring), and the trajectory is then wrong even though every step converged.
    """
    err = np.abs(result.energy_error[1:])
    if err.size < 20 or not np.all(np.isfinite(err)):
        return
    k = err.size // 10
    first, last = err[:k].max(), err[-k:].max()
    floor = 1e-6 * max(1.0, abs(result.energy[0]))
    if last > floor and last > ENERGY_GROWTH_ALARM * first:
        warnings.warn(
            f"the energy error grew from {first:.2e} to {last:.2e} over the run: h = {result.h:g} is "
            f"probably beyond the stability limit of {result.method.name} for this model (a stiff "
            "spring?); use a smaller h or a method with r = s, e.g. 'P2L-Q2G' (docs/robustness.md)",
            RuntimeWarning, stacklevel=3,
        )


def _retry_in_substeps(model, meth, h, tol, iters, prm, state, levels, total, every, outs, info, ws):
    """Retake the failed step (state rows 0–2 still hold its start) as 2, 4, … substeps.

    Returns the number of substeps that succeeded (the step is then accepted and booked as
    one step of the main grid), or 0 if all ``levels`` halvings failed.
    """
    fns, flags, Mc = model.kernel_arguments()
    tabs = meth.kernel_tables
    for level in range(1, levels + 1):
        sub = 2**level
        trial = state.copy()
        ws_sub = make_workspace(model.n, model.m, meth.s, meth.r, meth.J)
        outs_sub = _alloc(1, model.n)
        info_sub = np.zeros(drive.INFO_SIZE)
        info_sub[drive.I_FIRST] = 1
        with quiet():
            st = drive.run(fns, flags, Mc, prm, tabs, h / sub, tol, iters, trial, ws_sub, sub, sub, sub,
                           outs_sub, info_sub)
        if st == 0:
            state[:3] = trial[:3]
            info[drive.I_ITERS] += info_sub[drive.I_ITERS]
            info[drive.I_FIRST] = 1  # the last polynomial belongs to h/sub: no extrapolation
            with quiet():
                drive.accept(fns, prm, h, state, ws, total, every, outs, info, info_sub[drive.I_ITERS],
                             outs_sub[5][0], outs_sub[6][0], info_sub[drive.I_MAXRES])
            return sub
    return 0


def _nonfinite_callback(model, prm, state, ws):
    """Name the callback that returns NaN/inf at the failing step's start or last iterate."""
    n, m = model.n, model.m
    shapes = {"potential": (), "potential_grad": (n,), "mass": (n, n), "kinetic_grad": (n,),
              "constraint": (m,), "constraint_jacobian": (m, n)}
    for q, v in ((state[0], state[2]), (ws[6][0], ws[6][1])):
        for slot, shape in shapes.items():
            if slot in model._functions:
                val = model._eval(slot, q, v, params=prm, shape=shape)
                if not np.all(np.isfinite(val)):
                    return f"callback `{slot}` returned {val} at q = {np.array2string(np.asarray(q), precision=6)}"
    return None
