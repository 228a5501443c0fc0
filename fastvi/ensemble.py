"""Ensembles: many members (initial states, parameter values) of one model at once.

The Python side validates every member with the validators of :func:`fastvi.integrate`,
projects each initial state, then calls one compiled ``numba.prange`` loop
(:func:`fastvi.kernels.drive.run_members`) in which each member has its own workspace and runs
the same step kernel, in the same order, as the serial loop of ``integrate``: member ``i``
of an ensemble equals ``integrate`` of member ``i`` bit for bit. A member whose Newton
iteration fails stops alone; its status, failed step and last good state are recorded.
"""

from __future__ import annotations

import contextlib
import threading
import time
import warnings
from dataclasses import dataclass, field

import numba
import numpy as np

from . import _validate as check
from ._validate import flag as _flag
from . import events as events_
from . import guards
from . import scipy_compat as compat
from . import structure
from ._launch import Launcher
from ._numba import quiet
from .integrate import Result, timed
from .kernels import drive
from .kernels import layout as lay
from .kernels.step import step_kernel
from .model import Model
from .results import ResultBase, finish_figure, new_figure
from .status import MESSAGES, Status
from .tables import Method

__all__ = ["integrate_ensemble", "EnsembleResult"]

#: members per dynamic-scheduling chunk are N / (CHUNKS_PER_THREAD · threads): members that
#: fail early (or Newton-cheap ones) free their thread for the rest instead of idling it.
CHUNKS_PER_THREAD = 8

# numba's default (workqueue) threading layer must not be entered from two Python threads at
# once, and the thread count is per calling thread: one ensemble at a time per process.
_PARALLEL_LOCK = threading.Lock()
#: the parallel loop, called through its compiled entry points (no per-call typing)
_RUN_ENSEMBLE = Launcher(drive.run_members)

_MEMBER_FIELDS = ("q", "v", "p", "energy", "constraint_residual", "velocity_residual",
                  "newton_iterations", "max_energy_error", "max_constraint_residual",
                  "max_velocity_residual", "iterations", "max_residual", "residual", "status",
                  "failed_step", "steps", "n_saved", "initial_energy", "work", "t_events",
                  "q_events", "v_events", "n_events", "t_terminal")


@dataclass(repr=False)
class EnsembleResult(ResultBase):
    """What :func:`integrate_ensemble` kept of its ``N`` members.

    Member arrays are indexed by member first. Which of them are filled depends on ``save``:

    ========================  ==========================  ===================  ==================
    field                     ``save="final"``            ``save=k`` (stride)  ``"diagnostics"``
    ========================  ==========================  ===================  ==================
    ``t``                     None                        (K,)                 None
    ``q, v, p``               (N, n) last good state      (N, K, n)            (N, n)
    ``energy``                (N,) at the last state      (N, K)               (N,)
    ``constraint_residual``,  None                        (N, K) as in         None
    ``velocity_residual``,                                :class:`Result`
    ``newton_iterations``
    ``max_energy_error``,     None                        None                 (N,)
    ``max_constraint_…``,
    ``max_velocity_…``
    ========================  ==========================  ===================  ==================

    In stride mode the samples of a member that failed stop at ``n_saved[i]``; later slots
    are NaN. A member ended by a terminal event (status ``TERMINATED``) is a success that
    ends at the event, as :func:`fastvi.integrate` does: its last sample (stride mode) or
    final state (the other modes) is the state at the event time ``t_final[i]`` (not on the
    grid ``t``), taken from the step polynomial (the crossing's ``q_events``, ``v_events``),
    with ``p``, the energy and the residuals evaluated there and the work interpolated
    linearly between its last two samples; crossings later in that step are dropped.

    With ``events``, each member keeps its first ``K = keep_events`` crossings of each of
    the ``E`` events (SciPy's ``t_events`` per member, padded with NaN):

    ========================  ===============================================================
    ``t_events``              (N, E, K) times of the first K crossings, NaN where none
    ``q_events, v_events``    (N, E, K, n) the states at those times
    ``n_events``              (N, E) crossings of each event in all (kept or not)
    ========================  ===============================================================

    Attributes
    ----------
    t : ndarray (K,) or None
        Sample times ``t0, t0 + k h, t0 + 2k h, …`` and the final time (stride mode).
    q, v, p, energy : ndarray
        Positions, velocities ``v = M⁻¹p``, momenta, ``H = ½ vᵀp + V``.
    constraint_residual, velocity_residual, newton_iterations : ndarray (N, K) or None
        ``max |g|``, ``max |Gv|`` and Newton iterations since the previous sample.
    max_energy_error : ndarray (N,) or None
        ``max_k |H(q_k, p_k) − H(q_0, p_0) − W_k|`` over the ends of every step taken
        (``W`` the work of forces and time, zero for a conservative model). For a member a
        terminal event ended, the steps run to the end of the one that contains the event
        (past it), and the state at the event, its final state, is included too, except
        for a model with forces or time: the work is known at the ends of steps only.
    max_constraint_residual, max_velocity_residual : ndarray (N,) or None
        ``max_k |g(q_k)|`` and ``max_k |G(q_k) v_k + g_t|`` over every step, ``k = 0``
        included; for a member a terminal event ended, over its steps as above and the
        state at the event (interpolated from the step polynomial, so usually the largest).
    iterations : ndarray (N,) int
        Newton iterations of each member in total (the failed step's included).
    max_residual : ndarray (N,)
        Largest final Newton residual over the member's successful steps.
    residual : ndarray (N,)
        Final Newton residual of the last step tried (of the failed step, for a failure).
    status : ndarray (N,) int
        :class:`fastvi.Status` code of each member (``>= 0`` success).
    failed_step : ndarray (N,) int
        Index of the failed step (the step from ``t = failed_step · h``), ``-1`` if none.
    steps : ndarray (N,) int
        Steps completed.
    n_saved : ndarray (N,) int
        Samples written per member (stride mode; 1 otherwise).
    method : Method
    h : float
    n_steps : int
        Steps asked of every member.
    save : str or int
    stats : dict
        ``members``, ``member_steps`` (completed, all members), ``newton_iterations``,
        ``threads``, and times in seconds: ``integration_time`` (the compiled loop),
        ``setup_time`` (validation, first-use check, projection of the initial states,
        compiling the callbacks and loading or compiling the kernel), of which
        ``compile_time``, and ``wall_time`` (the total).
    initial_energy : ndarray (N,) or None
        ``H`` of each member's (projected) initial state.
    t0 : float
        Start time of every member.
    t_events, q_events, v_events, n_events : ndarray or None
        The event records (table above); None without ``events``.
    t_terminal : ndarray (N,) or None
        The time of the terminal event that ended each member, NaN for the members no
        terminal event ended; None without ``events``.
    """

    t: np.ndarray | None
    q: np.ndarray
    v: np.ndarray
    p: np.ndarray
    energy: np.ndarray
    constraint_residual: np.ndarray | None
    velocity_residual: np.ndarray | None
    newton_iterations: np.ndarray | None
    max_energy_error: np.ndarray | None
    max_constraint_residual: np.ndarray | None
    max_velocity_residual: np.ndarray | None
    iterations: np.ndarray
    max_residual: np.ndarray
    residual: np.ndarray
    status: np.ndarray
    failed_step: np.ndarray
    steps: np.ndarray
    n_saved: np.ndarray
    method: Method
    h: float
    n_steps: int
    save: str | int
    stats: dict
    model_name: str = field(default="model")
    initial_energy: np.ndarray | None = None
    #: (N, K) work of forces and time since t0 at the saved steps (stride mode, a model
    #: with forces or time), else None; see :attr:`fastvi.Result.energy_balance`
    work: np.ndarray | None = None
    t0: float = 0.0
    t_events: np.ndarray | None = None
    q_events: np.ndarray | None = None
    v_events: np.ndarray | None = None
    n_events: np.ndarray | None = None
    t_terminal: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.status.shape[0])

    @property
    def success(self) -> np.ndarray:
        """(N,) bool: the member reached the final time."""
        return self.status >= 0

    def _label(self) -> str:
        return self.method.name

    def _repr_items(self) -> list[str]:
        items = [f"model={self.model_name!r}", f"method={self._label()!r}", f"h={self.h:g}",
                 f"members={len(self)}", f"steps={self.n_steps}", f"save={self.save!r}",
                 f"status={self._status_text()}"]
        err = self.member_energy_error()
        if err is not None and np.isfinite(err).any():
            name = "max|ΔH−W|" if self.stats.get("timed") else "max|ΔH|"
            items.append(f"{name}={np.nanmax(err):.2g}")
        return items

    def final_state(self) -> tuple[np.ndarray, np.ndarray]:
        """``(q, v)``, each (N, n): every member's last good state, whatever ``save``."""
        if self.t is None:
            return self.q, self.v
        last = np.maximum(self.n_saved - 1, 0)
        rows = np.arange(len(self))
        return self.q[rows, last], self.v[rows, last]

    def member_energy_error(self) -> np.ndarray | None:
        """(N,) energy error per member: ``max |ΔH|`` over every step (``"diagnostics"``),
        over the samples (stride), or at the final state (``"final"``); for a model with
        forces or time the energy balance ``|ΔH − W|`` where the work is known (every
        step, the samples); None if unknown."""
        if self.max_energy_error is not None:
            return self.max_energy_error
        if self.t is not None:
            work = 0.0 if self.work is None else self.work  # a forced model: the balance
            with np.errstate(invalid="ignore"):
                return np.nanmax(np.abs(self.energy - self.energy[:, :1] - work), axis=1)
        if self.initial_energy is not None:
            return np.abs(self.energy - self.initial_energy)
        return None

    def plot(self, path=None, *, coordinates=(0, 1)):
        """Final states of the members and the distribution of their energy errors.

        Parameters
        ----------
        path : str or path-like, optional
            Save the figure there; drawn on its own canvas (the matplotlib backend of the
            process is never changed).
        coordinates : (int, int), default (0, 1)
            The components of ``q`` on the axes of the final-state scatter.

        Returns
        -------
        matplotlib.figure.Figure
            Left: ``q[i]`` against ``q[j]`` at each member's last good state (failed
            members as red crosses). Right: histogram of ``log10`` of each member's energy
            error (see :meth:`member_energy_error`; exact zeros are counted at the left edge).
        """
        i, j = (int(c) for c in coordinates)
        q, _ = self.final_state()
        ok = np.asarray(self.success)
        fig = new_figure(path, figsize=(10, 4.2))
        a1, a2 = fig.subplots(1, 2)
        a1.scatter(q[ok, i], q[ok, j], s=6, label="reached t_end")
        if (~ok).any():
            a1.scatter(q[~ok, i], q[~ok, j], s=18, marker="x", color="tab:red", label="failed (last good state)")
        a1.set_xlabel(f"q[{i}]")
        a1.set_ylabel(f"q[{j}]")
        a1.set_title(f"final states, {len(self)} members")
        a1.legend(fontsize="small")
        err = self.member_energy_error()
        if err is None:
            a2.text(0.5, 0.5, "energy error not recorded", ha="center", transform=a2.transAxes)
        else:
            err = err[np.isfinite(err)]
            positive = err[err > 0]
            floor = np.log10(positive.min()) if positive.size else -16.0
            logs = np.where(err > 0, np.log10(np.where(err > 0, err, 1.0)), floor)
            a2.hist(logs, bins=min(40, max(5, int(np.sqrt(max(logs.size, 1))))))
            a2.set_xlabel("log10 |ΔH| per member")
            a2.set_ylabel("members")
            a2.set_title("energy error")
        fig.suptitle(f"{self.model_name}, {self._label()}, h = {self.h:g}, {self.n_steps} steps")
        fig.tight_layout()
        return finish_figure(fig, path)

    @property
    def failed(self) -> np.ndarray:
        """Indices of the members that stopped early."""
        return np.flatnonzero(self.status < 0)

    @property
    def t_final(self) -> np.ndarray:
        """(N,) time of each member's last good state: ``t0 + steps · h``, or the event time
        of a member a terminal event ended."""
        at_steps = self.t0 + self.steps * self.h
        if self.t_terminal is None:
            return at_steps
        return np.where(self.status == Status.TERMINATED, self.t_terminal, at_steps)

    @property
    def terminated(self) -> np.ndarray:
        """Indices of the members that a terminal event ended."""
        return np.flatnonzero(self.status == Status.TERMINATED)

    def first_event_time(self) -> np.ndarray:
        """(N,) the earliest crossing of any event per member (NaN where none was kept)."""
        if self.t_events is None:
            raise ValueError("this ensemble was run without `events`")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: no event
            return np.nanmin(self.t_events.reshape(len(self), -1), axis=1)

    def failures(self) -> list[dict]:
        """One dict per failed member: ``member, status, step, time, residual, message``."""
        return [
            dict(member=int(i), status=Status(int(self.status[i])), step=int(self.failed_step[i]),
                 time=float(self.t0 + self.failed_step[i] * self.h), residual=float(self.residual[i]),
                 message=MESSAGES[Status(int(self.status[i]))])
            for i in self.failed
        ]

    def summary(self) -> str:
        """One paragraph: sizes, speed, failures by cause."""
        N = len(self)
        st = self.stats
        # the rate of the compiled loop alone: a first run's compile says nothing about speed
        rate = st["member_steps"] / max(st.get("integration_time", st["wall_time"]), 1e-12)
        lines = [
            f"{self.model_name}: {N} members × {self.n_steps} steps, method {self.method.name}, "
            f"h = {self.h:g}, save = {self.save!r}, {st['threads']} thread(s), "
            f"{self._timing()}, {rate:.3g} member-steps/s, "
            f"Newton iterations/step = {st['newton_iterations'] / max(1, st['member_steps']):.2f}",
        ]
        if self.max_energy_error is not None:
            balance = self.stats.get("timed")
            lines.append(f"max {'|ΔH − W|' if balance else '|ΔH|'} = {np.max(self.max_energy_error):.3e}, "
                         f"max |g| = {np.max(self.max_constraint_residual):.3e}, "
                         f"max {'|Gv + g_t|' if balance else '|Gv|'} = "
                         f"{np.max(self.max_velocity_residual):.3e}")
        failed = self.failed
        ended = self.terminated.size
        if ended:
            lines.append(f"{ended} of {N} members ended by a terminal event")
        if failed.size == 0:
            lines.append("all members reached the final time" if not ended else
                         "no member failed")
        else:
            codes, counts = np.unique(self.status[failed], return_counts=True)
            causes = ", ".join(f"{c} × {Status(int(s)).name}" for s, c in zip(codes, counts))
            lines.append(f"{failed.size} of {N} members failed ({causes}); first: member "
                         f"{failed[0]} at step {self.failed_step[failed[0]]}")
        return "\n".join(lines)

    def member(self, i: int) -> Result:
        """Member ``i`` as a :class:`fastvi.Result` (stride mode only).

        Equal, array for array, to ``integrate(..., save_every=k, on_failure="return")`` of
        that member, a member a terminal event ended included (its last sample is the state
        at the event, at ``t_final[i]``). The times in ``stats`` are NaN: members share the
        clock; the summary says "time not measured".
        """
        if self.t is None:
            raise ValueError(f"member trajectories need `save` = an integer stride; this ensemble "
                             f"was run with save={self.save!r}")
        i = int(i)
        J = int(self.n_saved[i])
        status = Status(int(self.status[i]))
        t = self.t[:J].copy()
        if status == Status.TERMINATED:
            t[-1] = self.t_final[i]  # the event: off the grid of samples
        kept = {}
        if self.t_events is not None:
            K = self.t_events.shape[2]
            if self.n_events[i].max(initial=0) > K:
                raise ValueError(f"member {i} has more crossings ({self.n_events[i].max()}) than "
                                 f"`keep_events` = {K} kept: its events are incomplete")
            c = self.n_events[i]
            kept = dict(t_events=[self.t_events[i, e, :c[e]].copy() for e in range(c.size)],
                        q_events=[self.q_events[i, e, :c[e]].copy() for e in range(c.size)],
                        v_events=[self.v_events[i, e, :c[e]].copy() for e in range(c.size)])
        return Result(
            t=t, q=self.q[i, :J].copy(), v=self.v[i, :J].copy(), p=self.p[i, :J].copy(),
            energy=self.energy[i, :J].copy(), constraint_residual=self.constraint_residual[i, :J].copy(),
            velocity_residual=self.velocity_residual[i, :J].copy(),
            newton_iterations=self.newton_iterations[i, :J].copy(),
            stats=dict(steps=int(self.steps[i]), newton_iterations=int(self.iterations[i]),
                       max_residual=float(self.max_residual[i]), recovered_steps=[],
                       wall_time=float("nan")),
            status=status, method=self.method, h=self.h, model_name=self.model_name,
            failed_step=None if status >= 0 else int(self.failed_step[i]),
            work=None if self.work is None else self.work[i, :J].copy(), **kept,
        )

    def save_npz(self, path) -> None:
        """Write the member arrays and stats to a ``.npz`` file (``numpy.load`` reads it)."""
        arrays = {k: getattr(self, k) for k in _MEMBER_FIELDS if getattr(self, k) is not None}
        if self.t is not None:
            arrays["t"] = self.t
        np.savez_compressed(path, h=self.h, n_steps=self.n_steps, method=self.method.name,
                            save=str(self.save), **arrays,
                            **{f"stats_{k}": v for k, v in self.stats.items()})

    @classmethod
    def concatenate(cls, parts) -> "EnsembleResult":
        """Join ensembles of the same run split by members (in order), e.g. Dask chunks."""
        parts = list(parts)
        if not parts:
            raise ValueError("`parts` must hold at least one EnsembleResult")
        first = parts[0]
        for other in parts[1:]:
            if (other.h, other.n_steps, other.save, other.method.name) != (
                    first.h, first.n_steps, first.save, first.method.name):
                raise ValueError("`parts` must come from one run (same h, n_steps, save, method)")
        joined = {k: (None if getattr(first, k) is None
                      else np.concatenate([getattr(p, k) for p in parts], axis=0))
                  for k in _MEMBER_FIELDS}
        summed = ("members", "member_steps", "newton_iterations", "wall_time", "setup_time",
                  "integration_time", "compile_time", "check_time")
        stats = {k: sum(p.stats[k] for p in parts) for k in summed if all(k in p.stats for p in parts)}
        stats["threads"] = max(p.stats["threads"] for p in parts)
        if "timed" in first.stats:
            stats["timed"] = first.stats["timed"]
        return cls(t=first.t, method=first.method, h=first.h, n_steps=first.n_steps,
                   save=first.save, stats=stats, model_name=first.model_name, t0=first.t0,
                   **joined)


def integrate_ensemble(
    model: Model,
    Q0,
    V0,
    *,
    h: float,
    t_end: float | None = None,
    n_steps: int | None = None,
    t0: float = 0.0,
    method: str | Method = "P2L-Q3G",
    params=None,
    save="final",
    threads: int | None = None,
    tol: float = check.DEFAULT_TOL,
    max_iter: int = check.DEFAULT_MAX_ITER,
    newton: str = "auto",
    check: bool = True,
    events=None,
    keep_events: int = 1,
    solver: str = "auto",
    specialize: bool | None = None,
    progress: bool = False,
) -> EnsembleResult:
    r"""Integrate ``N`` members (initial states and/or parameters) of one model in parallel.

    Every member is advanced by the integrator of :func:`fastvi.integrate` — the discrete
    Euler–Lagrange equations of the Galerkin action solved by Newton, the momentum
    projected onto ``G(q) M⁻¹ p = 0`` — inside one compiled ``numba.prange`` loop over
    members, each with its own workspace. Member ``i`` equals
    ``integrate(model, Q0[i], V0[i], params=params[i], ...)`` bit for bit, whatever the
    number of threads.

    Parameters
    ----------
    model : Model
    Q0, V0 : array_like (N, n)
        Initial configurations and velocities, one row per member; each is checked and
        projected as in :func:`fastvi.integrate` (members projected beyond round-off are
        reported in one warning).
    h : float
        Step size (shared).
    t_end, n_steps :
        Exactly one: final time (a whole number of steps) or number of steps.
    t0 : float, default 0.0
        Start time of every member, as in :func:`fastvi.integrate`.
    method : str or Method, default "P2L-Q3G"
    params : array_like (N, k) or (k,), optional
        Parameters per member (rows), one vector for all, or None for the model's.
    save : {"final", "diagnostics"} or int, default "final"
        ``"final"``: the last state of each member, memory ``O(N n)``. An integer ``k``: every
        k-th step and the last, memory ``O(N n n_steps / k)``. ``"diagnostics"``: the last
        state plus, per member, ``max |H − H₀ − W|`` (``W`` the work of forces and time,
        zero for a conservative model), ``max |g|``, ``max |Gv + g_t|`` over every step
        and the Newton iterations, with no trajectory (the energy is evaluated every step).
    threads : int, optional
        Numba threads for this call (``1 … NUMBA_NUM_THREADS``); the previous setting is
        restored afterwards. Default: numba's current setting.
    tol, max_iter, newton :
        Newton tolerance, iteration limit per step and variant, as in :func:`fastvi.integrate`.
    check : bool, default True
        As in :func:`fastvi.integrate`: compare the model's derivative callbacks with finite
        differences (at the first member's state) the first time the model is used.
        ``check=False`` skips that comparison only: the sizes of the callbacks' outputs are
        checked all the same (a size mistake would corrupt memory), and so are the event
        functions.
    events : callable or list of callables, optional
        Event functions ``event(t, q, v, params) -> float`` with the optional attributes
        ``terminal`` and ``direction``, exactly as in :func:`fastvi.integrate` (members get
        their own ``params`` row). Crossings are located inside the compiled loop; a terminal
        event ends that member only (status ``TERMINATED``, a success), at the event as
        :func:`fastvi.integrate` ends a run, and the others go on.
    keep_events : int, default 1
        Crossings kept per event and member (the first ones); later crossings are counted
        in ``n_events`` (and towards ``terminal``) but not located. Memory:
        ``8 N E K (2n + 1)`` bytes. The crossing that ends a member is always located (a
        ``terminal`` count above ``keep_events`` is kept for the run, then let go).
    solver : {"auto", "dense", "banded", "sparse"}, default "auto"
        How each member solves a step's linear systems, as in :func:`fastvi.integrate`: a
        large mechanism's members solve banded or sparse (planned once for the ensemble), a
        small model's densely.
    specialize : bool or None, default None
        As in :func:`fastvi.integrate`: the members' mechanics iteration and end projection
        compiled for the model's and method's sizes (the same trajectories bit for bit, a
        small model's step 0.55–0.6× as costly), chosen by the ensemble's member steps when
        ``None``.
    progress : bool, default False
        Show progress on stderr, in member-steps (one updating line on a terminal, a plain
        line every few seconds otherwise, as :func:`fastvi.integrate`): the members then
        run in about 20 consecutive groups, each a parallel loop of at least as many
        members as threads (the results are the same, bit for bit).

    Returns
    -------
    EnsembleResult
        Never raises for a member that fails during the integration: see ``status``,
        ``failed_step``, :meth:`EnsembleResult.failures`.

    Raises
    ------
    ValueError, TypeError
        Bad arguments, naming the argument (and the member, e.g. ``Q0[17]``).

    Notes
    -----
    The members are scheduled dynamically in chunks of ``N / (8 · threads)``. Validation and
    projection of the initial states run in Python before the compiled loop (a few hundred
    microseconds per member; in ``stats["setup_time"]``, with the first call's compile). Only one ensemble runs at a time per
    process (numba's default threading layer is not re-entrant); for more than one machine
    see :func:`fastvi.distributed.integrate_ensemble`.

    Examples
    --------
    >>> dp = fastvi.scenes.double_pendulum()
    >>> states = [dp.initial_state(a, b) for a, b in [(0.5, 1.0), (2.0, -1.0), (3.0, 0.0)]]
    >>> Q0, V0 = np.array([s[0] for s in states]), np.array([s[1] for s in states])
    >>> ens = fastvi.integrate_ensemble(dp, Q0, V0, h=0.01, n_steps=1000)
    >>> ens.q.shape, bool(ens.success.all())
    ((3, 4), True)
    """
    run_check = check
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    opts = _options(h, t_end, n_steps, method, save, tol, max_iter, newton, t0, keep_events, solver,
                    specialize)
    threads = _validate_threads(threads)
    if _flag(progress, "progress"):  # (`check` is the argument here, not _validate)
        return _ensemble_with_progress(model, Q0, V0, params, opts, threads, run_check, events)
    return _ensemble(model, Q0, V0, params, opts, threads, run_check, first_member=0,
                     events=events)


#: groups of members a run with ``progress=True`` is split into (at most)
PROGRESS_GROUPS = 20


def _ensemble_with_progress(model, Q0, V0, params, opts, threads, run_check, events):
    """:func:`_ensemble` over consecutive groups of members, a progress line updated after
    each group (the kernel runs a member to its end in one go), joined in order."""
    from .progress import ProgressBar

    Q0, V0, P = _members(model, Q0, V0, params)
    N = Q0.shape[0]
    size = max(threads or numba.get_num_threads(), -(-N // PROGRESS_GROUPS))
    bar = ProgressBar(N * opts["total"], unit="member-steps")
    parts, done = [], 0
    for a in range(0, N, size):
        part = _ensemble(model, Q0[a:a + size], V0[a:a + size], P[a:a + size], opts, threads,
                         run_check, first_member=a, events=events)
        parts.append(part)
        done += int(part.stats["member_steps"])
        end = a + size >= N
        bar.update(done, f"{min(a + size, N)}/{N} members", final=end)
    return EnsembleResult.concatenate(parts)


# ------------------------------------------------------------------ pieces shared with distributed
@contextlib.contextmanager
def parallel_section(threads, N: int):
    """Run a compiled ``prange`` loop over ``N`` members with ``threads`` threads (None:
    numba's setting), dynamically scheduled in chunks of ``N / (CHUNKS_PER_THREAD ·
    threads)``; one such loop at a time per process. Yields the thread count used and
    restores numba's settings after."""
    with _PARALLEL_LOCK:
        prev_threads = numba.get_num_threads()
        prev_chunk = numba.get_parallel_chunksize()
        try:
            if threads is not None:
                numba.set_num_threads(threads)
            used = numba.get_num_threads()
            numba.set_parallel_chunksize(max(1, N // (CHUNKS_PER_THREAD * used)))
            yield used
        finally:
            numba.set_parallel_chunksize(prev_chunk)
            numba.set_num_threads(prev_threads)


def _validate_threads(threads):
    return check.threads(threads)


def _options(h, t_end, n_steps, method, save, tol, max_iter, newton="auto", t0=0.0,
             keep_events=1, solver="auto", specialize=None) -> dict:
    """The validated scalar options of a run (cheap: the client of a Dask run calls it too)."""
    h = check.step_size(h)
    t0 = check.start_time(t0)
    return dict(h=h, t0=t0, total=check.step_count(h, t_end, n_steps, t0),
                method=check.method(method), save=check.ensemble_save(save),
                newton=check.newton_options(tol, max_iter, newton),
                keep_events=check.count(keep_events, "keep_events", 1),
                solver=check.solver(solver), specialize=check.optional_flag(specialize, "specialize"))


def _members(model: Model, Q0, V0, params):
    """Validated member arrays ``Q0, V0`` (N, n) and ``P`` (N, k)."""
    Q0 = check.member_vectors(Q0, "Q0", model.n)
    V0 = check.member_vectors(V0, "V0", model.n)
    if V0.shape[0] != Q0.shape[0]:
        raise ValueError(f"`Q0` and `V0` must have one row per member each, got {Q0.shape[0]} and "
                         f"{V0.shape[0]} rows")
    return Q0, V0, check.member_params(params, model, Q0.shape[0])


def _ensemble(model, Q0, V0, params, opts, threads, run_check, first_member=0,
              events=None) -> EnsembleResult:
    t_setup = time.perf_counter()
    Q0, V0, P = _members(model, Q0, V0, params)
    compile_time = timed(model.kernel_arguments)
    t_events = time.perf_counter()
    guards.signatures(events)  # SciPy's ev(t, y) named before numba's typing error
    ev = events_.prepare(model, opts["method"], events, 0, 1)  # compiles the event functions
    compile_time += time.perf_counter() - t_events
    check_time = 0.0
    t0 = opts.get("t0", 0.0)
    if run_check and not getattr(model, "checked", True):  # as integrate: before the projection
        check_time = timed(lambda: model.check(Q0[0], V0[0], params=P[0], n_random=1, t=t0))
    else:  # the sizes always (check=False skips the derivatives only)
        check_time = timed(lambda: guards.sizes(model, Q0[0], V0[0], P[0], t0))
    if ev.count:
        guards.events(model, ev, Q0[0], V0[0], P[0], t0)
    X0, H0, g0, gv0 = _initial_states(model, Q0, V0, P, first_member, t0)

    N, n = Q0.shape
    h, total, meth, save = opts["h"], opts["total"], opts["method"], opts["save"]
    if save == "final":
        mode, every, K = lay.SAVE_FINAL, total, 1
    elif save == "diagnostics":
        mode, every, K = lay.SAVE_DIAGNOSTICS, total, 1
    else:
        mode, every = lay.SAVE_STRIDE, save
        K = total // every + 1 + (1 if total % every else 0)
    fill = np.nan if mode == lay.SAVE_STRIDE else 0.0
    Qs, Vs, Ps = (np.full((N, K, n), fill) for _ in range(3))
    En, Gr, GVr, It, Wk = (np.full((N, K), fill) for _ in range(5))
    if mode == lay.SAVE_STRIDE:  # slot 0 is the initial state, exactly as in integrate
        Qs[:, 0], Ps[:, 0], Vs[:, 0] = X0[:, 0], X0[:, 1], X0[:, 2]
        En[:, 0], Gr[:, 0], GVr[:, 0], It[:, 0], Wk[:, 0] = H0, g0, gv0, 0.0, 0.0
    # the kernels' parameter rows (with the hidden time entry of a time-aware model)
    KP = np.ascontiguousarray(np.stack([model.kernel_params(P[i], t0) for i in range(N)]))
    ist = np.zeros((N, lay.E_SIZE), dtype=np.int64)
    fst = np.zeros((N, lay.F_SIZE))
    fst[:, lay.F_G], fst[:, lay.F_GV] = g0, gv0
    keep = opts.get("keep_events", 1)
    # a member ends at the state of its terminal crossing, so that crossing must be located
    # whatever `keep_events` (the room beyond it is let go after the run)
    E, cap = max(1, ev.count), max(keep, int(ev.terminal.max())) if ev.count else 1
    Te = np.full((N, E, cap), np.nan)
    Qe, Ve = np.full((N, E, cap, n), np.nan), np.full((N, E, cap, n), np.nan)
    Ne = np.zeros((N, lay.EVENT_SLOTS), dtype=np.int64)

    fns, flags, Mc = model.kernel_arguments()
    plan = structure.plan(model, meth, None, opts.get("solver", "auto"))
    with parallel_section(threads, N) as used:
        dims = (model.n, model.m, meth.s, meth.r, meth.J)
        # the members' step: the one integrate compiles for a workspace of this type
        t_step = time.perf_counter()
        ws = structure.workspace(model, meth, None, opts.get("solver", "auto"))
        sized = structure.sizing(opts.get("specialize"), model.n, N * total)
        stepk, stages = step_kernel(model.kernel_data(), meth.kernel_tables,
                                    opts["newton"], ws, full=True, sized=sized)
        compile_time += time.perf_counter() - t_step
        # each member's workspace as this one: what its step reads, the full Newton's
        # matrix in band storage for a long chain (layout.field_shapes)
        group = drive.EnsembleMembers(
            fns, flags, Mc, KP, meth.kernel_tables, opts["newton"], h, t0, dims, ws.si,
            plan.sb, lay.field_shapes(ws), X0, total, mode, every, H0, Qs, Vs, Ps, En, Gr,
            GVr, It, Wk, ist, fst, ev.fns, ev.count, ev.direction, ev.terminal, Te, Qe, Ve, Ne,
            stepk, stages)
        t_member = time.perf_counter()
        with quiet():
            member = drive.ensemble_member(group)
        compile_time += time.perf_counter() - t_member
        status = np.zeros(N, dtype=np.int64)  # also in ist[:, E_STATUS]
        run, seconds = _RUN_ENSEMBLE.bind(member, group, status)
        compile_time += seconds
        t_loop = time.perf_counter()
        run(member, group, status)
        t1 = time.perf_counter()

    steps = ist[:, lay.E_STEPS].copy()
    iterations = fst[:, lay.F_ITERS].astype(np.int64)
    stats = dict(members=N, member_steps=int(steps.sum()), newton_iterations=int(iterations.sum()),
                 threads=used, integration_time=t1 - t_loop, setup_time=t_loop - t_setup,
                 compile_time=compile_time, check_time=check_time, wall_time=t1 - t_setup,
                 timed=bool(model.timed))  # the energy figures are then balances H − H0 − W
    diag = mode == lay.SAVE_DIAGNOSTICS
    stride = mode == lay.SAVE_STRIDE
    if stride:
        ks = np.arange(every, total + 1, every)
        if total % every:
            ks = np.append(ks, total)
        t = np.concatenate(([t0], t0 + ks * h))
        q, v, p, energy = Qs, Vs, Ps, En
    else:
        t = None
        q, v, p, energy = Qs[:, 0], Vs[:, 0], Ps[:, 0], En[:, 0]
    result = EnsembleResult(
        t=t, q=q, v=v, p=p, energy=energy,
        constraint_residual=Gr if stride else None, velocity_residual=GVr if stride else None,
        newton_iterations=It if stride else None,
        max_energy_error=fst[:, lay.F_DH].copy() if diag else None,
        max_constraint_residual=fst[:, lay.F_G].copy() if diag else None,
        max_velocity_residual=fst[:, lay.F_GV].copy() if diag else None,
        iterations=iterations, max_residual=fst[:, lay.F_MAXRES].copy(),
        residual=fst[:, lay.F_RES].copy(), status=ist[:, lay.E_STATUS].copy(),
        failed_step=ist[:, lay.E_FAILED].copy(), steps=steps, n_saved=ist[:, lay.E_SAVED].copy(),
        method=meth, h=h, n_steps=total, save=save, stats=stats, model_name=model.name,
        initial_energy=H0.copy(), work=Wk if (stride and model.timed) else None, t0=t0,
        **({} if events is None else dict(t_events=Te[:, :ev.count], q_events=Qe[:, :ev.count],
                                          v_events=Ve[:, :ev.count],
                                          n_events=Ne[:, :ev.count].copy())),
    )
    if ev.count:
        result.t_terminal = _end_at_events(result, model, P, events)
        if cap > keep:  # the room for a terminal count beyond `keep_events` is let go
            result.t_events, result.q_events, result.v_events = (
                np.ascontiguousarray(a[:, :, :keep])
                for a in (result.t_events, result.q_events, result.v_events))
    return result


def _end_at_events(result: EnsembleResult, model: Model, P, events) -> np.ndarray:
    """End every member a terminal event ended at its event, as :func:`fastvi.integrate`
    ends a run (:func:`fastvi.scipy_compat.end_at_event`, by the same helpers): its last
    sample or final state moved to the event, crossings after the event dropped. Changes
    ``result`` in place; returns the members' event times (NaN where none ended one)."""
    t_terminal = np.full(len(result), np.nan)
    stride = result.t is not None
    for i in result.terminated:
        found = compat.terminal_crossing(events, result.n_events[i], result.t_events[i])
        if found is None:  # never: the kernel ends a member at such a crossing
            continue
        te, e, j = found
        qe, ve = result.q_events[i, e, j].copy(), result.v_events[i, e, j].copy()
        p, H, g, gv = compat.state_at_event(model, P[i], te, qe, ve)
        kept = compat.crossings_kept(result.t_events[i], te, e, j)
        for k, keep in enumerate(kept):
            # a dropped crossing is one that was located (a record beyond `keep_events`
            # holds no time to compare, and its count stays)
            result.n_events[i, k] -= int(np.count_nonzero(~keep & ~np.isnan(result.t_events[i, k])))
            result.t_events[i, k, ~keep] = np.nan
            result.q_events[i, k, ~keep] = np.nan
            result.v_events[i, k, ~keep] = np.nan
        if stride:
            last = int(result.n_saved[i]) - 1
            at = (i, last)
            result.constraint_residual[at], result.velocity_residual[at] = g, gv
            if result.work is not None:
                t_step = result.t0 + result.steps[i] * result.h  # the step's end, as sampled
                result.work[at] = compat.work_at_event(result.work[i, last - 1], result.work[at],
                                                       float(result.t[last - 1]), float(t_step), te)
        else:
            at = i
            if result.max_energy_error is not None:  # the final state is among the maxima
                result.max_constraint_residual[i] = max(result.max_constraint_residual[i], g)
                result.max_velocity_residual[i] = max(result.max_velocity_residual[i], gv)
                if not model.timed:  # the work at the event is not known
                    result.max_energy_error[i] = max(result.max_energy_error[i],
                                                     abs(H - result.initial_energy[i]))
        result.q[at], result.v[at], result.p[at], result.energy[at] = qe, ve, p, H
        t_terminal[i] = te
    return t_terminal


def _initial_states(model: Model, Q0, V0, P, first_member: int, t0: float = 0.0):
    """Projected ``(q0, p0, v0)`` per member, with ``H0``, ``max|g(q0)|``, ``max|G v0|``.

    The same operations as :func:`fastvi.integrate`, so the compiled loop starts from the
    same bits.
    """
    N, n = Q0.shape
    m = model.m
    X0 = np.empty((N, 3, n))
    H0 = np.empty(N)
    g0 = np.zeros(N)
    gv0 = np.zeros(N)
    projected = []
    with warnings.catch_warnings(record=True) as caught:
        # one summary instead of a warning per member; numba's typing notes stay silent
        warnings.simplefilter("always")
        warnings.simplefilter("ignore", numba.NumbaExperimentalFeatureWarning)
        for i in range(N):
            prm = P[i]
            seen = len(caught)
            try:
                q0, v0 = check.initial_state(model, Q0[i], V0[i], prm, t0)
            except ValueError as exc:
                j = first_member + i
                raise ValueError(f"member {j} (`Q0[{j}]`, `V0[{j}]`): {exc}") from None
            if len(caught) > seen:  # initial_state warns only when it projects
                projected.append((first_member + i, str(caught[-1].message)))
            p0 = model.mass_matrix(q0, prm) @ v0
            X0[i, 0], X0[i, 1], X0[i, 2] = q0, p0, v0
            H0[i] = 0.5 * v0 @ p0 + model.potential_energy(q0, prm, t0)
            if m:
                g0[i] = np.max(np.abs(model.constraint_value(q0, prm, t0)))
                gv0[i] = np.max(np.abs(model.constraint_jacobian_value(q0, prm, t0) @ v0
                                       + model.constraint_time_derivative_value(q0, prm, t0)))
    if projected:
        j, msg = projected[0]
        warnings.warn(f"{len(projected)} of {N} members' initial states were projected onto the "
                      f"constraints; first, member {j}: {msg}", stacklevel=4)
    return X0, H0, g0, gv0
