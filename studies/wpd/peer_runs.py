"""The compiled-peer panels' pendulum runs: fastvi with default settings against CyRK's DOP853.

Each contender and setting is one :class:`PeerPoint`, timed in CPU time of the process
(median of interleaved runs, :func:`interleaved`). fastvi runs through its public
:func:`fastvi.integrate` with default settings (what a user gets); the peers are the
hand-written compiled right-hand sides of :mod:`studies.peers`. The double pendulum from
π/2 is chaotic, so each setting's max|ΔH| is the median over :func:`peer_starts`.
"""

from __future__ import annotations

import time
import warnings
import weakref
from dataclasses import dataclass, field, replace

import numpy as np

import fastvi

from .. import peers
from .config import (ADAPTIVE, DOP_A, DOP_B, LONG_RUN, NO_SAMPLES, PEER_ADAPTIVE_KR,
                     PEER_LONG_RUN, PEER_PILOT_T, PEER_SAMPLE_DT, PEER_START_SEED,
                     PEER_START_SPREAD, THETA0)
from .runs import compile_kernels


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
                    **options):
    """One public ``fastvi.integrate`` call as the peer panels time it, energies saved every
    ``sample_dt`` seconds: ``(cpu, info)`` with the process CPU time of the call and ``info``
    holding ``dH`` (max|H − H0| over the samples), ``g`` (max|g|), ``steps``, ``ok`` and the
    final ``end`` configuration. Default settings otherwise, as a user calls it. ``method``
    ``"<name> adaptive"`` runs the adaptive step (``adaptive=PEER_ADAPTIVE_KR``, ``h`` its ε;
    saved every ``sample_dt`` s on average: :func:`adaptive_sample_every`). ``options`` go to
    ``fastvi.integrate`` as they are (the benchmarks' other settings)."""
    name, adaptive = _adaptive_label(method)
    every = peer_save_every(model, q0, v0, method, h, T, params, sample_dt)
    c0 = time.process_time()
    res = fastvi.integrate(model, q0, v0, h=h, t_end=T, method=name, save_every=every,
                           params=params, on_failure="return", adaptive=adaptive, **options)
    cpu = time.process_time() - c0
    ok = bool(res.success) and bool(np.isclose(res.t[-1], T))
    dH = float(np.max(np.abs(res.energy - res.energy[0]))) if len(res.energy) else np.inf
    g = float(np.max(res.constraint_residual)) if len(res.energy) else np.inf
    return cpu, dict(dH=dH, g=g, steps=int(res.stats["steps"]), ok=ok and np.isfinite(dH),
                     end=res.q[-1].copy() if len(res.q) else None)


def peer_save_every(model, q0, v0, label, h, T, params=None, sample_dt=PEER_SAMPLE_DT) -> int:
    """``save_every`` of a peer-panel contender ``label`` at step (or ε) ``h``: every
    ``sample_dt`` seconds, on average for an adaptive one (:func:`adaptive_sample_every`,
    whose pilot run is not timed: call this before the clock starts)."""
    name, adaptive = _adaptive_label(label)
    if adaptive is None:
        return max(1, int(round(sample_dt / h)))
    return adaptive_sample_every(model, q0, v0, name, h, T, params, sample_dt, adaptive)


def adaptive_sample_every(model, q0, v0, method, eps, T, params=None, sample_dt=PEER_SAMPLE_DT,
                          kr=PEER_ADAPTIVE_KR) -> int:
    """``save_every`` for an adaptive run of ε = ``eps`` that saves every ``sample_dt``
    seconds on average, as the fixed steps do: the mean step ``T_p / steps`` of a pilot run
    over ``T_p = min(T, PEER_PILOT_T)`` (steps shrink where the pendulum whips: the mean
    step of the double pendulum is ≈ ε/2.2, so ``sample_dt/ε`` would save 2.2× as often,
    and a saved sample costs a fraction of a step).

    The pilot is deterministic, so its answer is kept per model and arguments: the study
    and the bench scripts time the same setting 5–7 times, and each pilot is a tenth of the
    timed run."""
    key = (np.asarray(q0, float).tobytes(), np.asarray(v0, float).tobytes(), method,
           float(eps), float(T), None if params is None else np.asarray(params, float).tobytes(),
           float(sample_dt), float(kr))
    known = _PILOTS.setdefault(model, {})
    if key not in known:
        Tp = min(T, PEER_PILOT_T)
        pilot = fastvi.integrate(model, q0, v0, h=eps, t_end=Tp, method=method, params=params,
                                 save_every=NO_SAMPLES, on_failure="return", adaptive=kr)
        mean_step = float(pilot.t[-1] - pilot.t[0]) / max(1, int(pilot.stats["steps"]))
        known[key] = max(1, int(round(sample_dt / mean_step)))
    return known[key]


#: :func:`adaptive_sample_every`'s answers, per model (dropped with the model)
_PILOTS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def panel_methods(pcfg, adaptive_only: bool = False) -> set:
    """The method names the pendulum panels of ``pcfg`` run (only those run adaptive)."""
    return {_adaptive_label(m)[0] for d in pcfg["fastvi"].values() for m in d
            if not adaptive_only or m.endswith(ADAPTIVE)}


def _adaptive_label(label: str):
    """(method name, the ``adaptive`` argument) of a peer-panel contender's label."""
    if label.endswith(ADAPTIVE):
        return label[: -len(ADAPTIVE)], PEER_ADAPTIVE_KR
    return label, None


def interleaved(jobs, repeats, log, budget=LONG_RUN):
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
    """The pendulum panel's points with max|ΔH| of the nominal start alone, for the page's
    column that shows how much the median over the starts moves a ratio."""
    return [replace(p, dH=p.dHs[0]) if p.panel == "pendulum" and p.dHs else p for p in points]


def peer_pendulum_sweep(pcfg, log) -> list[PeerPoint]:
    """Work–precision panels at each T of ``pcfg``: fastvi vs DOP853 (a) and (b), timed from
    the nominal start; max|ΔH| the median over :func:`peer_starts` (``pcfg["starts"]``)."""
    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(*THETA0)
    prm = peers.DP_PARAMS
    for method in panel_methods(pcfg) | {pcfg["growth"]["fastvi"][0]}:
        compile_kernels(model, q0, v0, method, 0.01)
    specs = []
    for T in pcfg["T"]:
        for method, hs in pcfg["fastvi"][T].items():
            specs += [(method, h, T) for h in hs]
        for tol in pcfg["dop"][T]:
            specs += [(DOP_A, tol, T), (DOP_B, tol, T)]
    for T in pcfg["growth"]["T"]:  # the growth table's settings, where the panels lack them
        for label, knob in growth_settings(pcfg):
            if (label, knob, T) not in specs:
                specs.append((label, knob, T))

    def job(label, knob, T, theta=THETA0):
        if label == DOP_A:
            ya = peers.cartesian_start(theta)
            return lambda: cyrk_job("cartesian", ya, prm, T, knob, "DOP853")
        if label == DOP_B:
            yb = peers.angles_start(theta)
            return lambda: cyrk_job("angles", yb, prm, T, knob, "DOP853")
        q, v = model.initial_state(*theta)
        return lambda: fastvi_job(model, q, v, label, knob, T, sample_dt=PEER_SAMPLE_DT)

    t0 = time.perf_counter()
    cpus, infos = interleaved([job(*s) for s in specs], pcfg["repeats"], log, PEER_LONG_RUN)
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


def growth_settings(pcfg) -> list[tuple]:
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


def cyrk_job(system, y0, prm, T, tol, method):
    """One timed CyRK run (:func:`studies.peers.run_peer`) as ``(cpu, info)``, like
    :func:`fastvi_job`."""
    r = peers.run_peer(system, y0, prm, T=T, tol=tol, method=method)
    return r["cpu"], dict(dH=r["dH"], g=r["g"], steps=r["steps"], ok=r["ok"], end=r["y_end"])


def fastvi_job(model, q0, v0, method, h, T, params=None, sample_dt=PEER_SAMPLE_DT):
    """:func:`fastvi_peer_run` with the energy-growth alarm of an unstable setting silenced
    (the study records such a run as failed or far off the target; it warns nobody)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return fastvi_peer_run(model, q0, v0, method, h, T, params, sample_dt)
