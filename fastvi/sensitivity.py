r"""Forward sensitivities of the discrete flow: :func:`sensitivity`, :func:`tangent_space`.

The derivatives are those of the map the integrator computes — the composition of its
steps, each differentiated at its converged Newton solution — not of the differential
equations: exact up to round-off for the trajectory :func:`fastvi.integrate` returns
(``docs/sensitivities.md``).
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from . import _discrete as disc
from . import _validate as valid
from .kernels.tangent import differentiator, point_terms, run_tangent
from ._launch import Launcher
from ._numba import quiet
from .kernels import layout as lay
from .progress import UPDATES, ProgressBar
from .results import (Result, ResultBase, SavedResult, finish_figure, matching_model,
                      new_figure, residual_panel, result_arrays, result_from, run_items,
                      run_text, timing)

__all__ = ["sensitivity", "SensitivityResult", "tangent_space"]

#: the time loop, called through its compiled entry points (no per-call typing: _launch.py)
_RUN_TANGENT = Launcher(run_tangent)


@dataclass(repr=False)
class SensitivityResult(SavedResult, ResultBase):
    """The trajectory of :func:`sensitivity` and its derivatives at the saved steps.

    :meth:`save` writes it to one ``.npz`` file and :meth:`load` reads it back, bit for bit
    (``load(path, model=model)`` for :meth:`tangent_residual`); :meth:`summary` gives one
    line of what to check first.

    Attributes
    ----------
    result : Result
        The trajectory, equal bit for bit to :func:`fastvi.integrate`'s with the same
        arguments.
    t : ndarray (K,)
        The times of the samples (``result.t``).
    dq, dv, dp : ndarray (K, n, d)
        ``dq[i, :, j]``: the derivative of ``q(t_i)`` along direction ``j`` (``labels[j]``),
        and likewise of ``v(t_i)`` and ``p(t_i)``. For ``wrt=("q0", "v0", "params")`` the
        directions are the unit vectors of the raw inputs, so ``dq[i]`` is the Jacobian
        ``∂q(t_i)/∂(q0, v0, θ)`` (n, 2n + len(param_index)).
    labels : list of str
        What each direction perturbs: ``"q0[a]"``, ``"v0[a]"``, ``"params[l]"`` or
        ``"direction[j]"``.
    params : ndarray (k,)
        The parameters of the run.
    status : Status
        The run's (``result.status``); ``success`` and ``message`` as :class:`fastvi.Result`.
    """

    result: Result
    t: np.ndarray
    dq: np.ndarray
    dv: np.ndarray
    dp: np.ndarray
    labels: list
    params: np.ndarray
    _dth: np.ndarray = field(repr=False, default=None)
    _pidx: list = field(repr=False, default_factory=list)
    _model: object = field(repr=False, default=None)

    @property
    def status(self):
        """The status of the run (:attr:`fastvi.Result.status` of :attr:`result`)."""
        return self.result.status

    def _repr_items(self) -> list[str]:
        return [*run_items(self.result), f"samples={self.t.shape[0]}",
                f"directions={len(self.labels)}", f"status={self._status_text()}"]

    def summary(self) -> str:
        """One line with the figures a user checks first: the run, the number of samples and
        of directions (by what they perturb), the status, the time, and the largest entry of
        the last sample's Jacobian ``∂q(t_K)/∂(directions)``."""
        return (f"{self.result.model_name}: sensitivity, {run_text(self.result)}, "
                f"{self.t.shape[0]} samples × {directions_text(self.labels)}, "
                f"status {self._status_text()}, {timing(self.result.stats)}, "
                f"max |∂q(t_end)| = {largest_last(self.dq):.3e}")

    def _arrays(self) -> dict:
        return sensitivity_arrays(self)

    @classmethod
    def _from_stored(cls, stored, model) -> "SensitivityResult":
        return sensitivity_from(stored, model=model, cls=cls)

    def tangent_residual(self):
        r"""How far each sample's derivatives are from the tangent space of the constraints:
        ``(g, gv)`` (K,), the max-norms over the directions of the linearised constraint
        ``G δq + g_θ δθ`` and of the linearised hidden constraint
        ``H_v δq + G M⁻¹ (δp − C_q δq) + (∂(G M⁻¹ p)/∂θ) δθ``. At round-off for a
        consistent start: the linearised step maps tangent vectors to tangent vectors.

        Raises
        ------
        ValueError
            The result was read by :meth:`load` without ``model=``: it needs the model's
            constraints.
        """
        if self._model is None:
            raise ValueError("`tangent_residual()` needs the model of the run, which a file does "
                             "not hold: read the result with `SensitivityResult.load(path, "
                             "model=model)`, the model built as for the run")
        model, prm = self._model, self.params
        K = self.t.shape[0]
        g, gv = np.zeros(K), np.zeros(K)
        if model.m == 0:
            return g, gv
        res, pidx = self.result, self._pidx
        for start, Ms, Gs, Hvs, Cqs in disc.sample_terms_by_chunk(model, prm, res):
            s = slice(start, start + len(Ms))
            dq, dp = self.dq[s], self.dp[s]
            lin_g = Gs @ dq
            lin_h = Hvs @ dq + Gs @ np.linalg.solve(Ms, dp - Cqs @ dq)
            if pidx:
                gth, hth = disc.constraints_by_theta(model, prm, res, s.start, s.stop, pidx)
                for c in range(len(pidx)):
                    lin_g += gth[:, c, :, None] * self._dth[:, c]
                    lin_h += hth[:, c, :, None] * self._dth[:, c]
            g[s] = np.abs(lin_g).max(axis=(1, 2))
            gv[s] = np.abs(lin_h).max(axis=(1, 2))
        return g, gv

    def plot(self, path=None, *, directions=None):
        r"""How each direction grows along the run, and how far it stays from the tangent
        space of the constraints (needs matplotlib).

        The first two panels draw, for each direction ``j``, the Euclidean norms
        ``‖∂q(t_i)/∂x_j‖`` and ``‖∂p(t_i)/∂x_j‖`` on a log axis: on chaotic motion they grow
        as ``exp(λ t)``, with ``λ`` the largest Lyapunov exponent
        (:func:`fastvi.lyapunov_spectrum`). The third draws :meth:`tangent_residual` relative
        to the largest entry of the derivatives at each sample, at round-off for a
        consistent start; it needs the model and is left out for a result read by
        :meth:`load` without ``model=``, or a model without constraints.

        Parameters
        ----------
        path : str or path-like, optional
            Save the figure there (PNG, PDF, … by extension), on its own canvas: the
            process's matplotlib backend is never changed.
        directions : sequence of int or str, optional
            The directions to draw, by index or by label (``"q0[1]"``, ``"params[5]"``;
            :attr:`labels`). Default: every one.

        Returns
        -------
        matplotlib.figure.Figure
        """
        chosen = self._chosen(directions)
        model = self._model
        residuals = model is not None and model.m > 0
        fig = new_figure(path, figsize=(7, 7.5 if residuals else 5.0))
        axes = fig.subplots(3 if residuals else 2, 1, sharex=True)
        for ax, d, name in ((axes[0], self.dq, "q"), (axes[1], self.dp, "p")):
            for j in chosen:
                norm = np.linalg.norm(d[:, :, j], axis=1)
                # an exact 0 (a direction that does not move q at the start) has no log
                ax.semilogy(self.t, np.where(norm > 0, norm, np.nan), lw=0.8,
                            label=self.labels[j])
            ax.set_ylabel(f"‖∂{name}(t)/∂x‖")
            if len(chosen) <= 12:
                ax.legend(fontsize="small", ncol=min(len(chosen), 4), loc="upper left")
        if residuals:
            g, gv = self.tangent_residual()
            # the derivatives grow as exp(λ t) on chaotic motion, and their round-off with them
            scale = np.maximum(1.0, np.maximum(np.abs(self.dq).max(axis=(1, 2)),
                                               np.abs(self.dp).max(axis=(1, 2))))
            residual_panel(axes[2], self.t, {"linearised g": g / scale,
                                             "linearised hidden": gv / scale})
            axes[2].set_ylabel("residual / max|∂x|")
        axes[-1].set_xlabel("t")
        axes[0].set_title(f"{self.result.model_name}: sensitivity\n{run_text(self.result)}",
                          fontsize="medium")
        fig.tight_layout()
        return finish_figure(fig, path)

    def _chosen(self, directions) -> list[int]:
        """The indices of ``directions`` (indices or labels) into :attr:`labels`."""
        d = len(self.labels)
        if directions is None:
            return list(range(d))
        if isinstance(directions, (str, int, np.integer)):
            directions = [directions]
        chosen = []
        for x in directions:
            if isinstance(x, str):
                if x not in self.labels:
                    raise ValueError(f"`directions`: no direction is labelled {x!r}; the "
                                     f"labels are {self.labels}")
                chosen.append(self.labels.index(x))
            elif isinstance(x, (int, np.integer)) and -d <= int(x) < d:
                chosen.append(int(x) % d)
            else:
                raise ValueError(f"`directions` entries must be labels or indices from {-d} to "
                                 f"{d - 1} of the {d} directions, got {x!r}")
        if not chosen:
            raise ValueError("`directions` is empty: name at least one direction to draw")
        return chosen


def sensitivity(model, q0, v0, *, h: float, t_end: float | None = None,
                n_steps: int | None = None, t0: float = 0.0, t_span=None,
                method="P2L-Q3G", wrt=("q0", "v0"), param_index=None, initial_state=None,
                params=None, save_every: int = 1, tol: float = valid.DEFAULT_TOL,
                max_iter: int = valid.DEFAULT_MAX_ITER, newton: str = "auto",
                solver: str = "auto", check: bool = True, monitor: bool = True,
                progress: bool = False, specialize: bool | None = None,
                **unsupported) -> SensitivityResult:
    r"""Integrate like :func:`fastvi.integrate` and propagate derivatives along the run.

    Each step solves ``R(X; q_k, p_k, θ) = 0`` for its unknowns ``X`` and reads off
    ``(q_{k+1}, p_{k+1})``; at the converged ``X`` its derivative along
    ``(δq_k, δp_k, δθ)`` solves

    .. math::

        K\,\delta X = -\left(R_q\,\delta q_k + R_p\,\delta p_k + R_\theta\,\delta\theta\right),
        \qquad K = \partial R/\partial X,

    with one LU factorisation of the exact Newton matrix ``K`` per step and one solve per
    direction, followed by the derivative of ``q_{k+1} = q_k + ΔQ^s`` and of the end
    projection of the momentum (``docs/sensitivities.md``). These are the exact derivatives
    of the discrete map — of the numbers this function returns — not of the differential
    equations: they differ from the latter by the method's error, ``O(h^{2s})``.

    What a perturbation of the initial state means: the run starts from the consistent
    state that :func:`fastvi.integrate` makes of ``(q0, v0)`` — their projection onto
    ``g(q) = 0``, ``G(q) v = 0`` in the metric of ``M`` — so a raw perturbation
    ``(δq0, δv0, δθ)`` acts through the derivative of that projection:

    .. math::

        \delta q^* = \delta q - W S^{-1}(G\,\delta q + g_\theta\,\delta\theta),\qquad
        \delta v^* = \delta v - W S^{-1}(G\,\delta v + H_v\,\delta q^* + (G_\theta v)\,\delta\theta),

    ``W = M⁻¹Gᵀ``, ``S = G W``, ``H_v = ∂(G v)/∂q``: a tangent vector of the constrained
    phase space (the parameters may move the constraints: a rod length). The columns for
    ``q0`` and ``v0`` therefore have rank ``n − m`` each. These are the formulas at a
    consistent start; a start that the projection moves (by up to ``1e-6``, with a
    warning) is the nearest point in the metric of ``M`` at ``q0``, and its derivative
    also carries the terms of the size of the move (``docs/sensitivities.md``, "What a
    perturbation of the initial state means").

    Parameters
    ----------
    model, q0, v0, h, t_end, n_steps, t0, t_span, method, params, save_every, tol, max_iter, newton, solver, check, monitor, progress :
        As :func:`fastvi.integrate`. The run must be a whole number of steps of ``h``.
    **unsupported :
        ``events``, ``adaptive``, ``recover``, ``on_failure``, ``dense_output`` and
        ``t_eval`` of :func:`fastvi.integrate` raise ``TypeError`` saying why (an event
        makes the flow non-smooth; a recovered step changes the map; the step-size
        controller is not differentiated).
    specialize : bool or None, default None
        Compile the linearised step (with the step's stages, as in
        :func:`fastvi.integrate`) for this model's and method's sizes as compile-time
        constants. The derivatives are the generic kernels' bit for bit; a step of the
        double pendulum with one direction costs about 0.75× as much
        (``docs/decisions/0021-sized-linearised-step.md``). The price is one compile per
        size, about as long as the first generic one (``docs/benchmarks.md``), then cached
        on disk. ``None`` uses the sized step whenever it is compiled already (in this
        process or on disk) and compiles it for a run of at least
        ``fastvi.structure.SIZED_TANGENT_MIN_STEPS`` steps of a model of at most
        ``SIZED_MAX_N`` coordinates. ``True`` always compiles it, ``False`` never uses it.
        :func:`fastvi.adjoint` and :func:`fastvi.sensitivity_ensemble` take the same
        option.
    wrt : sequence of {"q0", "v0", "params"}, or array (2n + k, d), default ("q0", "v0")
        The directions: the unit vectors of ``q0`` (n), ``v0`` (n) and the parameters of
        ``param_index``, in the order named; or the columns of an array of raw directions
        ``(δq0, δv0, δθ)`` (all ``k`` parameters).
    param_index : sequence of int, optional
        The parameters of ``"params"`` (default: all ``k`` but ``model.fixed_params``, which
        cannot be named). Parameters are the entries of the parameter vector the model's
        callbacks read; a constant mass matrix is not one.
    initial_state : callable, optional
        ``initial_state(params) -> (q0, v0)``: where the initial state itself depends on the
        parameters (initial angles of rods whose lengths are fitted). Its derivative, by
        five-point differences, joins the parameters' directions. ``q0, v0`` should be its
        value at ``params``.

    Returns
    -------
    SensitivityResult
        ``result`` (the :class:`fastvi.Result`), and ``dq``, ``dv``, ``dp`` (K, n, d) at
        the saved steps.

    Raises
    ------
    fastvi.IntegrationError
        A step failed, or its Newton matrix is singular at the solution (the discrete flow
        has no derivative there): the partial result is attached; no NaN is returned.

    Notes
    -----
    Cost: one linearisation a step (an assembly of the exact Newton matrix, about twice the
    size of the step's, an LU factorisation, the second derivatives of the projection) and
    one solve per direction; each parameter moved adds one direction and, for a model
    without derivatives by θ (``Model(param_derivatives=...)``), four residual evaluations a
    step (its five-point difference). See ``docs/sensitivities.md`` for measured costs.

    References
    ----------
    J. M. Sanz-Serna, Symplectic Runge–Kutta schemes for adjoint equations, automatic
    differentiation, optimal control, and more, SIAM Review 58 (2016) 3–33.

    Examples
    --------
    >>> import numpy as np, fastvi
    >>> dp = fastvi.scenes.double_pendulum()
    >>> q0, v0 = dp.initial_state(0.5, 0.3)
    >>> sens = fastvi.sensitivity(dp, q0, v0, h=0.01, n_steps=100, wrt=("q0", "v0"))
    >>> sens.dq.shape                     # 101 samples, n = 4, 2n = 8 directions
    (101, 4, 8)
    """
    disc.refuse(unsupported, "fastvi.sensitivity")
    progress = valid.flag(progress, "progress")
    initial_state = disc.checked_initial_state(initial_state)
    # checked before the run: a bad `wrt` is reported without compiling or integrating
    D, labels = disc.directions(wrt, disc.checked_model(model).n, model.params.shape[0],
                                param_index, model.fixed_params, model.mass_params)
    if initial_state is not None and not np.any(D[:, 2 * model.n:]):
        raise ValueError("`initial_state` gives the start's dependence on the parameters, but no "
                         "direction of `wrt` moves a parameter: add 'params' to `wrt`, or drop "
                         "`initial_state`")
    run = disc.prepare(model, q0, v0, h=h, t_end=t_end, n_steps=n_steps, t0=t0, t_span=t_span,
                       method=method, save_every=save_every, tol=tol, max_iter=max_iter,
                       newton=newton, params=params, solver=solver, check=check,
                       monitor=monitor, what="the sensitivity", specialize=specialize)
    n = model.n
    dq0, dp0, pidx, dth = disc.initial_tangent(run, D, initial_state)
    d = D.shape[0]
    tw = disc.tangent_work(run, d, pidx)
    tw.dq[:], tw.dp[:] = dq0, dp0
    tw.th[:, :len(pidx)] = dth
    dQ = np.zeros((run.K, d, n))
    dP = np.zeros((run.K, d, n))
    dQ[0], dP[0] = dq0, dp0
    each, lin = differentiator(run.model_data, run.state, run.loop_ws, run.info, run.tx, tw, dQ,
                               run.sized)
    total = run.total
    bar = ProgressBar(total, label="fastvi sensitivity") if progress else None
    chunk = total if bar is None else max(1, total // UPDATES)
    t_loop = time.perf_counter()
    while True:
        with quiet():
            status = _RUN_TANGENT(run.model_data, run.tabs, run.tx, run.opts, run.h, run.state,
                                  run.loop_ws, chunk, total, run.every, run.smp, run.info, run.sout,
                                  run.ev, run.stepk, run.stages, tw, dQ, dP, each, lin)
        if status == lay.NEEDS_FULL_NEWTON:  # compiled on first need; the step is retaken
            disc.with_full_newton(run)
            continue
        done = int(run.info[lay.I_STEPS])
        if bar is not None:
            bar.update(done, f"t = {run.t0 + done * run.h:.6g}", final=status != 0 or done >= total)
        if status != 0 or done >= total:
            break
    loop_time = time.perf_counter() - t_loop
    result = disc.finish(run, int(status), loop_time, 0.0, "the sensitivity")
    K = result.t.shape[0]
    dq = np.ascontiguousarray(dQ[:K].transpose(0, 2, 1))
    dp = np.ascontiguousarray(dP[:K].transpose(0, 2, 1))
    dv = disc.velocity_derivatives(run, result, dq, dp, pidx, dth)
    return SensitivityResult(result, result.t, dq, dv, dp, labels, run.prm, dth, pidx, model)


def directions_text(labels) -> str:
    """``14 directions (4 q0, 4 v0, 6 params)``: the directions by what they perturb."""
    kinds = Counter(label.split("[")[0] for label in labels)
    return f"{len(labels)} directions ({', '.join(f'{c} {k}' for k, c in kinds.items())})"


def largest_last(a) -> float:
    """``max |a[…, -1, :, :]|`` of derivatives (K, n, d) or (N, K, n, d): 0 if empty."""
    last = a[..., -1, :, :]
    return float(np.abs(last).max()) if last.size else 0.0


def sensitivity_arrays(sens: SensitivityResult, prefix: str = "") -> dict:
    """The arrays :meth:`SensitivityResult.save` writes, each key after ``prefix`` (a member
    of an ensemble's file); the model is left out."""
    arrays = dict(dq=sens.dq, dv=sens.dv, dp=sens.dp, labels=np.array(sens.labels, dtype=str),
                  params=sens.params, pidx=np.asarray(sens._pidx, dtype=np.int64))
    if sens._dth is not None:
        arrays["dth"] = sens._dth
    return {**{prefix + k: v for k, v in arrays.items()},
            **result_arrays(sens.result, prefix + "result_")}


def sensitivity_from(stored, prefix: str = "", *, model=None, cls=SensitivityResult):
    """The :class:`SensitivityResult` whose arrays :func:`sensitivity_arrays` wrote under
    ``prefix`` in an open file (:func:`fastvi.results.open_npz`), with ``model``."""
    data = stored.under(prefix)
    result = result_from(data, "result_")
    return cls(result, result.t, data["dq"], data["dv"], data["dp"],
               [str(x) for x in data["labels"]], data["params"],
               data["dth"] if "dth" in data else None, [int(x) for x in data["pidx"]],
               matching_model(model, result, cls.__name__))


def tangent_space(model, q, v, *, params=None, t: float = 0.0) -> np.ndarray:
    r"""An orthonormal basis of the tangent space of the constrained phase space.

    At ``(q, p = M(q) v)``, in ``(δq, δp)``: the null space of

    .. math::

        \begin{pmatrix} G & 0 \\ H_v - G M^{-1} C_q & G M^{-1} \end{pmatrix},

    the linearised constraint ``G δq = 0`` and hidden constraint ``δ(G M⁻¹ p) = 0``
    (``H_v = ∂(G v + g_t)/∂q``, ``C_q = ∂(M v)/∂q``). Directions in this space are the meaningful
    perturbations of a state; :func:`sensitivity` maps them to tangent vectors at every
    later step.

    Parameters
    ----------
    model : Model
    q, v : array_like (n,)
        A consistent state (at time ``t``).
    params : array_like (k,), optional
        Parameters (default: the model's).
    t : float, default 0.0
        The time, for time-dependent constraints.

    Returns
    -------
    ndarray (2n, 2(n − m))
        Orthonormal columns ``(δq, δp)``.
    """
    n, m = model.n, model.m
    q = valid.vector(q, "q", n)
    v = valid.vector(v, "v", n)
    prm = valid.params(params, model)
    if m == 0:
        return np.eye(2 * n)
    M, G, _, Hv, Cq = point_terms(model.kernel_data(prm, float(t)), q, v, np.zeros(m))
    Y = np.linalg.solve(M, G.T).T
    C = np.block([[G, np.zeros((m, n))], [Hv - Y @ Cq, Y]])
    _, sv, Vt = np.linalg.svd(C)
    return np.ascontiguousarray(Vt[2 * m:].T)
