"""Panels (a)–(c) of the speed study: fastvi, RK4 and SciPy on the double pendulum.

Every contender integrates the same :class:`fastvi.Model` through its public call:
:func:`fastvi.integrate`, :func:`fastvi.baselines.rk4` and :func:`fastvi.baselines.solve_ivp`
(SciPy on the index-1 form, the model's compiled callbacks frozen into its right-hand side).
Each setting is one :class:`Point`: cost and errors from the same runs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

import fastvi
from fastvi import baselines
from fastvi.studies.reference import REF_TOL, chain_cartesian, chain_pendulum_reference

from .config import LONG_RUN, SAMPLE_DT, THETA0


def compile_kernels(model, q0, v0, method, h):
    """Compile (or load) the kernels of ``method`` for ``model`` outside any timing, the
    stages compiled for the model's sizes included: what one long run or ``python -m fastvi
    compile`` leaves in numba's disk cache, and what the timed runs, with default settings,
    then take (``specialize=None`` uses the sized stages once they are compiled)."""
    fastvi.integrate(model, q0, v0, h=h, n_steps=2, method=method, specialize=True)


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

    fastvi and RK4: the whole public call. SciPy: ``scipy.integrate.solve_ivp`` alone
    (:func:`fastvi.baselines.solve_ivp` times it; the energies and residuals at ``t_eval``
    are evaluated after the clock stops)."""
    if label.startswith("SciPy"):
        res = baselines.solve_ivp(model, q0, v0, t_end=T, method=label.split()[1], rtol=knob,
                                  atol=knob, t_eval=t_eval)
        return res.stats["wall_time"], res.stats["cpu_time"], res
    t0, c0 = time.perf_counter(), time.thread_time()
    if label.startswith("RK4"):
        res = baselines.rk4(model, q0, v0, h=knob, t_end=T, project=label == "RK4+proj",
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
        if label.startswith("P"):  # a fastvi method, with its sized stages
            compile_kernels(model, q0, v0, label.split()[0], knob)
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
