r"""Fitting parameters to observations of a trajectory: :class:`TrajectoryFit`.

The residuals ``r(θ) = y(θ) − data`` of an observation ``y`` of the saved states, with
their exact Jacobian from :func:`fastvi.sensitivity` (for
``scipy.optimize.least_squares(jac=...)``) and the gradient of ``½|r|²`` from
:func:`fastvi.adjoint` (for ``scipy.optimize.minimize(jac=True)``).
"""

from __future__ import annotations

import numpy as np

from . import _discrete as disc
from . import _validate as valid
from .adjoint import adjoint
from .integrate import integrate
from .model import Model
from .sensitivity import sensitivity

__all__ = ["TrajectoryFit"]

#: relative step of the central differences of an observation function
_OBS_STEP = 6.0554544523933395e-06


class TrajectoryFit:
    r"""Least-squares fit of some of a model's parameters to observations of its trajectory.

    The run is ``fastvi.integrate(model, q0, v0, h=h, n_steps=n_steps, params=θ, ...)``
    saved every ``save_every`` steps (K samples, ``t_i = t0 + i·save_every·h``); the
    residuals are

    .. math::

        r_i(\theta) = y(t_i, q_i, v_i) - \mathrm{data}_i, \qquad i = 0 … K-1,

    flattened sample by sample, where ``θ`` are the parameters ``param_index`` (the others
    keep their values in ``params``). Derivatives are those of the discrete flow, exact up
    to round-off for the trajectories the residuals are computed from, so a Gauss–Newton
    or quasi-Newton solver converges as it would on an exact model.

    Parameters
    ----------
    model : Model
    data : array_like (K, p)
        The observations at the K saved steps (a (K,) array for a scalar observation).
    observe : callable
        ``observe(t, q, v) -> y``, vectorised: ``t`` (K,), ``q``, ``v`` (K, n), ``y``
        (K, p) or (K,).
    param_index : sequence of int
        The parameters to fit (indices into the model's parameter vector).
    q0, v0 : array_like (n,), optional
        The initial state, fixed; or
    initial_state : callable, optional
        ``initial_state(params) -> (q0, v0)`` for an initial state that depends on the
        parameters (initial angles of rods whose lengths are fitted).
    h, n_steps, t_end, t0, t_span, method, save_every, tol, max_iter, newton, solver :
        As :func:`fastvi.integrate` (a whole number of steps).
    params : array_like (k,), optional
        The values of the parameters not fitted (default: the model's).
    observe_jacobian : callable, optional
        ``observe_jacobian(t, q, v) -> (dy_dq, dy_dv)``, (K, p, n) each; central
        differences of ``observe`` otherwise.

    Attributes
    ----------
    nfev, njev : int
        Residual and Jacobian (or gradient) evaluations so far.

    Examples
    --------
    >>> from scipy.optimize import least_squares                      # doctest: +SKIP
    >>> fit = fastvi.TrajectoryFit(model, data, observe, param_index=[3, 5],
    ...                            initial_state=start, h=0.01, n_steps=500)
    >>> sol = least_squares(fit.residuals, theta0, jac=fit.jacobian)  # doctest: +SKIP
    """

    def __init__(self, model, data, observe, *, param_index, h: float, q0=None, v0=None,
                 initial_state=None, n_steps: int | None = None, t_end: float | None = None,
                 t0: float = 0.0, t_span=None, method="P2L-Q3G", save_every: int = 1,
                 params=None, observe_jacobian=None, tol: float = valid.DEFAULT_TOL,
                 max_iter: int = valid.DEFAULT_MAX_ITER, newton: str = "auto",
                 solver: str = "auto"):
        if not isinstance(model, Model):
            raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
        if (initial_state is None) == (q0 is None or v0 is None):
            raise ValueError("give the initial state as `q0` and `v0`, or as "
                             "`initial_state(params) -> (q0, v0)`, not both")
        if initial_state is not None and not callable(initial_state):
            raise TypeError(f"`initial_state` must be callable, got {initial_state!r}")
        if not callable(observe):
            raise TypeError(f"`observe` must be callable, got {observe!r}")
        self.model = model
        self.params = valid.params(params, model).copy()
        if param_index is None:
            raise TypeError("`param_index` is required: name the parameters to fit")
        self.param_index = disc.param_indices(param_index, self.params.shape[0],
                                              model.fixed_params, model.mass_params)
        if not self.param_index:
            raise ValueError("`param_index` is empty: name the parameters to fit")
        self.data = np.asarray(data, dtype=float)
        if self.data.ndim == 1:
            self.data = self.data[:, None]
        if self.data.ndim != 2 or not np.all(np.isfinite(self.data)):
            raise ValueError(f"`data` must be a finite (K, p) or (K,) array, got shape "
                             f"{np.shape(data)}")
        self.observe = observe
        self.observe_jacobian = observe_jacobian
        self._q0 = None if q0 is None else valid.vector(q0, "q0", model.n)
        self._v0 = None if v0 is None else valid.vector(v0, "v0", model.n)
        self._initial_state = initial_state
        self._run = dict(h=h, n_steps=n_steps, t_end=t_end, t0=t0, t_span=t_span,
                         method=method, save_every=save_every, tol=tol, max_iter=max_iter,
                         newton=newton, solver=solver)
        self.nfev = 0
        self.njev = 0
        self._cache = {}

    # ------------------------------------------------------------------ runs
    def full_params(self, theta) -> np.ndarray:
        """The model's parameter vector with ``theta`` at ``param_index``."""
        theta = valid.vector(theta, "theta", len(self.param_index))
        p = self.params.copy()
        p[self.param_index] = theta
        return p

    def _start(self, prm):
        if self._initial_state is None:
            return self._q0, self._v0
        q0, v0 = self._initial_state(prm)
        return valid.vector(q0, "initial_state(params)[0]", self.model.n), \
            valid.vector(v0, "initial_state(params)[1]", self.model.n)

    def _cached(self, kind, theta, make):
        key = (kind, np.asarray(theta, dtype=float).tobytes())
        if key not in self._cache:
            self._cache = {k: v for k, v in self._cache.items() if k[1] == key[1]}
            self._cache[key] = make()
        return self._cache[key]

    def trajectory(self, theta):
        """The :class:`fastvi.Result` at ``theta``."""
        prm = self.full_params(theta)

        def make():
            q0, v0 = self._start(prm)
            return integrate(self.model, q0, v0, params=prm, **self._run)

        return self._cached("run", theta, make)

    def _observed(self, res):
        y = np.asarray(self.observe(res.t, res.q, res.v), dtype=float)
        if y.ndim == 1:
            y = y[:, None]
        if y.shape != self.data.shape:
            raise ValueError(f"`observe` gave shape {y.shape} on the {res.t.shape[0]} samples of the "
                             f"run, `data` has shape {self.data.shape}: the run must save one "
                             "sample per row of `data` (check `n_steps` and `save_every`)")
        return y

    def _observe_jacobian(self, res):
        """``(dy_dq, dy_dv)`` (K, p, n) at the samples of ``res``."""
        if self.observe_jacobian is not None:
            Jq, Jv = self.observe_jacobian(res.t, res.q, res.v)
            return (np.asarray(Jq, dtype=float).reshape(self.data.shape + (self.model.n,)),
                    np.asarray(Jv, dtype=float).reshape(self.data.shape + (self.model.n,)))
        out = []
        for which in (1, 2):
            cols = []
            for a in range(self.model.n):
                args = [res.t, res.q, res.v]
                x = args[which]
                step = _OBS_STEP * np.maximum(1.0, np.abs(x[:, a]))
                plus, minus = x.copy(), x.copy()
                plus[:, a] += step
                minus[:, a] -= step
                args[which] = plus
                yp = np.asarray(self.observe(*args), dtype=float).reshape(self.data.shape)
                args[which] = minus
                ym = np.asarray(self.observe(*args), dtype=float).reshape(self.data.shape)
                cols.append((yp - ym) / (2.0 * step[:, None]))
            out.append(np.stack(cols, axis=-1))
        return out[0], out[1]

    # ------------------------------------------------------------------ SciPy's callables
    def residuals(self, theta) -> np.ndarray:
        """``r(θ)`` (K p,), for ``scipy.optimize.least_squares(fun=...)``."""
        self.nfev += 1
        return (self._observed(self.trajectory(theta)) - self.data).ravel()

    def jacobian(self, theta) -> np.ndarray:
        """``∂r/∂θ`` (K p, len(param_index)) by forward sensitivities, for
        ``least_squares(jac=...)``."""
        self.njev += 1
        prm = self.full_params(theta)

        def make():
            q0, v0 = self._start(prm)
            return sensitivity(self.model, q0, v0, params=prm, wrt=("params",),
                               param_index=self.param_index, initial_state=self._initial_state,
                               **self._run)

        sens = self._cached("sens", theta, make)
        Jq, Jv = self._observe_jacobian(sens.result)
        J = np.einsum("kpn,knd->kpd", Jq, sens.dq) + np.einsum("kpn,knd->kpd", Jv, sens.dv)
        return J.reshape(-1, len(self.param_index))

    def cost(self, theta):
        """``(½|r|², ∇)`` with the gradient by the discrete adjoint, for
        ``scipy.optimize.minimize(fun, x0, jac=True)``."""
        self.nfev += 1
        self.njev += 1
        prm = self.full_params(theta)
        q0, v0 = self._start(prm)
        box = {}

        def cotangent(res):
            r = self._observed(res) - self.data
            box["r"] = r
            Jq, Jv = self._observe_jacobian(res)
            return np.einsum("kpn,kp->kn", Jq, r), np.einsum("kpn,kp->kn", Jv, r)

        adj = adjoint(self.model, q0, v0, cotangent, params=prm, param_index=self.param_index,
                      initial_state=self._initial_state, **self._run)
        return 0.5 * float(np.sum(box["r"] ** 2)), adj.grad_params
