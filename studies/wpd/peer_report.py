"""The page's sections on the compiled peers: ratios at equal energy error, energy growth with
T, where the ratio comes from, where fastvi loses, the figures and the data.

Every statement is read off the measured runs (:mod:`.peer_runs`, :mod:`.stiff`) with the
fronts of :mod:`.fronts`: ratios and crossovers as measured, no verdicts.
"""

from __future__ import annotations

import numpy as np

from .. import peers
from .config import (ADAPTIVE, DOP_A, DOP_B, PEER_ADAPTIVE_KR, PEER_LEVELS, PEER_LONG_RUN,
                     PEER_PILOT_T, PEER_SAMPLE_DT, PEER_START_SPREAD, STIFF_LONG_RUN,
                     STIFF_SAMPLE_DT)
from .fronts import peer_ratios, peer_split, step_costs
from .peer_runs import at_nominal_start, growth_settings, panel_methods, start_spread
from .stiff import stiff_lines, stiff_loses_lines, stiff_table
from .style import fmt, pyplot, save


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


def peer_figures(points, pcfg, outdir) -> list[str]:
    """CPU time and max|g| against max|ΔH| of every pendulum contender, a column per T:
    ``[path]`` relative to ``outdir``, or ``[]`` without matplotlib."""
    plt = pyplot(outdir)
    if plt is None:
        return []
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
    return [save(plt, fig, outdir, "wpd-peers.png", dpi=100)]


def peer_markdown(points, pcfg, figs, elapsed, missing: str | None = None) -> list[str]:
    """The page's sections on the compiled peers: the pendulum panels, the stiff panel
    (:func:`stiff.stiff_lines`), where fastvi loses, the figures ``figs`` and the data.
    ``missing``: why the peers did not run (CyRK not installed), said instead."""
    P = ["## Against a compiled DOP853\n"]
    if missing:
        P.append(f"Not run: {missing}.\n")
        return P
    import CyRK

    adaptive = ", ".join(f"`{n}`" for n in sorted(panel_methods(pcfg, adaptive_only=True)))
    P.append(
        f"The solver a speed-minded user would pick instead of fastvi: **DOP853 from CyRK "
        f"{CyRK.__version__}** (`CyRK.nbsolve2_ivp`, C++ solver, right-hand side a numba "
        "`cfunc` called through a function pointer; no Python in the loop; CyRK's pure-numba "
        "`nbsolve_ivp` was ≈ 1.8× slower here), on right-hand sides written by hand in "
        "`studies/peers.py` (no fastvi code): **(a)** the Cartesian index-1 form of the "
        "same double pendulum (the 2×2 multiplier system `G M⁻¹ Gᵀ λ = G M⁻¹ f + Ġv` solved "
        "inline, no Baumgarte terms, so the constraints drift) and **(b)** angle coordinates, its "
        "best case (no constraints). fastvi runs through its public `fastvi.integrate` with "
        "default settings, as a user calls it, after the kernels — the stages compiled for "
        "the model's sizes included, which the default then uses — were compiled or loaded "
        "from numba's cache outside the timing (as after one run of 10⁷ steps or "
        "`python -m fastvi compile`); `P1L-Q2G` … `P4L-Q5G` and `P4L-Q4G` "
        "(r = s: one quadrature point fewer than `P4L-Q5G`, the same order 8), h swept; and "
        f"`<method> adaptive` ({adaptive}) with "
        f"`adaptive={PEER_ADAPTIVE_KR:g}` (the "
        "time-reversible adaptive step: steps shrink where the "
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
        f"{peers.DOP853_STAGES} times per accepted step. The machine (in the header) was shared "
        "with other jobs; read ratios to within ≈ 1.5×.\n")
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
            f"rad, the same for every contender: `studies.wpd.peer_runs.peer_starts`); its CPU time is the "
            "nominal start's. Max / min of max|ΔH| over the starts, median over the settings at "
            f"T = {T0:g} s: "
            + ", ".join(f"{lab} {x:.2f}" for lab, x in sorted(spread.items())) + ".\n")
    P.append("### fastvi's best method / DOP853 at equal max energy error\n")
    P.append("CPU time of the cheapest fastvi method at that max|ΔH| divided by that of DOP853 "
             "(log–log interpolation on each contender's Pareto front; — where a curve does not "
             "reach the level). Above 1: fastvi is slower.\n")
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
            P.append(f"| {T:g} | {E:.0e} | {which or '—'} | {fmt(best, '.4f')} | {fmt(ca, '.4f')} | "
                     f"**{fmt(xa)}** | {fmt(cb, '.4f')} | **{fmt(xb)}** | "
                     f"{fmt(row0[4])} ({row0[2] or '—'}) | {fmt(rowf[4])} ({rowf[2] or '—'}) |")
    P.append("")
    for T in pcfg["T"]:
        line = dominated_line(points, T)
        if line:
            P.append(line + "\n")
    T0 = pcfg["T"][0]
    xs = [r[4] for r in peer_ratios(points, T0, DOP_A) if np.isfinite(r[4])]
    xf = [r[4] for r in peer_ratios(points, T0, DOP_A, fixed_only=True) if np.isfinite(r[4])]
    if xs:
        P.append(f"At T = {T0:g} s fastvi's best method takes {min(xs):.3g}× to {max(xs):.3g}× "
                 "the CPU time of DOP853 (a) at the levels both reach."
                 + (f" With fixed steps only (symplectic): {min(xf):.3g}× to {max(xf):.3g}×."
                    if xf else "")
                 + unreached_line(points, T0, DOP_A) + "\n")
    # growth with T
    settings = growth_settings(pcfg)
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
    cost = step_costs(points, T0)
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
    P.extend(stiff_lines(points, pcfg))
    # where fastvi loses
    P.append("### Where fastvi loses\n")
    P.extend(loses_lines(points, pcfg, stiff_table(points, pcfg)[0]))
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
                 f"{over} | {p.g:.1e} | {p.work} | {fmt(p.err_theta, '.1e')} | {fmt(p.err_r, '.1e')} |")
    P.append(f"\n(The peer sections took {elapsed / 60:.1f} min of this run.)\n")
    return P


def loses_lines(points, pcfg, table) -> list[str]:
    """A plain statement, from the measured numbers, of where fastvi is slower."""
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
    out.extend(stiff_loses_lines(table, pcfg))
    T0 = pcfg["T"][0]
    split = [r for r in peer_split(points, T0, DOP_A) if np.isfinite(r[2])]
    if split:
        why = "; ".join(f"at {E:.0e} J `{w}` takes {xs:.2g}× DOP853 (a)'s steps at {xc:.2g}× its "
                        "cost per step" for E, w, xs, xc in split)
        out.append(f"- Why (T = {T0:g} s, the table *Where the ratio comes from*): {why}. Where "
                   "the steps ratio dominates, fastvi's energy error at its fixed step is larger than "
                   "that of DOP853, which adapts its step to the motion; where the "
                   "cost ratio dominates, the step is a Newton solve of s n + J m unknowns against "
                   f"{peers.DOP853_STAGES} explicit evaluations (where a step's time goes: "
                   "`docs/benchmarks.md`, \"The step\").")
    out.append("- What fastvi wins regardless: constraints at round-off (max|g| above) and an "
               "energy error that does not drift with T.")
    return out
