r"""The discrete adjoint: gradients of a cost of the trajectory, :func:`adjoint`.

One backward sweep of the transposed linearised steps (:mod:`fastvi.kernels.adjoint`)
gives the gradient of a cost by the initial state and every parameter at once: for a cost
that depends on many parameters it replaces one forward direction per parameter
(:func:`fastvi.sensitivity`) by one transposed solve a step (``docs/sensitivities.md``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from . import _discrete as disc
from . import _validate as valid
from ._launch import Launcher
from ._numba import quiet
from .kernels.adjoint import (g_entries, make_checkpoints, make_records, recorder, run_adjoint,
                              run_checkpointed, sweeper)
from .kernels import layout as lay
from .progress import UPDATES, ProgressBar
from .results import (Result, ResultBase, SavedResult, matching_model, result_arrays,
                      result_from, run_items, run_text, stats_arrays, stats_from, timing)

__all__ = ["adjoint", "AdjointResult"]

#: the memory the default schedule gives the records and checkpoints (``max_memory``):
#: every step's records (nothing retaken) while they fit, else the longest segments that
#: fit, else the segments of least memory
KEEP_ALL_BYTES = 256 * 2**20

#: the forward and backward loops, called through their compiled entry points (_launch.py)
_FORWARD = Launcher(run_checkpointed)
_BACKWARD = Launcher(run_adjoint)


@dataclass(repr=False)
class AdjointResult(SavedResult, ResultBase):
    """The trajectory of :func:`adjoint` and the gradient of the cost.

    :meth:`save` writes it to one ``.npz`` file and :meth:`load` reads it back, bit for bit;
    :meth:`summary` gives one line of what to check first.

    Attributes
    ----------
    result : Result
        The trajectory (equal bit for bit to :func:`fastvi.integrate`'s).
    grad_q0, grad_v0 : ndarray (n,)
        ``∂J/∂q0`` and ``∂J/∂v0`` of the raw initial data (through their consistent
        projection, as :func:`fastvi.sensitivity` differentiates it).
    grad_params : ndarray (len(param_index),)
        ``∂J/∂θ_l`` for ``l`` in ``param_index``.
    param_index : list of int
    lam_q, lam_p : ndarray (n,)
        The adjoint at ``t0``: ``∂J/∂(q0, p0)`` of the consistent initial state.
    stats : dict
        ``checkpoints`` kept, ``segment`` (steps between them), ``memory`` (bytes of the
        records and checkpoints, at most ``max_memory`` unless the segment of least memory
        exceeds it), ``backward_time`` (s).
    status : Status
        The run's (``result.status``); ``success`` and ``message`` as :class:`fastvi.Result`.
    """

    result: Result
    grad_q0: np.ndarray
    grad_v0: np.ndarray
    grad_params: np.ndarray
    param_index: list
    lam_q: np.ndarray
    lam_p: np.ndarray
    stats: dict

    @property
    def status(self):
        """The status of the run (:attr:`fastvi.Result.status` of :attr:`result`)."""
        return self.result.status

    @property
    def gradient(self) -> np.ndarray:
        """``(grad_q0, grad_v0, grad_params)`` in one vector (2n + len(param_index),)."""
        return np.concatenate([self.grad_q0, self.grad_v0, self.grad_params])

    def _repr_items(self) -> list[str]:
        return [*run_items(self.result), f"samples={self.result.t.shape[0]}",
                f"parameters={len(self.param_index)}",
                f"|grad|={np.linalg.norm(self.gradient):.3g}", f"status={self._status_text()}"]

    def summary(self) -> str:
        """One line with the figures a user checks first: the run, the number of samples
        and of parameters, the norm of the gradient (and of its parts by ``q0``, ``v0`` and
        the parameters), the status, and the times of the forward run and backward sweep."""
        norm = np.linalg.norm
        st = self.stats
        return (f"{self.result.model_name}: adjoint, {run_text(self.result)}, "
                f"{self.result.t.shape[0]} samples, {len(self.param_index)} parameters, "
                f"|∇J| = {norm(self.gradient):.3e} (q0 {norm(self.grad_q0):.3e}, "
                f"v0 {norm(self.grad_v0):.3e}, params {norm(self.grad_params):.3e}), "
                f"status {self._status_text()}, forward: {timing(self.result.stats)}, "
                f"backward {st.get('backward_time', float('nan')):.3g} s (checkpoints: "
                f"{st.get('checkpoints', '?')}, every {st.get('segment', '?')} steps, "
                f"{st.get('memory', float('nan')) / 2**20:.3g} MiB)")

    def _arrays(self) -> dict:
        return dict(grad_q0=self.grad_q0, grad_v0=self.grad_v0, grad_params=self.grad_params,
                    param_index=np.asarray(self.param_index, dtype=np.int64), lam_q=self.lam_q,
                    lam_p=self.lam_p, **stats_arrays(self.stats),
                    **result_arrays(self.result, "result_"))

    @classmethod
    def _from_stored(cls, data, model) -> "AdjointResult":
        result = result_from(data, "result_")
        matching_model(model, result, cls.__name__)  # checked, not kept: no method needs it
        return cls(result, data["grad_q0"], data["grad_v0"], data["grad_params"],
                   [int(x) for x in data["param_index"]], data["lam_q"], data["lam_p"],
                   stats_from(data))


def adjoint(model, q0, v0, cotangent, *, h: float, t_end: float | None = None,
            n_steps: int | None = None, t0: float = 0.0, t_span=None, method="P2L-Q3G",
            param_index=None, initial_state=None, params=None, save_every: int = 1,
            checkpoint_every: int | None = None, max_memory: int | None = None,
            tol: float = valid.DEFAULT_TOL,
            max_iter: int = valid.DEFAULT_MAX_ITER, newton: str = "auto", solver: str = "auto",
            check: bool = True, monitor: bool = True, progress: bool = False,
            specialize: bool | None = None, **unsupported) -> AdjointResult:
    r"""The gradient of a cost ``J`` of the saved states by the discrete adjoint.

    For ``J`` a function of the samples ``(q_i, v_i)`` of the run, ``cotangent(result)``
    returns ``(∂J/∂q_i, ∂J/∂v_i)`` (two (K, n) arrays; the second may be None). The
    backward sweep over the steps (``x = (q, p)``)

    .. math::

        \lambda_k = \Big(\frac{\partial x_{k+1}}{\partial x_k}\Big)^{\!T} \lambda_{k+1}
                    + \frac{\partial J}{\partial x_k},\qquad
        \nabla_\theta J \mathrel{+}= \Big(\frac{\partial x_{k+1}}{\partial \theta}\Big)^{\!T}
                    \lambda_{k+1}

    transposes exactly the linearised steps of :func:`fastvi.sensitivity`, so
    ``⟨∇J, δ⟩`` equals the forward derivative of ``J`` along any direction ``δ`` to
    round-off. Each step costs one linearisation and one transposed solve with its exact
    Newton matrix; the parameters' part contracts the cotangent with the model's
    derivatives by θ point by point (about 0.1 µs a parameter and step on the double
    pendulum), or, for a model without them, adds four residual evaluations a parameter
    and step (five-point differences). The forward run records each step's converged
    unknowns for the sweep: all of them while they take at most ``max_memory`` bytes
    (default :data:`KEEP_ALL_BYTES`, 256 MiB: 288 bytes a step for a double pendulum with
    ``P2L-Q3G``, about 9 × 10⁵ steps; 34 KiB for a chain of 256 links, about 7 700), so
    that nothing is solved twice. A longer run is cut into segments of
    ``checkpoint_every`` steps, the last ``N`` steps first: the forward run keeps its state
    at the start of each, and the sweep takes the last segment from the records and
    retakes each earlier one from its checkpoint — ``N − C`` steps solved twice for
    segments of ``C``. By default ``C`` is the longest segment whose records and
    checkpoints fit in ``max_memory``; a run too long for it takes the segment of
    least memory, ``C ≈ √(N c / r)`` for checkpoints of ``c`` bytes and records of ``r``
    bytes a step (memory ∝ √N).

    Parameters
    ----------
    model, q0, v0, h, t_end, n_steps, t0, t_span, method, params, save_every, tol, max_iter, newton, solver, check, monitor, specialize :
        As :func:`fastvi.sensitivity`.
    progress : bool, default False
        Show progress on stderr: the forward run's steps, then the backward sweep's, over
        twice the number of steps (one updating line on a terminal, plain lines in a log).
        The gradient is the same bit for bit.
    cotangent : callable
        ``cotangent(result) -> (dJ_dq, dJ_dv)``, (K, n) each at the samples of
        ``result`` (a :class:`fastvi.Result`); ``dJ_dv`` may be None.
    param_index : sequence of int, optional
        The parameters to differentiate (default: all ``k`` but ``model.fixed_params``,
        which cannot be named).
    initial_state : callable, optional
        ``initial_state(params) -> (q0, v0)``, as in :func:`fastvi.sensitivity`.
    checkpoint_every : int, optional
        Steps between checkpoints ``C``: ``N`` keeps every step, smaller values trade time
        (``N − C`` steps retaken) for memory (``∝ N / C + C``). Default: the largest ``C``
        whose records and checkpoints take at most ``max_memory``, else the ``C`` of
        least memory.
    max_memory : int, optional
        Bytes the records and checkpoints of the default schedule may take (default
        :data:`KEEP_ALL_BYTES`, 256 MiB). Less memory, more steps retaken; the gradient is
        the same bit for bit. Give this or ``checkpoint_every``, not both.

    Returns
    -------
    AdjointResult

    Raises
    ------
    fastvi.IntegrationError
        A step failed, or its Newton matrix is singular at the solution.

    Notes
    -----
    Cost: the forward run records each step; the backward sweep linearises each step once
    (the exact Newton matrix, assembled and factored) and solves once with its transpose.
    That is about three to four plain runs for the gradient by ``q0``, ``v0`` and every
    parameter, however many there are, when the model gives its derivatives by θ
    (``Model(param_derivatives=...)``; :func:`fastvi.symbolic.model_from_lagrangian`
    generates them): each parameter then adds a few entries a point. Without them each
    parameter differences the step, four residual evaluations a parameter and step, and
    the gradient costs several times more (the free ``slider_crank``'s seven parameters:
    about 10 plain runs without, under 3 with). Name only the parameters needed in
    ``param_index`` for such a model. Steps retaken between checkpoints add up to one
    plain run. See ``docs/sensitivities.md`` for measured costs.

    References
    ----------
    J. M. Sanz-Serna, Symplectic Runge–Kutta schemes for adjoint equations, automatic
    differentiation, optimal control, and more, SIAM Review 58 (2016) 3–33.
    """
    disc.refuse(unsupported, "fastvi.adjoint")
    if not callable(cotangent):
        raise TypeError(f"`cotangent` must be a function `cotangent(result) -> (dJ_dq, dJ_dv)` "
                        f"of the run's samples, got {type(cotangent).__name__}")
    initial_state = disc.checked_initial_state(initial_state)
    budget = None if max_memory is None else valid.count(max_memory, "max_memory", 1)
    if budget is not None and checkpoint_every is not None:
        raise ValueError("give `checkpoint_every` (the segment's steps) or `max_memory` (the "
                         "bytes that choose it), not both")
    progress = valid.flag(progress, "progress")
    # checked before the run: a bad index is reported without compiling or integrating
    pidx = disc.param_indices(param_index, disc.checked_model(model).params.shape[0],
                              model.fixed_params, model.mass_params)
    if initial_state is not None and not pidx:
        raise ValueError("`initial_state` gives the start's dependence on the parameters, but "
                         "`param_index` names none: name the parameters, or drop `initial_state`")
    run = disc.prepare(model, q0, v0, h=h, t_end=t_end, n_steps=n_steps, t0=t0, t_span=t_span,
                       method=method, save_every=save_every, tol=tol, max_iter=max_iter,
                       newton=newton, params=params, solver=solver, check=check,
                       monitor=monitor, what="the adjoint", specialize=specialize)
    n, m = model.n, model.m
    meth = run.meth
    N = meth.s * n + meth.J * m
    g_size = g_entries(run.ws)
    if checkpoint_every is None:
        C = _segment_length(run.total, n, m, N, g_size, budget)
    else:
        C = valid.count(checkpoint_every, "checkpoint_every", 1)
    C = min(C, run.total)
    ck = make_checkpoints(-(-run.total // C), n, m, N, g_size)
    rec = make_records(C, n, m, N)
    info = run.info.copy()
    each = recorder(run.model_data, run.state, run.loop_ws, info, rec)
    total = run.total
    # the forward run, then the sweep, in chunks of steps between two updates of the line
    bar = ProgressBar(2 * total, label="fastvi adjoint") if progress else None
    chunk = total if bar is None else max(1, total // UPDATES)
    t_loop = time.perf_counter()
    while True:
        stop = min(int(run.info[lay.I_STEPS]) + chunk, total)
        with quiet():
            status = _FORWARD(run.model_data, run.tabs, run.opts, run.h, run.state, run.loop_ws,
                              total, run.every, run.smp, run.info, run.sout, run.ev,
                              run.stepk, run.stages, ck, rec, each, stop)
        if status == lay.NEEDS_FULL_NEWTON:  # compiled on first need; the step is retaken
            disc.with_full_newton(run)
            continue
        done = int(run.info[lay.I_STEPS])
        if bar is not None:
            bar.update(done, f"forward, t = {run.t0 + done * run.h:.6g}", final=status != 0)
        if status != 0 or done >= total:
            break
    loop_time = time.perf_counter() - t_loop
    result = disc.finish(run, int(status), loop_time, 0.0, "the adjoint")
    Lq, Lp, direct = _cotangents(run, result, cotangent, pidx)
    tw = disc.tangent_work(run, 0, pidx)  # no forward directions: pull contracts R_θ
    lq, lp, lth = np.zeros(n), np.zeros(n), np.zeros(max(len(pidx), 1))
    back, lin = sweeper(run.model_data, run.tx, tw, rec, lth, run.sized)
    t_back = time.perf_counter()
    info[:] = run.info
    hi = total
    while hi > 0:
        lo = max(hi - chunk, 0)
        with quiet():
            status = _BACKWARD(run.model_data, run.tabs, run.tx, run.opts, run.h, run.state,
                               run.loop_ws, total, run.every, run.smp, info, run.sout, run.ev,
                               run.stepk, run.stages, tw, ck, rec, Lq, Lp, lq, lp, lth, each,
                               back, lin, hi, lo)
        if status != 0:
            break
        hi = lo
        if bar is not None:
            bar.update(2 * total - hi, f"backward, t = {run.t0 + hi * run.h:.6g}",
                       final=hi == 0)
    if bar is not None and status != 0:
        bar.update(2 * total - hi, "backward", final=True)
    back_time = time.perf_counter() - t_back
    if status != 0:
        run.info[:] = info
        disc.finish(run, int(status), loop_time, 0.0, "the adjoint")
    # through the consistent initial state: the transpose of its derivative
    grad = disc.initial_cotangent(run, lq, lp, pidx, initial_state)
    grad[2 * n:] += lth[:len(pidx)] + direct
    memory = sum(a.nbytes for a in ck) + sum(a.nbytes for a in rec)
    return AdjointResult(result, grad[:n], grad[n:2 * n], grad[2 * n:], pidx, lq, lp,
                         dict(checkpoints=ck.steps.shape[0], segment=C, memory=memory,
                              backward_time=back_time))


def _record_bytes(n, m, N):
    """The bytes of one step's records (:func:`.kernels.adjoint.make_records`)."""
    return 8 * (5 * n + N + 2 + max(m, 1))


def _checkpoint_bytes(n, N, g_size):
    """The bytes of one checkpoint (:func:`.kernels.adjoint.make_checkpoints`)."""
    return 8 * (4 + 3 * n + 2 * N + lay.H_SIZE + g_size)


def _segment_length(total, n, m, N, g_size, budget=None):
    """The default ``checkpoint_every`` of a run of ``total`` steps: the longest segment
    whose records, with the checkpoints of all segments, take at most ``budget`` bytes
    (:data:`KEEP_ALL_BYTES`), and never shorter than the segment of least memory.

    The sweep retakes ``total − C`` steps, so the longest segment that fits is the
    cheapest. Records of ``r`` bytes a step and checkpoints of ``c`` bytes take
    ``(total / C) c + C r``, least at ``C = √(total c / r)``: the choice of a run too long
    (or a model too large) for the budget, whose memory then grows like ``√total``."""
    budget = KEEP_ALL_BYTES if budget is None else budget
    rec, ck = _record_bytes(n, m, N), _checkpoint_bytes(n, N, g_size)
    x = -(-total * ck // rec)
    lightest = min(total, math.isqrt(x) + (math.isqrt(x) ** 2 < x))  # ⌈√x⌉
    for count in range(1, -(-total // lightest) + 1):  # the fewest checkpoints first
        C = min(total, (budget - count * ck) // rec)  # the longest with `count` checkpoints
        if C >= max(lightest, -(-total // count)):  # ... and `count` segments cover the run
            return C
    return lightest


def _cotangents(run, result, cotangent, pidx):
    r"""``(Lq, Lp, direct)``: the cotangents on ``(q_i, p_i)`` of ``cotangent(result)`` =
    ``(∂J/∂q_i, ∂J/∂v_i)``, with ``v = M(q, θ)⁻¹ p``: ``Lp = M⁻¹ J_v``,
    ``Lq = J_q − C_qᵀ M⁻¹ J_v``, and the direct part by the parameters
    ``−Σ_i (M_θ v_i)ᵀ M⁻¹ J_v`` (for a configuration-dependent mass: the model's ``∂M/∂θ``,
    or five-point differences in θ of :func:`fastvi._discrete.momentum`, which depends on
    ``q`` and ``θ`` for a singular constant mass)."""
    model = run.model
    n, K = model.n, result.t.shape[0]
    out = cotangent(result)
    if not (isinstance(out, tuple) and len(out) == 2):
        raise TypeError("`cotangent(result)` must return a pair (dJ_dq, dJ_dv) of (K, n) arrays "
                        f"(dJ_dv may be None), got {type(out).__name__}")
    Jq = _cotangent_array(out[0], "dJ_dq", K, n)
    Jv = None if out[1] is None else _cotangent_array(out[1], "dJ_dv", K, n)
    direct = np.zeros(len(pidx))
    if Jv is None:
        return Jq, np.zeros((K, n)), direct
    if model.mass_matrix_constant is not None and not model.mass_singular:
        return Jq, np.linalg.solve(model.mass_matrix_constant, Jv.T).T.copy(), direct
    Lq, Lp = Jq.copy(), np.zeros((K, n))
    for start, Ms, _, _, Cqs in disc.sample_terms_by_chunk(model, run.prm, result, len(pidx)):
        s = slice(start, start + len(Ms))
        Lp[s] = np.linalg.solve(Ms, Jv[s, :, None])[..., 0]
        Lq[s] -= np.matmul(Cqs.transpose(0, 2, 1), Lp[s, :, None])[..., 0]
        if pidx:
            Pth = disc.momentum_by_theta(model, run.prm, result, s.start, s.stop, pidx)
            for d in np.matmul(Pth, Lp[s, :, None])[..., 0]:  # sample by sample, in order
                direct -= d
    return Lq, Lp, direct


def _cotangent_array(x, name, K, n):
    arr = np.asarray(x)
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"`cotangent(result)` must give `{name}` as a real array, got dtype "
                        f"{arr.dtype}: the gradient of a real cost")
    arr = arr.astype(float, copy=False)
    if arr.shape != (K, n):
        raise ValueError(f"`cotangent(result)` must give `{name}` as a ({K}, {n}) array (one "
                         f"row per sample), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        rows = np.nonzero(~np.all(np.isfinite(arr), axis=1))[0]
        raise ValueError(f"`cotangent(result)` gave `{name}` with NaN or inf in {rows.size} "
                         f"row(s), the first at sample {int(rows[0])}: it must be finite")
    return np.ascontiguousarray(arr)
