r"""Forward sensitivities of many members at once: :func:`sensitivity_ensemble`.

Each member (an initial state and its parameters) is set up and validated exactly as by
:func:`fastvi.sensitivity`; then one compiled ``numba.prange`` loop
(:func:`fastvi.kernels.drive.run_members` with
:func:`fastvi.kernels.tangent.tangent_member`) runs every member's linearised flow,
each with its own workspaces. Member ``i`` equals ``sensitivity`` of that member bit for bit,
trajectory and derivatives alike.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from . import _discrete as disc
from . import _validate as valid
from ._launch import Launcher
from ._numba import quiet
from .ensemble import PROGRESS_GROUPS, parallel_section
from .integrate import IntegrationError
from .kernels.layout import Samples, field_shapes
from .kernels.drive import member_function, run_members
from .kernels.tangent import Members, differentiator, index_maps, tangent_member
from .model import Model
from .progress import ProgressBar
from .results import (ResultBase, SavedResult, run_items, run_text, stats_arrays,
                      stats_from, timing)
from .sensitivity import (SensitivityResult, directions_text, largest_last,
                          sensitivity_arrays, sensitivity_from)

__all__ = ["sensitivity_ensemble", "EnsembleSensitivityResult"]

#: the parallel loop, called through its compiled entry points (no per-call typing)
_RUN = Launcher(run_members)


@dataclass(repr=False)
class EnsembleSensitivityResult(SavedResult, ResultBase):
    """The members of :func:`sensitivity_ensemble`: trajectories and their derivatives.

    :meth:`save` writes it to one ``.npz`` file (each member once) and :meth:`load` reads it
    back, bit for bit; :meth:`summary` gives one line of what to check first.

    Attributes
    ----------
    t : ndarray (K,)
        Sample times, common to the members.
    q, v, p : ndarray (N, K, n)
        Each member's trajectory (``members[i].result``).
    dq, dv, dp : ndarray (N, K, n, d)
        ``dq[i, j, :, c]``: the derivative of member ``i``'s ``q(t_j)`` along direction
        ``c`` (``labels[c]``), as :attr:`fastvi.SensitivityResult.dq` of that member.
    labels : list of str
        What each direction perturbs (the same for every member).
    params : ndarray (N, k)
        Each member's parameters.
    members : list of SensitivityResult
        Member ``i`` as :func:`fastvi.sensitivity` returns it.
    stats : dict
        ``members``, ``threads``, ``integration_time`` (the parallel loop),
        ``setup_time``, ``compile_time`` and ``wall_time`` in seconds.
    status : ndarray (N,) of int
        Each member's :attr:`fastvi.Result.status`; ``success`` (N,) and ``message`` (of
        the worst member) as :class:`fastvi.EnsembleResult`.
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    p: np.ndarray
    dq: np.ndarray
    dv: np.ndarray
    dp: np.ndarray
    labels: list
    params: np.ndarray
    members: list
    stats: dict

    def __len__(self) -> int:
        return len(self.members)

    @property
    def status(self) -> np.ndarray:
        """Each member's status (N,)."""
        return np.array([int(s.result.status) for s in self.members], dtype=np.int64)

    def _repr_items(self) -> list[str]:
        model, *run = run_items(self.members[0].result)
        return [model, f"members={len(self)}", *run, f"samples={self.t.shape[0]}",
                f"directions={len(self.labels)}", f"status={self._status_text()}"]

    def summary(self) -> str:
        """One line with the figures a user checks first: the number of members, the run,
        the number of samples and of directions (by what they perturb), the status, the
        time, and the largest entry of the members' last Jacobians ``∂q(t_K)/∂(directions)``."""
        run = self.members[0].result
        return (f"{run.model_name}: sensitivity ensemble of {len(self)} members, {run_text(run)}, "
                f"{self.t.shape[0]} samples × {directions_text(self.labels)}, "
                f"status {self._status_text()}, {self.stats.get('threads', '?')} threads, "
                f"{timing(self.stats)}, max |∂q(t_end)| = {largest_last(self.dq):.3e}")

    def _arrays(self) -> dict:
        # each member once: the stacked arrays (q, dq, …) are stacked again on load
        arrays = dict(members=len(self), labels=np.array(self.labels, dtype=str),
                      params=self.params, **stats_arrays(self.stats))
        for i, member in enumerate(self.members):
            arrays.update(sensitivity_arrays(member, f"member{i}_"))
        return arrays

    @classmethod
    def _from_stored(cls, data, model) -> "EnsembleSensitivityResult":
        members = [sensitivity_from(data, f"member{i}_", model=model)
                   for i in range(int(data["members"]))]
        return _gathered(members, [str(x) for x in data["labels"]], data["params"],
                         stats_from(data), cls)

    def jacobian(self, j: int = -1) -> np.ndarray:
        r"""Each member's Jacobian of the state at sample ``j`` (default the last) by the
        directions: ``∂(q, v)(t_j)/∂(directions)``, shape (N, 2n, d)."""
        return np.concatenate([self.dq[:, j], self.dv[:, j]], axis=1)


def sensitivity_ensemble(model, Q0, V0, *, h: float, t_end: float | None = None,
                         n_steps: int | None = None, t0: float = 0.0, t_span=None,
                         method="P2L-Q3G", wrt=("q0", "v0"), param_index=None, params=None,
                         save_every: int = 1, tol: float = valid.DEFAULT_TOL,
                         max_iter: int = valid.DEFAULT_MAX_ITER, newton: str = "auto",
                         solver: str = "auto", check: bool = True, monitor: bool = True,
                         threads: int | None = None, progress: bool = False,
                         specialize: bool | None = None,
                         **unsupported) -> EnsembleSensitivityResult:
    r"""Forward sensitivities of ``N`` members in one parallel loop.

    Member ``i`` starts from ``(Q0[i], V0[i])`` with parameters ``params[i]`` and carries
    the same directions ``wrt`` along its run: what :func:`fastvi.sensitivity` computes for
    it, equal bit for bit. For each member and step, the derivative of the step along a
    direction ``(δq_k, δp_k, δθ)`` solves

    .. math::

        K\,\delta X = -\left(R_q\,\delta q_k + R_p\,\delta p_k + R_\theta\,\delta\theta\right)

    with the exact Newton matrix ``K`` of that member's converged step, factored once a step
    (``docs/sensitivities.md``).

    Parameters
    ----------
    model : Model
    Q0, V0 : array_like (N, n)
        One initial state per member, each projected onto the constraints as
        :func:`fastvi.integrate` does.
    params : array_like (k,) or (N, k), optional
        The parameters of all members, or of each (default: the model's).
    h, t_end, n_steps, t0, t_span, method, wrt, param_index, save_every, tol, max_iter, newton, solver, check, monitor, specialize :
        As :func:`fastvi.sensitivity`; the same for every member.
    threads : int, optional
        Threads of the parallel loop (default: numba's setting), as
        :func:`fastvi.integrate_ensemble`.
    progress : bool, default False
        Show progress on stderr in member-steps, as :func:`fastvi.integrate_ensemble`: the
        members run in up to 20 groups, one after the other, each in the parallel loop.
        The results are the same bit for bit.

    Returns
    -------
    EnsembleSensitivityResult
        Trajectories ``q, v, p`` (N, K, n) and derivatives ``dq, dv, dp`` (N, K, n, d), and
        each member's :class:`fastvi.SensitivityResult` in ``members``.

    Raises
    ------
    fastvi.IntegrationError
        A member's step failed or its Newton matrix is singular at the solution: the error
        of the first such member, naming all of them, with that member's partial result
        attached. Derivatives are never returned as NaN.

    See Also
    --------
    sensitivity : one member.
    integrate_ensemble : the trajectories alone.

    Examples
    --------
    >>> import numpy as np, fastvi
    >>> dp = fastvi.scenes.double_pendulum()
    >>> starts = [dp.initial_state(a, 0.3) for a in (0.2, 0.5, 0.8)]
    >>> Q0 = np.array([q for q, v in starts]); V0 = np.array([v for q, v in starts])
    >>> ens = fastvi.sensitivity_ensemble(dp, Q0, V0, h=0.01, n_steps=100, save_every=100)
    >>> ens.dq.shape                  # 3 members, 2 samples, n = 4, 2n = 8 directions
    (3, 2, 4, 8)
    """
    started = time.perf_counter()
    disc.refuse(unsupported, "fastvi.sensitivity_ensemble")
    progress = valid.flag(progress, "progress")
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    Q0 = valid.member_vectors(Q0, "Q0", model.n)
    V0 = valid.member_vectors(V0, "V0", model.n)
    if V0.shape[0] != Q0.shape[0]:
        raise ValueError(f"`Q0` and `V0` must have one row per member each, got {Q0.shape[0]} "
                         f"and {V0.shape[0]} rows")
    threads = valid.threads(threads)
    N, n = Q0.shape
    P = valid.member_params(params, model, N)
    runs = []
    for i in range(N):
        try:
            runs.append(disc.prepare(
                model, Q0[i], V0[i], h=h, t_end=t_end, n_steps=n_steps, t0=t0, t_span=t_span,
                method=method, save_every=save_every, tol=tol, max_iter=max_iter, newton=newton,
                params=P[i], solver=solver, check=check, monitor=monitor,
                what="the sensitivity", specialize=specialize,
                full=True))  # members run in one compiled loop
        except ValueError as exc:
            raise ValueError(f"member {i} (`Q0[{i}]`, `V0[{i}]`, `params[{i}]`): {exc}") from None
    first = runs[0]
    meth, m, k = first.meth, model.m, P.shape[1]
    D, labels = disc.directions(wrt, n, k, param_index, model.fixed_params, model.mass_params)
    d = D.shape[0]
    tangents = [disc.initial_tangent(r, D) for r in runs]
    pidx = tangents[0][2]
    DQ = np.stack([tg[0] for tg in tangents])
    DP = np.stack([tg[1] for tg in tangents])
    TH = np.zeros((N, d, max(len(pidx), 1)))
    TH[:, :, :len(pidx)] = np.stack([tg[3] for tg in tangents])
    # the members' samples and counters, stacked (slot 0 is each member's initial sample)
    smp = Samples(*(np.ascontiguousarray(np.stack(a)) for a in zip(*(r.smp for r in runs))))
    infos = np.stack([r.info for r in runs])
    X0 = np.stack([r.state[:3] for r in runs])
    KP = np.stack([r.model_data.prm for r in runs])
    dQ = np.zeros((N, first.K, d, n))
    dP = np.zeros((N, first.K, d, n))
    dQ[:, 0], dP[:, 0] = DQ, DP
    status = np.zeros(N, dtype=np.int64)
    md, ws, ev = first.model_data, first.ws, first.ev
    rows, cols = index_maps(n, m, meth.s, meth.J)
    # the hook for a member's argument types, which are those of a single run's
    tw = disc.tangent_work(first, d, pidx)
    each, lin = differentiator(md, first.state, first.loop_ws, first.info, first.tx, tw, dQ[0],
                               first.sized)
    # each member allocates the single run's workspaces again: what its steps read, a long
    # chain's matrices in band storage with their maps (layout.field_shapes)
    group = Members(md.fns, md.flags, md.Mc, KP, first.tabs, first.tx, first.opts, first.h,
                    ws.dims, ws.si, ws.sb, ws.structured, field_shapes(ws), tw.ws.si,
                    field_shapes(tw.ws), X0, first.total, first.every, smp,
                    infos, ev, first.stepk, first.stages, rows, cols,
                    np.asarray(pidx, dtype=np.int64), first.sparsity,
                    model.param_derivative_data(), DQ, DP, TH, dQ, dP, each, lin)
    with quiet():
        t_compile = time.perf_counter()
        member = member_function(tangent_member, group)
        compile_time = time.perf_counter() - t_compile
    bar = ProgressBar(N * first.total, unit="member-steps",
                      label="fastvi sensitivity_ensemble") if progress else None
    with parallel_section(threads, N) as used:
        # consecutive groups of members between two updates of the line (a member runs to
        # its end in one go)
        size = N if bar is None else max(used, -(-N // PROGRESS_GROUPS))
        with quiet():
            run, seconds = _RUN.bind(member, group, status)
            compile_time += seconds
            t_loop = time.perf_counter()
            for a in range(0, N, size):
                b = min(a + size, N)
                run(member, _members_of(group, a, b), status[a:b])
                if bar is not None:
                    bar.update(b * first.total, f"{b}/{N} members", final=b == N)
            loop_time = time.perf_counter() - t_loop
    members, failed = [], []
    for i, r in enumerate(runs):
        r = dataclasses.replace(r, smp=Samples(*(a[i] for a in smp)), info=infos[i])
        try:
            result = disc.finish(r, int(status[i]), loop_time / N, compile_time / N,
                                 f"the sensitivity of member {i}")
        except IntegrationError as err:
            failed.append((i, err))
            continue
        K = result.t.shape[0]
        dq = np.ascontiguousarray(dQ[i, :K].transpose(0, 2, 1))
        dp = np.ascontiguousarray(dP[i, :K].transpose(0, 2, 1))
        dv = disc.velocity_derivatives(r, result, dq, dp, pidx, tangents[i][3])
        members.append(SensitivityResult(result, result.t, dq, dv, dp, labels, r.prm,
                                         tangents[i][3], pidx, model))
    if failed:
        i, err = failed[0]
        names = ", ".join(str(j) for j, _ in failed)
        raise IntegrationError(err.status, err.step, err.time, err.residual, err.result,
                               f"{err.detail}; members that failed: {names} of {N}")
    wall = time.perf_counter() - started
    stats = dict(members=N, threads=used, integration_time=loop_time, compile_time=compile_time,
                 setup_time=wall - loop_time, wall_time=wall)
    return _gathered(members, labels, P, stats)


def _members_of(group: Members, a: int, b: int) -> Members:
    """The members ``a … b − 1`` of ``group``: views of the rows of its arrays indexed by
    member first, the same numba types (the compiled loop is not compiled again)."""
    if a == 0 and b == group.P.shape[0]:
        return group
    rows = slice(a, b)
    return group._replace(P=group.P[rows], X0=group.X0[rows],
                          smp=Samples(*(x[rows] for x in group.smp)),
                          infos=group.infos[rows], DQ=group.DQ[rows], DP=group.DP[rows],
                          TH=group.TH[rows], dQ=group.dQ[rows], dP=group.dP[rows])


def _gathered(members, labels, params, stats, cls=EnsembleSensitivityResult):
    """The ensemble of ``members`` (:class:`fastvi.SensitivityResult`): their trajectories
    and derivatives stacked, member first."""
    runs = [s.result for s in members]

    def stack(objs, name):
        return np.stack([getattr(o, name) for o in objs])

    return cls(members[0].t, stack(runs, "q"), stack(runs, "v"), stack(runs, "p"),
               stack(members, "dq"), stack(members, "dv"), stack(members, "dp"), labels, params,
               members, stats)
