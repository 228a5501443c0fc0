"""What the forward sensitivities and the discrete adjoint share: validating and setting up a
run of the linearised flow, the derivative of the consistent initial state, and the
:class:`fastvi.Result` of the run.

The trajectory of such a run is taken by the compiled step of :func:`fastvi.integrate`
(:func:`fastvi.kernels.drive.run`, one step at a time), so it equals ``integrate``'s bit for
bit; :mod:`fastvi.kernels.tangent` differentiates each step after it.
"""

from __future__ import annotations

import time
import warnings
from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from . import _validate as valid
from . import events as events_
from . import monitor as monitor_
from . import scipy_compat as compat
from . import structure
from .integrate import IntegrationError, _buffers, _filled
from .kernels import layout as lay
from .kernels.linalg import AUGMENT_SCALE, augment_weights
from .kernels.step import linear_force, step_kernel
from .kernels.tangent import (extended_tables, make_sparsity, make_tangent_work, point_terms,
                             sample_callback, sample_masses, sample_terms, step_band)
from .model import Model
from .results import Result
from .status import Status
from .tables import Method

__all__ = ["Run", "refuse", "prepare", "with_full_newton", "checked_model", "directions",
           "param_indices", "tangent_work", "initial_tangent", "initial_cotangent",
           "checked_initial_state", "theta_derivative", "momentum_mass", "momentum", "velocity", "data_at",
           "sample_terms_by_chunk", "momentum_by_theta", "constraints_by_theta",
           "velocity_derivatives", "finish"]


@dataclass
class Run:
    """A validated run: the kernels' arguments and the sizes of its output."""

    model: Model
    meth: Method
    prm: np.ndarray
    t0: float
    h: float
    total: int
    every: int
    q0: np.ndarray
    v0: np.ndarray
    model_data: object
    tabs: object
    tx: object
    ws: object
    opts: object
    ev: object
    stepk: object
    stages: object
    state: np.ndarray
    info: np.ndarray
    sout: np.ndarray
    smp: object
    K: int
    started: float
    compile_time: float
    check_time: float
    monitor: bool
    #: what the linearised step uses of the model's structure (large mechanisms)
    sparsity: object
    #: whether the linearised step is compiled for the model's sizes (``structure.sizing``:
    #: True, "cached" or False)
    sized: object
    #: the same for the step's stages
    step_sized: object
    #: ``(q0, v0)`` as given, where the projection onto the constraints moved them by more
    #: than round-off (:func:`_moved_start`), else None
    raw_start: object = None

    @property
    def loop_ws(self):
        """The workspace as the step and the time loops take it (:func:`.kernels.layout.loop_view`);
        ``ws`` itself is typed with its plan, for the stages that solve."""
        return lay.loop_view(self.ws)


#: options of :func:`fastvi.integrate` that the derivatives of the discrete flow do not take,
#: and why
_NOT_DIFFERENTIATED = {
    "events": "an event crossing makes the flow non-smooth there (a terminal event's time "
              "depends on the state); split the run at the event and chain the derivatives "
              "of the pieces",
    "adaptive": "the step-size controller is not differentiated; pass a fixed step `h`",
    "recover": "a recovered step would change the map being differentiated; a failed step "
               "raises `fastvi.IntegrationError` with the partial result instead",
    "on_failure": "a failed step always raises: the derivative is not defined from it on",
    "dense_output": "derivatives are given at the saved steps; save more often with "
                    "`save_every`",
    "t_eval": "derivatives are given at the saved steps; choose them with `save_every`",
}


def refuse(options: dict, what: str) -> None:
    """Raise ``TypeError`` for keyword arguments of :func:`fastvi.integrate` that ``what``
    does not take, saying why, and for unknown ones as Python would."""
    for name in options:
        why = _NOT_DIFFERENTIATED.get(name)
        if why is None:
            raise TypeError(f"{what} got an unexpected keyword argument {name!r}")
        raise TypeError(f"{what} does not take `{name}`: {why}")


def prepare(model, q0, v0, *, h, t_end, n_steps, t0, t_span, method, save_every, tol, max_iter,
            newton, params, solver, check, monitor, what, specialize=None, full=False) -> Run:
    """Validate the arguments of a run of the linearised flow (as :func:`fastvi.integrate`
    does, and refusing what ``what`` — the caller's name — does not differentiate) and
    allocate its kernels' arguments.

    ``full``: the step's full Newton compiled now (a driver that cannot stop for it);
    else the caller compiles it on a step's first need (:func:`with_full_newton`), as
    :func:`fastvi.integrate` does."""
    started = time.perf_counter()
    n = checked_model(model).n
    q0 = valid.vector(q0, "q0", n)
    v0 = valid.vector(v0, "v0", n)
    prm = valid.params(params, model).copy()
    h = valid.step_size(h)
    t0, t_end = compat.span(t_span, t0, t_end, n_steps)
    t0 = valid.start_time(t0)
    total, h, h_last = compat.steps(h, t_end, n_steps, t0)
    if h_last:
        raise ValueError(
            f"{what} needs a whole number of steps of `h`: t_end − t0 = {float(t_end) - t0:g} "
            f"is {total} steps of h = {h:g} and a shorter one of {h_last:g}; pass `n_steps`, or an "
            f"`h` that divides the span (e.g. h = {(float(t_end) - t0) / (total + 1):.6g})")
    every = valid.save_every(save_every)
    opts = valid.newton_options(tol, max_iter, newton)
    meth = valid.method(method)
    check_time = time.perf_counter()
    # a plain run's check leaves the derivatives by θ out; the linearised step reads them
    if check and (not model.checked
                  or model.param_derivatives_exact and not model.param_derivatives_checked):
        model.check(q0, v0, params=prm, n_random=1, t=t0)
    check_time = time.perf_counter() - check_time
    raw = q0, v0
    q0, v0 = valid.initial_state(model, q0, v0, prm, t0)
    # below 1e-14 the terms of the projection's derivative that the move scales are round-off
    moved = (np.max(np.abs(q0 - raw[0])) > 1e-14 * max(1.0, np.max(np.abs(raw[0])))
             or np.max(np.abs(v0 - raw[1])) > 1e-14 * max(1.0, np.max(np.abs(raw[1]))))
    compile_time = time.perf_counter()
    md = model.kernel_data(prm, t0)
    tabs = meth.kernel_tables
    ws = structure.workspace(model, meth, prm, solver, newton=False)
    # the structured paths of the linearised step are compiled for structured workspaces
    # only (_numba.only_if): a model whose plan keeps every solve dense gets none of them
    patterns = structure.plan(model, meth, prm, solver).patterns if ws.structured else {}
    if model.mass_singular and ws.structured:
        # the projection's derivative factors M + Gᵀ W G densely: O(n³) a step
        raise ValueError(
            f"{what} of model {model.name!r} is not available with the structured solves of a "
            "large mechanism: its constant mass matrix is singular (a body with a zero principal "
            "inertia, such as a rod or a lamina). Pass `solver=\"dense\"` for a model small "
            "enough, or give every body inertia about each axis")
    diagonal = bool(lay.reciprocal_mass.py_func(md.flags))
    sparsity = make_sparsity(step_band(ws), structure.linearisation_patterns(
        patterns["G"], patterns["newton"], meth.s, meth.J, diagonal) if patterns else None)
    specialize = valid.optional_flag(specialize, "specialize")
    # the stages compiled for the model's sizes when integrate has compiled them: the same
    # steps bit for bit, at half the cost
    step_sized = structure.sizing(specialize, n, total)
    stepk, stages = step_kernel(md, tabs, opts, ws, full=full, sized=step_sized)
    sized = False if ws.structured else structure.sizing(specialize, n, total,
                                                         structure.SIZED_TANGENT_MIN_STEPS)
    compile_time = time.perf_counter() - compile_time
    state = np.zeros((6, n))
    state[0], state[1], state[2] = q0, model.mass_matrix(q0, prm) @ v0, v0
    K = total // every + 1 + (1 if total % every else 0)
    smp, info = _buffers(model, K, t0, q0, v0, state[1], prm)
    return Run(model, meth, prm, t0, h, total, every, q0, v0, md, tabs,
               extended_tables(tabs, meth.s, meth.J), ws, opts,
               events_.prepare(model, meth, None, 0), stepk, stages, state, info,
               np.zeros(lay.STEP_OUT_SIZE), smp, K, started, compile_time, check_time,
               valid.flag(monitor, "monitor"), sparsity, sized, step_sized,
               raw if moved else None)


def with_full_newton(run: Run) -> None:
    """Give ``run`` the step's full Newton, compiled now: after its time loop returned
    ``NEEDS_FULL_NEWTON``, having kept nothing of the step it then retakes (the same steps
    bit for bit as a run that had it from the start)."""
    started = time.perf_counter()
    run.stepk, run.stages = step_kernel(run.model_data, run.tabs, run.opts, run.ws, full=True,
                                        sized=run.step_sized)
    run.compile_time += time.perf_counter() - started


def tangent_work(run: Run, d: int, pidx):
    """The linearised step's work of ``run`` for ``d`` directions by the parameters
    ``pidx``, with the model's derivatives by θ where it gives them
    (:meth:`fastvi.Model.param_derivative_data`), and its constant −∇V set."""
    meth = run.meth
    pd = run.model.param_derivative_data()
    # the model's derivatives by θ give the step's (tangent._exact_in_theta): the adjoint
    # then contracts them and needs no columns R_θ
    exact = pd.exact != 0 and run.model_data.flags[lay.F_AUGMENT] == 0
    tw = make_tangent_work(run.model.n, run.model.m, meth.s, meth.r, meth.J, d, pidx, pd,
                           len(run.prm), run.sparsity, run.ws, exact=exact)
    _linear_part(run, tw)
    return tw


def _linear_part(run: Run, tw) -> None:
    """Set the extended step's constant −∇V of a linear potential (the step sets its own at
    a trajectory's first step)."""
    linear_force(run.model_data, tw.ws, run.q0)


# ----------------------------------------------------------------------------- directions
def theta_derivative(f, prm: np.ndarray, l: int) -> np.ndarray:
    """``∂f/∂θ_l`` at ``prm`` by the kernels' five-point difference (``layout.FD_T``)."""
    points, scale = _theta_stencil(prm, l)
    acc = 0.0
    for p, wgt in points:
        acc = acc + wgt * np.asarray(f(p), dtype=float)
    return acc / scale


def _theta_stencil(prm, l: int):
    """``([(θ_j, w_j)], 12 δ)``: the points and weights of :func:`theta_derivative`'s rule
    in ``θ_l`` and its divisor, ``∂f/∂θ_l ≈ Σ_j w_j f(θ_j) / (12 δ)``."""
    dt = lay.FD_T * max(1.0, abs(float(prm[l])))
    points = []
    for sgn, wgt in lay.FD_T_POINTS:
        p = prm.copy()
        p[l] += sgn * dt
        points.append((p, wgt))
    return points, 12.0 * dt


def checked_model(model) -> Model:
    """``model``, or a TypeError that names it."""
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    return model


def directions(wrt, n: int, k: int, param_index, fixed=(),
               mass=()) -> tuple[np.ndarray, list[str]]:
    """``(D, labels)``: the raw directions (d, 2n + k) in ``(δq0, δv0, δθ)`` of ``wrt`` — a
    sequence of the names ``"q0"``, ``"v0"``, ``"params"`` (``param_index`` the parameters
    of ``"params"``, default all but the model's ``fixed`` ones) or an array (2n + k, d) of
    directions — and a label for each."""
    if isinstance(wrt, str):
        wrt = (wrt,)
    idx = param_indices(param_index, k, fixed, mass)
    if isinstance(wrt, np.ndarray) or (isinstance(wrt, (list, tuple)) and wrt
                                       and not isinstance(wrt[0], str)):
        D = np.asarray(wrt, dtype=float)
        if D.ndim == 1:
            D = D[:, None]
        if D.ndim != 2 or D.shape[0] != 2 * n + k:
            raise ValueError(f"`wrt` as an array must hold directions (δq0, δv0, δθ) as "
                             f"columns, shape ({2 * n + k}, d) for n = {n}, k = {k}; got shape "
                             f"{D.shape}")
        if not np.all(np.isfinite(D)):
            raise ValueError(f"`wrt` as an array must be finite; column(s) "
                             f"{sorted(set(np.nonzero(~np.isfinite(D))[1].tolist()))} hold NaN "
                             f"or inf")
        for l in fixed:
            if np.any(D[2 * n + l] != 0.0):
                raise ValueError(f"`wrt` moves params[{l}], which the model marks fixed "
                                 f"({_FIXED}): set row {2 * n + l} of the directions to zero")
        return np.ascontiguousarray(D.T), [f"direction[{i}]" for i in range(D.shape[1])]
    rows, labels = [], []
    names = list(wrt)
    for name in names:
        if name not in ("q0", "v0", "params"):
            raise ValueError(f"`wrt` entries must be 'q0', 'v0' or 'params', got {name!r}")
        if names.count(name) > 1:
            raise ValueError(f"`wrt` names {name!r} twice")
    if param_index is not None and "params" not in names:
        raise ValueError(f"`param_index` chooses among the directions of 'params', which `wrt` = "
                         f"{tuple(names)} does not name: add 'params' to `wrt`, or drop "
                         f"`param_index`")
    for name in names:
        if name == "params":
            for l in idx:
                r = np.zeros(2 * n + k)
                r[2 * n + l] = 1.0
                rows.append(r)
                labels.append(f"params[{l}]")
        else:
            off = 0 if name == "q0" else n
            for i in range(n):
                r = np.zeros(2 * n + k)
                r[off + i] = 1.0
                rows.append(r)
                labels.append(f"{name}[{i}]")
    if not rows:
        raise ValueError("`wrt` is empty (or 'params' with an empty `param_index`): nothing to "
                         "differentiate")
    return np.array(rows), labels


#: why a fixed parameter has no derivative, for the errors that name one
_FIXED = ("`Model.fixed_params`: data its callbacks read, such as an index, not a quantity; "
          "it has no derivative")


def param_indices(param_index, k: int, fixed=(), mass=()) -> list[int]:
    """The parameters to differentiate by: ``param_index`` checked against the ``k``
    parameters and the model's ``fixed`` ones, or (None) every parameter but those."""
    if param_index is None:
        return [l for l in range(k) if l not in fixed]
    idx = np.atleast_1d(np.asarray(param_index))
    if idx.size == 0:
        return []
    if idx.dtype.kind not in "iu" or idx.ndim != 1:
        raise TypeError(f"`param_index` must be a sequence of parameter indices, got {param_index!r}")
    out = []
    for i in idx:
        if not 0 <= i < k:
            raise ValueError(f"`param_index` entry {int(i)} is out of range for k = {k} parameters")
        if int(i) in out:
            raise ValueError(f"`param_index` lists parameter {int(i)} twice")
        if int(i) in fixed:
            raise ValueError(f"`param_index` names params[{int(i)}], which the model marks "
                             f"fixed ({_FIXED}); leave it out")
        out.append(int(i))
    named = [l for l in out if l in mass]
    if named:
        warnings.warn(valid.mass_params_warning(named, "`param_index` differentiates by"),
                      UserWarning, stacklevel=3)
    return out


def initial_tangent(run: Run, D: np.ndarray, initial_state=None):
    r"""The tangent vectors ``(δq0, δp0)`` (d, n) each of the raw directions ``D``
    (d, 2n + k) in ``(δq0, δv0, δθ)``: the derivative of the consistent initial state.

    With ``W = M⁻¹Gᵀ``, ``S = G W`` at ``(q0, v0)`` (the metric of the projection
    :func:`fastvi.integrate` applies to initial data)::

        δq* = δq − W S⁻¹ (G δq + g_θ δθ)
        δv* = δv − W S⁻¹ (G δv + H_v δq* + (G_θ v) δθ)
        δp* = M δv* + C_q δq* + (M_θ v) δθ

    ``initial_state(params) -> (q0, v0)``, if given, adds its own derivative by the
    parameters to ``(δq, δv)`` (five-point differences). Returns ``(dq, dp, pidx, dth)``
    with ``pidx`` the parameters some direction moves and ``dth`` (d, len(pidx)).
    :func:`initial_cotangent` is its transpose.
    """
    n = run.model.n
    dq, dv, dth_all = D[:, :n].copy(), D[:, n:2 * n].copy(), D[:, 2 * n:]
    pidx = [l for l in range(run.prm.shape[0]) if np.any(dth_all[:, l] != 0.0)]
    dth = dth_all[:, pidx]
    t = _start_parts(run, pidx, initial_state)
    for j in range(len(pidx) if t.dstate is not None else 0):
        dq += np.outer(dth[:, j], t.dstate[j, :n])
        dv += np.outer(dth[:, j], t.dstate[j, n:])
    if t.moved is not None:
        dq, dv = _moved_projection(t, dq, dv, dth)
    elif t.G.shape[0]:
        dq = dq - np.linalg.solve(t.S, t.G @ dq.T + t.g_th.T @ dth.T).T @ t.W.T
        dv = dv - np.linalg.solve(t.S, t.G @ dv.T + t.Hv @ dq.T + t.gv_th.T @ dth.T).T @ t.W.T
    dp = dv @ t.M.T + dq @ t.Cq.T + dth @ t.mv_th
    return np.ascontiguousarray(dq), np.ascontiguousarray(dp), pidx, np.ascontiguousarray(dth)


def initial_cotangent(run: Run, lq, lp, pidx, initial_state=None) -> np.ndarray:
    r"""``λᵀ ∂(q0*, p0*)/∂(q0, v0, θ_pidx)`` (2n + len(pidx),): the cotangent ``(λ_q, λ_p)``
    on the consistent initial state pulled back to the raw initial data and the
    parameters ``pidx`` — the transpose of :func:`initial_tangent` (its formulas read
    backwards), in O(m n) for a given ``S``'s factors instead of the ``(2n + k) × n``
    tangent: with ``a_v = Mᵀ λ_p``, ``b = S⁻ᵀ Wᵀ a_v``, ``c = λ_q + C_qᵀ λ_p − H_vᵀ b`` and
    ``e = S⁻ᵀ Wᵀ c``::

        λ_{q0} = c − Gᵀ e,    λ_{v0} = a_v − Gᵀ b,
        λ_θ = (M_θ v)ᵀ λ_p − (G_θ v)ᵀ b − g_θᵀ e
              (+ the derivative of ``initial_state(params)`` applied to (λ_{q0}, λ_{v0}))
    """
    t = _start_parts(run, pidx, initial_state)
    if t.moved is not None:
        return _moved_cotangent(t, lq, lp)
    av = t.M.T @ lp
    c = lq + t.Cq.T @ lp
    lth = t.mv_th @ lp
    if t.G.shape[0]:
        b = np.linalg.solve(t.S.T, t.W.T @ av)
        c = c - t.Hv.T @ b
        e = np.linalg.solve(t.S.T, t.W.T @ c)
        lq0, lv0 = c - t.G.T @ e, av - t.G.T @ b
        lth = lth - t.gv_th @ b - t.g_th @ e
    else:
        lq0, lv0 = c, av
    if t.dstate is not None:
        lth = lth + t.dstate @ np.concatenate([lq0, lv0])
    return np.concatenate([lq0, lv0, lth])


#: what :func:`initial_tangent` and :func:`initial_cotangent` read at the consistent start
#: (:func:`_start_parts`)
StartParts = namedtuple("StartParts", [
    "M", "G", "Hv", "Cq",  # :func:`_start_terms`
    "W", "S",  # M⁻¹Gᵀ and G W (None without constraints)
    # (len(pidx), m), (len(pidx), m), (len(pidx), n): the derivatives by each parameter in
    # pidx of g, G v (+ ∂g/∂t) and M v
    "g_th", "gv_th", "mv_th",
    "dstate",  # (len(pidx), 2n) that of initial_state(params) (None without it)
    "moved",  # a MovedStart where the projection moved the given start, else None
])


#: the terms of the derivative of the projection of a start off the constraints that the
#: move scales (:func:`_moved_start`), beside :class:`StartParts`
MovedStart = namedtuple("MovedStart", [
    "metric0",  # M̄ at the given q0, the metric of the positions' projection
    "B",  # M̄0 + Σ μ_c ∇²g_c at q*
    "Eq",  # (n, n) ∂(M̄(q0) w)/∂q0, w = q* − q0 (None for a constant definite mass)
    "Eth",  # (n, len(pidx)) ∂(M̄(q0) w + G(q*)ᵀ μ)/∂θ
    "metric",  # M̄ at q*, the metric of the velocities' projection
    "Cq",  # (n, n) ∂(M̄(q) a + G(q)ᵀ ν)/∂q at q*, a = v* − v0
    "Cth",  # (n, len(pidx)) the same by θ
])


def _start_parts(run: Run, pidx, initial_state) -> StartParts:
    """The :class:`StartParts` of ``run`` by the parameters ``pidx``: the derivatives by θ
    from the model's where it gives them (``constraint``; ``G v`` is zero for a declared
    ``constraint_jacobian=0``, a constant mass's ``M v`` always), else five-point
    differences of the callbacks."""
    model, prm, q0, v0 = run.model, run.prm, run.q0, run.v0
    n, m = model.n, model.m
    dstate = None
    if initial_state is not None and len(pidx):
        dstate = np.ascontiguousarray(
            _jacobian(lambda p: np.concatenate(_state_of(initial_state, p, n)), prm, pidx).T)
    M, G, Hv, Cq = _start_terms(run)
    kp = len(pidx)
    g_th, gv_th, mv_th = np.zeros((kp, m)), np.zeros((kp, m)), np.zeros((kp, n))

    def by_differences(f):
        return np.ascontiguousarray(_jacobian(f, prm, pidx).T)

    # the model's derivatives by θ where it gives them, as the linearised step takes them;
    # five-point differences of the callbacks elsewhere
    if m and kp:
        if "constraint" in model.param_derivatives:
            g_th = model.param_derivative_value("constraint", q0, v0, prm, run.t0)[list(pidx)]
        else:
            g_th = by_differences(lambda p: model.constraint_value(q0, p, run.t0))
        if ("constraint_jacobian" not in model.param_derivatives_zero
                or model.time_dependent):  # else G v is not a parameter's
            gv_th = by_differences(lambda p: model.constraint_jacobian_value(q0, p, run.t0) @ v0
                                   + model.constraint_time_derivative_value(q0, p, run.t0))
    if model.mass_matrix_constant is None and kp:  # a constant mass is not a parameter's
        if "mass" in model.param_derivatives:  # the model's ∂M/∂θ, as the steps take it
            mv_th = model.param_derivative_value("mass", q0, params=prm)[list(pidx)] @ v0
        else:
            mv_th = by_differences(lambda p: model.mass_matrix(q0, p) @ v0)
    W = S = None
    if m:
        # a large mechanism's constant diagonal mass: M⁻¹Gᵀ by its reciprocals, O(m n); a
        # singular one projects in the metric M̄ = M + Gᵀ W G, as valid.initial_state does
        diagonal = run.ws.structured and lay.reciprocal_mass.py_func(run.model_data.flags)
        W = G.T / np.diag(M)[:, None] if diagonal else np.linalg.solve(M, G.T)
        S = G @ W
    moved = None if run.raw_start is None else _moved_start(run, pidx, G, S)
    if model.mass_singular:  # p0 = M v0 itself: its derivative M δv0 has no C_q term
        M, Cq = model.mass_matrix_constant, np.zeros((n, n))
    return StartParts(M, G, Hv, Cq, W, S, g_th, gv_th, mv_th, dstate, moved)


def _jacobian(f, x: np.ndarray, idx) -> np.ndarray:
    """``∂f/∂x_j`` for ``j`` in ``idx``, as columns, by :func:`theta_derivative`'s rule."""
    cols = [np.asarray(theta_derivative(f, x, j), dtype=float) for j in idx]
    return np.stack(cols, axis=1) if cols else np.zeros((np.asarray(f(x)).shape[0], 0))


def _moved_start(run: Run, pidx, G, S) -> MovedStart:
    r"""The terms of the derivative of the projection of a given start ``(q0, v0)`` off the
    constraints that its move scales (:func:`fastvi._validate.initial_state`).

    The positions' projection ``q*`` solves ``M̄0 (q* − q0) + G(q*)ᵀ μ = 0``,
    ``g(q*) = 0`` with ``M̄0 = M̄(q0)``; the velocities' ``v*`` solves
    ``M̄(q*) (v* − v0) + G(q*)ᵀ ν = 0``, ``G(q*) v* + g_t = 0``. Their derivatives by the
    implicit function theorem carry, beside the linearised projection of a consistent
    start, the terms in ``μ``, ``ν``, ``w = q* − q0`` and ``a = v* − v0``: all of the size
    of the move, so five-point differences of the callbacks give them to round-off of the
    derivative."""
    model, prm, t0 = run.model, run.prm, run.t0
    q0, v0 = run.raw_start
    qs, vs = run.q0, run.v0
    n = model.n
    every = range(n)

    def metric(q, p):
        return valid.mass_metric(model.mass_matrix(q, p), model.constraint_jacobian_value(q, p, t0))

    def gt_mul(q, p, y):
        return model.constraint_jacobian_value(q, p, t0).T @ y

    metric0 = metric(q0, prm)
    w = qs - q0
    W0 = np.linalg.solve(metric0, G.T)
    mu = -np.linalg.solve(G @ W0, G @ w)
    B = metric0 + _jacobian(lambda q: gt_mul(q, prm, mu), qs, every)
    moving_metric = model.mass_matrix_constant is None or model.mass_singular
    Eq = _jacobian(lambda q: metric(q, prm) @ w, q0, every) if moving_metric else None
    Eth = _jacobian(lambda p: metric(q0, p) @ w + gt_mul(qs, p, mu), prm, pidx)
    a = vs - v0
    nu = -np.linalg.solve(S, G @ a)
    Cq = _jacobian(lambda q: metric(q, prm) @ a + gt_mul(q, prm, nu), qs, every)
    Cth = _jacobian(lambda p: metric(qs, p) @ a + gt_mul(qs, p, nu), prm, pidx)
    return MovedStart(metric0, B, Eq, Eth, metric(qs, prm), Cq, Cth)


def _moved_projection(t: StartParts, dq, dv, dth):
    r"""``(δq*, δv*)`` (d, n) of the raw directions ``(δq, δv, δθ)`` (rows) through the
    projection of a start it moved (:class:`MovedStart`)::

        u   = B⁻¹ (M̄0 δq − E_q δq − E_θ δθ),    W_B = B⁻¹ Gᵀ,  S_B = G W_B
        δq* = u − W_B S_B⁻¹ (G u + g_θ δθ)
        δv' = δv − M̄⁻¹ (C_q δq* + C_θ δθ)
        δv* = δv' − W S⁻¹ (G δv' + H_v δq* + (G_θ v) δθ)

    which is :func:`initial_tangent`'s for a consistent start, where ``B = M̄0 = M̄`` and
    the ``E`` and ``C`` terms vanish."""
    ms = t.moved
    rhs = dq @ ms.metric0.T - dth @ ms.Eth.T
    if ms.Eq is not None:
        rhs -= dq @ ms.Eq.T
    u = np.linalg.solve(ms.B, rhs.T).T
    WB = np.linalg.solve(ms.B, t.G.T)
    dq = u - np.linalg.solve(t.G @ WB, t.G @ u.T + t.g_th.T @ dth.T).T @ WB.T
    dv = dv - np.linalg.solve(ms.metric, ms.Cq @ dq.T + ms.Cth @ dth.T).T
    dv = dv - np.linalg.solve(t.S, t.G @ dv.T + t.Hv @ dq.T + t.gv_th.T @ dth.T).T @ t.W.T
    return dq, dv


def _moved_cotangent(t: StartParts, lq, lp) -> np.ndarray:
    """:func:`initial_cotangent` through the projection of a moved start: the transpose of
    :func:`_moved_projection`, applied as the Jacobian it gives on the unit directions
    (O(n³), for a start that was off the constraints only)."""
    n, kp = t.M.shape[0], t.mv_th.shape[0]
    eye = np.eye(2 * n + kp)
    dq, dv = _moved_projection(t, eye[:, :n], eye[:, n:2 * n], eye[:, 2 * n:])
    dp = dv @ t.M.T + dq @ t.Cq.T + eye[:, 2 * n:] @ t.mv_th
    out = dq @ lq + dp @ lp
    if t.dstate is not None:
        out[2 * n:] += t.dstate @ out[:2 * n]
    return out


def _start_terms(run: Run):
    """``(M, G, H_v, C_q)`` at the run's consistent start (:func:`.kernels.tangent.point`),
    ``H_v = ∂(G v)/∂q``. Where the linearised step takes ``H_v`` by groups of constraints
    that share no coordinate (``run.sparsity``, :func:`fastvi.structure.linearisation_patterns`),
    so does the start, for a model with an exact constraint Hessian, a constant mass and
    no time in its constraints (:func:`_rate_jacobian`): ``point`` takes one Hessian a
    constraint, O(m n²)."""
    model, q0, v0 = run.model, run.q0, run.v0
    if not (run.sparsity.gsta.shape[0] > 0 and "constraint_hessian" in model.callbacks
            and not model.time_dependent and model.mass_matrix_constant is not None):
        # at t0 itself: the adjoint pulls its cotangent back to the start after the sweep
        M, G, _, Hv, Cq = point_terms(data_at(run, run.t0), q0, v0, np.zeros(model.m))
        return M, G, Hv, Cq
    M = model.mass_matrix(q0, run.prm)
    G = model.constraint_jacobian_value(q0, run.prm, run.t0)
    return M, G, _rate_jacobian(model, run.sparsity, run.prm, q0, v0), np.zeros((model.n, model.n))


def _rate_jacobian(model: Model, sp, prm, q, v):
    """``∂(G v)/∂q`` (m, n), row c ``(∇²g_c v)ᵀ``, by the groups of the :class:`Sparsity`
    ``sp`` (constraints whose patterns share no coordinate), as the linearised step's
    ``_grouped_hv``: one Hessian of ``Σ_{c in the group} g_c`` a group, whose rows on
    constraint c's own coordinates are ``∇²g_c``'s."""
    Hv = np.zeros((model.m, model.n))
    for k in range(sp.gsta.shape[0] - 1):
        rows = sp.grow[sp.gsta[k]:sp.gsta[k + 1]]
        eta = np.zeros(model.m)
        eta[rows] = 1.0
        H = model.callback_value("constraint_hessian", q, eta, params=prm)
        for c in rows:
            a = sp.gcol[sp.gptr[c]:sp.gptr[c + 1]]
            Hv[c, a] = H[np.ix_(a, a)] @ v[a]
    return Hv


def checked_initial_state(initial_state):
    """``initial_state`` (None or a callable ``params -> (q0, v0)``), or a TypeError that
    names it, before any run."""
    if initial_state is not None and not callable(initial_state):
        raise TypeError(f"`initial_state` must be a function `initial_state(params) -> (q0, v0)` "
                        f"(or None), got {type(initial_state).__name__}")
    return initial_state


def _state_of(initial_state, p, n):
    out = initial_state(p)
    if not (isinstance(out, (tuple, list)) and len(out) == 2):
        raise TypeError(f"`initial_state(params)` must return a pair (q0, v0), got "
                        f"{type(out).__name__}" + (f" of length {len(out)}"
                                                   if isinstance(out, (tuple, list)) else ""))
    q, v = out
    return valid.vector(q, "initial_state(params)[0]", n), valid.vector(v, "initial_state(params)[1]", n)


def momentum_mass(model, q, prm, t=0.0) -> np.ndarray:
    """The matrix of ``p = M v`` on the constraints, as the linearised step reads it:
    ``M(q, θ)``, or for a singular constant ``M`` the definite ``M̄ = M + Gᵀ W G``
    (:func:`.kernels.linalg.augmented_mass`), equal to it where ``G v = 0``
    (:func:`momentum` where the constraints move)."""
    M = model.mass_matrix(q, prm)
    if not model.mass_singular:
        return M
    return valid.mass_metric(M, model.constraint_jacobian_value(q, prm, t))


def _rate_shift(model, q, prm, t):
    """``Gᵀ W g_t`` of a singular constant mass (zero for fixed constraints): on the
    constraints ``M v = M̄ v + Gᵀ W g_t``."""
    if not (model.mass_singular and model.time_dependent):
        return 0.0
    M = model.mass_matrix_constant
    G = model.constraint_jacobian_value(q, prm, t)
    w = np.zeros(model.m)
    augment_weights(M, np.ascontiguousarray(G), w, model.n, model.m)
    return G.T @ (w * model.constraint_time_derivative_value(q, prm, t))


def momentum(model, q, v, prm, t=0.0) -> np.ndarray:
    """``p`` of ``(q, v)`` as the linearised step reads it on the constraints:
    ``M(q, θ) v``, or for a singular constant ``M`` the smooth ``M̄ v + Gᵀ W g_t``, equal to
    ``M v`` where ``G v + g_t = 0`` (its derivatives by ``q`` and ``θ`` are those of the
    projection of :mod:`.kernels.tangent`)."""
    return momentum_mass(model, q, prm, t) @ v + _rate_shift(model, q, prm, t)


def data_at(run, t):
    """The model's kernel data at time ``t``, for :func:`.kernels.tangent.point_terms`: the
    run's own for a model without time (the run's carries the time its steps last set)."""
    return run.model.kernel_data(run.prm, t) if run.model.time_dependent else run.model_data


def velocity(model, q, p, prm, t=0.0) -> np.ndarray:
    """The inverse of :func:`momentum` at ``q``."""
    return np.linalg.solve(momentum_mass(model, q, prm, t), p - _rate_shift(model, q, prm, t))


#: the bytes of the terms of the samples one call of :func:`.kernels.tangent.sample_terms`
#: computes: on a long run they are taken a chunk at a time
_SAMPLE_BYTES = 32 * 2**20


def sample_terms_by_chunk(model, prm, result, by_theta=0):
    """``(start, Ms, Gs, Hvs, Cqs)`` over consecutive chunks of the samples of ``result``:
    ``M``, ``G``, ``H_v`` and ``C_q`` of the linearised step's projection
    (:func:`.kernels.tangent.point`) at each sample, from ``start`` on; chunks small enough
    for ``by_theta`` more (n,) vectors a sample too (:func:`momentum_by_theta`)."""
    K, n = result.q.shape
    m = model.m
    chunk = max(1, _SAMPLE_BYTES // (8 * n * (3 * n + 2 * m + by_theta)))
    md = model.kernel_data(prm, float(result.t[0]))  # its own: the loop sets its time
    for i0 in range(0, K, chunk):
        i1 = min(K, i0 + chunk)
        yield (i0, *sample_terms(md, result.q[i0:i1], result.v[i0:i1], result.t[i0:i1], m))


def momentum_by_theta(model, prm, result, start, stop, pidx) -> np.ndarray:
    """``∂p/∂θ_l`` (``p`` the :func:`momentum`) at the samples ``start … stop − 1`` of
    ``result``, (stop − start, len(pidx), n): ``(∂M/∂θ_l) v`` from the model's derivative of
    its mass function by θ where it gives one, as the linearised step takes it, else
    :func:`theta_derivative`'s rule, sample by sample the same arithmetic, with the masses
    of each point in θ in one compiled loop (:func:`.kernels.tangent.sample_masses`)."""
    q, v, t = result.q[start:stop], result.v[start:stop], result.t[start:stop]
    if "mass" in model.param_derivatives and not model.mass_singular:
        dM = _mass_by_theta(model, prm, q, t)[:, list(pidx)]
        return np.matmul(dM, v[:, None, :, None])[..., 0]
    out = np.zeros((stop - start, len(pidx), model.n))
    for c, l in enumerate(pidx):
        points, scale = _theta_stencil(prm, l)
        for p, wgt in points:
            Mv = _stacked(sample_masses(model.kernel_data(p, float(t[0])), q, t, model.m), v)
            out[:, c] += wgt * (Mv + _rate_shifts(model, q, p, t))
        out[:, c] /= scale
    return out


def _mass_by_theta(model, prm, q, t) -> np.ndarray:
    """``∂M/∂θ`` (K, k, n, n) at the samples ``q[i]``: the model's derivative of ``mass`` by
    θ (:meth:`fastvi.Model.param_derivative_value`'s) at every sample in one compiled loop
    (:func:`.kernels.tangent.sample_callback`, given the derivatives by θ in place of the
    callbacks)."""
    md = model.kernel_data(prm, float(t[0]))
    by_theta = md._replace(fns=model.param_derivative_data().fns)
    n = model.n
    return sample_callback(by_theta, lay.PARAM_SLOTS.index("mass"), q, t,
                           (model.params.shape[0], n, n))


def _rate_shifts(model, q, prm, t):
    """:func:`_rate_shift` at every sample ``(q[i], t[i])`` ((K, n), or 0.0 where it
    vanishes): ``G`` and ``g_t`` at every sample in compiled loops, and the weights of
    :func:`.kernels.linalg.augment_weights` in its own order of sums over a whole chunk."""
    if not (model.mass_singular and model.time_dependent):
        return 0.0
    md = model.kernel_data(prm, float(t[0]))
    return _shifts_of(model, sample_callback(md, lay.CJAC, q, t, (model.m, model.n)),
                      _constraint_rates(model, md, q, t))


def _shifts_of(model, G, gt):
    """:func:`_rate_shifts` from ``G`` (K, m, n) and ``g_t`` (K, m) at the samples."""
    n = model.n
    M = model.mass_matrix_constant
    gamma = min(M[a, a] for a in range(n) if M[a, a] > 0.0) * AUGMENT_SCALE
    norm2 = np.zeros(G.shape[:2])
    for a in range(n):
        norm2 += G[:, :, a] * G[:, :, a]
    w = np.divide(gamma, norm2, out=np.zeros_like(norm2), where=norm2 != 0.0)
    return _stacked(G.transpose(0, 2, 1), w * gt)


def constraints_by_theta(model, prm, result, start, stop, pidx):
    """``(∂g/∂θ_l, ∂(G v + g_t)/∂θ_l)`` at the samples ``start … stop − 1`` of ``result``,
    two (stop − start, len(pidx), m) arrays, ``v`` the :func:`velocity` of the sample's
    ``(q, p)`` at each θ: :func:`theta_derivative`'s rule, with the callbacks at every
    sample in one compiled loop a point in θ (:func:`.kernels.tangent.sample_callback`)."""
    q, p, t = result.q[start:stop], result.p[start:stop], result.t[start:stop]
    n, m = model.n, model.m
    gth = np.zeros((stop - start, len(pidx), m))
    hth = np.zeros_like(gth)
    for c, l in enumerate(pidx):
        points, scale = _theta_stencil(prm, l)
        for th, wgt in points:
            md = model.kernel_data(th, float(t[0]))
            # G and g_t at θ once: the velocity's shift (a singular mass whose constraints
            # move) and the rate of the hidden constraint both read them
            G = sample_callback(md, lay.CJAC, q, t, (m, n))
            gt = _constraint_rates(model, md, q, t)
            shift = _shifts_of(model, G, gt) if model.mass_singular and model.time_dependent else 0.0
            v = np.linalg.solve(sample_masses(md, q, t, m), (p - shift)[..., None])[..., 0]
            gth[:, c] += wgt * sample_callback(md, lay.CON, q, t, (m,))
            hth[:, c] += wgt * (_stacked(G, v) + gt)
        gth[:, c] /= scale
        hth[:, c] /= scale
    return gth, hth


def _constraint_rates(model, md, q, t):
    """``g_t = ∂g/∂t`` at the samples ``(q[i], t[i])`` (K, m):
    :meth:`fastvi.Model.constraint_time_derivative_value`'s rule at every sample."""
    K, m = q.shape[0], model.m
    if not model.time_dependent:
        return np.zeros((K, m))
    if "constraint_time_derivative" in model.callbacks:
        return sample_callback(md, lay.GT, q, t, (m,))
    dt = lay.FD_T * np.maximum(1.0, np.abs(t))
    out = np.zeros((K, m))
    for at, weight in lay.FD_T_POINTS:
        out += weight * sample_callback(md, lay.CON, q, t + at * dt, (m,))
    return out * (1.0 / (12.0 * dt))[:, None]


def _stacked(A, x):
    """``A[i] @ x[i]`` for a stack of matrices ``A`` (K, r, c) and vectors or matrices ``x``
    (K, c) or (K, c, d)."""
    return np.matmul(A, x[..., None])[..., 0] if x.ndim == 2 else np.matmul(A, x)


def velocity_derivatives(run, result, dq, dp, pidx, dth):
    """``δv = M⁻¹ (δp − C_q δq − (∂p/∂θ) δθ)`` at every sample, ``p`` the :func:`momentum` of
    ``(q, v)`` (which depends on ``q`` and ``θ`` through ``G`` for a singular constant mass)."""
    model = run.model
    if model.mass_matrix_constant is not None and not model.mass_singular:
        return np.linalg.solve(model.mass_matrix_constant, dp)
    dv = np.empty_like(dp)
    for start, Ms, _, _, Cqs in sample_terms_by_chunk(model, run.prm, result, len(pidx)):
        s = slice(start, start + len(Ms))
        Pth = momentum_by_theta(model, run.prm, result, s.start, s.stop, pidx)
        rhs = dp[s] - _stacked(Cqs, dq[s])
        for c in range(len(pidx)):
            rhs -= Pth[:, c, :, None] * dth[:, c]
        dv[s] = np.linalg.solve(Ms, rhs)
    return dv


# ----------------------------------------------------------------------------- the result
def finish(run: Run, status: int, loop_time: float, extra_compile: float, what: str) -> Result:
    """The :class:`fastvi.Result` of the run (its samples up to the last good step), judged
    by the reliability monitor like :func:`fastvi.integrate`'s; raises
    :class:`fastvi.IntegrationError` where the run or its derivative failed, naming ``what``."""
    info, model = run.info, run.model
    out = _filled(run.smp, int(info[lay.I_SLOT]))
    st = Status(status) if status <= 0 else Status.SUCCESS
    wall = time.perf_counter() - run.started
    result = Result(
        t=out.t, q=out.q, v=out.v, p=out.p, energy=out.energy,
        work=out.work if model.timed else None, work_forces=out.work_forces if model.timed else None,
        constraint_residual=out.g, velocity_residual=out.gv, newton_iterations=out.iters,
        stats=dict(steps=int(info[lay.I_STEPS]), newton_iterations=int(info[lay.I_ITERS]),
                   max_residual=float(info[lay.I_MAXRES]), full_newton_steps=int(info[lay.I_FULL]),
                   recovered_steps=[], integration_time=loop_time, setup_time=wall - loop_time,
                   compile_time=run.compile_time + extra_compile, check_time=run.check_time,
                   wall_time=wall),
        status=st, method=run.meth, h=run.h, model_name=model.name,
        failed_step=None if st >= 0 else int(info[lay.I_FAILED]))
    if st < 0:
        k = int(info[lay.I_FAILED])
        raise IntegrationError(st, k, run.t0 + k * run.h, float(info[lay.I_RES]), result,
                               f"{what} is not defined from this step on")
    if run.monitor:
        verdict = monitor_.judge(result, every=run.every, newton_tol=run.opts.tol)
        result.stats.update(monitor_.stats(verdict))
        if not verdict.ok:
            result, k, t_fail, detail = monitor_.cut(result, verdict, every=run.every)
            raise IntegrationError(Status.UNRELIABLE, k, t_fail, float("nan"), result, detail)
    return result
