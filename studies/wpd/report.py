"""The page of panels (a)–(c): fastvi against RK4 and SciPy at equal error, the diagrams and
the data.

Ratios are read off the Pareto fronts (:mod:`.fronts`) and stated as measured: the wall time
of a rival divided by that of fastvi's cheapest method at the same error, the error ranges
where each fastvi method is the cheapest, and where a ratio crosses 1.
"""

from __future__ import annotations

import os

import numpy as np

from fastvi.studies.reference import REF_TOL

from ..machine import environment
from .config import LONG_RUN, SAMPLE_DT
from .fronts import compare, crossings, method_crossovers, select
from .growth import growth_lines
from .runs import Point
from .style import pyplot, save

#: the rivals of the comparisons at equal error, in the page's order
RIVALS = ("SciPy DOP853", "RK4+proj", "RK4", "SciPy RK45", "SciPy Radau")

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
    plt = pyplot(outdir, log)
    if plt is None:
        return []
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
        paths.append(save(plt, fig, outdir, fname))
    return paths


def _at_decades(E, ratio, which):
    """The ratio (and the fastvi method) at each power of ten inside ``E``."""
    out = []
    for k in range(int(np.floor(np.log10(E.max()))), int(np.ceil(np.log10(E.min()))) - 1, -1):
        d = 10.0 ** k
        if E.min() <= d <= E.max():
            j = int(np.argmin(np.abs(np.log(E) - np.log(d))))
            out.append((d, float(ratio[j]), which[j]))
    return out


def comparison_lines(points, metric: str, rival: str, what: str, unit: str) -> tuple[list[str], dict]:
    """One bullet (and sub-lines) comparing fastvi's best method with ``rival`` at equal error.

    The speed ratio (the rival's time over fastvi's best at the same error) over the range
    both fronts cover, at each decade, in wall and CPU time, and where it crosses 1. Returns
    the lines and ``{"E", "ratio", "which", "cpu_ratio"}`` (empty if the rival's and fastvi's
    errors do not overlap)."""
    E, ratio, which = compare(points, metric, rival)
    if len(E) == 0:
        return [f"- **{rival}**: its {what} and fastvi's do not overlap (see the table): no "
                "ratio at equal error."], {}
    _, rc, _ = compare(points, metric, rival, cost="cpu")
    k_lo, k_hi = int(np.argmin(ratio)), int(np.argmax(ratio))
    dec = "; ".join(f"{r:.3g}× at {d:.0e} {unit} ({w})" for d, r, w in _at_decades(E, ratio, which))
    lines = [f"- **{rival}**: over {what} from {E.max():.1e} to {E.min():.1e} {unit}, fastvi's "
             f"best method is {ratio.min():.3g}× ({which[k_lo]}, at {E[k_lo]:.1e} {unit}) to "
             f"{ratio.max():.3g}× ({which[k_hi]}, at {E[k_hi]:.1e} {unit}) {rival}'s speed"
             + (f"; at each decade: {dec}" if dec else "") + "."
             + (f" In CPU time (insensitive to other jobs' load): {rc.min():.3g}× to "
                f"{rc.max():.3g}×." if len(rc) else "")]
    even = crossings(E, ratio, 1.0)
    if even:
        lines.append(f"  Break-even (ratio = 1×) at {what} ≈ " + ", ".join(f"{c:.1e}" for c in even)
                     + f" {unit}" + ("; the rival is faster on the looser side." if ratio[0] < 1.0
                                     else "; the rival is faster on the tighter side."))
    else:
        lines.append(f"  No break-even inside the common range: the ratio stays "
                     f"{'above' if ratio.min() >= 1.0 else 'below'} 1×.")
    return lines, dict(E=E, ratio=ratio, which=which, cpu_ratio=rc)


def ratio_lines(points, metric: str, what: str, unit: str) -> tuple[list[str], dict]:
    """:func:`comparison_lines` for every rival that ran in ``metric``'s panel.

    Returns the Markdown lines and ``{rival: {"E", "ratio", "which", "cpu_ratio"}}``."""
    lines, summary = [], {}
    for rival in RIVALS:
        if not select(points, metric, rival):
            continue
        ls, data = comparison_lines(points, metric, rival, what, unit)
        lines += ls
        if data:
            summary[rival] = data
    return lines, summary


def energy_ratio_lines(points, cfg) -> list[str]:
    """The ratios at equal max|ΔH| over the long runs (panel b): the page's first section, and
    what the command prints at its end."""
    return ratio_lines(points, "dH", f"max|ΔH| over T = {cfg['T_long']:g} s", "J")[0]


def evaluation_cost_lines(points) -> list[str]:
    """What one right-hand-side evaluation costs SciPy DOP853 against the compiled physics
    behind it (RK4+proj's evaluations), from the runs of panel (b)."""
    dop = [p for p in select(points, "dH", "SciPy DOP853") if p.ok]
    rk = [p for p in select(points, "dH", "RK4+proj") if p.ok]
    if not dop:
        return []
    per_eval = np.median([p.wall / p.work for p in dop])
    line = (f"**Cost of an evaluation.** SciPy DOP853 costs {1e6 * per_eval:.1f} µs per "
            "right-hand-side evaluation (wall time / nfev, median over its runs of panel b)")
    if rk:
        per_rk = np.median([p.wall / (4 * p.work) for p in rk])
        line += (f"; the compiled index-1 physics behind one evaluation costs ≈ {1e6 * per_rk:.1f} µs "
                 "(RK4+proj's wall time per evaluation, projection included): the rest is "
                 "SciPy's Python per stage")
    return [line + ".\n"]


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


def markdown(points, cfg, figs, ref_floor, command, elapsed, growth=None) -> str:
    """The page: header, set-up, the ratios at equal error, cost growth (``growth``: the rows
    of :func:`.growth.chain_cost`), the diagrams ``figs`` and the data."""
    spans = method_crossovers(points, "dH")
    spans_a = method_crossovers(points, "err_q")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    P = []
    P.append("# Speed against error: work–precision diagrams\n")
    P.append(f"Generated by `{command}` with {environment()}; load average {load:.1f} at the "
             f"end; the run took {elapsed / 60:.1f} min. Do not edit by hand: rerun the "
             "command.\n")
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
        "rtol = atol (`fastvi.baselines.solve_ivp`, with the model's cfuncs frozen into the "
        "compiled right-hand side, a few µs per call, so SciPy's own per-step overhead is what "
        "is measured).\n")
    P.append(
        f"**Measurements.** Wall time after compilation: fastvi and RK4, the whole public call "
        f"(`fastvi.integrate` / `fastvi.baselines.rk4`: validation, the initial projection, "
        f"the loop, energies and residuals at every step); SciPy, `scipy.integrate.solve_ivp` "
        f"alone (as `fastvi.baselines.solve_ivp` times it; its energies are evaluated "
        f"afterwards), "
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
        "**Noise.** The machine (in the header) was shared with other jobs while this ran; single "
        "timings vary by tens of per cent, and load that comes and goes during the sweeps "
        "shifts one contender against another. The CPU time of the calling thread "
        "(`time.thread_time`), recorded for the same runs, is insensitive to the other jobs; "
        "the ratios are given both ways. (Every contender here runs in that one thread: the "
        "matrices are too small for BLAS to use its threads.) Read the ratios to within a "
        "factor ≈ 1.5, not to three digits.\n")
    P.append("## Against SciPy and RK4 at equal error\n")
    P.append(f"At equal maximum energy error over T = {cfg['T_long']:g} s: fastvi's speed over "
             "each rival's, i.e. the rival's wall time divided by that of the cheapest fastvi "
             "method at that error (log–log interpolation between measured points, only where "
             "both curves have points):\n")
    P.extend(energy_ratio_lines(points, cfg))
    P.append("")
    if spans:
        P.append("**Which fastvi method is cheapest** at a given max|ΔH| over "
                 f"T = {cfg['T_long']:g} s: " + "; ".join(
                     f"{w} from {a:.1e} down to {b:.1e}" for w, a, b in spans) + ".\n")
    if spans_a:
        P.append(f"For the position error at T = {cfg['T_error']:g} s: " + "; ".join(
            f"{w} from {a:.1e} down to {b:.1e}" for w, a, b in spans_a) + ".\n")
    lines_a = ratio_lines(points, "err_q", f"error of q at T = {cfg['T_error']:g} s", "m")[0]
    if lines_a:
        P.append(f"At equal position error at T = {cfg['T_error']:g} s (panel a; short runs, so "
                 "fixed costs such as validation and the initial projection weigh more):\n")
        P.extend(lines_a)
        P.append("")
    P.extend(evaluation_cost_lines(points))
    P.append("Where the time of a fastvi step goes, part by part: `docs/benchmarks.md`, "
             "\"The step\".\n")
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


