r"""``python -m fastvi wpd``: work–precision diagrams, fastvi against RK4 and SciPy.

Single source of ``docs/wpd.md`` and ``docs/figures/wpd-*.png``. On the planar double
pendulum (Cartesian, ``n = 4``, ``m = 2``, paper B's parameters, released at rest from
θ1 = θ2 = π/2) it runs, on the *same* :class:`fastvi.Model` callbacks,

* fastvi ``P1L-Q2G`` … ``P4L-Q5G`` (defaults: Lobatto control nodes, constraints at every
  node) and paper B's own scheme ``P2L-Q3G-NE-CE``, sweeping the step ``h``;
* classical RK4 on the index-1 form, with and without projection onto the constraints
  (:func:`fastvi.baselines.rk4`), sweeping ``h``;
* SciPy ``solve_ivp`` (RK45, DOP853, Radau) on the same compiled index-1 right-hand side,
  sweeping ``rtol = atol``,

and plots wall time against

(a) the error of ``q`` at ``T = 10`` s against a tight, independent reference (SciPy DOP853
    at ``rtol = atol = 1e-13`` in angle coordinates,
    :func:`fastvi.studies.reference.chain_pendulum_reference`);
(b) the maximum energy error ``max |H − H(0)|`` over ``T = 1000`` s;
(c) the maximum constraint residual ``max |g(q)|`` over the same runs as (b).

It then reads off, at equal maximum energy error over ``T = 1000`` s, how much faster
fastvi's best method is than SciPy DOP853 and than RK4 (goals of issue 6: ≥ 100× and > 1×),
where the curves cross, profiles one step (which part costs what), and tabulates the cost
per step on ``fastvi.scenes.chain(N)``, N = 2 … 64, with the fitted exponent and the share
of the dense LU.

**Compiled peers** (issue 11, item 5; :func:`run_peers`, needs CyRK, the ``bench`` extra):
CyRK's C++ DOP853 on hand-written ``@njit`` right-hand sides (:mod:`fastvi.studies.peers`) of
the same pendulum, (a) Cartesian index-1 and (b) angle coordinates, against fastvi through
its public :func:`fastvi.integrate`: CPU time against ``max |H − H(0)|`` at ``T = 1000`` s
and ``T = 10^4`` s, the ratio "fastvi best / DOP853" at ``max|ΔH| = 1e-2, 1e-4, 1e-6, 1e-8``
J (log–log interpolation on each contender's Pareto front), the growth of the energy error
and of the constraint drift with ``T``; and a **stiff panel**: the rod–slider with spring
stiffness ``k = 10^3 … 10^8`` over ``T = 10`` s, fastvi against CyRK DOP853, LSODA and Radau,
the CPU time of each to reach ``max|ΔH| ≤`` :data:`STIFF_TARGET_REL` × the spring energy,
the crossover stiffness and the ratio at the largest ``k``. Without CyRK these sections say
how to install it; ``--no-peers`` skips them.

SciPy runs through :func:`scipy_run`: the equations of :func:`fastvi.baselines.solve_ivp`
(the compiled index-1 acceleration :func:`fastvi.baselines.rk4.acceleration`) with the
model's cfuncs frozen into the right-hand side, a few microseconds per call, timed around
``solve_ivp`` alone, so SciPy's own per-step overhead is what is measured.

Timing: everything is compiled (or loaded from numba's cache) before timing; each point is
the median of ``REPEATS`` runs (runs longer than ``LONG_RUN`` seconds are timed once: they
are long enough to average out the timer, not the machine's other load). All ratios come
from one process, one run of this command.

Usage::

    python -m fastvi wpd                 # full study (≈ 4–10 min on 2 cores), writes ./fastvi-study-wpd/
    python -m fastvi wpd --quick         # T = 1 s and 10 s, few points (tests, a first look)
    python -m fastvi wpd --out DIR       # write DIR/wpd.md and DIR/figures/wpd-*.png
    python -m fastvi wpd --no-peers      # without the compiled-peer (CyRK) panels
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time
import weakref
from dataclasses import dataclass, field, replace

import numba as nb
import numpy as np
import scipy
import scipy.integrate

import fastvi
from fastvi import _validate as check
from fastvi._numba import njit, ptr, quiet
from fastvi.baselines import rk4 as rk4_baseline
from fastvi.baselines.rk4 import OBS_G, OBS_GV, OBS_H, OBS_SIZE, BaselineResult, acceleration, observe
from fastvi.baselines.rk4 import make_workspace as rk_workspace
from fastvi.kernels.linalg import lu_factor, lu_solve
from fastvi.kernels.layout import PGRAD as _PGRAD
from fastvi.kernels.layout import F_M, F_N, NEWTON_FULL, STEP_OUT_SIZE, NewtonOptions
from fastvi.kernels.layout import make_workspace as vi_workspace
from fastvi.kernels.step import assemble
from fastvi.kernels.step import step_once as _vi_step
from fastvi.status import Status
from fastvi.studies.profile import loop_assemble, loop_callback, loop_end, loop_lu, loop_solve
from fastvi.studies.reference import REF_TOL, chain_cartesian, chain_pendulum_reference

#: fastvi's defaults P1…P4 and paper B's own scheme
FASTVI_METHODS = ("P1L-Q2G", "P2L-Q3G", "P3L-Q4G", "P4L-Q5G", "P2L-Q3G-NE-CE")
THETA0 = (np.pi / 2, np.pi / 2)  # paper B's start, at rest
T_ERROR = 10.0  # panel (a)
T_LONG = 1000.0  # panels (b), (c)
#: SciPy's energies and residuals over T = 1000 s are read from its dense output every
#: SAMPLE_DT seconds (denser output costs SciPy extra evaluations, and sparser sampling can
#: only lower its maxima); fastvi and RK4 keep every step, so their maxima are over more
#: samples (never in their favour). Panel (a) asks SciPy for q(T) only.
SAMPLE_DT = 1.0
REPEATS = 3
LONG_RUN = 6.0  # s: a run longer than this is timed once (budget of the whole study)
GOAL_SCIPY = 100.0  # issue 6: best fastvi ≥ 100× faster than DOP853 at equal max|ΔH|, T = 1000
GOAL_RK4 = 1.0  # … and faster than RK4

# Sweeps: step sizes (fixed-step) or rtol = atol (adaptive), chosen to span ~1e-1 … 1e-10 in
# error at a total cost of a few minutes. T must be a whole number of steps.
FULL = dict(
    T_error=T_ERROR,
    T_long=T_LONG,
    repeats=REPEATS,
    error={
        "P1L-Q2G": (0.02, 0.01, 0.005, 0.0025, 0.00125),
        "P2L-Q3G": (0.08, 0.04, 0.02, 0.01, 0.005, 0.0025),
        "P3L-Q4G": (0.1, 0.05, 0.025, 0.0125, 0.00625),
        "P4L-Q5G": (0.1, 0.05, 0.025, 0.0125),
        "P2L-Q3G-NE-CE": (0.02, 0.01, 0.005, 0.0025, 0.00125),
        "RK4": (0.01, 0.005, 0.0025, 0.00125, 0.000625),
        "RK4+proj": (0.01, 0.005, 0.0025, 0.00125, 0.000625),
        "SciPy RK45": (1e-4, 1e-6, 1e-8, 1e-10, 1e-12),
        "SciPy DOP853": (1e-4, 1e-6, 1e-8, 1e-10, 1e-12),
        "SciPy Radau": (1e-4, 1e-6, 1e-8),
    },
    long={
        "P1L-Q2G": (0.02, 0.01),
        "P2L-Q3G": (0.04, 0.02, 0.01, 0.005),
        "P3L-Q4G": (0.1, 0.05, 0.025, 0.0125, 0.00625),
        "P4L-Q5G": (0.1, 0.05, 0.025, 0.0125),
        "P2L-Q3G-NE-CE": (0.02, 0.01),
        "RK4": (0.005, 0.0025, 0.00125),
        "RK4+proj": (0.01, 0.005, 0.0025, 0.00125),
        "SciPy RK45": (1e-8, 1e-9),
        "SciPy DOP853": (1e-9, 1e-11, 1e-13),
        "SciPy Radau": (1e-5, 1e-7),
    },
    #: SciPy contenders run over a shorter horizon in panels (b), (c) (cost); label says so
    long_horizon={"SciPy Radau": 100.0},
    #: (method, h) profiled, steps per profiling run, interleaved rounds, budget per timing (s)
    profile=((("P2L-Q3G", 0.01), ("P3L-Q4G", 0.0125), ("P4L-Q5G", 0.025)), 2000, 3, 0.05),
    #: chain(N) sizes of the cost-growth table
    growth=(2, 4, 8, 16, 32, 64, 128, 256),
)
QUICK = dict(
    T_error=1.0,
    T_long=10.0,
    repeats=1,
    error={
        "P1L-Q2G": (0.02, 0.01),
        "P2L-Q3G": (0.05, 0.02),
        "P3L-Q4G": (0.05, 0.025),
        "P4L-Q5G": (0.05, 0.025),
        "P2L-Q3G-NE-CE": (0.02, 0.01),
        "RK4": (0.01, 0.005),
        "RK4+proj": (0.01, 0.005),
        "SciPy RK45": (1e-5, 1e-8),
        "SciPy DOP853": (1e-5, 1e-8),
        "SciPy Radau": (1e-4,),
    },
    long={
        "P2L-Q3G": (0.04, 0.02),
        "P3L-Q4G": (0.05, 0.025),
        "P4L-Q5G": (0.05, 0.025),
        "RK4": (0.005,),
        "RK4+proj": (0.01, 0.005),
        "SciPy DOP853": (1e-6, 1e-9),
    },
    long_horizon={},
    profile=((("P3L-Q4G", 0.0125),), 200, 1, 0.01),
    growth=(2, 4),
)


# ----------------------------------------------------------------------------- SciPy
def _compiled_for(fns):
    """The index-1 right-hand side and the observation loop with the cfuncs frozen in.

    Passing the tuple of cfuncs from Python costs ~0.2 ms per call (numba types each
    first-class function argument on every call); frozen in, a call costs microseconds. One
    compile per model, not cached (cfuncs do not pickle)."""

    @nb.njit(nogil=True, error_model="numpy", boundscheck=False)
    def rhs(flags, Mc, prm, y, dy, ws):
        n = flags[F_N]
        for i in range(n):
            dy[i] = y[n + i]
        return acceleration(fns, flags, Mc, prm, y[:n], y[n:], dy[n:], ws)

    @nb.njit(nogil=True, error_model="numpy", boundscheck=False)
    def observe_all(flags, Mc, prm, Y, out, ws):
        n = flags[F_N]
        q = np.empty(n)
        v = np.empty(n)
        for j in range(Y.shape[0]):
            for i in range(n):
                q[i] = Y[j, i]
                v[i] = Y[j, n + i]
            observe(fns, flags, Mc, prm, q, v, ws, out[j])

    return rhs, observe_all


_COMPILED: dict[int, tuple] = {}


def scipy_run(model, q0, v0, *, t_end: float, method: str, tol: float, t_eval) -> BaselineResult:
    r"""SciPy ``solve_ivp`` (``rtol = atol = tol``) on the index-1 form of ``model``.

    The same equations and compiled physics as :func:`fastvi.baselines.solve_ivp`
    (``y = (q, v) ↦ (v, a(q, v))``, ``a`` from :func:`fastvi.baselines.rk4.acceleration`),
    timed around ``scipy.integrate.solve_ivp`` alone: ``stats["wall_time"]`` and
    ``stats["cpu_time"]`` (CPU time of the calling thread). The energies and residuals at
    ``t_eval`` are evaluated afterwards by a compiled loop (the baseline evaluates them with
    one Python-level call per sample, ~0.2 ms each, which would swamp a long run).
    """
    n = model.n
    prm = check.params(None, model)
    q0, v0 = check.initial_state(model, check.vector(q0, "q0", n), check.vector(v0, "v0", n), prm)
    fns, flags, Mc = model.kernel_arguments()
    key = id(model)
    if key not in _COMPILED or _COMPILED[key][0] is not model:
        _COMPILED[key] = (model, *_compiled_for(fns))
    _, rhs_kernel, observe_all = _COMPILED[key]
    ws = rk_workspace(n, model.m)
    y0 = np.concatenate((q0, v0))
    failure = []
    with quiet():
        rhs_kernel(flags, Mc, prm, y0, np.empty(2 * n), ws)  # compiled outside the timing

        def rhs(t, y):
            dy = np.empty(2 * n)
            st = rhs_kernel(flags, Mc, prm, np.ascontiguousarray(y), dy, ws)
            if st != 0 and not failure:
                failure.append(st)
            return dy

        w0, c0 = time.perf_counter(), time.thread_time()
        sol = scipy.integrate.solve_ivp(rhs, (0.0, float(t_end)), y0, method=method, rtol=tol,
                                        atol=tol, t_eval=t_eval)
        wall, cpu = time.perf_counter() - w0, time.thread_time() - c0
        Y = np.ascontiguousarray(sol.y.T)
        obs = np.zeros((Y.shape[0], OBS_SIZE))
        observe_all(flags, Mc, prm, Y, obs, ws)
    status = Status(failure[0]) if failure else (Status.SUCCESS if sol.success else Status.NONFINITE)
    return BaselineResult(
        t=sol.t.copy(), q=Y[:, :n].copy(), v=Y[:, n:].copy(), energy=obs[:, OBS_H].copy(),
        constraint_residual=obs[:, OBS_G].copy(), velocity_residual=obs[:, OBS_GV].copy(),
        stats=dict(steps=int(sol.nfev), rhs_evaluations=int(sol.nfev), wall_time=wall,
                   cpu_time=cpu, message=sol.message),
        status=status, name=f"SciPy {method}", h=float("nan"), model_name=model.name,
    )


# ----------------------------------------------------------------------------- one point
@dataclass
class Point:
    """One run of one contender: cost and errors from the same run."""

    panel: str  # "error" (a) or "long" (b, c)
    label: str
    knob: float  # h, or rtol = atol
    T: float
    wall: float  # median over `walls`, s
    walls: list = field(default_factory=list)
    cpu: float = float("nan")  # median CPU time of the calling thread, same runs, s
    err_q: float = float("nan")  # max |q(T) − q_ref(T)| (panel a)
    dH: float = float("nan")  # max |H − H(0)|
    g: float = float("nan")  # max |g(q)|
    gv: float = float("nan")  # max |G v|
    work: int = 0  # steps (fixed-step) or right-hand-side evaluations (SciPy)
    newton: float = float("nan")  # Newton iterations per step (fastvi)
    ok: bool = True

    @property
    def kind(self) -> str:
        if self.label.startswith("SciPy"):
            return "scipy"
        if self.label.startswith("RK4"):
            return "rk4"
        return "fastvi"


def _run_once(label, model, q0, v0, knob, T, t_eval):
    """Run a contender once; returns (wall seconds, CPU seconds, result).

    fastvi and RK4: the whole public call. SciPy: ``solve_ivp`` alone (:func:`scipy_run`)."""
    if label.startswith("SciPy"):
        res = scipy_run(model, q0, v0, t_end=T, method=label.split()[1], tol=knob, t_eval=t_eval)
        return res.stats["wall_time"], res.stats["cpu_time"], res
    t0, c0 = time.perf_counter(), time.thread_time()
    if label.startswith("RK4"):
        res = rk4_baseline(model, q0, v0, h=knob, t_end=T, project=label == "RK4+proj",
                           on_failure="return")
    else:
        res = fastvi.integrate(model, q0, v0, h=knob, t_end=T, method=label, on_failure="return")
    return time.perf_counter() - t0, time.thread_time() - c0, res


def measure(panel, label, model, q0, v0, knob, T, repeats, q_ref=None) -> Point:
    """Time one contender at one setting (median of ``repeats``) and record its errors."""
    t_eval = (np.array([0.0, T]) if panel == "error" else
              np.linspace(0.0, T, int(round(T / SAMPLE_DT)) + 1))
    walls, cpus = [], []
    res = None
    for _ in range(repeats):
        w, c, res = _run_once(label, model, q0, v0, knob, T, t_eval)
        walls.append(w)
        cpus.append(c)
        if w > LONG_RUN:
            break
    pt = Point(panel, label, knob, T, float(np.median(walls)), walls, float(np.median(cpus)))
    pt.ok = bool(res.success) and bool(np.isclose(res.t[-1], T))
    pt.dH = float(np.max(np.abs(res.energy - res.energy[0])))
    pt.g = float(np.max(res.constraint_residual))
    pt.gv = float(np.max(res.velocity_residual))
    pt.work = int(res.stats["steps"])
    if "newton_iterations" in res.stats:
        pt.newton = res.stats["newton_iterations"] / max(1, res.stats["steps"])
    if q_ref is not None and pt.ok:
        pt.err_q = float(np.max(np.abs(res.q[-1] - q_ref)))
    if not (np.isfinite(pt.dH) and np.isfinite(pt.g)):
        pt.ok = False
    return pt


def reference_q(T: float, tol: float = REF_TOL) -> np.ndarray:
    """Cartesian q(T) of the double pendulum from θ = (π/2, π/2) at rest (angle-coordinate DOP853)."""
    th, om = chain_pendulum_reference(THETA0, (0.0, 0.0), [T], (1.0, 1.0), (1.0, 1.0), tol=tol)
    return chain_cartesian(th, om, (1.0, 1.0))[0][0]


def warm_up(model, q0, v0, labels, log) -> None:
    """Compile (or load from numba's cache) everything before timing anything."""
    t0 = time.perf_counter()
    for label in labels:
        knob = 1e-3 if label.startswith("SciPy") else 0.01
        _run_once(label, model, q0, v0, knob, 0.1, np.array([0.0, 0.1]))
    log(f"warm-up (compilation / cache loads): {time.perf_counter() - t0:.1f} s")


def sweep(cfg, model, q0, v0, log) -> list[Point]:
    """Panels (a) and (b, c): every contender at every setting of the configuration."""
    points = []
    T_a = cfg["T_error"]
    q_ref = reference_q(T_a)
    for label, knobs in cfg["error"].items():
        for knob in knobs:
            pt = measure("error", label, model, q0, v0, knob, T_a, cfg["repeats"], q_ref)
            points.append(pt)
            log(f"(a) {label:<36} {knob:<9g} wall {pt.wall:8.4f} s  |Δq| {pt.err_q:.2e}")
    for label, knobs in cfg["long"].items():
        T = cfg["long_horizon"].get(label, cfg["T_long"])
        for knob in knobs:
            pt = measure("long", label, model, q0, v0, knob, T, cfg["repeats"])
            points.append(pt)
            log(f"(b) {label:<36} {knob:<9g} T {T:<6g} wall {pt.wall:8.3f} s  max|ΔH| {pt.dH:.2e}"
                f"  max|g| {pt.g:.1e}{'' if pt.ok else '  FAILED'}")
    return points


# ----------------------------------------------------------------------------- comparisons
#: the methods "fastvi's best" is chosen from: the defaults (paper B's -NE-CE variant is on
#: the diagrams, but on the double pendulum it is the same map as P1L-Q2G, RATTLE)
BEST_OF = FASTVI_METHODS[:4]
#: which runs a metric is read from
_PANEL = {"err_q": "error", "dH": "long", "g": "long"}


def pareto(points, metric: str, cost: str = "wall"):
    """(error, cost) of the runs that no cheaper run of the same set beats in error.

    Returns two arrays, by increasing cost (so decreasing error)."""
    pts = sorted((p for p in points if p.ok and np.isfinite(getattr(p, metric))
                  and getattr(p, metric) > 0), key=lambda p: getattr(p, cost))
    errs, costs = [], []
    for p in pts:
        e = getattr(p, metric)
        if not errs or e < errs[-1]:
            errs.append(e)
            costs.append(getattr(p, cost))
    return np.array(errs), np.array(costs)


def cost_at(points, metric: str, E, cost: str = "wall"):
    """Cost to reach error ``E``: log–log interpolation on the Pareto front, NaN outside it."""
    errs, costs = pareto(points, metric, cost)
    E = np.atleast_1d(np.asarray(E, float))
    out = np.full(E.shape, np.nan)
    if len(errs) < 2:
        return out
    le, lc = np.log(errs[::-1]), np.log(costs[::-1])  # increasing error
    inside = (E >= errs.min()) & (E <= errs.max())
    out[inside] = np.exp(np.interp(np.log(E[inside]), le, lc))
    return out


def _select(points, metric, label=None, labels=None):
    panel = _PANEL[metric]
    return [p for p in points if p.panel == panel and (label is None or p.label == label)
            and (labels is None or p.label in labels)]


def best_fastvi(points, metric, E, cost: str = "wall"):
    """(cost, method) of the cheapest of :data:`BEST_OF` at each error level ``E``."""
    E = np.atleast_1d(E)
    costs = np.array([cost_at(_select(points, metric, m), metric, E, cost) for m in BEST_OF])
    best = np.full(E.shape, np.nan)
    which = np.full(E.shape, "", dtype=object)
    for k in range(len(E)):
        col = costs[:, k]
        if np.any(np.isfinite(col)):
            j = int(np.nanargmin(col))
            best[k], which[k] = col[j], BEST_OF[j]
    return best, which


def _grid(lo, hi, per_decade):
    return np.logspace(np.log10(hi), np.log10(lo), max(2, int(per_decade * np.log10(hi / lo)) + 1))


def compare(points, metric: str, rival: str, cost: str = "wall", per_decade: int = 40):
    """Speed-up of the best fastvi method over ``rival`` at equal error (a fine error grid).

    Returns ``(E, ratio, method)`` over the error range both Pareto fronts cover (empty if
    they do not overlap), ``E`` decreasing."""
    e1, _ = pareto(_select(points, metric, rival), metric, cost)
    fronts = [pareto(_select(points, metric, m), metric, cost)[0] for m in BEST_OF]
    e2 = np.concatenate([f for f in fronts if len(f) >= 2] or [np.array([])])
    empty = (np.array([]), np.array([]), np.array([]))
    if len(e1) < 2 or len(e2) < 2:
        return empty
    lo, hi = max(e1.min(), e2.min()), min(e1.max(), e2.max())
    if not lo < hi:
        return empty
    E = _grid(lo, hi, per_decade)
    fw, which = best_fastvi(points, metric, E, cost)
    ratio = cost_at(_select(points, metric, rival), metric, E, cost) / fw
    keep = np.isfinite(ratio)
    return E[keep], ratio[keep], which[keep]


def crossings(E, ratio, target: float) -> list[float]:
    """Error levels where ``ratio`` crosses ``target`` (log-linear interpolation)."""
    out = []
    d = np.log(ratio) - np.log(target)
    for k in range(len(E) - 1):
        if d[k] == 0.0:
            out.append(float(E[k]))
        elif d[k] * d[k + 1] < 0:
            f = d[k] / (d[k] - d[k + 1])
            out.append(float(np.exp(np.log(E[k]) + f * (np.log(E[k + 1]) - np.log(E[k])))))
    return out


def method_crossovers(points, metric: str, per_decade: int = 40):
    """Error ranges where each of :data:`BEST_OF` is the cheapest: [(method, E_hi, E_lo)]."""
    fronts = [pareto(_select(points, metric, m), metric)[0] for m in BEST_OF]
    errs = np.concatenate([f for f in fronts if len(f) >= 2] or [np.array([])])
    if len(errs) < 2:
        return []
    E = _grid(errs.min(), errs.max(), per_decade)
    _, which = best_fastvi(points, metric, E)
    spans = []
    for e, w in zip(E, which):
        if not w:
            continue
        if spans and spans[-1][0] == w:
            spans[-1][2] = e
        else:
            spans.append([w, e, e])
    # a method cheapest at a single grid point only is interpolation noise between two others
    return [tuple(s) for s in spans if s[1] != s[2] or len(spans) == 1]


# ----------------------------------------------------------------------------- profile
def _per_call(fn, *args, budget: float = 0.05, repeats: int = 5) -> float:
    """CPU seconds per iteration of a compiled loop ``fn(*args, K)``: the minimum of
    ``repeats`` timings of ``K`` iterations, ``K`` grown until one takes ``budget`` seconds.
    CPU time of the calling thread, and the minimum, because on a shared machine both keep
    other jobs' load (and idle-spinning BLAS threads) out of a measurement of the code."""
    fn(*args, 1)
    K = 1
    while True:
        t0 = time.thread_time()
        fn(*args, K)
        dt = time.thread_time() - t0
        if dt > budget or K > 1 << 22:
            break
        K *= 4
    cpus = []
    for _ in range(repeats):
        t0 = time.thread_time()
        fn(*args, K)
        cpus.append((time.thread_time() - t0) / K)
    return float(np.min(cpus))


def newton_matrix(model, q, p, v, method: str, h: float) -> np.ndarray:
    """The Newton matrix of one step from the state ``(q, p, v)``, at the converged unknowns.

    Its sparsity matters for timing: the LU of :mod:`fastvi.kernels.linalg` skips zero
    multipliers, so a random dense matrix of the same size would overstate its cost."""
    meth = fastvi.method(method)
    md = model.kernel_data()
    n, m = model.n, model.m
    N = meth.s * n + meth.J * m
    q, p, v = (np.ascontiguousarray(x, dtype=float) for x in (q, p, v))
    with quiet():
        st, ws = _one_full_step(md, meth, h, q, p, v)
        if st != 0:
            raise RuntimeError(f"the step for the Newton matrix failed with status {st}")
        assemble(md, meth.kernel_tables, h, q, p, ws, True)
    return ws.A[:N, :N].copy()


def _one_full_step(md, meth, h, q, p, v):
    """One full-Newton step from ``(q, p, v)``: ``(status, workspace)`` (the profile's
    parts are those of the full Newton)."""
    n = q.shape[0]
    ws = vi_workspace(n, int(md.flags[F_M]), meth.s, meth.r, meth.J)
    state = np.zeros((6, n))
    state[0], state[1], state[2] = q, p, v
    st = _vi_step(md, meth.kernel_tables, NewtonOptions(1e-14, 30, NEWTON_FULL), h, state, ws,
                  True, np.zeros(STEP_OUT_SIZE))
    return st, ws


def lu_factor_cost(A0: np.ndarray, budget: float = 0.05, repeats: int = 3) -> float:
    """CPU seconds of one in-place LU factorisation of (a copy of) ``A0``, copy excluded."""
    N = A0.shape[0]
    A, piv = np.zeros_like(A0), np.zeros(N, dtype=np.int64)
    return max(0.0, _per_call(loop_lu, A0, A, piv, N, True, budget=budget, repeats=repeats)
               - _per_call(loop_lu, A0, A, piv, N, False, budget=budget, repeats=repeats))


def profile_step(model, q0, v0, method: str, h: float, n_steps: int = 2000, rounds: int = 3,
                 budget: float = 0.05) -> dict:
    r"""Cost of the parts of one full-Newton fastvi step, in CPU seconds (of this thread) per call.

    Runs ``n_steps`` steps with :func:`fastvi.integrate` (the cost per step, and Newton
    iterations per step), and times each kernel alone on the state reached: the residual with the
    Newton matrix (``assemble(jac=True)``, once per Newton iteration), the dense LU
    factorisation and solve of the ``N × N`` Newton matrix (``N = s n + J m``, once per
    iteration), the residual alone (once per step, for the end momentum), the RATTLE
    momentum projection (``end_momentum``, once per step), and one model callback (∇V).

    Returns
    -------
    dict
        ``step``, ``assemble_jac``, ``lu_factor``, ``lu_solve``, ``assemble_res``,
        ``end_momentum``, ``callback`` (s per call), ``iterations`` (Newton, per step),
        ``N`` (Newton matrix rows), ``shares`` (each part × its calls per step / ``step``)
        and ``other`` = 1 − Σ shares: the predictor, bookkeeping, saving every step and the
        Python driver; it comes out negative when the machine's load inflated the parts'
        timings more than the step's.
    """
    meth = fastvi.method(method)
    md = model.kernel_data()
    fns, prm = md.fns, md.prm
    tabs = meth.kernel_tables
    n, m = model.n, model.m
    N = meth.s * n + meth.J * m
    with quiet():
        fastvi.integrate(model, q0, v0, h=h, n_steps=2, method=method, newton="full")
        res = fastvi.integrate(model, q0, v0, h=h, n_steps=n_steps, method=method, newton="full")
    its = res.stats["newton_iterations"] / res.stats["steps"]
    qk, pk, vk = res.q[-1].copy(), res.p[-1].copy(), res.v[-1].copy()
    q1, p1, v1 = np.zeros(n), np.zeros(n), np.zeros(n)
    t: dict[str, float] = {}
    with quiet():
        st, ws = _one_full_step(md, meth, h, qk, pk, vk)
        if st != 0:
            raise RuntimeError(f"profile step failed with status {st}")
        # the Newton matrix at the converged unknowns, then its factors
        assemble(md, tabs, h, qk, pk, ws, True)
        A0 = ws.A[:N, :N].copy()
        R0 = ws.R[:N].copy()
        A, piv, R = np.zeros((N, N)), np.zeros(N, dtype=np.int64), np.zeros(N)
        P = ws.P.copy()
        # rounds interleave the whole step with its parts; each keeps its fastest round, so
        # a burst of other load shifts no part against the others
        timed = dict(budget=budget, repeats=3)
        for _ in range(rounds):
            t0 = time.thread_time()
            fastvi.integrate(model, q0, v0, h=h, n_steps=n_steps, method=method, newton="full")
            parts = dict(
                step=(time.thread_time() - t0) / n_steps,
                assemble_jac=_per_call(loop_assemble, md, tabs, h, qk, pk, ws, True, **timed),
                assemble_res=_per_call(loop_assemble, md, tabs, h, qk, pk, ws, False, **timed),
                lu_factor=lu_factor_cost(A0, **timed),
                lu_solve=_per_call(loop_solve, A, piv, R0, R, N, **timed),
                end_momentum=_per_call(loop_end, md, q1, P, p1, v1, ws.G[meth.J], ws,
                                       np.zeros(STEP_OUT_SIZE), **timed),
                callback=_per_call(loop_callback, fns[_PGRAD], qk.copy(), prm, np.zeros(n), **timed),
            )
            for k, v in parts.items():
                t[k] = min(t.get(k, np.inf), v)
    step_cost = t.pop("step")
    calls = dict(assemble_jac=its, lu_factor=its, lu_solve=its, assemble_res=1.0, end_momentum=1.0)
    shares = {k: t[k] * calls[k] / step_cost for k in calls}
    shares["other"] = 1.0 - sum(shares.values())
    return dict(step=step_cost, iterations=its, N=N, n=n, m=m, method=method, h=h, shares=shares,
                **t)


# ----------------------------------------------------------------------------- cost growth
GROWTH_METHOD = "P2L-Q3G"
GROWTH_H = 0.01
GROWTH_STEP_BUDGET = 20_000  # steps(N) ≈ budget / N: the structured step costs O(N)
GROWTH_MIN_STEPS = 20


def chain_angles(N: int) -> np.ndarray:
    """The start of the cost-growth runs: a smooth arc of link angles, at most 0.6 rad."""
    return 0.6 * np.sin(np.linspace(0.3, 2.8, N))


def growth_steps(N: int) -> int:
    """Steps timed for ``chain(N)``: fewer for large N, so each run takes ~10–50 ms."""
    return int(max(GROWTH_MIN_STEPS, min(10_000, GROWTH_STEP_BUDGET // N)))


def fit_exponent(rows: dict, key: str = "cpu_per_step") -> dict:
    """Least-squares slope of log(cost per step) against log N, and the local slopes."""
    Ns = np.array(sorted(rows))
    c = np.array([rows[N][key] for N in Ns])
    slope = float(np.polyfit(np.log(Ns), np.log(c), 1)[0])
    local = {f"{a}-{b}": float(np.log(c[i + 1] / c[i]) / np.log(b / a))
             for i, (a, b) in enumerate(zip(Ns[:-1], Ns[1:]))}
    return dict(exponent=slope, local=local, sizes=[int(N) for N in Ns])


def chain_cost(N: int, method: str = GROWTH_METHOD, h: float = GROWTH_H) -> dict:
    r"""Cost per step of ``method`` on ``fastvi.scenes.chain(N)`` and how its systems are solved.

    The integration loop's time per step (``stats["integration_time"]``: set-up — pattern,
    ordering, initial projection — excluded; best of two runs of :func:`growth_steps`
    steps), Newton iterations per step, the solvers and Schur bandwidth of the plan
    (:func:`fastvi.structure.plan`) and the constraint residual.
    """
    from .. import structure

    model = fastvi.scenes.chain(N)
    q0, v0 = model.initial_state(chain_angles(N))
    steps = growth_steps(N)
    meth = fastvi.method(method)
    with quiet():
        fastvi.integrate(model, q0, v0, h=h, n_steps=2, method=method)
        per = []
        for _ in range(2):
            res = fastvi.integrate(model, q0, v0, h=h, n_steps=steps, method=method,
                                   save_every=steps)
            per.append(res.stats["integration_time"] / steps)
    plan = structure.plan(model, meth)
    its = res.stats["newton_iterations"] / res.stats["steps"]
    return dict(N=N, rows=meth.s * model.n + meth.J * model.m, steps=steps,
                cpu_per_step=min(per), iterations=its, solvers=plan.solvers,
                band=plan.bandwidths.get("schur"), g=float(np.max(res.constraint_residual)))


def growth_lines(rows: dict) -> list[str]:
    """The cost-growth section: table, fitted exponent and local slopes."""
    if len(rows) < 2:
        return []
    f = fit_exponent(rows)
    P = ["## Cost growth with the number of bodies\n",
         f"`fastvi.scenes.chain(N)` (n = 2N, m = N constraints), `{GROWTH_METHOD}`, "
         f"h = {GROWTH_H:g}, at rest from a smooth arc of angles; time per step of the "
         "integration loop (`stats[\"integration_time\"]`, best of two runs; fewer steps for "
         "large N), with the linear solves `solver=\"auto\"` chose for the Schur complement of "
         "the mechanics iteration and the end projection (`fastvi.structure`: banded after a "
         "reverse Cuthill–McKee ordering for a chain) and the Schur complement's bandwidth. "
         "The same measurement under pytest-benchmark, with the dense path beside it: "
         "`bench/test_bench_chain.py`; the crossover dense / banded / sparse on chains, "
         "ladders and trees: `docs/benchmarks.md`.\n",
         "| N | Newton rows | steps | µs/step | Newton its/step | Schur / projection | Schur band (kl, ku) | max\\|g\\| |",
         "|---|---|---|---|---|---|---|---|"]
    for N in sorted(rows):
        r = rows[N]
        sv = r["solvers"]
        band = "–" if r["band"] is None or sv["schur"] == "dense" else f"({r['band'][0]}, {r['band'][1]})"
        P.append(f"| {N} | {r['rows']} | {r['steps']} | {1e6 * r['cpu_per_step']:.1f} | "
                 f"{r['iterations']:.2f} | {sv['schur']} / {sv['projection']} | {band} | {r['g']:.1e} |")
    Ns = f["sizes"]
    P.append("")
    P.append(f"Fitted exponent of the cost per step over N = {Ns[0]}…{Ns[-1]}: **{f['exponent']:.2f}**; "
             "local slopes " + ", ".join(f"{k}: {v:.2f}" for k, v in f["local"].items()) + ".")
    P.append("")
    return P


def splice_growth(path: str, rows: dict, command: str) -> None:
    """Replace the cost-growth section of an existing page ``path`` (``--growth-only``)."""
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    head, sep, rest = text.partition("## Cost growth with the number of bodies\n")
    if not sep:
        raise ValueError(f"{path} has no section '## Cost growth with the number of bodies'")
    _, sep2, tail = rest.partition("\n## ")
    lines = growth_lines(rows)
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    lines.insert(1, f"*This section regenerated alone on {stamp}: `{command}`.*\n")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(head + "\n".join(lines) + (sep2 + tail if sep2 else ""))


# ----------------------------------------------------------------------------- figures
_STYLE = {"fastvi": dict(ls="-", marker="o"), "rk4": dict(ls="--", marker="s"),
          "scipy": dict(ls=":", marker="^")}
PANELS = (
    ("error", "err_q", "wpd-q-error.png", "error of q at T = {T_error:g} s (max-norm, m)",
     "(a) position error at T = {T_error:g} s vs reference"),
    ("long", "dH", "wpd-energy.png", "max |H(t) − H(0)| over T = {T_long:g} s (J)",
     "(b) maximum energy error over T = {T_long:g} s"),
    ("long", "g", "wpd-constraint.png", "max |g(q)| over T = {T_long:g} s (m²)",
     "(c) maximum constraint residual over T = {T_long:g} s"),
)


def _label(p: Point, cfg) -> str:
    T = cfg["long_horizon"].get(p.label)
    return p.label + (f" (T = {T:g} s only)" if p.panel == "long" and T else "")


def figures(points, cfg, outdir: str, log) -> list[str]:
    """Write the three log–log diagrams; returns their paths relative to ``outdir``."""
    try:
        import matplotlib
    except ImportError:
        log("matplotlib is not installed (pip install fastvi[plot]): no figures")
        return []
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(os.path.join(outdir, "figures"), exist_ok=True)
    paths = []
    for panel, metric, fname, xlabel, title in PANELS:
        fig, ax = plt.subplots(figsize=(8, 5.5))
        labels = list(dict.fromkeys(p.label for p in points if p.panel == panel))
        for k, label in enumerate(labels):
            pts = sorted((p for p in points if p.panel == panel and p.label == label and p.ok
                          and getattr(p, metric) > 0), key=lambda p: p.knob, reverse=True)
            if not pts:
                continue
            st = _STYLE[pts[0].kind]
            floor = 1e-17 if metric == "g" else 0.0
            ax.loglog([max(getattr(p, metric), floor) for p in pts], [p.wall for p in pts],
                      ls=st["ls"], marker=st["marker"], color=f"C{k % 10}", label=_label(pts[0], cfg))
        if metric == "err_q":
            ax.axvline(cfg.get("ref_floor", np.nan), color="0.6", lw=0.8, ls="-.",
                       label="reference uncertainty")
        ax.set_xlabel(xlabel.format(**cfg))
        ax.set_ylabel("wall time (s)")
        ax.set_title(title.format(**cfg) + ", double pendulum")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
        fig.tight_layout()
        rel = f"figures/{fname}"
        fig.savefig(os.path.join(outdir, rel), dpi=110)
        plt.close(fig)
        paths.append(rel)
    return paths


# ----------------------------------------------------------------------------- the page
def _fmt_ratio(x: float) -> str:
    return f"{x:.3g}×" if np.isfinite(x) else "–"


def _at_decades(E, ratio, which):
    """The ratio (and the fastvi method) at each power of ten inside ``E``."""
    out = []
    for k in range(int(np.floor(np.log10(E.max()))), int(np.ceil(np.log10(E.min()))) - 1, -1):
        d = 10.0 ** k
        if E.min() <= d <= E.max():
            j = int(np.argmin(np.abs(np.log(E) - np.log(d))))
            out.append((d, float(ratio[j]), which[j]))
    return out


#: (rival, goal) of the comparisons at equal max|ΔH| over T = 1000 s; None: no goal, reported
RIVALS = (("SciPy DOP853", GOAL_SCIPY), ("RK4+proj", GOAL_RK4), ("RK4", GOAL_RK4),
          ("SciPy RK45", None), ("SciPy Radau", None))
#: rivals of the position-error comparison (panel a), all reported without a goal
RIVALS_A = ("SciPy DOP853", "RK4+proj", "RK4", "SciPy RK45", "SciPy Radau")


def comparison_lines(points, metric: str, rival: str, goal, what: str, unit: str) -> tuple[list[str], dict]:
    """One bullet (and sub-lines) comparing the best fastvi method with ``rival`` at equal error.

    ``goal`` (a ratio, or None) adds a verdict, the error where the ratio crosses it and the
    trend of the ratio beyond the measured range. Break-even points (ratio = 1) are always
    stated. Returns the lines and ``{"E", "ratio", "which", "cpu_ratio"}`` (empty if the
    rival's and fastvi's errors do not overlap)."""
    E, ratio, which = compare(points, metric, rival)
    if len(E) == 0:
        return [f"- **vs {rival}**: its {what} and fastvi's do not overlap (see the table): no "
                "ratio at equal error."], {}
    _, rc, _ = compare(points, metric, rival, cost="cpu")
    k_lo, k_hi = int(np.argmin(ratio)), int(np.argmax(ratio))
    head = f"- **vs {rival}**"
    met_all = goal is not None and bool(np.all(ratio >= goal))
    if goal is not None:
        verdict = ("met over the whole common range" if met_all else
                   "met only in part of the range" if np.any(ratio >= goal) else "**not met**")
        head += f" (goal ≥ {goal:g}×): {verdict}"
    else:
        head += " (no goal)"
    dec = "; ".join(f"{r:.3g}× at {d:.0e} {unit} ({w})" for d, r, w in _at_decades(E, ratio, which))
    lines = [head + f". Over {what} from {E.max():.1e} to {E.min():.1e} {unit} the best fastvi method "
             f"is {ratio.min():.3g}× ({which[k_lo]}, at {E[k_lo]:.1e} {unit}) to {ratio.max():.3g}× "
             f"({which[k_hi]}, at {E[k_hi]:.1e} {unit}) faster" + (f"; at each decade: {dec}" if dec else "")
             + "." + (f" In CPU time (insensitive to other jobs' load): {rc.min():.3g}× to "
                      f"{rc.max():.3g}×." if len(rc) else "")]
    cross = crossings(E, ratio, goal) if goal not in (None, 1.0) else []
    even = crossings(E, ratio, 1.0)
    if cross:
        lines.append(f"  Crossover (ratio = {goal:g}×) at {what} ≈ "
                     + ", ".join(f"{c:.1e}" for c in cross) + f" {unit}.")
    if even:
        lines.append(f"  Break-even (ratio = 1×, the rival is cheaper on the looser side) at "
                     f"{what} ≈ " + ", ".join(f"{c:.1e}" for c in even) + f" {unit}."
                     if ratio[0] < 1.0 else
                     f"  Break-even (ratio = 1×) at {what} ≈ " + ", ".join(f"{c:.1e}" for c in even)
                     + f" {unit}.")
    if not cross and not even:
        ref = goal if goal is not None else 1.0
        lines.append(f"  No crossover inside the common range: the ratio stays "
                     f"{'above' if ratio.min() >= ref else 'below'} {ref:g}×.")
    if goal is not None and not met_all and len(E) > 2:
        # log ratio against log error, least squares: the trend beyond the common range
        slope = np.polyfit(np.log10(E), np.log10(ratio), 1)[0]
        per_dec = 10.0 ** (-slope)
        if per_dec > 1.0 + 1e-3:
            E_goal = 10.0 ** (np.log10(E[-1]) - np.log10(goal / ratio[-1]) / np.log10(per_dec))
            lines.append(f"  Trend: the ratio grows ≈ {per_dec:.2f}× per decade of accuracy; "
                         f"continued, it would reach {goal:g}× at {what} ≈ {E_goal:.0e} {unit}"
                         + (" (below round-off: never in practice)." if E_goal < 1e-13 else
                            " (an extrapolation, not a measurement)."))
        else:
            lines.append("  Trend: the ratio does not grow with accuracy.")
    return lines, dict(E=E, ratio=ratio, which=which, cpu_ratio=rc)


def goal_lines(points, cfg) -> tuple[list[str], dict]:
    """The goal verdicts and crossover points at equal max|ΔH| over T = 1000 s (panel b).

    Returns the Markdown lines and ``{rival: {"E", "ratio", "which", "cpu_ratio"}}``."""
    lines, summary = [], {}
    what = f"max|ΔH| over T = {cfg['T_long']:g} s"
    for rival, goal in RIVALS:
        if not _select(points, "dH", rival):
            continue
        ls, data = comparison_lines(points, "dH", rival, goal, what, "J")
        lines += ls
        if data:
            summary[rival] = data
    return lines, summary


def limits_lines(points, prof, cfg) -> list[str]:
    """What a 100× lead over DOP853 would need from a fastvi step, against what it costs."""
    dop = [p for p in _select(points, "dH", "SciPy DOP853") if p.ok]
    rk = [p for p in _select(points, "dH", "RK4+proj") if p.ok]
    lines = []
    if dop:
        per_eval = np.median([p.wall / p.work for p in dop])
        lines.append(f"SciPy DOP853 costs {1e6 * per_eval:.1f} µs per right-hand-side evaluation "
                     f"(wall time / nfev, median over its runs of panel b)")
        if rk:
            per_rk = np.median([p.wall / (4 * p.work) for p in rk])
            lines[-1] += (f"; the compiled index-1 physics behind one evaluation costs ≈ "
                          f"{1e6 * per_rk:.1f} µs (RK4+proj's wall time per evaluation, projection "
                          "included), so most of DOP853's cost is SciPy's Python per stage")
        lines[-1] += "."
    need = []
    for p in dop:
        best, which = best_fastvi(points, "dH", np.array([p.dH]))
        if not which[0]:
            continue
        steps = cost_at(_select(points, "dH", which[0]), "dH", np.array([p.dH]), cost="work")[0]
        if np.isfinite(steps):
            need.append((p, which[0], steps, p.wall / (GOAL_SCIPY * steps), best[0] / steps))
    if need:
        lines.append(
            f"Over T = {cfg['T_long']:g} s, for a 100× lead at DOP853's own accuracies a fastvi "
            "step would have to cost "
            + "; ".join(f"{1e6 * r:.2f} µs at max|ΔH| = {p.dH:.1e} J (DOP853: {p.work} evaluations "
                        f"in {p.wall:.2f} s; {w}: ≈ {n:.0f} steps at {1e6 * c:.1f} µs each)"
                        for p, w, n, r, c in need) + ".")
        factors = [c / r for _, _, _, r, c in need]
        lines.append(f"fastvi's step would have to become {min(factors):.0f}–{max(factors):.0f}× "
                     "cheaper.")
        if prof:
            res_min = min(pr["assemble_res"] for pr in prof)
            worst = max(r for _, _, _, r, _ in need)
            if worst < res_min:
                lines.append(
                    f"Even one evaluation of the residual of the step equations, which every "
                    f"Newton iteration needs, costs {1e6 * res_min:.2f} µs (profile table): more "
                    "than the whole budget of a step.")
        lines.append(
            "A 100× lead presumes that SciPy pays a large overhead per evaluation; with a "
            f"compiled right-hand side it pays {1e6 * per_eval:.1f} µs, and DOP853 (order 8) "
            "takes long steps.")
    return lines


def _table(points, panel, metric_cols, cfg) -> list[str]:
    head = "| contender | h or tol | T (s) | wall (s) | CPU (s) | runs | " \
        + " | ".join(c[0] for c in metric_cols) + " | steps or nfev | Newton its/step |"
    out = [head, "|" + "---|" * (8 + len(metric_cols))]
    for p in points:
        if p.panel != panel:
            continue
        vals = " | ".join(("FAILED" if not p.ok else f"{getattr(p, c[1]):.2e}") for c in metric_cols)
        nt = f"{p.newton:.2f}" if np.isfinite(p.newton) else ""
        out.append(f"| {p.label} | {p.knob:g} | {p.T:g} | {p.wall:.4g} | {p.cpu:.4g} | {len(p.walls)} | {vals} | "
                   f"{p.work} | {nt} |")
    return out


def markdown(points, cfg, figs, prof, ref_floor, command, elapsed, growth=None) -> str:
    goals, summary = goal_lines(points, cfg)
    spans = method_crossovers(points, "dH")
    spans_a = method_crossovers(points, "err_q")
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    P = []
    P.append("# Speed against error: work–precision diagrams\n")
    P.append(f"Generated by `{command}` ({now}; {platform.machine()}, {os.cpu_count()} cores, "
             f"load average {load:.1f} at the end; Python {platform.python_version()}, "
             f"numba {nb.__version__}, NumPy {np.__version__}, SciPy {scipy.__version__}; the run "
             f"took {elapsed / 60:.1f} min). Do not edit by hand: rerun the command.\n")
    P.append(
        "**Problem.** The planar double pendulum in Cartesian coordinates "
        "(`fastvi.scenes.double_pendulum()`, n = 4, m = 2 constraints, unit masses and rods, "
        "g = 9.81), released at rest from θ1 = θ2 = π/2 (paper B's start; the motion is chaotic). "
        "Every contender integrates the same `fastvi.Model` callbacks:\n\n"
        "- fastvi `P1L-Q2G` … `P4L-Q5G` (default Lobatto nodes, constraints at every node; orders "
        "2, 4, 6, 8) and paper B's scheme `P2L-Q3G-NE-CE` (order 2), default Newton tolerance "
        "1e-14, sweeping h;\n"
        "- `RK4`, `RK4+proj`: `fastvi.baselines.rk4`, classical RK4 on the index-1 form "
        "(numba), without / with projection onto g = 0, Gv = 0 after every step, sweeping h;\n"
        "- `SciPy RK45`, `SciPy DOP853`, `SciPy Radau`: `scipy.integrate.solve_ivp` on the same "
        "index-1 right-hand side (the compiled `fastvi.baselines.rk4.acceleration`), sweeping "
        "rtol = atol (`fastvi.studies.wpd.scipy_run`: the equations of "
        "`fastvi.baselines.solve_ivp`, with the model's cfuncs frozen into the compiled "
        "right-hand side, a few µs per call, so SciPy's own per-step overhead is what is "
        "measured).\n")
    P.append(
        f"**Measurements.** Wall time after compilation: fastvi and RK4, the whole public call "
        f"(`fastvi.integrate` / `fastvi.baselines.rk4`: validation, the initial projection, "
        f"the loop, energies and residuals at every step); SciPy, `scipy.integrate.solve_ivp` "
        f"alone (`fastvi.studies.wpd.scipy_run`; its energies are evaluated afterwards), "
        + (f"median of {cfg['repeats']} runs (runs longer than {LONG_RUN:g} s timed once). "
           if cfg["repeats"] > 1 else "one run each. ")
        + f"(a) max-norm of q(T) − q_ref(T) at T = {cfg['T_error']:g} s, q_ref from SciPy DOP853 at "
        f"rtol = atol = {REF_TOL:g} in angle coordinates (independent of fastvi); the reference "
        f"itself is uncertain at ≈ {ref_floor:.0e} (its distance to the same solve at tolerance "
        f"1e-12), so errors below that are not resolved. (b) max over the run of |H − H(0)| over "
        f"T = {cfg['T_long']:g} s (fastvi and RK4: every step; SciPy: its dense output every "
        f"{SAMPLE_DT:g} s: denser output would cost it extra evaluations, and sparser sampling "
        f"can only lower its maximum). (c) max |g(q)| over the runs of (b).\n")
    P.append(
        "**Noise.** The machine (2 cores) was shared with other jobs while this ran; single "
        "timings vary by tens of per cent, and load that comes and goes during the sweeps "
        "shifts one contender against another. The CPU time of the calling thread "
        "(`time.thread_time`), recorded for the same runs, is insensitive to the other jobs; "
        "the ratios are given both ways. (Every contender here runs in that one thread: the "
        "matrices are too small for BLAS to use its threads.) Read the ratios to within a "
        "factor ≈ 1.5, not to three digits.\n")
    P.append("## Where fastvi stands (goals of issue 6)\n")
    P.append(f"At equal maximum energy error over T = {cfg['T_long']:g} s, wall time of the rival "
             "divided by that of the cheapest fastvi method at that error (log–log interpolation "
             "between measured points, only where both curves have points):\n")
    P.extend(goals)
    P.append("")
    if spans:
        P.append("**Which fastvi method is cheapest** at a given max|ΔH| over "
                 f"T = {cfg['T_long']:g} s: " + "; ".join(
                     f"{w} from {a:.1e} down to {b:.1e}" for w, a, b in spans) + ".\n")
    if spans_a:
        P.append(f"For the position error at T = {cfg['T_error']:g} s: " + "; ".join(
            f"{w} from {a:.1e} down to {b:.1e}" for w, a, b in spans_a) + ".\n")
    # position-error comparison (panel a): no goal, but the crossovers
    what_a = f"error of q at T = {cfg['T_error']:g} s"
    lines_a = []
    for rival in RIVALS_A:
        if _select(points, "err_q", rival):
            lines_a += comparison_lines(points, "err_q", rival, None, what_a, "m")[0]
    if lines_a:
        P.append(f"At equal position error at T = {cfg['T_error']:g} s (panel a; short runs, so "
                 "fixed costs such as validation and the initial projection weigh more):\n")
        P.extend(lines_a)
        P.append("")
    lim = limits_lines(points, prof, cfg)
    if prof:
        P.append("## What a step costs\n")
        P.append("`fastvi.studies.wpd.profile_step`, in CPU time of the thread: the cost per "
                 "step of `fastvi.integrate` with `newton=\"full\"` (saving every step; the "
                 "default mechanics-matrix iteration is profiled in `docs/benchmarks.md`), and "
                 "each kernel of the full Newton timed alone in a "
                 "compiled loop on the same state, times its calls per step (Newton iterations "
                 f"for the parts inside Newton's loop); fastest of {cfg['profile'][2]} "
                 "interleaved round(s). "
                 "*other* = the step minus the parts (predictor, bookkeeping, saving, the Python "
                 "driver); negative values mean the machine's load inflated the parts more than "
                 "the step, i.e. the noise of this table. One model callback (∇V) costs "
                 f"{1e9 * min(pr['callback'] for pr in prof):.0f} ns per call: the model is not "
                 "what a step spends its time on.\n")
        P.append("| method | h | N (Newton rows) | µs/step | Newton its/step | residual + Newton matrix | "
                 "LU factor | LU solve | residual (end) | momentum projection | other |")
        P.append("|---|---|---|---|---|---|---|---|---|---|---|")
        for pr in prof:
            s = pr["shares"]
            P.append(
                f"| {pr['method']} | {pr['h']:g} | {pr['N']} | {1e6 * pr['step']:.1f} | "
                f"{pr['iterations']:.2f} | {1e6 * pr['assemble_jac']:.2f} µs ({100 * s['assemble_jac']:.0f}%) | "
                f"{1e6 * pr['lu_factor']:.2f} µs ({100 * s['lu_factor']:.0f}%) | "
                f"{1e6 * pr['lu_solve']:.2f} µs ({100 * s['lu_solve']:.0f}%) | "
                f"{1e6 * pr['assemble_res']:.2f} µs ({100 * s['assemble_res']:.0f}%) | "
                f"{1e6 * pr['end_momentum']:.2f} µs ({100 * s['end_momentum']:.0f}%) | "
                f"{100 * s['other']:.0f}% |")
        P.append("")
    if lim:
        P.append("**What limits the ratio to SciPy.** " + " ".join(lim) + "\n")
    P.extend(growth_lines(growth or {}))
    P.append("## Diagrams\n")
    for (panel, metric, fname, xlabel, title), rel in zip(PANELS, figs):
        P.append(f"![{title.format(**cfg)}]({rel})\n")
    if not figs:
        P.append("(matplotlib was not installed when this page was generated: no figures.)\n")
    P.append(f"## Data\n\n### (a) position error at T = {cfg['T_error']:g} s\n")
    P.extend(_table(points, "error", [("max\\|Δq\\| (m)", "err_q")], cfg))
    horizon = "; ".join(f"{k} at T = {v:g} s only (cost)" for k, v in cfg["long_horizon"].items())
    P.append(f"\n### (b), (c) energy and constraints over T = {cfg['T_long']:g} s"
             + (f" ({horizon})" if horizon else "") + "\n")
    P.extend(_table(points, "long", [("max\\|ΔH\\| (J)", "dH"), ("max\\|g\\|", "g"),
                                      ("max\\|Gv\\|", "gv")], cfg))
    if horizon:
        P.append(f"\n{horizon}: over a shorter horizon a drifting energy error is smaller and the "
                 "run cheaper, so those points flatter SciPy; they are plotted as measured, not "
                 "extrapolated.\n")
    return "\n".join(P) + "\n"


# ----------------------------------------------------------------------------- compiled peers
# Issue 11, item 5: fastvi against a compiled DOP853 (CyRK's C++ solver on hand-written @njit
# right-hand sides, :mod:`fastvi.studies.peers`), and a stiff panel on the rod–slider.
#: a peer-panel run longer than this (CPU s) is timed once: long enough to average out the
#: timer (the T = 10^4 s fastvi runs), and the study stays within minutes
PEER_LONG_RUN = 2.0
#: … and in the stiff panel (its slowest settings are the finest steps at k = 10^8)
STIFF_LONG_RUN = 0.5
#: energy levels (J) at which the fastvi / DOP853 ratio is read off (issue 11's goal range)
PEER_LEVELS = (1e-2, 1e-4, 1e-6, 1e-8)
PEER_GOAL = 2.0  # issue 11: fastvi's best within 2× of DOP853 (a) at equal max|ΔH|, T = 1000 s
#: the double pendulum from π/2 is chaotic: starts 1e-12 rad apart follow different paths
#: after a few tens of seconds, and max|ΔH| over T = 1000 s, an extreme of the path, then
#: differs by up to 4× for the same method and h (docs/benchmarks.md, "Against a compiled DOP853").
#: Each setting's max|ΔH| is the median over the nominal start and ``starts − 1`` starts of
#: the panel's configuration perturbed by PEER_START_SPREAD (rad, the same for every
#: contender: peer_starts); the CPU time is the nominal start's (it does not depend on the
#: path beyond noise).
PEER_START_SPREAD = 1e-12
PEER_START_SEED = 2026
STIFF_GOAL = 10.0  # issue 11: ≥ 10× ahead of every compiled peer at k = 1e8
#: fastvi's energies are sampled every PEER_SAMPLE_DT seconds (save_every = PEER_SAMPLE_DT/h):
#: saving every step would cost fastvi more than the peer pays for storing its steps
PEER_SAMPLE_DT = 0.1
#: … and in the stiff panel every STIFF_SAMPLE_DT seconds (≥ 10⁴ samples over T = 10 s: the
#: energy error of a step beyond the fast period oscillates from step to step)
STIFF_SAMPLE_DT = 1e-3
#: tolerance of the stiff panel's reference end state (CyRK DOP853, untimed)
STIFF_REF_TOL = 1e-11
#: the stiff panel's target: max|ΔH| ≤ STIFF_TARGET_REL × the spring energy at the start
STIFF_TARGET_REL = 1e-4
#: the stiff panel's fastvi steps: h = T/⌈T ω / c⌉ for each c (ωh ≈ c), at most the stiff
#: configuration's ``h_max`` (this, unless a configuration says otherwise)
STIFF_H_MAX = 0.01
#: the pendulum panels' adaptive contenders (label "<method> adaptive", knob ε):
#: ``integrate(..., adaptive=PEER_ADAPTIVE_KR)``, the energy scale of the step density
#: (docs/benchmarks.md: 3 J fits this pendulum, whose kinetic energy reaches ≈ 30 J)
PEER_ADAPTIVE_KR = 3.0
#: the length (s) of the untimed pilot run that gives an adaptive contender's mean step
PEER_PILOT_T = 100.0
_NO_SAMPLES = 1 << 40  # save_every of a run whose samples are not read: the first and last
ADAPTIVE = " adaptive"

PEERS_FULL = dict(
    #: the host's load slows single runs by up to 40 %: a median of 5 interleaved runs
    #: keeps one slow stretch from moving a contender's point (3 did not, 2026-11-27)
    repeats=5,
    starts=8,
    #: fastvi as a speed-minded user runs it against a compiled peer: the kernels compiled
    #: for the model's sizes (bit for bit the default kernels' trajectories; one compile per
    #: method, outside the timing). The quick check of the section leaves them out.
    specialize=True,
    T=(1000.0, 10000.0),
    fastvi={
        # (h = 0.1 is beyond P4L-Q5G's stability limit here: its energy error explodes).
        # P4L-Q4G (r = s: one quadrature point fewer, the same order 8; docs/orders.md) costs
        # 0.89–0.96 of a P4L-Q5G step here, with 0.35–1.04× its energy error; P2L-Q2G and
        # P3L-Q3G cost 0.93–0.96 of their defaults' step but leave 1.4–2.1× their energy
        # error at h = 0.02, 0.025, so they are left out (docs/benchmarks.md)
        # The adaptive contenders (time-reversible, not symplectic) run ε where their
        # energy errors meet the fixed steps' levels. P5L-Q5G (order 10, r = s) adaptive
        # reaches 1e-6 J at 0.94–1.0 of P4L-Q4G adaptive's cost and 1e-8 J at the same
        # cost; at 1e-4 J it costs ≈ 1.15× P3L-Q4G adaptive (docs/benchmarks.md)
        1000.0: {"P1L-Q2G": (0.01,), "P2L-Q3G": (0.04, 0.02, 0.01),
                 "P3L-Q4G": (0.05, 0.025, 0.0125), "P4L-Q5G": (0.05, 0.025, 0.0125),
                 "P4L-Q4G": (0.05, 0.025, 0.0125),
                 "P2L-Q3G" + ADAPTIVE: (0.08, 0.0625, 0.05, 0.04),
                 "P3L-Q4G" + ADAPTIVE: (0.1, 0.08, 0.0625, 0.05, 0.04),
                 "P4L-Q4G" + ADAPTIVE: (0.0625, 0.05, 0.04, 0.03),
                 "P5L-Q5G" + ADAPTIVE: (0.1, 0.08, 0.0625, 0.05)},
        # fewer points at T = 10^4 s (cost; the finest, 8·10^5 steps, is timed once)
        10000.0: {"P3L-Q4G": (0.05, 0.025), "P4L-Q5G": (0.05, 0.025, 0.0125),
                  "P4L-Q4G": (0.05, 0.025, 0.0125),
                  "P3L-Q4G" + ADAPTIVE: (0.08, 0.0625, 0.05),
                  "P4L-Q4G" + ADAPTIVE: (0.0625, 0.05, 0.04),
                  "P5L-Q5G" + ADAPTIVE: (0.08, 0.0625)},
    },
    dop={1000.0: (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14),
         10000.0: (1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14)},
    #: energy-error growth with T at one setting per contender
    growth=dict(T=(100.0, 1000.0, 10000.0), fastvi=("P3L-Q4G", 0.025), tol=1e-10,
                adaptive=("P3L-Q4G" + ADAPTIVE, 0.0625)),
    # r = s methods (P2L-Q2G, P3L-Q3G) are stable at any ωh; the defaults (r = s + 1) are not
    stiff=dict(T=10.0, ks=(1e3, 1e4, 1e5, 1e6, 1e7, 1e8),
               methods=("P2L-Q2G", "P3L-Q3G", "P2L-Q3G", "P3L-Q4G"),
               c=(64.0, 16.0, 4.0, 1.0, 0.5),
               peers={"DOP853": (1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10),
                      "LSODA": (1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10),
                      "Radau": (1e-5, 1e-6, 1e-7, 1e-8, 1e-9)}),
)
PEERS_QUICK = dict(
    repeats=1,
    starts=2,
    specialize=False,
    T=(100.0,),
    fastvi={100.0: {"P3L-Q4G": (0.05, 0.025), "P4L-Q5G": (0.05,),
                    "P3L-Q4G" + ADAPTIVE: (0.0625,)}},
    dop={100.0: (1e-8, 1e-10, 1e-12)},
    growth=dict(T=(10.0, 100.0), fastvi=("P3L-Q4G", 0.025), tol=1e-10),
    stiff=dict(T=1.0, ks=(1e3, 1e6), methods=("P2L-Q2G", "P3L-Q4G"), c=(4.0, 0.5),
               peers={"DOP853": (1e-6, 1e-9), "LSODA": (1e-6, 1e-9), "Radau": (1e-6,)}),
)
#: contender labels of the peer panels
DOP_A, DOP_B = "DOP853 (a) Cartesian", "DOP853 (b) angles"


@dataclass
class PeerPoint:
    """One run of one contender in the peer panels: CPU time and errors of the same run."""

    panel: str  # "pendulum" or "stiff"
    label: str
    knob: float  # h (fastvi) or rtol = atol (CyRK)
    T: float
    cpu: float = float("nan")  # median CPU time (process), s
    cpus: list = field(default_factory=list)
    dH: float = float("nan")  # pendulum panel: the median over the starts (peer_starts)
    g: float = float("nan")
    work: int = 0  # steps (fastvi: fixed; CyRK: accepted)
    #: pendulum panel: max|ΔH| of each start, the nominal start (THETA0) first
    dHs: list = field(default_factory=list)
    k: float = float("nan")  # stiffness (stiff panel)
    ok: bool = True
    #: stiff panel: |θ(T) − θ_ref(T)| (the slow motion) and |r(T) − r_ref(T)| (the spring),
    #: against CyRK DOP853 at STIFF_REF_TOL
    err_theta: float = float("nan")
    err_r: float = float("nan")

    @property
    def wall(self) -> float:  # so that pareto()/cost_at() can read either cost
        return self.cpu

    @property
    def is_fastvi(self) -> bool:
        return self.label.startswith("P")


def fastvi_peer_run(model, q0, v0, method, h, T, params=None, sample_dt=PEER_SAMPLE_DT,
                     specialize=False):
    """One public ``fastvi.integrate`` call as the peer panels time it, energies saved every
    ``sample_dt`` seconds: ``(cpu, info)`` with the process CPU time of the call and ``info``
    holding ``dH`` (max|H − H0| over the samples), ``g`` (max|g|), ``steps``, ``ok`` and the
    final ``end`` configuration. ``method`` ``"<name> adaptive"`` runs the adaptive step
    (``adaptive=PEER_ADAPTIVE_KR``, ``h`` its ε; saved every ``sample_dt`` s on average:
    :func:`adaptive_sample_every`)."""
    name, adaptive = _adaptive_label(method)
    every = peer_save_every(model, q0, v0, method, h, T, params, sample_dt, specialize)
    c0 = time.process_time()
    res = fastvi.integrate(model, q0, v0, h=h, t_end=T, method=name, save_every=every,
                           params=params, on_failure="return", specialize=specialize,
                           adaptive=adaptive)
    cpu = time.process_time() - c0
    ok = bool(res.success) and bool(np.isclose(res.t[-1], T))
    dH = float(np.max(np.abs(res.energy - res.energy[0]))) if len(res.energy) else np.inf
    g = float(np.max(res.constraint_residual)) if len(res.energy) else np.inf
    return cpu, dict(dH=dH, g=g, steps=int(res.stats["steps"]), ok=ok and np.isfinite(dH),
                     end=res.q[-1].copy() if len(res.q) else None)


def peer_save_every(model, q0, v0, label, h, T, params=None, sample_dt=PEER_SAMPLE_DT,
                    specialize=False) -> int:
    """``save_every`` of a peer-panel contender ``label`` at step (or ε) ``h``: every
    ``sample_dt`` seconds, on average for an adaptive one (:func:`adaptive_sample_every`,
    whose pilot run is not timed: call this before the clock starts)."""
    name, adaptive = _adaptive_label(label)
    if adaptive is None:
        return max(1, int(round(sample_dt / h)))
    return adaptive_sample_every(model, q0, v0, name, h, T, params, sample_dt, specialize,
                                 adaptive)


def adaptive_sample_every(model, q0, v0, method, eps, T, params=None, sample_dt=PEER_SAMPLE_DT,
                          specialize=False, kr=PEER_ADAPTIVE_KR) -> int:
    """``save_every`` for an adaptive run of ε = ``eps`` that saves every ``sample_dt``
    seconds on average, as the fixed steps do: the mean step ``T_p / steps`` of a pilot run
    over ``T_p = min(T, PEER_PILOT_T)`` (steps shrink where the pendulum whips: the mean
    step of the double pendulum is ≈ ε/2.2, so ``sample_dt/ε`` would save 2.2× as often,
    and a saved sample costs a fraction of a step).

    The pilot is deterministic, so its answer is kept per model and arguments: the study
    and the bench scripts time the same setting 5–7 times, and each pilot is a tenth of the
    timed run. ``specialize`` is not part of the key (the same trajectory bit for bit)."""
    key = (np.asarray(q0, float).tobytes(), np.asarray(v0, float).tobytes(), method,
           float(eps), float(T), None if params is None else np.asarray(params, float).tobytes(),
           float(sample_dt), float(kr))
    known = _PILOTS.setdefault(model, {})
    if key not in known:
        Tp = min(T, PEER_PILOT_T)
        pilot = fastvi.integrate(model, q0, v0, h=eps, t_end=Tp, method=method, params=params,
                                 save_every=_NO_SAMPLES, on_failure="return",
                                 specialize=specialize, adaptive=kr)
        mean_step = float(pilot.t[-1] - pilot.t[0]) / max(1, int(pilot.stats["steps"]))
        known[key] = max(1, int(round(sample_dt / mean_step)))
    return known[key]


#: :func:`adaptive_sample_every`'s answers, per model (dropped with the model)
_PILOTS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _panel_methods(pcfg, adaptive_only: bool = False) -> set:
    """The method names the pendulum panels of ``pcfg`` run (only those run adaptive)."""
    return {_adaptive_label(m)[0] for d in pcfg["fastvi"].values() for m in d
            if not adaptive_only or m.endswith(ADAPTIVE)}


def _adaptive_label(label: str):
    """(method name, the ``adaptive`` argument) of a peer-panel contender's label."""
    if label.endswith(ADAPTIVE):
        return label[: -len(ADAPTIVE)], PEER_ADAPTIVE_KR
    return label, None


def _interleaved(jobs, repeats, log, budget=LONG_RUN):
    """Run ``jobs`` (callables returning (cpu, info)) round-robin ``repeats`` times.

    Interleaving spreads the machine's changing load over every contender alike. A job
    whose run took longer than ``budget`` seconds is not repeated."""
    cpus = [[] for _ in jobs]
    infos = [None] * len(jobs)
    for r in range(repeats):
        for j, job in enumerate(jobs):
            if r and cpus[j] and cpus[j][-1] > budget:
                continue
            c, info = job()
            cpus[j].append(c)
            infos[j] = info
    return cpus, infos


def peer_starts(count: int) -> list[tuple]:
    """The pendulum panel's starting angles: ``THETA0``, then ``count − 1`` starts perturbed
    by ``PEER_START_SPREAD`` (standard normal, fixed seed: the same for every contender)."""
    rng = np.random.default_rng(PEER_START_SEED)
    return [tuple(THETA0)] + [tuple(np.array(THETA0) + PEER_START_SPREAD * rng.standard_normal(2))
                              for _ in range(count - 1)]


def at_nominal_start(points) -> list[PeerPoint]:
    """The pendulum panel's points with max|ΔH| of the nominal start alone (as the study read
    it before it took several starts), for the side-by-side column of the page."""
    return [replace(p, dH=p.dHs[0]) if p.panel == "pendulum" and p.dHs else p for p in points]


def peer_pendulum_sweep(pcfg, log) -> list[PeerPoint]:
    """Work–precision panels at each T of ``pcfg``: fastvi vs DOP853 (a) and (b), timed from
    the nominal start; max|ΔH| the median over :func:`peer_starts` (``pcfg["starts"]``)."""
    from fastvi.studies import peers

    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(*THETA0)
    prm = peers.DP_PARAMS
    for method in _panel_methods(pcfg) | {
            pcfg["growth"]["fastvi"][0]}:
        fastvi.integrate(model, q0, v0, h=0.01, n_steps=2, method=method,
                         specialize=pcfg["specialize"])  # compile / load
    specs = []
    for T in pcfg["T"]:
        for method, hs in pcfg["fastvi"][T].items():
            specs += [(method, h, T) for h in hs]
        for tol in pcfg["dop"][T]:
            specs += [(DOP_A, tol, T), (DOP_B, tol, T)]
    for T in pcfg["growth"]["T"]:  # the growth table's settings, where the panels lack them
        for label, knob in _growth_settings(pcfg):
            if (label, knob, T) not in specs:
                specs.append((label, knob, T))

    def job(label, knob, T, theta=THETA0):
        if label == DOP_A:
            ya = peers.cartesian_start(theta)
            return lambda: _peer_job(peers, "cartesian", ya, prm, T, knob, "DOP853")
        if label == DOP_B:
            yb = peers.angles_start(theta)
            return lambda: _peer_job(peers, "angles", yb, prm, T, knob, "DOP853")
        q, v = model.initial_state(*theta)
        return lambda: _quiet_fastvi(model, q, v, label, knob, T, sample_dt=PEER_SAMPLE_DT,
                                     specialize=pcfg["specialize"])

    t0 = time.perf_counter()
    cpus, infos = _interleaved([job(*s) for s in specs], pcfg["repeats"], log, PEER_LONG_RUN)
    others = peer_starts(pcfg.get("starts", 1))[1:]
    points = []
    for (label, knob, T), cs, info in zip(specs, cpus, infos):
        # the other starts run once each, untimed: only their energy error is read
        dHs = [info["dH"]] + [_start_error(job(label, knob, T, th)) for th in others]
        pt = PeerPoint("pendulum", label, knob, T, float(np.median(cs)), cs,
                       float(np.median(dHs)), info["g"], info["steps"], ok=info["ok"], dHs=dHs)
        points.append(pt)
        log(f"(peers) {label:<22} {knob:<8g} T {T:<7g} CPU {pt.cpu:8.4f} s  max|ΔH| {pt.dH:.2e} "
            f"({min(dHs):.1e}…{max(dHs):.1e} over {len(dHs)} starts)  "
            f"max|g| {pt.g:.1e}{'' if pt.ok else '  FAILED'}")
    log(f"peer pendulum panels: {time.perf_counter() - t0:.0f} s")
    return points


def _growth_settings(pcfg) -> list[tuple]:
    """The (label, knob) of each contender of the energy-growth table."""
    g = pcfg["growth"]
    fv = [g["fastvi"]] + ([g["adaptive"]] if "adaptive" in g else [])
    return fv + [(DOP_A, g["tol"]), (DOP_B, g["tol"])]


def _start_error(run) -> float:
    """max|ΔH| of one run of another start; inf where it failed (it then raises the median)."""
    info = run()[1]
    return info["dH"] if info["ok"] else np.inf


def start_spread(points, T) -> dict:
    """{label: median over the settings at ``T`` of max / min of max|ΔH| over the starts}:
    how much of a setting's energy error is the path's chance, not the method."""
    out = {}
    for p in points:
        if p.panel == "pendulum" and p.T == T and p.ok and len(p.dHs) > 1:
            d = np.array(p.dHs)
            if np.all(np.isfinite(d)) and d.min() > 0:
                out.setdefault(p.label, []).append(d.max() / d.min())
    return {lab: float(np.median(v)) for lab, v in out.items()}


def _peer_job(peers, system, y0, prm, T, tol, method):
    r = peers.run_peer(system, y0, prm, T=T, tol=tol, method=method)
    return r["cpu"], dict(dH=r["dH"], g=r["g"], steps=r["steps"], ok=r["ok"], end=r["y_end"])


def _stiff_hs(k: float, T: float, cs, h_max: float) -> list[float]:
    from fastvi.studies import peers

    om = peers.slider_omega(k)
    hs = []
    for c in cs:
        n = max(int(np.ceil(T / h_max)), int(np.ceil(T * om / c)))
        h = T / n
        if h not in hs:
            hs.append(h)
    return hs


def peer_stiff_sweep(pcfg, log) -> list[PeerPoint]:
    """The stiff panel: rod–slider at each k, fastvi (h swept) vs CyRK DOP853/LSODA/Radau."""
    from fastvi.studies import peers

    s = pcfg["stiff"]
    T, h_max = s["T"], s.get("h_max", STIFF_H_MAX)
    points = []
    t0 = time.perf_counter()
    # one model, k passed as a parameter (a new model per k would compile its kernels anew)
    model = fastvi.scenes.rotary_rod_slider(k=s["ks"][0])
    with quiet():
        for method in s["methods"]:  # compile / load outside the timing
            q0, v0 = model.initial_state(0.0, peers.SLIDER_R0)
            fastvi.integrate(model, q0, v0, h=1e-4, n_steps=2, method=method,
                             specialize=pcfg["specialize"])
    for k in s["ks"]:
        q0, v0 = model.initial_state(0.0, peers.SLIDER_R0 + peers.slider_stretch(k))
        y0, prm = peers.slider_start(k), peers.slider_params(k)
        specs = [(m, h) for m in s["methods"] for h in _stiff_hs(k, T, s["c"], h_max)]
        specs += [(f"CyRK {meth}", tol) for meth, tols in s["peers"].items() for tol in tols]

        def job(label, knob):
            if label.startswith("CyRK"):
                return lambda: _peer_job(peers, "slider", y0, prm, T, knob, label.split()[1])
            return lambda: _quiet_fastvi(model, q0, v0, label, knob, T, prm,
                                         specialize=pcfg["specialize"])

        cpus, infos = _interleaved([job(*sp) for sp in specs], pcfg["repeats"], log, STIFF_LONG_RUN)
        ref = peers.run_peer("slider", y0, prm, T=T, tol=STIFF_REF_TOL)["y_end"]  # untimed
        for (label, knob), cs, info in zip(specs, cpus, infos):
            pt = PeerPoint("stiff", label, knob, T, float(np.median(cs)), cs, info["dH"], info["g"],
                           info["steps"], k=k, ok=info["ok"])
            end = info.get("end")
            if pt.ok and end is not None:  # fastvi q = (θ, r, φ); CyRK y = (θ, r, θ̇, ṙ)
                pt.err_theta, pt.err_r = abs(end[0] - ref[0]), abs(end[1] - ref[1])
            points.append(pt)
            log(f"(stiff) k {k:<6g} {label:<12} {knob:<10.3g} CPU {pt.cpu:8.4f} s  "
                f"max|ΔH| {pt.dH:.2e}{'' if pt.ok else '  FAILED'}")
    log(f"stiff panel: {time.perf_counter() - t0:.0f} s")
    return points


def _quiet_fastvi(model, q0, v0, method, h, T, params=None, sample_dt=STIFF_SAMPLE_DT,
                  specialize=False):
    with quiet():
        import warnings

        with warnings.catch_warnings():  # the energy-growth alarm of an unstable setting
            warnings.simplefilter("ignore", RuntimeWarning)
            return fastvi_peer_run(model, q0, v0, method, h, T, params, sample_dt, specialize)


def _step_costs(points, T) -> dict:
    """Median CPU time per step (s) of each contender of the pendulum panel at ``T``."""
    per = {}
    for p in points:
        if p.panel == "pendulum" and p.T == T and p.ok and p.work:
            per.setdefault(p.label, []).append(p.cpu / p.work)
    return {lab: float(np.median(v)) for lab, v in per.items()}


def _front_at(points, E, bound: bool = True):
    """(CPU time, steps) to reach max|ΔH| = E on these runs' Pareto front in (max|ΔH|, CPU),
    each interpolated log–log between the two front runs around E.

    With ``bound``, at an E looser than the whole front where a run of the set is that
    loose but costs more than the front's cheapest run (so the front dropped it: a longer
    step that needs more iterations, or the machine's load between two close settings): the
    cheapest front run's, which reaches E, so its CPU time bounds the cost there (as the
    stiff table's "≤" cells). NaN otherwise outside the front."""
    ok = [p for p in points if p.ok]
    errs, cpus = pareto(ok, "dH", cost="cpu")
    work = {(p.dH, p.cpu): p.work for p in ok}
    if bound and len(errs) and E > errs.max() and any(p.dH >= E for p in ok):
        return float(cpus[0]), float(work[(errs[0], cpus[0])])
    if len(errs) < 2 or not errs.min() <= E <= errs.max():
        return np.nan, np.nan
    steps = np.array([work[(e, c)] for e, c in zip(errs, cpus)], float)
    le = np.log(errs[::-1])  # increasing error
    x = np.log(E)
    return (float(np.exp(np.interp(x, le, np.log(cpus[::-1])))),
            float(np.exp(np.interp(x, le, np.log(steps[::-1])))))


def peer_split(points, T, rival, levels=PEER_LEVELS):
    """Where each ratio of :func:`peer_ratios` comes from: ``[(E, method, steps ratio, cost
    per step ratio)]``, fastvi's cheapest method at ``E`` against ``rival``, each contender's
    steps and CPU time read off its own front at ``E`` (the product of the two ratios is the
    CPU ratio). NaN where either front does not reach ``E``."""
    rows = []
    riv = [p for p in points if p.label == rival and p.T == T and p.panel == "pendulum"]
    for E, _, which, _, _ in peer_ratios(points, T, rival, levels):
        mine = [p for p in points if p.label == which and p.T == T and p.panel == "pendulum"]
        (cf, sf), (cr, sr) = _front_at(mine, E), _front_at(riv, E)
        rows.append((E, which, sf / sr, (cf / sf) / (cr / sr)))
    return rows


def dominated_line(points, T) -> str:
    """A sentence on the fastvi runs at ``T`` that a shorter step of the same method beats in
    both CPU time and max|ΔH| ('' if none): the fronts drop them, so a method whose longer
    step costs more (more iterations, full-Newton fallbacks) reaches no level looser than
    its shorter step's error, though that run is an upper bound of the cost there."""
    out = []
    runs = [p for p in points if p.panel == "pendulum" and p.T == T and p.is_fastvi and p.ok]
    for p in runs:
        better = [o for o in runs if o.label == p.label and o.knob < p.knob and o.cpu <= p.cpu
                  and o.dH < p.dH]
        if better:
            o = min(better, key=lambda o: o.cpu)
            out.append(f"{p.label} h = {p.knob:g} ({p.cpu:.3g} s, {p.dH:.1e} J; h = {o.knob:g}: "
                       f"{o.cpu:.3g} s, {o.dH:.1e} J)")
    if not out:
        return ""
    return (f"Runs beaten by a shorter step of the same method at T = {T:g} s, left off the "
            "fronts (at a level looser than the rest of its front, a method's cost is then the "
            "shorter step's, an upper bound: that run reaches the level): " + "; ".join(out) + ".")


def unreached_line(points, T, rival, levels=PEER_LEVELS) -> str:
    """A sentence on the levels that fastvi reaches and ``rival`` does not at any of its
    tolerances ('' if none): there fastvi is ahead by default."""
    riv = [p for p in points if p.label == rival and p.T == T and p.panel == "pendulum" and p.ok]
    if not riv:
        return ""
    floor = min(riv, key=lambda p: p.dH)
    out = [(E, which) for E, best, which, _, _ in peer_ratios(points, T, rival, levels)
           if np.isfinite(best) and E < floor.dH]
    if not out:
        return ""
    return (" At " + ", ".join(f"{E:.0e} J ({which})" for E, which in out)
            + f" only fastvi gets there: the smallest max|ΔH| over T = {T:g} s of {rival}, "
            f"at any tolerance down to {min(p.knob for p in riv):g}, is {floor.dH:.2e} J "
            f"(rtol = atol = {floor.knob:g}).")


def peer_ratios(points, T, rival, levels=PEER_LEVELS, fixed_only=False):
    """[(E, fastvi-best CPU, method, rival CPU, fastvi / rival)] at each level ``E``;
    ``fixed_only``: the best of the fixed-step (symplectic) contenders."""
    rows = []
    riv = [p for p in points if p.label == rival and p.T == T and p.panel == "pendulum"]
    methods = sorted({p.label for p in points if p.is_fastvi and p.T == T and p.panel == "pendulum"
                      and not (fixed_only and p.label.endswith(ADAPTIVE))})
    for E in levels:
        best, which = np.nan, ""
        for m in methods:
            c = _front_at([p for p in points if p.label == m and p.T == T and p.panel == "pendulum"], E)[0]
            if np.isfinite(c) and not (c >= best):
                best, which = c, m
        r = _front_at(riv, E)[0]
        rows.append((E, best, which, r, best / r if np.isfinite(best) and np.isfinite(r) else np.nan))
    return rows


def stiff_table(points, pcfg):
    """{k: {contender: (cpu, how)}} at the target max|ΔH|; how = "interp" (on the front),
    "≤" (every run met the target: the cheapest run's time, an upper bound), "—" (not
    reached by any run)."""
    from fastvi.studies import peers

    target = STIFF_TARGET_REL * peers.SPRING_ENERGY
    out = {}
    for k in pcfg["stiff"]["ks"]:
        row = {}
        labels = list(dict.fromkeys(p.label for p in points if p.panel == "stiff" and p.k == k))
        for label in labels:
            pts = [p for p in points if p.panel == "stiff" and p.k == k and p.label == label and p.ok]
            meeting = [p for p in pts if p.dH <= target]
            c = _front_at(pts, target, bound=False)[0]  # its bound is the "run" cell below
            if np.isfinite(c):
                row[label] = (c, "interp")
            elif meeting and all(p.dH <= target for p in pts):
                row[label] = (min(p.cpu for p in meeting), "≤")
            elif meeting:
                row[label] = (min(p.cpu for p in meeting), "run")
            else:
                row[label] = (np.nan, "—")
        out[k] = row
    return out, target


def stiff_summary(table, pcfg):
    """(crossover k or None, ratio best peer / best fastvi at the largest k, per-k ratios)."""
    ratios = {}
    for k, row in table.items():
        fv = [c for lab, (c, _) in row.items() if not lab.startswith("CyRK") and np.isfinite(c)]
        pr = [c for lab, (c, _) in row.items() if lab.startswith("CyRK") and np.isfinite(c)]
        f = min(fv) if fv else np.nan
        p = min(pr) if pr else np.nan
        ratios[k] = p / f if fv and pr else (np.inf if fv else (0.0 if pr else np.nan))
    ks = sorted(ratios)
    cross = None
    for i, k in enumerate(ks):  # smallest k from which fastvi is ahead at every larger k
        if all(ratios[kk] > 1.0 for kk in ks[i:]):
            cross = k
            break
    return cross, ratios[ks[-1]], ratios


def peer_figures(points, pcfg, table, outdir, log) -> list[str]:
    try:
        import matplotlib
    except ImportError:
        return []
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(os.path.join(outdir, "figures"), exist_ok=True)
    paths = []
    Ts = pcfg["T"]
    fig, axes = plt.subplots(2, len(Ts), figsize=(6.5 * len(Ts), 9), squeeze=False)
    every = list(dict.fromkeys(p.label for p in points if p.panel == "pendulum"))
    for col, T in enumerate(Ts):
        labels = list(dict.fromkeys(p.label for p in points if p.panel == "pendulum" and p.T == T))
        for label in labels:
            k = every.index(label)  # one colour per contender in every panel
            pts = sorted((p for p in points if p.panel == "pendulum" and p.T == T and p.label == label
                          and p.ok), key=lambda p: p.dH)
            if not pts:
                continue
            style = dict(ls="-", marker="o") if pts[0].is_fastvi else dict(ls="--", marker="s")
            axes[0, col].loglog([p.dH for p in pts], [p.cpu for p in pts], color=f"C{k % 10}",
                                label=label, **style)
            axes[1, col].loglog([p.dH for p in pts], [max(p.g, 1e-17) for p in pts],
                                color=f"C{k % 10}", label=label, **style)
        axes[0, col].set_title(f"double pendulum, T = {T:g} s")
        axes[0, col].set_ylabel("CPU time (s)")
        axes[1, col].set_ylabel("max |g(q)| (angles: 0, plotted at 1e-17)")
        for r in (0, 1):
            axes[r, col].set_xlabel(f"max |H − H(0)| over T = {T:g} s (J)")
            axes[r, col].grid(True, alpha=0.3)
            axes[r, col].legend(fontsize=7)
    fig.tight_layout()
    rel = "figures/wpd-peers.png"
    fig.savefig(os.path.join(outdir, rel), dpi=100)
    plt.close(fig)
    paths.append(rel)
    if table:
        fig, ax = plt.subplots(figsize=(8, 5.5))
        labels = list(dict.fromkeys(lab for row in table.values() for lab in row))
        for j, label in enumerate(labels):
            ks = [k for k in table if label in table[k] and np.isfinite(table[k][label][0])]
            style = dict(ls="--", marker="s") if label.startswith("CyRK") else dict(ls="-", marker="o")
            ax.loglog(ks, [table[k][label][0] for k in ks], color=f"C{j % 10}", label=label, **style)
        ax.set_xlabel("spring stiffness k (N/m)")
        ax.set_ylabel("CPU time to reach the target max|ΔH| (s)")
        ax.set_title(f"stiff rod–slider, T = {pcfg['stiff']['T']:g} s")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        rel = "figures/wpd-stiff.png"
        fig.savefig(os.path.join(outdir, rel), dpi=100)
        plt.close(fig)
        paths.append(rel)
    return paths


def _fmt(x, spec=".3g"):
    return format(x, spec) if np.isfinite(x) else "—"


def peer_markdown(points, pcfg, figs, elapsed, missing: str | None = None) -> list[str]:
    """The page's sections on the compiled peers (issue 11, item 5)."""
    P = ["## Against a compiled DOP853 (issue 11)\n"]
    if missing:
        P.append(f"Not run: {missing}.\n")
        return P
    from fastvi.studies import peers

    import CyRK

    adaptive = ", ".join(f"`{n}`" for n in sorted(_panel_methods(pcfg, adaptive_only=True)))
    P.append(
        f"The solver a speed-minded user would pick instead of fastvi: **DOP853 from CyRK "
        f"{CyRK.__version__}** (`CyRK.nbsolve2_ivp`, C++ solver, right-hand side a numba "
        "`cfunc` called through a function pointer; no Python in the loop; CyRK's pure-numba "
        "`nbsolve_ivp` was ≈ 1.8× slower here), on right-hand sides written by hand in "
        "`fastvi/studies/peers.py` (no fastvi code): **(a)** the Cartesian index-1 form of the "
        "same double pendulum (the 2×2 multiplier system `G M⁻¹ Gᵀ λ = G M⁻¹ f + Ġv` solved "
        "inline, no Baumgarte terms, so the constraints drift) and **(b)** angle coordinates, its "
        "best case (no constraints). fastvi runs through its public `fastvi.integrate` (so the "
        "numbers follow the kernels) with `specialize=True` (the kernels compiled for the "
        "model's sizes, bit for bit the default kernels' trajectories: what a speed-minded "
        "user runs; compiled outside the timing); `P1L-Q2G` … `P4L-Q5G` and `P4L-Q4G` "
        "(r = s: one quadrature point fewer than `P4L-Q5G`, the same order 8), h swept; and "
        f"`<method> adaptive` ({adaptive}) with "
        f"`adaptive={PEER_ADAPTIVE_KR:g}` (the "
        "time-reversible adaptive step of `fastvi.kernels.adapt`: steps shrink where the "
        "pendulum whips; each step variational and on the constraints, but the map reversible, "
        "not symplectic), ε swept. "
        "Regenerate with "
        "`make wpd` (installs the `bench` extra, CyRK, into `.venv`) or `python -m fastvi wpd` "
        "with CyRK installed (`pip install -e .[bench]`); `--no-peers` skips these sections. "
        "The same comparison at the 1e-2 and 1e-4 J levels, in a minute, under "
        "pytest-benchmark: `bench/test_bench_peers.py` (`make bench`).\n")
    P.append(
        f"**Measurements.** CPU time of the process (`time.process_time`), median of "
        f"{pcfg['repeats']} runs, every contender and setting run round-robin in one process "
        f"(runs longer than {PEER_LONG_RUN:g} s, in the stiff panel {STIFF_LONG_RUN:g} s, timed "
        "once), after compilation. fastvi: the whole "
        f"public call (validation, initial projection, energies of the saved steps), saving every "
        f"{PEER_SAMPLE_DT:g} s (`save_every = {PEER_SAMPLE_DT:g}/h`; adaptive: every "
        f"{PEER_SAMPLE_DT:g} s on average, `save_every` = {PEER_SAMPLE_DT:g} s / the mean step of "
        f"an untimed {PEER_PILOT_T:g} s pilot run; stiff panel: every "
        f"{STIFF_SAMPLE_DT:g} s). CyRK: the solver call "
        "storing every accepted step (its default; no dense output, no `t_eval`) and the copy of "
        "the stored steps out of CyRK (< 1 %). Energy errors max |H − H(0)|: fastvi over its saved "
        f"samples, CyRK over **every accepted step** (denser: never "
        "in fastvi's favour). Constraint residual max |g_i(q)| with fastvi's g = ½(|r|² − l²). "
        "DOP853 evaluates the right-hand side "
        f"{peers.DOP853_STAGES} times per accepted step. The machine has 2 cores and was shared with "
        "other jobs; read ratios to within ≈ 1.5×.\n")
    nst = pcfg.get("starts", 1)
    if nst > 1:
        T0 = pcfg["T"][0]
        spread = start_spread(points, T0)
        P.append(
            f"**Starts.** The double pendulum from θ1 = θ2 = π/2 is chaotic: paths from starts "
            f"{PEER_START_SPREAD:g} rad apart part after a few tens of seconds, and the maximum "
            "of |ΔH| over T, an extreme of the path, then differs between them for the same "
            f"solver and setting. Each setting's max|ΔH| in the pendulum panels is the median "
            f"over {nst} starts (the nominal one and {nst - 1} perturbed by {PEER_START_SPREAD:g} "
            f"rad, the same for every contender: `wpd.peer_starts`); its CPU time is the "
            "nominal start's. Max / min of max|ΔH| over the starts, median over the settings at "
            f"T = {T0:g} s: "
            + ", ".join(f"{lab} {x:.2f}" for lab, x in sorted(spread.items())) + ".\n")
    P.append("### fastvi's best method / DOP853 at equal max energy error\n")
    P.append("CPU time of the cheapest fastvi method at that max|ΔH| divided by that of DOP853 "
             "(log–log interpolation on each contender's Pareto front; — where a curve does not "
             f"reach the level). Above 1: fastvi is slower. Goal of issue 11: ≤ {PEER_GOAL:g} "
             "against (a) at T = 1000 s over 1e-2 … 1e-8 J.\n")
    P.append("| T (s) | max\\|ΔH\\| (J) | best fastvi | fastvi CPU (s) | DOP853 (a) CPU (s) | "
             "**fastvi / (a)** | DOP853 (b) CPU (s) | **fastvi / (b)** | fastvi / (a), nominal "
             "start only | fixed step only: fastvi / (a) |")
    P.append("|---|---|---|---|---|---|---|---|---|---|")
    nominal = at_nominal_start(points)
    for T in pcfg["T"]:
        ra = peer_ratios(points, T, DOP_A)
        rb = peer_ratios(points, T, DOP_B)
        r0 = peer_ratios(nominal, T, DOP_A)
        rf = peer_ratios(points, T, DOP_A, fixed_only=True)
        for (E, best, which, ca, xa), (_, _, _, cb, xb), row0, rowf in zip(ra, rb, r0, rf):
            P.append(f"| {T:g} | {E:.0e} | {which or '—'} | {_fmt(best, '.4f')} | {_fmt(ca, '.4f')} | "
                     f"**{_fmt(xa)}** | {_fmt(cb, '.4f')} | **{_fmt(xb)}** | "
                     f"{_fmt(row0[4])} ({row0[2] or '—'}) | {_fmt(rowf[4])} ({rowf[2] or '—'}) |")
    P.append("")
    for T in pcfg["T"]:
        line = dominated_line(points, T)
        if line:
            P.append(line + "\n")
    T0 = pcfg["T"][0]
    xs = [r[4] for r in peer_ratios(points, T0, DOP_A) if np.isfinite(r[4])]
    xf = [r[4] for r in peer_ratios(points, T0, DOP_A, fixed_only=True) if np.isfinite(r[4])]
    if xs:
        met = all(x <= PEER_GOAL for x in xs)
        P.append(f"Goal (fastvi within {PEER_GOAL:g}× of DOP853 (a) at T = {T0:g} s): "
                 f"**{'met' if met else 'not met'}** — fastvi is {min(xs):.3g}× to {max(xs):.3g}× "
                 "the CPU time of DOP853 (a) at the levels it reaches."
                 + (f" With fixed steps only (symplectic): {min(xf):.3g}× to {max(xf):.3g}× "
                    f"(**{'met' if all(x <= PEER_GOAL for x in xf) else 'not met'}**)."
                    if xf else "")
                 + unreached_line(points, T0, DOP_A) + "\n")
    # growth with T
    settings = _growth_settings(pcfg)
    tol = pcfg["growth"]["tol"]
    P.append(f"### Energy error and constraint drift against T\n")
    P.append("One setting per contender (fastvi " + ", ".join(
        f"`{lab}` {'ε' if lab.endswith(ADAPTIVE) else 'h'} = {kn:g}"
        for lab, kn in settings if lab.startswith("P"))
        + f"; DOP853 rtol = atol = {tol:g}), max over [0, T]:\n")
    P.append("| contender | T (s) | CPU (s) | max\\|ΔH\\| (J) | max\\|g(q)\\| | steps |")
    P.append("|---|---|---|---|---|---|")
    for label, knob in settings:
        for T in pcfg["growth"]["T"]:
            pt = [p for p in points if p.panel == "pendulum" and p.label == label and p.knob == knob
                  and p.T == T]
            if pt:
                p = pt[0]
                P.append(f"| {label} | {T:g} | {p.cpu:.4g} | {p.dH:.2e} | {p.g:.1e} | {p.work} |"
                         + ("" if p.ok else " FAILED |"))
    P.append("")
    growth = []
    Tg = pcfg["growth"]["T"]
    for label, knob in settings:
        pts = {p.T: p for p in points if p.panel == "pendulum" and p.label == label
               and p.knob == knob and p.T in (Tg[0], Tg[-1]) and p.ok}
        if len(pts) == 2 and pts[Tg[0]].dH > 0:
            dec = np.log10(Tg[-1] / Tg[0])
            f = (pts[Tg[-1]].dH / pts[Tg[0]].dH) ** (1.0 / dec)
            gg = (pts[Tg[-1]].g / pts[Tg[0]].g) ** (1.0 / dec) if pts[Tg[0]].g > 0 else np.nan
            growth.append(f"{label} {f:.3g}×" + (f" (max|g| {gg:.3g}×)" if np.isfinite(gg) else ""))
    if growth:
        P.append(f"Growth of max|ΔH| per decade of T ({Tg[0]:g} → {Tg[-1]:g} s): "
                 + "; ".join(growth) + ". fastvi's energy error is bounded (symplectic: its "
                 "slow rise is the chaotic motion visiting more extreme states over longer runs; "
                 "the adaptive step is reversible, not symplectic, and is measured here rather "
                 "than guaranteed) and its constraints stay at round-off; DOP853's energy error drifts (≈ linearly "
                 "in T at fixed tolerance), and in Cartesian form so does its constraint "
                 "residual. Holding DOP853's error fixed as T grows costs it a tighter tolerance, "
                 "which it buys cheaply (the panels above).\n")
    # cost per step: where the gap comes from
    T0 = pcfg["T"][0]
    cost = _step_costs(points, T0)
    fv = sorted(lab for lab in cost if lab.startswith("P"))
    if fv and DOP_A in cost:
        P.append(f"**Cost per step** (T = {T0:g} s, median over each contender's runs): fastvi "
                 + ", ".join(f"{lab} {1e6 * cost[lab]:.2f}" for lab in fv)
                 + f" µs (whole public call / steps), DOP853 (a) {1e6 * cost[DOP_A]:.2f} µs per "
                 f"accepted step ({peers.DOP853_STAGES} evaluations).\n")
    split = [r for r in peer_split(points, T0, DOP_A) if np.isfinite(r[2])]
    if split:
        P.append(f"**Where the ratio comes from** (T = {T0:g} s): each ratio of the first table is "
                 "the product of how many more steps fastvi's cheapest method takes than DOP853 "
                 "(a) at that energy error and how much more a step of it costs there, both read "
                 "off each contender's own front (log–log, like the CPU times):\n")
        P.append("| max\\|ΔH\\| (J) | best fastvi | its steps / DOP853 (a)'s | its cost per step "
                 "/ DOP853 (a)'s | product |")
        P.append("|---|---|---|---|---|")
        for E, which, xs, xc in split:
            P.append(f"| {E:.0e} | {which} | {xs:.3g} | {xc:.3g} | {xs * xc:.3g} |")
        P.append("")
    # stiff
    table, target = stiff_table(points, pcfg)
    s = pcfg["stiff"]
    h_max = s.get("h_max", STIFF_H_MAX)
    if table:
        cross, r_top, ratios = stiff_summary(table, pcfg)
        P.append("### Stiff rod–slider\n")
        P.append(
            f"`fastvi.scenes.rotary_rod_slider(k=…)` (paper B's l = {peers.SLIDER_L:g} m, mA = "
            f"{peers.SLIDER_MA:g} kg, mB = {peers.SLIDER_MB:g} kg, r0 = {peers.SLIDER_R0:g} m), the "
            f"rod released horizontally at rest with the spring stretched so that it holds "
            f"{peers.SPRING_ENERGY:g} J at every k (δ = sqrt(2 J/k); the fast mode, ω = sqrt(k/mB), "
            f"carries the same energy at every k, so a solver that damps it pays in energy error), "
            f"T = {s['T']:g} s. Peers: CyRK DOP853, LSODA and Radau (C++, same `cfunc` mechanism) on "
            "the hand-written minimal-coordinate (θ, r) right-hand side, rtol = atol swept; LSODA "
            "and Radau form their Jacobians by finite differences of the compiled right-hand "
            f"side. fastvi: {', '.join('`' + m + '`' for m in s['methods'])} with h = T/⌈Tω/c⌉, "
            f"ωh ≈ c ∈ {{{', '.join(f'{c:g}' for c in s['c'])}}}, h ≤ {h_max:g} (so at small "
            "k every c gives the same h). The methods with r = s (`P2L-Q2G`, `P3L-Q3G`) stay "
            "stable and keep the energy at any ωh; the defaults (r = s + 1) have a stability "
            "limit (FAILED or exploding energy beyond it). At ωh ≫ 1 the energy is right but "
            "the phase of the fast oscillation is not resolved (it is aliased): a step that "
            "keeps the energy, not one that follows the fast mode. "
            f"**Target: max|ΔH| ≤ {target:.0e} J** ({STIFF_TARGET_REL:g} of the spring energy). "
            "Each cell: CPU time to reach the target, log–log interpolated on the contender's "
            "front; ≤: every run met it, the cheapest run's time (an upper bound: for fastvi "
            f"the cheapest is h = {h_max:g}, a step the slow motion, not the spring, "
            "limits, so the ratio in the last column is then a lower bound of fastvi's lead); "
            "—: no run reached it.\n")
        labels = list(dict.fromkeys(lab for row in table.values() for lab in row))
        P.append("| k (N/m) | ω (rad/s) | " + " | ".join(labels) + " | best peer / best fastvi |")
        P.append("|---" * (len(labels) + 3) + "|")
        for k, row in table.items():
            cells = []
            for lab in labels:
                c, how = row.get(lab, (np.nan, "—"))
                cells.append("—" if not np.isfinite(c) else (("≤ " if how == "≤" else "")
                                                             + f"{c:.4g}"))
            P.append(f"| {k:.0e} | {peers.slider_omega(k):.3g} | " + " | ".join(cells)
                     + f" | **{_fmt(ratios[k])}** |")
        P.append("")
        ks = sorted(table)
        P.append(
            (f"**Crossover:** fastvi is ahead of every compiled peer from k = {cross:.0e} on. "
             if cross is not None else
             "**Crossover:** none — fastvi is not ahead of every compiled peer at the largest k "
             "(or at every k from some k on). ")
            + f"At k = {ks[-1]:.0e} the best peer takes {_fmt(r_top)}× fastvi's CPU time "
            f"(goal ≥ {STIFF_GOAL:g}×: **{'met' if r_top >= STIFF_GOAL else 'not met'}**).\n")
        big = [p for p in points if p.panel == "stiff" and p.k == ks[-1] and p.is_fastvi and p.ok
               and np.isfinite(p.err_theta) and p.dH <= target]
        if big:
            p = max(big, key=lambda p: p.knob)
            P.append(
                f"**Is the motion right, not only the energy?** At k = {ks[-1]:.0e}, `{p.label}` "
                f"with h = {p.knob:.3g} (ωh ≈ {peers.slider_omega(ks[-1]) * p.knob:.3g}) ends "
                f"{p.err_theta:.1e} rad from a tight DOP853 reference (rtol = atol = "
                f"{STIFF_REF_TOL:g}) in the rod angle θ (the slow motion), but {p.err_r:.1e} m in "
                f"r, against a spring amplitude δ = {peers.slider_stretch(ks[-1]):.1e} m: the "
                "slow motion and the energy are right, the phase of the spring's oscillation is "
                "not. A user who needs the fast oscillation itself must resolve it, and there "
                "DOP853 is cheaper (the rows at small ωh).\n")
    # where fastvi loses
    P.append("### Where fastvi loses\n")
    P.extend(_loses_lines(points, pcfg, table))
    P.append("")
    for rel in figs:
        P.append(f"![{rel}]({rel})\n")
    P.append(f"### Data (peer panels)\n")
    P.append("| panel | contender | h or tol | k | T (s) | CPU (s) | runs | max\\|ΔH\\| (J) | "
             "over the starts | max\\|g\\| | steps | \\|θ(T) − ref\\| | \\|r(T) − ref\\| |")
    P.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for p in points:
        over = f"{min(p.dHs):.1e} … {max(p.dHs):.1e}" if len(p.dHs) > 1 else ""
        P.append(f"| {p.panel} | {p.label} | {p.knob:.4g} | {'' if not np.isfinite(p.k) else f'{p.k:.0e}'} | "
                 f"{p.T:g} | {p.cpu:.4g} | {len(p.cpus)} | {'FAILED' if not p.ok else f'{p.dH:.2e}'} | "
                 f"{over} | {p.g:.1e} | {p.work} | {_fmt(p.err_theta, '.1e')} | {_fmt(p.err_r, '.1e')} |")
    P.append(f"\n(The peer sections took {elapsed / 60:.1f} min of this run.)\n")
    return P


def _loses_lines(points, pcfg, table) -> list[str]:
    """A plain statement, from the measured numbers, of where fastvi is slower."""
    from fastvi.studies import peers

    out = []
    for T in pcfg["T"]:
        for rival in (DOP_A, DOP_B):
            xs = [(E, x, w) for E, _, w, _, x in peer_ratios(points, T, rival) if np.isfinite(x)]
            slow = [(E, x, w) for E, x, w in xs if x > 1.0]
            if slow:
                out.append(f"- T = {T:g} s, against {rival}: fastvi is slower at "
                           + ", ".join(f"{E:.0e} J ({x:.3g}×, {w})" for E, x, w in slow) + ".")
            elif xs:
                out.append(f"- T = {T:g} s, against {rival}: fastvi is not slower at any level "
                           "both reach.")
    if table:
        _, _, ratios = stiff_summary(table, pcfg)
        lose = [k for k, r in ratios.items() if np.isfinite(r) and r < 1.0]
        if lose:
            out.append("- Stiff rod–slider: a compiled peer is cheaper at the target at k = "
                       + ", ".join(f"{k:.0e} ({1 / ratios[k]:.3g}× cheaper)" if ratios[k] > 0
                                   else f"{k:.0e} (fastvi never reaches the target)"
                                   for k in lose) + ".")
        # the default methods (r = s + 1) on their own
        defaults = [lab for lab in next(iter(table.values())) if lab in ("P2L-Q3G", "P3L-Q4G")]
        behind = []
        for k, row in table.items():
            fd = [row[lab][0] for lab in defaults if lab in row and np.isfinite(row[lab][0])]
            pr = [c for lab, (c, _) in row.items() if lab.startswith("CyRK") and np.isfinite(c)]
            if fd and pr and min(fd) > min(pr):
                behind.append(f"{k:.0e} ({min(fd) / min(pr):.3g}×)")
        if behind:
            out.append("- Stiff rod–slider with fastvi's *default* methods (r = s + 1, "
                       + ", ".join(f"`{d}`" for d in defaults) + "): slower than the best peer at "
                       "k = " + ", ".join(behind) + ": their stability limit makes them resolve "
                       "the spring, like DOP853, at a higher cost per step. The lead at large k "
                       "belongs to the r = s methods only.")
    T0 = pcfg["T"][0]
    split = [r for r in peer_split(points, T0, DOP_A) if np.isfinite(r[2])]
    if split:
        why = "; ".join(f"at {E:.0e} J `{w}` takes {xs:.2g}× DOP853 (a)'s steps at {xc:.2g}× its "
                        "cost per step" for E, w, xs, xc in split)
        out.append(f"- Why (T = {T0:g} s, the table *Where the ratio comes from*): {why}. Where "
                   "the steps ratio dominates, fastvi's energy error at its fixed step is larger than "
                   "that of DOP853, which adapts its step to the motion; where the "
                   "cost ratio dominates, the step is a Newton solve of s n + J m unknowns against "
                   f"{peers.DOP853_STAGES} explicit evaluations. fastvi's step runs at about its arithmetic and its "
                   "Newton iteration count is at the limit of this design for momenta conserved "
                   "to round-off (`docs/benchmarks.md`, issue 11).")
    out.append("- What fastvi wins regardless: constraints at round-off (max|g| above) and an "
               "energy error that does not drift with T.")
    return out


def run_peers(pcfg, log):
    """Run the peer panels; returns (points, elapsed s, missing-reason or None)."""
    from fastvi.studies import peers

    if not peers.have_cyrk():
        log(f"compiled peer skipped: {peers.INSTALL_HINT}")
        return [], 0.0, peers.INSTALL_HINT
    t0 = time.perf_counter()
    with quiet():
        peers.warm_up_peers()
    points = peer_pendulum_sweep(pcfg, log) + peer_stiff_sweep(pcfg, log)
    return points, time.perf_counter() - t0, None


# ----------------------------------------------------------------------------- main
def run_study(cfg, outdir: str, log, command: str, figures_on: bool = True, profile: bool = True,
              growth_on: bool = True, peers_on: bool = True, peers_cfg=None):
    """Run the sweeps, write ``outdir/wpd.md`` and the figures; returns (points, path).

    ``peers_on``: also the compiled-peer panels (:func:`run_peers`, needs CyRK; skipped with
    a note on the page when it is missing), configured by ``peers_cfg`` (default
    :data:`PEERS_QUICK` for the quick configuration, :data:`PEERS_FULL` otherwise)."""
    t_start = time.perf_counter()
    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(*THETA0)
    labels = list(dict.fromkeys(list(cfg["error"]) + list(cfg["long"])))
    warm_up(model, q0, v0, labels, log)
    q_tight = reference_q(cfg["T_error"])
    ref_floor = float(np.max(np.abs(reference_q(cfg["T_error"], tol=10 * REF_TOL) - q_tight)))
    cfg = dict(cfg, ref_floor=ref_floor)
    points = sweep(cfg, model, q0, v0, log)
    prof = []
    if profile:
        cases, n_steps, rounds, budget = cfg["profile"]
        for method, h in cases:
            pr = profile_step(model, q0, v0, method, h, n_steps=n_steps, rounds=rounds, budget=budget)
            prof.append(pr)
            log(f"profile {method} h={h:g}: {1e6 * pr['step']:.1f} µs/step, "
                + ", ".join(f"{k} {100 * v:.0f}%" for k, v in pr["shares"].items()))
    growth = {}
    if growth_on:
        for N in cfg["growth"]:
            growth[N] = chain_cost(N)
            r = growth[N]
            log(f"chain({N}): {r['rows']} rows, {1e6 * r['cpu_per_step']:.1f} µs/step, "
                f"Schur {r['solvers']['schur']}")
    peer_text = []
    os.makedirs(outdir, exist_ok=True)
    if peers_on:
        pcfg = peers_cfg if peers_cfg is not None else (PEERS_QUICK if cfg is QUICK or
                                                        cfg.get("repeats") == 1 else PEERS_FULL)
        ppoints, p_elapsed, missing = run_peers(pcfg, log)
        ptable = stiff_table(ppoints, pcfg)[0] if ppoints else {}
        pfigs = peer_figures(ppoints, pcfg, ptable, outdir, log) if figures_on and ppoints else []
        peer_text = peer_markdown(ppoints, pcfg, pfigs, p_elapsed, missing)
    figs = figures(points, cfg, outdir, log) if figures_on else []
    path = os.path.join(outdir, "wpd.md")
    text = markdown(points, cfg, figs, prof, ref_floor, command, time.perf_counter() - t_start,
                    growth)
    if peer_text:
        head, sep, tail = text.partition("## Diagrams\n")
        text = head + "\n".join(peer_text) + "\n" + sep + tail
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
    log(f"wrote {path}" + (f" and {len(figs)} figures" if figs else ""))
    return points, path


def main(argv=None) -> int:
    from ._cli import default_out, study_parser

    parser = study_parser("python -m fastvi wpd", __doc__)
    parser.add_argument("--quick", action="store_true",
                        help=f"T = {QUICK['T_error']:g} s and {QUICK['T_long']:g} s, few points, single runs")
    parser.add_argument("--out", default=default_out("wpd"), help="directory for wpd.md and figures/ "
                        "(the package's own page: --out docs, from the repository root)")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    parser.add_argument("--no-profile", action="store_true", help="skip the per-step profile")
    parser.add_argument("--no-growth", action="store_true", help="skip the chain(N) cost-growth table")
    parser.add_argument("--no-peers", action="store_true",
                        help="skip the compiled-peer panels (CyRK DOP853 / LSODA / Radau)")
    parser.add_argument("--growth-only", action="store_true",
                        help="regenerate only the chain(N) cost-growth section of the wpd.md in --out")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    args = parser.parse_args(argv)

    def log(msg):
        if not args.quiet:
            print(msg, file=sys.stderr, flush=True)

    command = "python -m fastvi wpd" + (" --quick" if args.quick else "")
    if args.growth_only:
        cfg = QUICK if args.quick else FULL
        rows = {}
        for N in cfg["growth"]:
            rows[N] = chain_cost(N)
            log(f"chain({N}): {1e6 * rows[N]['cpu_per_step']:.1f} µs/step")
        path = os.path.join(args.out, "wpd.md")
        splice_growth(path, rows, command + f" --growth-only --out {args.out}")
        print(f"wrote the cost-growth section of {path}")
        return 0
    points, path = run_study(QUICK if args.quick else FULL, args.out, log, command,
                             figures_on=not args.no_figures, profile=not args.no_profile,
                             growth_on=not args.no_growth, peers_on=not args.no_peers)
    goals, _ = goal_lines(points, QUICK if args.quick else FULL)
    print("\n".join(goals))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
