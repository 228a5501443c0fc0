"""The stiff panel: the rotary rod–slider with a stiff spring, fastvi against CyRK's DOP853,
LSODA and Radau.

The spring (k = 10^3 … 10^8 N/m) starts stretched so that it holds the same energy at every
k; each contender's CPU time to keep max|ΔH| below a fixed share of that energy is read off
its front. fastvi runs with default settings through :func:`fastvi.integrate`, its steps set
by ωh (:func:`stiff_steps`); the peers on the hand-written minimal-coordinate right-hand side
of :mod:`studies.peers`.
"""

from __future__ import annotations

import time

import numpy as np

import fastvi

from .. import peers
from .config import STIFF_H_MAX, STIFF_LONG_RUN, STIFF_REF_TOL, STIFF_SAMPLE_DT, STIFF_TARGET_REL
from .fronts import front_at
from .peer_runs import PeerPoint, cyrk_job, fastvi_job, interleaved
from .runs import compile_kernels
from .style import fmt, pyplot, save


def stiff_steps(k: float, T: float, cs, h_max: float) -> list[float]:
    """fastvi's steps at stiffness ``k``: ``h = T/⌈T ω / c⌉`` for each ``c`` (ωh ≈ c), at
    most ``h_max`` (so at small k several ``c`` give the same h, kept once)."""
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
    s = pcfg["stiff"]
    T, h_max = s["T"], s.get("h_max", STIFF_H_MAX)
    points = []
    t0 = time.perf_counter()
    # one model, k passed as a parameter (a new model per k would compile its kernels anew)
    model = fastvi.scenes.rotary_rod_slider(k=s["ks"][0])
    q0, v0 = model.initial_state(0.0, peers.SLIDER_R0)
    for method in s["methods"]:
        compile_kernels(model, q0, v0, method, 1e-4)
    for k in s["ks"]:
        q0, v0 = model.initial_state(0.0, peers.SLIDER_R0 + peers.slider_stretch(k))
        y0, prm = peers.slider_start(k), peers.slider_params(k)
        specs = [(m, h) for m in s["methods"] for h in stiff_steps(k, T, s["c"], h_max)]
        specs += [(f"CyRK {meth}", tol) for meth, tols in s["peers"].items() for tol in tols]

        def job(label, knob):
            if label.startswith("CyRK"):
                return lambda: cyrk_job("slider", y0, prm, T, knob, label.split()[1])
            return lambda: fastvi_job(model, q0, v0, label, knob, T, prm, STIFF_SAMPLE_DT)

        cpus, infos = interleaved([job(*sp) for sp in specs], pcfg["repeats"], log, STIFF_LONG_RUN)
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


def stiff_table(points, pcfg):
    """{k: {contender: (cpu, how)}} at the target max|ΔH|; how = "interp" (on the front),
    "≤" (every run met the target: the cheapest run's time, an upper bound), "—" (not
    reached by any run)."""
    target = STIFF_TARGET_REL * peers.SPRING_ENERGY
    out = {}
    for k in pcfg["stiff"]["ks"]:
        row = {}
        labels = list(dict.fromkeys(p.label for p in points if p.panel == "stiff" and p.k == k))
        for label in labels:
            pts = [p for p in points if p.panel == "stiff" and p.k == k and p.label == label and p.ok]
            meeting = [p for p in pts if p.dH <= target]
            c = front_at(pts, target, bound=False)[0]  # its bound is the "run" cell below
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


def stiff_lines(points, pcfg) -> list[str]:
    """The page's section on the stiff panel: the set-up, the table of CPU time to reach the
    target per k and contender, the crossover stiffness, and whether the motion (not only
    the energy) is right at the largest k. Empty without stiff runs."""
    table, target = stiff_table(points, pcfg)
    s = pcfg["stiff"]
    h_max = s.get("h_max", STIFF_H_MAX)
    P = []
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
                     + f" | **{fmt(ratios[k])}** |")
        P.append("")
        ks = sorted(table)
        P.append(
            (f"**Crossover:** fastvi is ahead of every compiled peer from k = {cross:.0e} on. "
             if cross is not None else
             "**Crossover:** none — fastvi is not ahead of every compiled peer at the largest k "
             "(or at every k from some k on). ")
            + f"At k = {ks[-1]:.0e} the best peer takes {fmt(r_top)}× fastvi's CPU time.\n")
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
    return P


def stiff_loses_lines(table, pcfg) -> list[str]:
    """Bullets of the page's "Where fastvi loses" on the stiff panel, from the measured
    ``table`` (:func:`stiff_table`)."""
    out = []
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
    return out


def stiff_figure(table, pcfg, outdir: str) -> list[str]:
    """The CPU time to reach the target against k, one curve a contender: ``[path]`` relative
    to ``outdir``, or ``[]`` without matplotlib or stiff runs."""
    plt = pyplot(outdir) if table else None
    if plt is None:
        return []
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
    return [save(plt, fig, outdir, "wpd-stiff.png", dpi=100)]
