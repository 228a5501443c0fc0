r"""Derivative checks: compare every derivative a model supplies with finite differences.

A variational integrator with a wrong gradient is not unstable, it is *silently wrong*: it
conserves the energy of a different Lagrangian. :func:`check_model` (also
:meth:`fastvi.Model.check`) therefore compares every supplied derivative callback with
finite differences of the callback it differentiates,

==========================  ================================================
callback                    compared with finite differences of
==========================  ================================================
``kinetic_grad``            ``T(q) = ½ vᵀ M(q) v`` (the ``mass`` callback)
``momentum_jacobian``       ``M(q) v`` (the ``mass`` callback)
``kinetic_hessian``         ``kinetic_grad``
``potential_grad``          ``potential``
``potential_hessian``       ``potential_grad``
``constraint_jacobian``     ``constraint``
``constraint_hessian``      ``Gᵀ η`` (the ``constraint_jacobian`` callback),
                            for ``η = e_1 … e_m`` and a random ``η``
==========================  ================================================

and checks that a ``mass`` callback returns a symmetric matrix. The comparison runs at the
given state and at a few random nearby states (a wrong derivative can agree by accident at a
special point, e.g. ``x = 0``). The callbacks are evaluated through the compiled cfuncs, so
what is checked is exactly what the kernels call.

Finite differences use three central differences with steps ``h, h/2, h/4``
(``h = 10⁻³·max(1, |q_b|)``) combined by Richardson extrapolation: the reference is
accurate to about ``10⁻¹²`` relative for smooth callbacks, and the difference of the two
extrapolations estimates its error. A derivative ``D`` passes when

.. math::

    \max |D - D_{FD}| \le \text{rtol}\,\max(|D|, |D_{FD}|) + 10\,e_{FD} + 100\,\varepsilon\,|f|/h_{min},

with ``e_FD`` the estimated finite-difference error and the last term the round-off of
differencing ``f``. With the default ``rtol = 1e-6`` a genuine mistake (a sign, a factor,
a transposed index, a missing term) fails by many orders of magnitude.

:func:`fastvi.integrate` runs a cheap version (the initial state and one nearby state) the
first time a model is integrated; pass ``check=False`` to skip it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .model import SLOTS, Model, _call

__all__ = ["check_model", "CheckReport", "CheckRow", "ModelCheckError", "DEFAULT_RTOL"]

#: Relative tolerance of a derivative against its finite-difference reference.
DEFAULT_RTOL = 1e-6
#: Largest central-difference step, relative to ``max(1, |q_b|)`` (then h/2, h/4).
FD_STEP = 1e-3
#: Random nearby states checked by :func:`check_model` by default (and by integrate: 1).
DEFAULT_RANDOM_STATES = 3
#: Size of the random perturbation of the nearby states, relative to ``max(1, |q|)``.
DEFAULT_RADIUS = 1e-2
_NOISE = 10.0  # safety factor on the estimated finite-difference error
_ROUNDOFF = 100.0 * np.finfo(float).eps

# What each derivative callback is compared with (in the order the checks run: a second
# derivative is checked against its first derivative only if that one passed).
_REFERENCE = {
    "mass": "its transpose (symmetry)",
    "kinetic_grad": "FD of ½vᵀM(q)v (mass)",
    "momentum_jacobian": "FD of M(q)v (mass)",
    "potential_grad": "FD of potential",
    "constraint_jacobian": "FD of constraint",
    "kinetic_hessian": "FD of kinetic_grad",
    "potential_hessian": "FD of potential_grad",
    "constraint_hessian": "FD of Gᵀη (constraint_jacobian)",
}
_PARENT = {
    "kinetic_hessian": "kinetic_grad",
    "potential_hessian": "potential_grad",
    "constraint_hessian": "constraint_jacobian",
}


@dataclass(frozen=True)
class CheckRow:
    """One comparison of a callback with its finite-difference reference at one state.

    Attributes
    ----------
    callback : str
        The callback checked (a name of :data:`fastvi.model.SLOTS`).
    reference : str
        What it was compared with.
    state : int
        0 for the given state, ``1 …`` for the random nearby states.
    error : float
        ``max |D − D_FD|`` over the entries (absolute).
    scale : float
        ``max(|D|, |D_FD|)``: the size relative errors refer to.
    allowed : float
        The largest ``error`` that passes (absolute; see the module docstring).
    index : tuple of int
        Entry of ``D`` where the error is largest.
    status : {"ok", "wrong", "skipped"}
        ``"skipped"`` when the reference could not be computed (non-finite values near the
        state, or the first derivative it differentiates is itself wrong).
    note : str
        Extra detail (``η`` used, reason for skipping, non-finite output).
    """

    callback: str
    reference: str
    state: int
    error: float
    scale: float
    allowed: float
    index: tuple = ()
    status: str = "ok"
    note: str = ""

    @property
    def ok(self) -> bool:
        """True unless the callback disagreed with its reference."""
        return self.status != "wrong"

    @property
    def relative_error(self) -> float:
        """``error / scale`` (``error`` itself when the scale is zero)."""
        return self.error / self.scale if self.scale > 0 else self.error


@dataclass
class CheckReport:
    """Outcome of :func:`check_model`: one :class:`CheckRow` per comparison.

    ``str(report)`` is a table with one line per callback (the worst comparison over the
    states checked); ``report.ok`` is True when every callback agreed.

    Attributes
    ----------
    model_name : str
    rows : list of CheckRow
    states : list of (q, v) pairs
        The states checked: the given one first, then the random nearby ones.
    rtol : float
    evaluations : int
        Callback evaluations spent.
    wall_time : float
        Seconds spent (including compiling the model's callbacks if that had not happened).
    """

    model_name: str
    rows: list = field(default_factory=list)
    states: list = field(default_factory=list)
    rtol: float = DEFAULT_RTOL
    evaluations: int = 0
    wall_time: float = 0.0

    @property
    def ok(self) -> bool:
        """True when no callback disagreed with its reference."""
        return all(r.ok for r in self.rows)

    @property
    def checked(self) -> list[str]:
        """Callbacks compared at least once, in check order."""
        return list(dict.fromkeys(r.callback for r in self.rows if r.status != "skipped"))

    @property
    def failures(self) -> list[str]:
        """Callbacks that disagreed with their reference at some state, in check order."""
        return list(dict.fromkeys(r.callback for r in self.rows if not r.ok))

    def worst(self, callback: str) -> CheckRow:
        """The comparison of ``callback`` with the largest error relative to what is allowed."""
        rows = [r for r in self.rows if r.callback == callback]
        if not rows:
            raise KeyError(f"callback {callback!r} was not checked; checked: {self.checked}")
        return max(rows, key=_badness)

    def __str__(self) -> str:
        n_states = len(self.states)
        head = (f"derivative check of {self.model_name!r}: {n_states} state(s) (the given one and "
                f"{n_states - 1} random nearby), rtol = {self.rtol:.0e}, {self.evaluations} "
                f"callback evaluations, {self.wall_time * 1e3:.1f} ms")
        lines = [head, f"{'callback':<20} {'compared with':<32} {'max rel. error':>14} "
                       f"{'allowed':>9}  result"]
        for cb in dict.fromkeys(r.callback for r in self.rows):
            w = self.worst(cb)
            allowed = w.allowed / w.scale if w.scale > 0 else w.allowed
            res = {"ok": "ok", "wrong": "WRONG", "skipped": "skipped"}[w.status]
            if w.status == "wrong":
                where = "given state" if w.state == 0 else f"nearby state {w.state}"
                res += f" (at {where}, entry {list(w.index)}{'; ' + w.note if w.note else ''})"
            elif w.status == "skipped":
                res += f" ({w.note})"
            lines.append(f"{cb:<20} {w.reference:<32} {w.relative_error:>14.2e} {allowed:>9.1e}  {res}")
        if not self.rows:
            lines.append("(no derivative callbacks to check)")
        return "\n".join(lines)

    def raise_if_wrong(self) -> None:
        """Raise :class:`ModelCheckError` if any callback disagreed with its reference."""
        if not self.ok:
            raise ModelCheckError(self)


class ModelCheckError(ValueError):
    """A model callback disagrees with finite differences of the function it differentiates.

    Attributes
    ----------
    callback : str
        The first wrong callback, in check order (first derivatives before second ones).
    callbacks : list of str
        Every wrong callback.
    report : CheckReport
        The full comparison table.
    """

    def __init__(self, report: CheckReport):
        self.report = report
        self.callbacks = report.failures
        self.callback = self.callbacks[0]
        w = report.worst(self.callback)
        where = "the given state" if w.state == 0 else f"random nearby state {w.state}"
        detail = f"; {w.note}" if w.note else ""
        others = [c for c in self.callbacks if c != self.callback]
        also = f" Also wrong: {', '.join(f'`{c}`' for c in others)}." if others else ""
        super().__init__(
            f"model {report.model_name!r}: callback `{self.callback}` disagrees with its reference "
            f"({w.reference}): max relative error {w.relative_error:.2e} at {where}, entry "
            f"{list(w.index)}{detail} (allowed {w.allowed / w.scale if w.scale > 0 else w.allowed:.1e})."
            f"{also} Fix the callback, or pass check=False to fastvi.integrate to skip this check."
            f"\n{report}"
        )


def _badness(row: CheckRow) -> float:
    if row.status == "skipped":
        return -1.0
    return row.error / row.allowed if row.allowed > 0 else (np.inf if row.error > 0 else 0.0)


class _Callbacks:
    """The model's compiled callbacks, evaluated from Python (counting evaluations)."""

    def __init__(self, model: Model, params: np.ndarray):
        cfs = model.kernel_arguments()[0]
        self.fn = dict(zip(SLOTS, cfs))
        self.present = set(model._functions)
        self.p = params
        self.n, self.m = model.n, model.m
        self.count = 0
        n, m = self.n, self.m
        self.shape = dict(mass=(n, n), kinetic_grad=(n,), potential=(), potential_grad=(n,),
                          constraint=(m,), constraint_jacobian=(m, n), potential_hessian=(n, n),
                          constraint_hessian=(n, n), kinetic_hessian=(n, n),
                          momentum_jacobian=(n, n))

    def __call__(self, slot: str, q: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        shape = self.shape[slot]
        out = np.zeros(shape if shape else (1,))
        q = np.ascontiguousarray(q)
        _call(self.fn[slot], q, q if v is None else np.ascontiguousarray(v), self.p, out)
        self.count += 1
        return out if shape else out.reshape(())


def _fd(f, q: np.ndarray):
    """Richardson-extrapolated central differences of ``f`` along each coordinate.

    Returns ``(J, est, fscale, hmin)`` with ``J[..., b] ≈ ∂f/∂q_b``, ``est`` the estimated
    error of ``J``, ``fscale = max |f|`` over the evaluations, and the smallest step.
    """
    n = q.shape[0]
    f0 = np.asarray(f(q), dtype=float)
    J = np.empty(f0.shape + (n,))
    est = np.empty_like(J)
    fscale = float(np.max(np.abs(f0))) if f0.size else 0.0
    hmin = np.inf
    for b in range(n):
        base = FD_STEP * max(1.0, abs(q[b]))
        D = []
        for k in (1.0, 2.0, 4.0):
            qp, qm = q.copy(), q.copy()
            qp[b] += base / k
            qm[b] -= base / k
            fp, fm = np.asarray(f(qp), dtype=float), np.asarray(f(qm), dtype=float)
            fscale = max(fscale, float(np.max(np.abs(fp))) if fp.size else 0.0,
                         float(np.max(np.abs(fm))) if fm.size else 0.0)
            D.append((fp - fm) / (qp[b] - qm[b]))  # the step actually taken (rounded)
            hmin = min(hmin, qp[b] - q[b])
        r1 = (4.0 * D[1] - D[0]) / 3.0
        r2 = (4.0 * D[2] - D[1]) / 3.0
        J[..., b] = r2
        est[..., b] = np.abs(r2 - r1)
    return J, est, fscale, hmin


def _compare(callback: str, state: int, exact: np.ndarray, fd, rtol: float, note: str = "") -> CheckRow:
    ref, est, fscale, hmin = fd
    reference = _REFERENCE[callback]
    exact = np.asarray(exact, dtype=float)
    if not np.all(np.isfinite(exact)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(exact))[0]) if exact.ndim else ()
        if state > 0:  # a random nearby state may lie outside the model's domain
            return CheckRow(callback, reference, state, np.nan, 0.0, 0.0, bad, "skipped",
                            "non-finite values at this nearby state")
        return CheckRow(callback, reference, state, np.inf, 0.0, 0.0, bad, "wrong",
                        (note + "; " if note else "") + "returned non-finite values")
    if not (np.all(np.isfinite(ref)) and np.all(np.isfinite(est))):
        return CheckRow(callback, reference, state, np.nan, 0.0, 0.0, (), "skipped",
                        "reference not finite near this state")
    diff = np.abs(exact - ref)
    idx = np.unravel_index(int(np.argmax(diff)), diff.shape) if diff.size else ()
    error = float(diff.max()) if diff.size else 0.0
    scale = max(float(np.abs(exact).max()), float(np.abs(ref).max())) if diff.size else 0.0
    noise = _NOISE * (float(est.max()) if est.size else 0.0) + _ROUNDOFF * fscale / hmin
    allowed = rtol * scale + noise
    return CheckRow(callback, reference, state, error, scale, allowed,
                    tuple(int(i) for i in idx), "ok" if error <= allowed else "wrong", note)


def check_model(model: Model, q, v=None, *, params=None, n_random: int = DEFAULT_RANDOM_STATES,
                radius: float = DEFAULT_RADIUS, rtol: float = DEFAULT_RTOL, seed: int = 0,
                raise_on_error: bool = True) -> CheckReport:
    r"""Compare every derivative callback of ``model`` with finite differences.

    Parameters
    ----------
    model : Model
    q : array_like (n,)
        The configuration to check at. It need not satisfy the constraints.
    v : array_like (n,), optional
        The velocity for the kinetic-energy derivatives (default: random, ``~N(0, 1)``).
    params : array_like (k,), optional
        Parameter vector (default: the model's).
    n_random : int, default 3
        Random nearby states checked in addition to ``(q, v)``:
        ``q + radius·max(1, |q|)·ξ``, ``v + radius·max(1, |v|)·ξ'`` with ``ξ, ξ' ~ N(0, I)``.
    radius : float, default 1e-2
        Relative size of the perturbation of the nearby states.
    rtol : float, default 1e-6
        Relative tolerance (on top of the estimated finite-difference error).
    seed : int, default 0
        Seed of the random nearby states and of the random ``η`` (reproducible reports).
    raise_on_error : bool, default True
        Raise :class:`ModelCheckError` when a callback disagrees; otherwise only return the
        report (``report.ok`` is False).

    Returns
    -------
    CheckReport
        ``print(report)`` shows one line per callback: what it was compared with, the
        largest relative error over the states, the tolerance, and the verdict.

    Raises
    ------
    ModelCheckError
        Naming the first wrong callback (``.callback``) with the report attached.

    Notes
    -----
    The finite-difference steps assume coordinates of order one (``h = 10⁻³ max(1, |q_b|)``):
    for a model in, say, micrometres the reference is coarse, its error estimate widens the
    tolerance, and only gross mistakes are caught; choose units accordingly. Non-finite
    values at a random nearby state (outside the model's domain) skip that state; at the
    given state they count as wrong.

    A model that passes is marked as checked, and :func:`fastvi.integrate` then skips its
    automatic check. Costs ``≈ 6 n`` callback evaluations per derivative and state (a few
    microseconds each): milliseconds for small models, far below compiling the callbacks.

    Examples
    --------
    >>> import fastvi
    >>> model = fastvi.scenes.pendulum()
    >>> report = model.check([0.6, -0.8], [0.8, 0.6])
    >>> report.ok
    True
    """
    t0 = time.perf_counter()
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    n, m = model.n, model.m
    q = _vector(q, "q", n)
    rng = np.random.default_rng(seed)
    v = rng.standard_normal(n) if v is None else _vector(v, "v", n)
    prm = model.params if params is None else _vector(params, "params", model.params.shape[0])
    if isinstance(n_random, bool) or not isinstance(n_random, (int, np.integer)) or n_random < 0:
        raise ValueError(f"`n_random` must be a non-negative integer, got {n_random!r}")
    if not (isinstance(radius, (int, float, np.floating)) and 0 < radius < 1):
        raise ValueError(f"`radius` must be in (0, 1), got {radius!r}")
    if not (isinstance(rtol, (int, float, np.floating)) and 0 < rtol < 1):
        raise ValueError(f"`rtol` must be in (0, 1), got {rtol!r}")

    cb = _Callbacks(model, prm)
    states = [(q, v)]
    qs, vs = max(1.0, float(np.abs(q).max())), max(1.0, float(np.abs(v).max()))
    for _ in range(int(n_random)):
        states.append((q + radius * qs * rng.standard_normal(n), v + radius * vs * rng.standard_normal(n)))
    etas = [np.eye(m)[a] for a in range(m)] + ([rng.standard_normal(m)] if m > 1 else [])
    report = CheckReport(model.name, states=states, rtol=float(rtol))
    has = cb.present.__contains__

    for k, (qk, vk) in enumerate(states):
        rows: dict[str, list[CheckRow]] = {}

        def add(row: CheckRow, _rows=rows):
            _rows.setdefault(row.callback, []).append(row)

        if has("mass"):
            M = cb("mass", qk)
            if not np.all(np.isfinite(M)):
                add(CheckRow("mass", _REFERENCE["mass"], k, np.inf if k == 0 else np.nan, 0.0, 0.0, (),
                             "wrong" if k == 0 else "skipped", "returned non-finite values"))
            else:
                asym = np.abs(M - M.T)
                idx = tuple(int(i) for i in np.unravel_index(int(np.argmax(asym)), asym.shape))
                scale = float(np.abs(M).max())
                allowed = _ROUNDOFF * scale  # a symmetric formula gives exact symmetry
                add(CheckRow("mass", _REFERENCE["mass"], k, float(asym.max()), scale, allowed, idx,
                             "ok" if asym.max() <= allowed else "wrong"))
            add(_compare("kinetic_grad", k, cb("kinetic_grad", qk, vk),
                         _fd(lambda x: 0.5 * vk @ cb("mass", x) @ vk, qk), rtol))
            if has("momentum_jacobian"):
                add(_compare("momentum_jacobian", k, cb("momentum_jacobian", qk, vk),
                             _fd(lambda x: cb("mass", x) @ vk, qk), rtol))
        add(_compare("potential_grad", k, cb("potential_grad", qk), _fd(lambda x: cb("potential", x), qk), rtol))
        if m:
            add(_compare("constraint_jacobian", k, cb("constraint_jacobian", qk),
                         _fd(lambda x: cb("constraint", x), qk), rtol))
        for slot in ("kinetic_hessian", "potential_hessian", "constraint_hessian"):
            if not has(slot):
                continue
            parent = _PARENT[slot]
            if not all(r.ok for r in rows.get(parent, [])):
                add(CheckRow(slot, _REFERENCE[slot], k, np.nan, 0.0, 0.0, (), "skipped",
                             f"its reference `{parent}` is wrong"))
                continue
            if slot == "kinetic_hessian":
                add(_compare(slot, k, cb(slot, qk, vk), _fd(lambda x: cb("kinetic_grad", x, vk), qk), rtol))
            elif slot == "potential_hessian":
                add(_compare(slot, k, cb(slot, qk), _fd(lambda x: cb("potential_grad", x), qk), rtol))
            else:
                dG, est, fscale, hmin = _fd(lambda x: cb("constraint_jacobian", x), qk)  # (m, n, n)
                for j, eta in enumerate(etas):
                    ref = np.einsum("c,cab->ab", eta, dG)
                    e = np.einsum("c,cab->ab", np.abs(eta), est)
                    note = f"η = e_{j}" if j < m else "random η"
                    add(_compare(slot, k, cb(slot, qk, eta), (ref, e, fscale * np.abs(eta).sum(), hmin), rtol, note))
        for slot_rows in rows.values():
            report.rows.extend(slot_rows)

    report.evaluations = cb.count
    report.wall_time = time.perf_counter() - t0
    if report.ok:
        model._checked = True
    elif raise_on_error:
        raise ModelCheckError(report)
    return report


def _vector(x, name: str, n: int) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != (n,):
        raise ValueError(f"`{name}` must have shape ({n},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}` must be finite, got {arr}")
    return np.ascontiguousarray(arr)
