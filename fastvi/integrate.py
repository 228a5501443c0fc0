"""The Python driver: validate, allocate, call the compiled loop, build the :class:`Result`.

:class:`Result` is defined in :mod:`fastvi.results` and re-exported here.
"""

from __future__ import annotations

import math
import time

import numpy as np

from . import _validate as valid
from . import events as events_
from . import guards
from . import monitor as monitor_
from . import scipy_compat as compat
from . import structure
from .kernels.events import event_values
from ._launch import Launcher
from ._numba import quiet
from .kernels import drive
from .kernels import layout as lay
from .kernels.layout import Samples
from .kernels.step import step_kernel
from .model import Model
from .progress import UPDATES, ProgressBar
from .results import NoDenseOutput, Result
from .status import MESSAGES, Status
from .tables import Method

__all__ = ["integrate", "Result", "IntegrationError"]

_ADAPTIVE_CHUNK = 1 << 10  # least steps a kernel call of an adaptive run takes
_ADAPTIVE_BUFFER = 1 << 28  # bytes of samples an adaptive run allocates before it must grow
_ADAPTIVE_CAP = 1 << 62  # no step count: an adaptive run ends at t_end


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
        res = f"residual {residual:.3e}, " if residual == residual else ""  # NaN: no Newton failure
        super().__init__(
            f"{MESSAGES[status]} (status {int(status)} {status.name}, at step {step}, t = {time:.6g}, "
            f"{res}method {result.method.name}, h = {result.h:g})"
            + (f": {detail}" if detail else "")
        )


def _alloc(K: int, n: int) -> Samples:
    return Samples(np.zeros(K), np.zeros((K, n)), np.zeros((K, n)), np.zeros((K, n)), np.zeros(K),
                   np.zeros(K), np.zeros(K), np.zeros(K), np.zeros(K), np.zeros(K))


def _adaptive_chunk(span: float, eps: float, every: int, n: int, progress: bool) -> int:
    """Steps a kernel call of an adaptive run takes: three times the steps of ``eps`` over
    the run (ρ ≥ 1 makes the steps at most ``eps``; the double pendulum's whips make its mean
    step ≈ ε/2.2 at K_r = 3 J), so that one buffer usually holds the run and ends up at
    least half full (then :func:`_filled` need not copy it), unless its samples would take
    more than ``_ADAPTIVE_BUFFER`` bytes; a fiftieth of that with ``progress``."""
    est = 3 * math.ceil(span / eps) + 2
    per_sample = 8 * (3 * n + 6)
    chunk = max(_ADAPTIVE_CHUNK, min(est, _ADAPTIVE_BUFFER // per_sample * every))
    return max(1, chunk // UPDATES) if progress else chunk


def _samples_after_chunk(slot: int, chunk: int, every: int) -> int:
    """Samples a buffer needs before a kernel call of ``chunk`` steps that starts filling at
    ``slot``: every ``every``-th step and the last."""
    return slot + chunk // every + 1


def _buffers(model, K: int, t0: float, q0, v0, p0, prm):
    """``(smp, info)`` of a run from ``t0``: room for ``K`` samples, the first one the
    initial state with its energy and residuals, and the run's counters."""
    smp = _alloc(K, model.n)
    smp.t[0] = t0
    smp.q[0], smp.v[0], smp.p[0] = q0, v0, p0
    smp.energy[0] = 0.5 * v0 @ p0 + model.potential_energy(q0, prm, t0)
    if model.m:
        smp.g[0] = np.max(np.abs(model.constraint_value(q0, prm, t0)))
        smp.gv[0] = np.max(np.abs(model.constraint_jacobian_value(q0, prm, t0) @ v0
                                  + model.constraint_time_derivative_value(q0, prm, t0)))
    info = np.zeros(lay.INFO_SIZE)
    info[lay.I_SLOT] = 1
    info[lay.I_FIRST] = 1
    info[lay.I_T0] = t0
    return smp, info


def _room(smp: Samples, K: int) -> Samples:
    """``smp``, or a copy with room for at least ``K`` samples (doubling: an adaptive run
    does not know its number of steps in advance)."""
    if smp.t.shape[0] >= K:
        return smp
    grown = _alloc(max(K, 2 * smp.t.shape[0]), smp.q.shape[1])
    for old, new in zip(smp, grown):
        new[: old.shape[0]] = old
    return grown


def _filled(smp: Samples, J: int) -> Samples:
    """The first ``J`` samples of each buffer: the buffers themselves when full (a fixed-step
    run sizes them exactly), views when at least half full, else trimmed copies. Copying is
    not free here: written into fresh memory, a copy costs ≈ 0.1 µs a sample (page faults),
    a fifth of a ``P2L-Q3G`` step when every other step is saved. A view keeps its buffer's
    unwritten tail (at most as long as the view) alive with it."""
    K = smp.t.shape[0]
    if J == K:
        return smp
    if 2 * J >= K:
        return Samples(*(a[:J] for a in smp))
    return Samples(*(a[:J].copy() for a in smp))


def integrate(
    model: Model,
    q0,
    v0,
    *,
    h: float,
    t_end: float | None = None,
    n_steps: int | None = None,
    t0: float = 0.0,
    method: str | Method = "P2L-Q3G",
    save_every: int = 1,
    tol: float = valid.DEFAULT_TOL,
    max_iter: int = valid.DEFAULT_MAX_ITER,
    newton: str = "auto",
    params=None,
    progress: bool = False,
    on_failure: str = "raise",
    recover: int = 0,
    check: bool = True,
    dense_output: bool = False,
    events=None,
    solver: str = "auto",
    specialize: bool | None = None,
    adaptive: float | None = None,
    monitor: bool = True,
    t_span=None,
    t_eval=None,
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
        ``g = 0``, ``G v = 0`` (with a warning when the move exceeds round-off): ``q0`` to
        the nearest point in the metric of ``M(q0)``, then ``v0`` to the nearest velocity in
        the metric of ``M`` there. Data off by more than 1e-6 raise.
    h : float
        Step size.
    t_end, n_steps :
        Exactly one: final time or number of steps. A ``t_end − t0`` that is not a whole
        number of steps of ``h`` ends with one shorter step that lands on ``t_end`` (as
        SciPy's ``solve_ivp`` does; ``stats["last_step"]`` is its length): the same
        variational step with another ``h``, so only the modified energy of that one step
        differs. A span shorter than ``h`` is one step of the span.
    t0 : float, default 0.0
        Start time: ``Result.t`` starts there, and step k runs from ``t0 + k h``. It matters
        to a model with forces or time-dependent callbacks (whose initial data must then
        satisfy ``g(t0, q0) = 0`` and ``G v0 + g_t(t0, q0) = 0``).
    method : str or Method, default "P2L-Q3G"
        See :mod:`fastvi.tables`. ``P<s>L-Q<r>G`` is order ``2s`` for ``r >= s``.
    save_every : int, default 1
        Keep every k-th step (and the last); residuals are maxima over the skipped steps.
    tol : float, default 1e-14
        Newton stops when the predicted error of the control points, relative to
        ``max(1, |q_k|)``, is below ``tol`` (increment-based: residual tolerances on the
        momentum rows would leave an error of order ``tol/h`` per step). The default holds
        the constraints to round-off. A looser ``tol`` saves iterations — 1e-10 took 0.82×
        the time on the double pendulum at h = 0.025, with ``max|g|`` ≈ 1e-12 — but only
        where the step's own error is far larger: with ``"P4L-Q4G"`` at h = 0.0125 it
        multiplied the energy and position errors by ≈ 20
        (``docs/decisions/0001-mechanics-newton.md``).
    max_iter : int, default 30
        Newton iterations per step before giving up.
    newton : {"auto", "full"}, default "auto"
        ``"auto"``: iterate with the *mechanics matrix* — the mass block ``(1/h) A ⊗ M(q_k)``
        and the exact constraint-Jacobian blocks, with the force and constraint Hessians
        dropped — solved through a Schur complement of size ``J m`` on the impulses
        (``docs/method.md`` §10). It contracts like ``(ωh)²``; a step on which it contracts
        slower than ``MECH_THETA_MAX`` (a stiff spring) is redone with the full Newton, which
        then stays on for ``FULL_HOLD`` steps (``stats["full_newton_steps"]`` counts them).
        Being linearly convergent, it stops only when the increment itself is below ``tol``:
        more iterations than the full Newton, each far cheaper. For ``s = 1``, a potential
        linear in q (``potential_hessian=0``) and a constant mass it drops nothing: it is
        Newton's method and stops like the full Newton (3.0 iterations a step for
        ``P1L-Q2G`` on the double pendulum). Methods whose quadrature has fewer than ``s``
        points (the mass block is singular) use the full Newton under ``"auto"``.
        ``"full"``: the exact Newton matrix, assembled and factored at every iteration
        (Newton's method proper). Both solve the same equations to the same
        tolerance; the trajectories differ at round-off.
    params : array_like (k,), optional
        Parameters for this run (default: the model's).
    progress : bool, default False
        Show progress on stderr: one updating line on a terminal, a plain line every few
        seconds otherwise (the run is split into chunks; results are identical).
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
        What it can save: an isolated hard step in a run whose ``h`` resolves the motion (a
        pass near a singular position, a brief fast whip), where the neighbouring steps
        are fine. What it cannot: an ``h`` too large for the motion. Then the steps around
        the failing one are already wrong (their Newton solutions converge, possibly to
        another branch of the step's equations), and substeps only carry the wrong state
        on; the reliability monitor (``monitor``) stops such a run where its energy error
        leaves the bounded regime, whatever ``recover`` retook (on the slider–crank of
        ``tests/test_reliability.py`` at h = 0.1: ``UNRELIABLE`` at t = 0.4, where without
        the monitor the run ended as a success with an energy error of 92 J on 14.4 J).
        Use a smaller ``h``.
    check : bool, default True
        The first time a model is integrated, run :func:`fastvi.check.check_model` at ``q0``
        and one nearby state (a few milliseconds): first every callback is evaluated once
        into guarded buffers, so one that writes past its declared output shape, into its
        inputs, or leaves an entry unset raises :class:`fastvi.ModelCheckError` instead of
        corrupting memory in the kernels; then its derivative callbacks are compared with
        finite differences. Models that passed once (or passed :meth:`Model.check`) are not
        checked again. ``check=False`` skips the comparison of the derivatives only, at your
        own risk (a wrong derivative integrates another Lagrangian; the reliability monitor
        then usually sees the energy drift). The size check always runs (once per model, well
        under a millisecond): a size mistake would write out of bounds.
    dense_output : bool, default False
        Keep every step's control points and return ``Result.sol``, a
        :class:`fastvi.events.DenseSolution`: ``sol(t) -> (q, v)`` at any time(s) of the run
        from the step polynomials (``8 (s+1) n`` bytes a step; interior accuracy in
        ``docs/events.md``).
    events : callable or list of callables, optional
        ``event(t, q, v, params) -> float`` (numba's nopython subset, compiled once like the
        model's callbacks), at most 8, with SciPy's optional attributes ``terminal`` (bool or
        a count) and ``direction`` (−1, 0, +1). Zero crossings are located on the step
        polynomial to round-off in ``t`` (no extra steps) and returned in
        ``Result.t_events``, ``q_events``, ``v_events`` (one array per event). A terminal
        event ends the run at the event, with ``status`` 1 (``Status.TERMINATED``): as in
        SciPy, the last sample is the state at the event time from the step polynomial
        (``q`` of order ``s + 1``, ``v`` of order ``s`` inside a step; the energy and
        residuals of that sample are evaluated there, the work of a forced model is
        interpolated linearly between the last two samples). Before the first step each event is
        evaluated once in guarded buffers: one that writes into ``q``, ``v`` or ``params``,
        reads past their ends, or follows SciPy's ``ev(t, y)`` raises
        :class:`fastvi.guards.EventFunctionError`.

    solver : {"auto", "dense", "banded", "sparse"}, default "auto"
        How the step's linear systems (full Newton matrix, Schur complement of the mechanics
        iteration, end projection ``G M⁻¹ Gᵀ``) are solved. ``"auto"``: by the flop counts
        of the detected sparsity pattern, a banded LU after a reverse Cuthill–McKee ordering
        (large chains, e.g. ``chain(N)`` from N ≈ 8), a sparse LU in a minimum-degree order
        (trees and loops a band does not fit: the Schur complement and the projection), or
        the dense LU — every small model runs the dense path, bit for bit
        (:mod:`fastvi.structure`). ``"dense"``/``"banded"``/``"sparse"`` force one (the
        trajectories agree at round-off; the full Newton matrix, which needs row
        interchanges, is banded under ``"sparse"``).
    specialize : bool or None, default None
        Compile the step's mechanics iteration and end projection for this model's and
        method's sizes ``(n, m, s, r, J)`` as compile-time constants, so that every small
        loop in them is unrolled (:func:`fastvi.kernels.step.step_kernel`). The trajectory is
        the generic kernels' bit for bit; a step of the double pendulum costs 0.55–0.6× as
        much (``docs/decisions/0012-sized-stages.md``). The price is one compile per size,
        ≈ 8 s of CPU on a fresh install (``python -m fastvi compile --report --only
        specialize``), then cached on disk like the generic kernels. ``None`` chooses: the
        sized stages are used whenever they are compiled already (in this process or on
        disk), and compiled for a run of at least ``fastvi.structure.SIZED_MIN_STEPS``
        steps (an adaptive run: steps of ``ε`` over its span) of a model of at most
        ``SIZED_MAX_N`` coordinates, where the compile pays.
        ``True`` always compiles them, ``False`` never uses them.
        :func:`fastvi.integrate_ensemble` takes the same option.
    adaptive : float, optional
        A time-reversible adaptive step (:mod:`fastvi.kernels.adapt`): the energy scale
        ``K_r`` (in the model's energy units) of the step density
        ``ρ(q) = sqrt(1 + KE(q)/K_r)``, ``KE(q) = E0 − V(q)`` the kinetic energy on the
        energy shell of the start. Step k then has the length ``h / ρ_{k+1/2}`` (``h`` is
        the step where the motion is slow; about ``h sqrt(K_r / KE)`` where it is fast),
        with ρ carried from step to step by Hairer & Söderlind's explicit symmetric rule,
        and the last step ends on ``t_end``. Each step is the method's variational step,
        so constraints hold to round-off as with a fixed step, but the map is
        time-reversible, *not* symplectic: no modified energy bounds its energy error
        (reversibility does near quasi-periodic motion), and a chaotic motion's may creep
        (measured in ``docs/decisions/0002-adaptive-step.md``: on the double pendulum
        1.34–1.40× fewer steps than the fixed step at equal maximum energy error over 1000 s, and no faster growth up to
        10⁴ s for orders 6 and 8). ``Result.t`` then holds the times of the saved steps.
        Needs ``t_end`` and a conservative, autonomous model; not with ``events``,
        ``dense_output``, ``t_eval`` or ``recover``.
    monitor : bool, default True
        After the run, check that it is not broken although every step converged
        (:mod:`fastvi.monitor`): its energy error (for a forced or driven model the energy
        balance ``H − H0 − W``) against a tenth of the largest kinetic energy (or work) so
        far, the constraint residuals against the tolerance initial data must meet, and
        each step's displacement against its length times its velocities. A run that
        breaks a limit ends with ``Status.UNRELIABLE``: :class:`IntegrationError` (or, with
        ``on_failure="return"``, the result) holds the samples up to the last good one, and
        the message says at which step and time which indicator broke. The indicators'
        largest values (fractions of their limits) are in ``stats["monitor_energy"]``,
        ``["monitor_constraint"]``, ``["monitor_hidden_constraint"]``,
        ``["monitor_displacement"]``. ``False`` skips the check.
    t_span : (float, float), optional
        SciPy's spelling of ``t0`` and ``t_end``: ``t_span=(t0, t1)``.
    t_eval : array_like, optional
        Return the samples at these times (sorted, within the run), taken from the step
        polynomials as SciPy does: ``q``, ``v`` (orders ``s + 1`` and ``s`` between grid
        points), ``p = M(q) v``, the energy and residuals evaluated there, the work of a
        forced model interpolated linearly. The steps are still of ``h``; the monitor
        judges them on the grid. ``Result.sol`` stays unset unless ``dense_output=True``.

    Returns
    -------
    Result

    References
    ----------
    Paper A: S. Man, Q. Gao, W. Zhong, Variational integrators in holonomic mechanics,
    Mathematics 8 (2020) 1358 (constraint points, split action). Paper B: J. Ding, Z. Pan,
    Higher order variational integrators for multibody system dynamics with constraints,
    Advances in Mechanical Engineering 6 (2014) 383680. The method is written out in
    ``docs/method.md``.
    """
    t_start = time.perf_counter()
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    if on_failure not in ("raise", "return"):
        raise ValueError(f"`on_failure` must be 'raise' or 'return', got {on_failure!r}")
    n = model.n
    q0 = valid.vector(q0, "q0", n)
    v0 = valid.vector(v0, "v0", n)
    prm = valid.params(params, model)
    h = valid.step_size(h)
    t0, t_end = compat.span(t_span, t0, t_end, n_steps)
    t0 = valid.start_time(t0)
    adaptive = valid.adaptive(adaptive, model, t_end, n_steps, t0, events=events,
                              dense_output=dense_output, recover=recover)
    if adaptive is None:  # a span not a whole number of steps ends with a shorter step
        total, h, h_last = compat.steps(h, t_end, n_steps, t0)
    else:
        total, h_last = _ADAPTIVE_CAP, 0.0
        if t_eval is not None:
            raise ValueError("`t_eval` needs fixed steps (it samples the step polynomials); "
                             "pass `adaptive=None`, or read the adaptive samples `Result.t`")
    t_eval = compat.eval_times(t_eval, t0, t0 + total * h + h_last if adaptive is None else None)
    dense_asked = dense_output
    if t_eval is not None:  # samples at given times come from the step polynomials
        dense_output = True
    every = valid.save_every(save_every)
    opts = valid.newton_options(tol, max_iter, newton)
    recover = valid.recover(recover)
    meth = valid.method(method)
    dense_output = valid.flag(dense_output, "dense_output")
    specialize = valid.optional_flag(specialize, "specialize")
    if recover and (dense_output or events is not None):
        raise ValueError("`recover` cannot be combined with `dense_output`, `t_eval` or `events` (a "
                         "recovered step has no single polynomial); use a smaller `h` instead")
    compile_time = timed(model.kernel_arguments)
    check_time = 0.0
    if check and not model.checked:  # before the projection, which trusts G(q)
        check_time = timed(lambda: model.check(q0, v0, params=prm, n_random=1, t=t0,
                                               param_derivatives=False))
    else:  # check=False skips the derivatives, never the sizes (a size mistake corrupts memory)
        check_time = timed(lambda: guards.sizes(model, q0, v0, prm, t0))
    guards.signatures(events)
    q0, v0 = valid.initial_state(model, q0, v0, prm, t0)

    md = model.kernel_data(prm, t0)
    M0 = model.mass_matrix(q0, prm)
    state = np.zeros((6, n))
    state[0], state[1], state[2] = q0, M0 @ v0, v0
    ws = structure.workspace(model, meth, prm, solver, newton=False)
    # an adaptive run has no step count (total is a cap): its steps are ε / ρ with a density
    # ρ ≥ 1 (fastvi.kernels.adapt), about span / ε of them at least, what its stages are
    # sized by
    sized = structure.sizing(specialize, n, total if adaptive is None
                             else math.ceil((float(t_end) - t0) / h))
    chunk = total if not progress else max(1, total // UPDATES)
    if adaptive is not None:  # steps not known: chunks of steps, sample buffers grown
        chunk = _adaptive_chunk(float(t_end) - t0, h, every, n, progress)
        K = _samples_after_chunk(1, chunk, every)
    else:
        K = total // every + 1 + (1 if total % every else 0)
    smp, info = _buffers(model, K, t0, q0, v0, state[1], prm)
    if adaptive is not None:
        info[lay.I_KR], info[lay.I_E0] = adaptive, smp.energy[0]
        info[lay.I_T], info[lay.I_TEND] = t0, float(t_end)
    tabs = meth.kernel_tables
    ev = events_.prepare(model, meth, events, total if dense_output else 0)
    if ev.count:
        guards.events(model, ev, q0, v0, prm, t0)  # before the kernels call them
        with quiet():
            event_values(md, ev, t0, q0, v0)

    sout = np.zeros(lay.STEP_OUT_SIZE)
    t_step = time.perf_counter()
    stepk, stages = step_kernel(md, tabs, opts, ws, sized=sized)
    compile_time += time.perf_counter() - t_step
    # a run without events or dense output has a time loop compiled without their code
    evk = True if ev.count or ev.dense.shape[0] else None
    # the time loop and the step take the workspace's loop view: one compiled loop and step
    # for small and large models (a large one's solving stages are its own: step_kernel)
    loop = lay.loop_view(ws)
    run, seconds = _RUN.bind(md, tabs, opts, h, state, loop, chunk, total, every, smp, info, sout,
                             ev, stepk, stages, evk)
    compile_time += seconds
    span = None if adaptive is None else float(t_end) - t0
    bar = None
    if progress:
        # an adaptive run counts simulated seconds: its number of steps is not known
        bar = ProgressBar(total) if span is None else ProgressBar(math.ceil(span), unit="s simulated")
    t_loop = time.perf_counter()
    status = 0
    recovered = []
    while info[lay.I_STEPS] < total and not (span is not None and info[lay.I_T] >= t_end):
        if span is not None:
            smp = _room(smp, _samples_after_chunk(int(info[lay.I_SLOT]), chunk, every))
        with quiet():
            status = run(md, tabs, opts, h, state, loop, chunk, total, every, smp, info, sout, ev,
                         stepk, stages, evk)
        if status == lay.NEEDS_FULL_NEWTON:  # compiled on first need; the step is retaken
            t_step = time.perf_counter()
            stepk, stages = step_kernel(md, tabs, opts, ws, full=True, sized=sized)
            compile_time += time.perf_counter() - t_step
            status = 0
            continue
        if status == lay.EVENTS_FULL:
            ev = events_.grow(ev)
            run = _RUN.bind(md, tabs, opts, h, state, loop, chunk, total, every, smp, info, sout, ev,
                            stepk, stages, evk)[0]
            status = 0
            continue
        if status == lay.EVENT_TERMINAL:  # the step containing the event is the last sample
            break
        if status != 0 and recover:
            sub = _retry_in_substeps(md, model, meth, h, opts, state, recover, total, every, smp,
                                     info, prm=prm, solver=solver, sized=sized)
            if sub:
                recovered.append((int(info[lay.I_STEPS]) - 1, sub))
                status = 0
                continue
        if bar is not None:
            done = int(info[lay.I_STEPS])
            if span is None:
                bar.update(done, f"t = {t0 + done * h:.6g}", final=status != 0 or done >= total)
            else:
                t = info[lay.I_T]
                bar.update(bar.total if t >= t_end else int(t - t0), f"t = {t:.6g}, {done} steps",
                           final=status != 0 or t >= t_end)
        if status != 0:
            break
    t_end_loop = time.perf_counter()
    J = int(info[lay.I_SLOT])
    status = Status(status)
    ev_out = {}
    if events is not None:
        ev_out.update(zip(("t_events", "q_events", "v_events"), events_.collect(ev)))
    if dense_output:
        steps_done = int(info[lay.I_STEPS])
        ev_out["sol"] = events_.DenseSolution(t0, h, meth.tau, ev.dense[:steps_done].copy())
    out = _filled(smp, J)
    result = Result(
        t=out.t, q=out.q, v=out.v, p=out.p,
        energy=out.energy, work=out.work if model.timed else None,
        work_forces=out.work_forces if model.timed else None,
        constraint_residual=out.g,
        velocity_residual=out.gv, newton_iterations=out.iters,
        stats=dict(steps=int(info[lay.I_STEPS]), newton_iterations=int(info[lay.I_ITERS]),
                   max_residual=float(info[lay.I_MAXRES]), full_newton_steps=int(info[lay.I_FULL]),
                   recovered_steps=recovered, integration_time=t_end_loop - t_loop,
                   setup_time=t_loop - t_start, compile_time=compile_time, check_time=check_time,
                   wall_time=t_end_loop - t_start,
                   **({} if adaptive is None else {"adaptive": adaptive})),
        status=status, method=meth, h=h, model_name=model.name,
        failed_step=None if status >= 0 else int(info[lay.I_FAILED]),
        drawing=getattr(model, "drawing", None), **ev_out,
    )
    # the monitor reads the grid samples, before the last sample moves to an event
    verdict = monitor_.judge(result, every=every, newton_tol=opts.tol) if monitor else None
    if verdict is not None:
        result.stats.update(monitor_.stats(verdict))
    error = None
    if verdict is not None and not verdict.ok:  # broken before any failure of a step
        later = None
        if status < 0:
            later = f"{Status(status).name} at step {int(info[lay.I_FAILED])}"
        result, k, t_fail, detail = monitor_.cut(result, verdict, every=every, later=later)
        error = IntegrationError(Status.UNRELIABLE, k, t_fail, float("nan"), result, detail)
    elif status < 0:
        k = int(info[lay.I_FAILED])
        culprit = _nonfinite_callback(model, prm, state, ws) if status == Status.NONFINITE else None
        t_fail = t0 + k * h if adaptive is None else float(ws.time[0])
        error = IntegrationError(status, k, t_fail, float(info[lay.I_RES]), result, culprit)
    else:
        result = compat.end_at_event(result, model, prm, events)
        if h_last and result.status == Status.SUCCESS:  # the shorter last step, onto t_end
            t_last = float(result.t[-1])
            tail = integrate(model, result.q[-1], result.v[-1], h=h_last, n_steps=1, t0=t_last,
                             method=meth, tol=tol, max_iter=max_iter, newton=newton, params=prm,
                             on_failure="return", check=False, dense_output=dense_output,
                             events=events, solver=solver, specialize=specialize, monitor=monitor)
            result = compat.append_last_step(result, tail, h_last, t0 + total * h + h_last
                                             if t_end is None else float(t_end))
            if result.status < 0:
                error = IntegrationError(result.status, total, t_last, float("nan"), result,
                                         f"in the shorter last step (h = {h_last:g}) onto t_end")
    if t_eval is not None:
        result = compat.resample(result, model, prm, t_eval)
        if not dense_asked:
            result.sol = NoDenseOutput()
        if error is not None:
            error.result = result
    if error is not None and on_failure == "raise":
        raise error
    return result


def timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


#: the time loop, called through its compiled entry points (no per-call typing: _launch.py)
_RUN = Launcher(drive.run)


def _retry_in_substeps(md, model, meth, h, opts, state, levels, total, every, smp, info,
                       prm=None, solver="auto", sized=False):
    """Retake the failed step (state rows 0–2 still hold its start) as 2, 4, … substeps.

    Returns the number of substeps that succeeded (the step is then accepted and booked as
    one step of the main grid), or 0 if all ``levels`` halvings failed.
    """
    tabs = meth.kernel_tables
    for level in range(1, levels + 1):
        sub = 2**level
        trial = state.copy()
        ws_sub = structure.workspace(model, meth, model.params if prm is None else prm, solver)
        loop_sub = lay.loop_view(ws_sub)
        smp_sub = _alloc(1, model.n)
        info_sub = np.zeros(lay.INFO_SIZE)
        info_sub[lay.I_FIRST] = 1
        info_sub[lay.I_T0] = info[lay.I_T0] + info[lay.I_STEPS] * h
        with quiet():
            st = _RUN(md, tabs, opts, h / sub, trial, loop_sub, sub, sub, sub, smp_sub, info_sub,
                      np.zeros(lay.STEP_OUT_SIZE), events_.prepare(model, meth, None, 0),
                      *step_kernel(md, tabs, opts, ws_sub, full=True, sized=sized and "cached"),
                      None)
        if st == 0:
            state[:3] = trial[:3]
            info[lay.I_ITERS] += info_sub[lay.I_ITERS]
            info[lay.I_FIRST] = 1  # the last polynomial belongs to h/sub: no extrapolation
            sout = np.zeros(lay.STEP_OUT_SIZE)
            sout[lay.S_ITERS] = info_sub[lay.I_ITERS]
            sout[lay.S_G] = smp_sub.g[0]
            sout[lay.S_GV] = smp_sub.gv[0]
            sout[lay.S_RES] = info_sub[lay.I_MAXRES]
            sout[lay.S_FULL] = info_sub[lay.I_FULL]
            sout[lay.S_WORK] = info_sub[lay.I_WORK]
            sout[lay.S_WORK_F] = info_sub[lay.I_WORK_F]
            k = int(info[lay.I_STEPS]) + 1
            with quiet():
                drive.accept(md, info[lay.I_T0] + k * h, k == total, state, loop_sub, every, smp,
                             info, sout)
            return sub
    return 0


def _nonfinite_callback(model, prm, state, ws):
    """Name the callback that returns NaN/inf at the failing step's start or last iterate."""
    for q, v in ((state[0], state[2]), (ws.qi, ws.vi)):
        for slot in ("potential", "potential_grad", "mass", "kinetic_grad", "constraint",
                     "constraint_jacobian"):
            if slot in model.callbacks:
                val = model.callback_value(slot, q, v, params=prm, t=float(ws.time[0]))
                if not np.all(np.isfinite(val)):
                    return f"callback `{slot}` returned {val} at q = {np.array2string(np.asarray(q), precision=6)}"
    return None
