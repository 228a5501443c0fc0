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
where the curves cross, and profiles one step (which part costs what).

SciPy's right-hand side is :func:`fastvi.baselines.solve_ivp`'s: the compiled index-1
acceleration (:func:`fastvi.baselines.rk4.acceleration`) with the model's cfuncs frozen in,
a few microseconds per call, so SciPy's own per-step overhead is what is measured.

Timing: everything is compiled (or loaded from numba's cache) before timing; each point is
the median of ``REPEATS`` runs (runs longer than ``LONG_RUN`` seconds are timed once: they
are long enough to average out the timer, not the machine's other load). All ratios come
from one process, one run of this command.

Usage::

    python -m fastvi wpd                 # full study (≈ 5–10 min on 2 cores), writes docs/
    python -m fastvi wpd --quick         # T = 1 s and 10 s, few points (tests, a first look)
    python -m fastvi wpd --out DIR       # write DIR/wpd.md and DIR/figures/wpd-*.png
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time
from dataclasses import dataclass, field

import numba as nb
import numpy as np
import scipy

import fastvi
from fastvi import _validate as check
from fastvi._numba import njit, quiet
from fastvi.baselines import rk4 as rk4_baseline
from fastvi.baselines import solve_ivp as baseline_solve_ivp
from fastvi.kernels.linalg import lu_factor, lu_solve
from fastvi.kernels.step import _PGRAD, assemble, end_momentum
from fastvi.kernels.step import make_workspace as vi_workspace
from fastvi.kernels.step import step as vi_step
from fastvi.status import Status
from fastvi.studies.reference import REF_TOL, chain_cartesian, chain_pendulum_reference

#: fastvi's defaults P1…P4 and paper B's own scheme
FASTVI_METHODS = ("P1L-Q2G", "P2L-Q3G", "P3L-Q4G", "P4L-Q5G", "P2L-Q3G-NE-CE")
SCIPY_METHODS = ("RK45", "DOP853", "Radau")
THETA0 = (np.pi / 2, np.pi / 2)  # paper B's start, at rest
T_ERROR = 10.0  # panel (a)
T_LONG = 1000.0  # panels (b), (c)
#: energies are sampled every SAMPLE_DT seconds for SciPy (dense output); fastvi and RK4 keep
#: every step, so their maxima are over more samples (never in their favour)
SAMPLE_DT = 0.1
REPEATS = 3
LONG_RUN = 2.0  # s: a run longer than this is timed once
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
        "P2L-Q3G": (0.04, 0.02, 0.01, 0.005, 0.0025),
        "P3L-Q4G": (0.05, 0.025, 0.0125, 0.00625),
        "P4L-Q5G": (0.05, 0.025, 0.0125),
        "P2L-Q3G-NE-CE": (0.02, 0.01, 0.005, 0.0025, 0.00125),
        "RK4": (0.01, 0.005, 0.0025, 0.00125, 0.000625),
        "RK4+proj": (0.01, 0.005, 0.0025, 0.00125, 0.000625),
        "SciPy RK45": (1e-4, 1e-6, 1e-8, 1e-10, 1e-12),
        "SciPy DOP853": (1e-4, 1e-6, 1e-8, 1e-10, 1e-12),
        "SciPy Radau": (1e-4, 1e-6, 1e-8),
    },
    long={
        "P1L-Q2G": (0.02, 0.01, 0.005),
        "P2L-Q3G": (0.04, 0.02, 0.01, 0.005),
        "P3L-Q4G": (0.05, 0.025, 0.0125, 0.00625),
        "P4L-Q5G": (0.05, 0.025, 0.0125),
        "P2L-Q3G-NE-CE": (0.02, 0.01),
        "RK4": (0.005, 0.0025),
        "RK4+proj": (0.01, 0.005, 0.0025, 0.00125),
        "SciPy RK45": (1e-7, 1e-9),
        "SciPy DOP853": (1e-7, 1e-9, 1e-11, 1e-13),
        "SciPy Radau": (1e-5, 1e-7),
    },
    #: SciPy contenders run over a shorter horizon in panels (b), (c) (cost); label says so
    long_horizon={"SciPy Radau": 100.0},
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
    """Run a contender once; returns (wall seconds, result)."""
    if label.startswith("SciPy"):
        # wall_time covers solve_ivp alone; its right-hand side is compiled beforehand
        res = baseline_solve_ivp(model, q0, v0, t_end=T, method=label.split()[1], rtol=knob,
                                 atol=knob, t_eval=t_eval)
        return res.stats["wall_time"], res
    t0 = time.perf_counter()
    if label.startswith("RK4"):
        res = rk4_baseline(model, q0, v0, h=knob, t_end=T, project=label == "RK4+proj",
                           on_failure="return")
    else:
        res = fastvi.integrate(model, q0, v0, h=knob, t_end=T, method=label, on_failure="return")
    return time.perf_counter() - t0, res


def measure(panel, label, model, q0, v0, knob, T, repeats, q_ref=None) -> Point:
    """Time one contender at one setting (median of ``repeats``) and record its errors."""
    t_eval = np.linspace(0.0, T, int(round(T / SAMPLE_DT)) + 1)
    walls = []
    res = None
    for _ in range(repeats):
        w, res = _run_once(label, model, q0, v0, knob, T, t_eval)
        walls.append(w)
        if w > LONG_RUN:
            break
    pt = Point(panel, label, knob, T, float(np.median(walls)), walls)
    pt.ok = bool(res.success) and np.isclose(res.t[-1], T)
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
def pareto(points, metric: str):
    """(error, wall) of the runs no other run of the same contender beats in both, by error.

    Returns two arrays sorted by decreasing error (increasing wall time)."""
    pts = sorted((p for p in points if p.ok and np.isfinite(getattr(p, metric))
                  and getattr(p, metric) > 0), key=lambda p: p.wall)
    errs, walls = [], []
    for p in pts:
        e = getattr(p, metric)
        if not errs or e < errs[-1]:
            errs.append(e)
            walls.append(p.wall)
    return np.array(errs), np.array(walls)


def cost_at(points, metric: str, E):
    """Wall time to reach error ``E`` (log–log interpolation on the Pareto front; NaN outside)."""
    errs, walls = pareto(points, metric)
    E = np.atleast_1d(np.asarray(E, float))
    out = np.full(E.shape, np.nan)
    if len(errs) == 0:
        return out
    if len(errs) == 1:
        out[np.isclose(E, errs[0], rtol=1e-12)] = walls[0]
        return out
    le, lw = np.log(errs[::-1]), np.log(walls[::-1])  # increasing error
    inside = (E >= errs.min()) & (E <= errs.max())
    out[inside] = np.exp(np.interp(np.log(E[inside]), le, lw))
    return out


def best_fastvi(points, metric, E):
    """(wall, method) of the cheapest fastvi method at each error level ``E``."""
    labels = [m for m in FASTVI_METHODS if any(p.label == m for p in points)]
    costs = np.array([cost_at([p for p in points if p.label == m], metric, E) for m in labels])
    walls = np.full(np.shape(E), np.nan)
    which = np.full(np.shape(E), "", dtype=object)
    for k in range(len(np.atleast_1d(E))):
        col = costs[:, k]
        if np.any(np.isfinite(col)):
            j = int(np.nanargmin(col))
            walls[k], which[k] = col[j], labels[j]
    return walls, which


def compare(points, metric: str, rival: str, per_decade: int = 40):
    """Speed-up of the best fastvi method over ``rival`` at equal error, on a fine error grid.

    Returns ``(E, ratio, method)`` over the error range both cover (empty if none)."""
    rp = [p for p in points if p.label == rival]
    fp = [p for p in points if p.kind == "fastvi"]
    e1, _ = pareto(rp, metric)
    e2 = np.concatenate([pareto([p for p in fp if p.label == m], metric)[0] for m in FASTVI_METHODS])
    if len(e1) < 2 or len(e2) < 2:
        return np.array([]), np.array([]), np.array([])
    lo, hi = max(e1.min(), e2.min()), min(e1.max(), e2.max())
    if not lo < hi:
        return np.array([]), np.array([]), np.array([])
    E = np.logspace(np.log10(lo), np.log10(hi), max(2, int(per_decade * np.log10(hi / lo)) + 1))
    fw, which = best_fastvi(fp, metric, E)
    ratio = cost_at(rp, metric, E) / fw
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
    """Error ranges where each fastvi method is the cheapest: [(method, E_hi, E_lo)]."""
    fp = [p for p in points if p.kind == "fastvi"]
    errs = np.concatenate([pareto([p for p in fp if p.label == m], metric)[0] for m in FASTVI_METHODS])
    if len(errs) == 0:
        return []
    lo, hi = errs.min(), errs.max()
    E = np.logspace(np.log10(hi), np.log10(lo), max(2, int(per_decade * np.log10(hi / lo)) + 1))
    _, which = best_fastvi(fp, metric, E)
    spans = []
    for e, w in zip(E, which):
        if not w:
            continue
        if spans and spans[-1][0] == w:
            spans[-1][2] = e
        else:
            spans.append([w, e, e])
    return [tuple(s) for s in spans]


# ----------------------------------------------------------------------------- profile
@njit
def _loop_assemble(fns, flags, Mc, prm, tabs, h, qk, pk, ws, jac, K):
    st = 0
    for _ in range(K):
        st += assemble(fns, flags, Mc, prm, tabs, h, qk, pk, ws, jac)
    return st


@njit
def _loop_factor(A0, A, piv, N, factor, K):
    st = 0
    for _ in range(K):
        for i in range(N):
            for j in range(N):
                A[i, j] = A0[i, j]
        if factor:
            st += lu_factor(A, piv, N)
    return st


@njit
def _loop_solve(A, piv, R0, R, N, K):
    for _ in range(K):
        for i in range(N):
            R[i] = R0[i]
        lu_solve(A, piv, R, N)
    return R[0]


@njit
def _loop_callback(fns, q, prm, out, K):
    acc = 0.0
    for _ in range(K):
        fns[_PGRAD](q.ctypes, q.ctypes, prm.ctypes, out.ctypes)
        acc += out[0]
    return acc


@njit
def _loop_end(fns, flags, Mc, prm, q1, P, p1, v1, G1, ws, K):
    st = 0
    for _ in range(K):
        st += end_momentum(fns, flags, Mc, prm, q1, P, p1, v1, G1, ws)
    return st


def _per_call(fn, *args, budget: float = 0.05, repeats: int = 5) -> float:
    """Seconds per iteration of a compiled loop ``fn(*args, K)``: the least disturbed
    (minimum) of ``repeats`` timings of ``K`` iterations, ``K`` grown until one takes
    ``budget`` seconds. On a shared machine the minimum estimates the cost of the code; a
    median adds a share of other jobs' load."""
    fn(*args, 1)
    K = 1
    while True:
        t0 = time.perf_counter()
        fn(*args, K)
        dt = time.perf_counter() - t0
        if dt > budget or K > 1 << 22:
            break
        K *= 4
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(*args, K)
        walls.append((time.perf_counter() - t0) / K)
    return float(np.min(walls))


def profile_step(model, q0, v0, method: str, h: float, n_steps: int = 2000) -> dict:
    r"""Cost of the parts of one fastvi step, in seconds per call.

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
    fns, flags, Mc = model.kernel_arguments()
    prm = np.asarray(model.params, float)
    tabs = meth.kernel_tables
    n, m = model.n, model.m
    N = meth.s * n + meth.J * m
    with quiet():
        fastvi.integrate(model, q0, v0, h=h, n_steps=2, method=method)
        res = fastvi.integrate(model, q0, v0, h=h, n_steps=n_steps, method=method)
    its = res.stats["newton_iterations"] / res.stats["steps"]
    qk, pk, vk = res.q[-1].copy(), res.p[-1].copy(), res.v[-1].copy()
    ws = vi_workspace(n, m, meth.s, meth.r, meth.J)
    q1, p1, v1 = np.zeros(n), np.zeros(n), np.zeros(n)
    out = np.zeros(4)
    t: dict[str, float] = {}
    with quiet():
        st = vi_step(fns, flags, Mc, prm, tabs, h, qk, pk, vk, q1, p1, v1, ws, 1e-14, 30, True, out)
        if st != 0:
            raise RuntimeError(f"profile step failed with status {st}")
        # the Newton matrix at the converged unknowns, then its factors
        assemble(fns, flags, Mc, prm, tabs, h, qk, pk, ws, True)
        A0 = ws[2][:N, :N].copy()
        R0 = ws[1][:N].copy()
        A, piv, R = np.zeros((N, N)), np.zeros(N, dtype=np.int64), np.zeros(N)
        P = ws[14].copy()
        # rounds interleave the whole step with its parts; each keeps its fastest round, so
        # a burst of other load shifts no part against the others
        for _ in range(3):
            t0 = time.perf_counter()
            fastvi.integrate(model, q0, v0, h=h, n_steps=n_steps, method=method)
            parts = dict(
                step=(time.perf_counter() - t0) / n_steps,
                assemble_jac=_per_call(_loop_assemble, fns, flags, Mc, prm, tabs, h, qk, pk, ws,
                                       True, repeats=3),
                assemble_res=_per_call(_loop_assemble, fns, flags, Mc, prm, tabs, h, qk, pk, ws,
                                       False, repeats=3),
                lu_factor=max(0.0, _per_call(_loop_factor, A0, A, piv, N, True, repeats=3)
                              - _per_call(_loop_factor, A0, A, piv, N, False, repeats=3)),
                lu_solve=_per_call(_loop_solve, A, piv, R0, R, N, repeats=3),
                end_momentum=_per_call(_loop_end, fns, flags, Mc, prm, q1, P, p1, v1,
                                       ws[5][meth.J], ws, repeats=3),
                callback=_per_call(_loop_callback, fns, qk.copy(), prm, np.zeros(n), repeats=3),
            )
            for k, v in parts.items():
                t[k] = min(t.get(k, np.inf), v)
    step_cost = t.pop("step")
    calls = dict(assemble_jac=its, lu_factor=its, lu_solve=its, assemble_res=1.0, end_momentum=1.0)
    shares = {k: t[k] * calls[k] / step_cost for k in calls}
    shares["other"] = 1.0 - sum(shares.values())
    return dict(step=step_cost, iterations=its, N=N, n=n, m=m, method=method, h=h, shares=shares,
                **t)


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
        ax.invert_xaxis()
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


def goal_lines(points, cfg) -> tuple[list[str], dict]:
    """The goal verdicts and crossover points, in words, with the numbers behind them."""
    lines, summary = [], {}
    T = cfg["T_long"]
    for rival, goal in (("SciPy DOP853", GOAL_SCIPY), ("RK4+proj", GOAL_RK4), ("RK4", GOAL_RK4)):
        E, ratio, which = compare(points, "dH", rival)
        if len(E) == 0:
            lines.append(f"- **vs {rival}**: no common range of max|ΔH| over T = {T:g} s "
                         "(no comparison possible).")
            continue
        k_lo, k_hi = int(np.argmin(ratio)), int(np.argmax(ratio))
        summary[rival] = dict(E=E, ratio=ratio, which=which)
        met_all = bool(np.all(ratio >= goal))
        met_any = bool(np.any(ratio >= goal))
        verdict = "met over the whole common range" if met_all else (
            "met only in part of the range" if met_any else "NOT met")
        decades = [10.0 ** k for k in range(int(np.floor(np.log10(E.max()))),
                                            int(np.ceil(np.log10(E.min()))) - 1, -1)]
        at = [(d, cost_at([p for p in points if p.label == rival], "dH", d)[0],
               best_fastvi([p for p in points if p.kind == "fastvi"], "dH", np.array([d])))
              for d in decades if E.min() <= d <= E.max()]
        at_txt = "; ".join(f"{r / b[0][0]:.3g}× at {d:.0e} ({b[1][0]})" for d, r, b in at)
        lines.append(
            f"- **vs {rival}** (goal ≥ {goal:g}×): {verdict}. Over max|ΔH| = {E.max():.1e} … "
            f"{E.min():.1e} J the best fastvi method is {ratio.min():.3g}× ({which[k_lo]}, at "
            f"{E[k_lo]:.1e}) to {ratio.max():.3g}× ({which[k_hi]}, at {E[k_hi]:.1e}) faster"
            + (f"; by decade: {at_txt}" if at_txt else "") + ".")
        cross = crossings(E, ratio, goal)
        even = crossings(E, ratio, 1.0) if goal != 1.0 else []
        if cross:
            lines.append(f"  Crossover (ratio = {goal:g}×) at max|ΔH| ≈ "
                         + ", ".join(f"{c:.1e}" for c in cross) + " J.")
        if even:
            lines.append("  Break-even (ratio = 1×) at max|ΔH| ≈ " + ", ".join(f"{c:.1e}" for c in even)
                         + " J.")
        if not cross and not even:
            lines.append(f"  No crossover inside the common range (the ratio stays "
                         f"{'above' if ratio.min() >= goal else 'below'} {goal:g}×).")
    return lines, summary


def _table(points, panel, metric_cols, cfg) -> list[str]:
    head = "| contender | h or tol | T (s) | wall (s) | runs | " + " | ".join(c[0] for c in metric_cols) \
        + " | steps or nfev | Newton its/step |"
    out = [head, "|" + "---|" * (6 + len(metric_cols) + 1)]
    for p in points:
        if p.panel != panel:
            continue
        vals = " | ".join(("FAILED" if not p.ok else f"{getattr(p, c[1]):.2e}") for c in metric_cols)
        nt = f"{p.newton:.2f}" if np.isfinite(p.newton) else ""
        out.append(f"| {p.label} | {p.knob:g} | {p.T:g} | {p.wall:.4g} | {len(p.walls)} | {vals} | "
                   f"{p.work} | {nt} |")
    return out


def markdown(points, cfg, figs, prof, ref_floor, command, elapsed) -> str:
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
        "rtol = atol (`fastvi.baselines.solve_ivp`; the cfuncs are frozen into its right-hand "
        "side, a few µs per call, so SciPy's own per-step overhead is what is measured).\n")
    P.append(
        f"**Measurements.** Wall time of the whole call (fastvi: `fastvi.integrate`, including "
        f"validation and saving every step; SciPy: `solve_ivp` alone), after compilation, "
        + (f"median of {cfg['repeats']} runs (runs longer than {LONG_RUN:g} s timed once). "
           if cfg["repeats"] > 1 else "one run each. ")
        + f"(a) max-norm of q(T) − q_ref(T) at T = {cfg['T_error']:g} s, q_ref from SciPy DOP853 at "
        f"rtol = atol = {REF_TOL:g} in angle coordinates (independent of fastvi); the reference "
        f"itself is uncertain at ≈ {ref_floor:.0e} (its distance to the same solve at tolerance "
        f"1e-12), so errors below that are not resolved. (b) max over the run of |H − H(0)| over "
        f"T = {cfg['T_long']:g} s (fastvi and RK4: every step; SciPy: its dense output every "
        f"{SAMPLE_DT:g} s). (c) max |g(q)| over the runs of (b).\n")
    P.append(
        "**Noise.** The machine (2 cores) was shared with other jobs while this ran; single "
        "timings vary by tens of per cent. The ratios below compare runs of one process, "
        "interleaved in time only at the granularity of the sweeps, so read them to within a "
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
    # position-error comparison at the same time
    E, ratio, which = compare(points, "err_q", "SciPy DOP853")
    if len(E):
        P.append(f"For the position error at T = {cfg['T_error']:g} s (panel a) the best fastvi "
                 f"method is {ratio.min():.3g}× to {ratio.max():.3g}× faster than SciPy DOP853 over "
                 f"errors {E.max():.1e} … {E.min():.1e} m.\n")
    if prof:
        P.append("## What a step costs\n")
        P.append("`fastvi.studies.wpd.profile_step`: the measured cost per step of "
                 "`fastvi.integrate` (saving every step), and each kernel timed alone in a "
                 "compiled loop on the same state, times its calls per step (Newton iterations "
                 "for the parts inside Newton's loop); fastest of three interleaved rounds. "
                 "*other* = the step minus the parts (predictor, bookkeeping, saving, the Python "
                 "driver); negative values mean the machine's load inflated the parts more than "
                 "the step, i.e. the noise of this table. One model callback (∇V) costs "
                 + ", ".join(f"{1e9 * pr['callback']:.0f} ns" for pr in prof)
                 + " per call: the model is not what a step spends its time on.\n")
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
    P.append("## Diagrams\n")
    for (panel, metric, fname, xlabel, title), rel in zip(PANELS, figs):
        P.append(f"![{title.format(**cfg)}]({rel})\n")
    if not figs:
        P.append("(matplotlib was not installed when this page was generated: no figures.)\n")
    P.append(f"## Data\n\n### (a) position error at T = {cfg['T_error']:g} s\n")
    P.extend(_table(points, "error", [("max\\|Δq\\| (m)", "err_q"), ("max\\|ΔH\\| (J)", "dH"),
                                       ("max\\|g\\|", "g")], cfg))
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


# ----------------------------------------------------------------------------- main
def run_study(cfg, outdir: str, log, command: str, figures_on: bool = True, profile: bool = True):
    """Run the sweeps, write ``outdir/wpd.md`` and the figures; returns (points, path)."""
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
        for method, h in (("P2L-Q3G", 0.01), ("P3L-Q4G", 0.0125), ("P4L-Q5G", 0.025)):
            pr = profile_step(model, q0, v0, method, h, n_steps=200 if cfg["repeats"] == 1 else 2000)
            prof.append(pr)
            log(f"profile {method} h={h:g}: {1e6 * pr['step']:.1f} µs/step, "
                + ", ".join(f"{k} {100 * v:.0f}%" for k, v in pr["shares"].items()))
    os.makedirs(outdir, exist_ok=True)
    figs = figures(points, cfg, outdir, log) if figures_on else []
    path = os.path.join(outdir, "wpd.md")
    text = markdown(points, cfg, figs, prof, ref_floor, command, time.perf_counter() - t_start)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
    log(f"wrote {path}" + (f" and {len(figs)} figures" if figs else ""))
    return points, path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m fastvi wpd", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help=f"T = {QUICK['T_error']:g} s and {QUICK['T_long']:g} s, few points, single runs")
    parser.add_argument("--out", default="docs", help="directory for wpd.md and figures/ (default: docs)")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    parser.add_argument("--no-profile", action="store_true", help="skip the per-step profile")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    args = parser.parse_args(argv)

    def log(msg):
        if not args.quiet:
            print(msg, file=sys.stderr, flush=True)

    command = "python -m fastvi wpd" + (" --quick" if args.quick else "")
    points, path = run_study(QUICK if args.quick else FULL, args.out, log, command,
                             figures_on=not args.no_figures, profile=not args.no_profile)
    goals, _ = goal_lines(points, QUICK if args.quick else FULL)
    print("\n".join(goals))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
