"""What the time-reversible adaptive step buys at equal energy error, and what a step costs.

    .venv/bin/python docs/decisions/scripts/adaptive_steps.py [--starts=8] [--T=1000] [--methods=P2L-Q3G,...]
    .venv/bin/python docs/decisions/scripts/adaptive_steps.py cost [--rounds=5] [--methods=P2L-Q3G,...]
    .venv/bin/python docs/decisions/scripts/adaptive_steps.py drift [--starts=3]

``integrate(..., adaptive=K_r)`` (``fastvi.kernels.adapt``: Hairer & Söderlind's explicit,
time-reversible step-size rule with the density ρ(q) = sqrt(1 + KE(q)/K_r), KE = E0 − V on
the energy shell) against the fixed step, on the chaotic double pendulum from π/2, π/2 at
rest. The first form sweeps h (fixed) and ε (adaptive, ``h=ε``) and prints, per method, the
steps to t = T at the study's energy levels (log–log along each front, max|ΔH| over every
step, median over ``--starts`` starts 1e-12 rad apart, `studies.wpd.peer_runs.peer_starts`)
and their ratio. ``cost`` times a step of each (``specialize=True``, process CPU, nothing
saved but the ends, the two interleaved in one process, best of ``--rounds``) at settings
of about equal energy error, with the Newton iterations a step. ``drift`` prints the
growth of max|ΔH| up to 10⁴ s of both at about equal step counts (the adaptive step is
time-reversible, not symplectic).
"""

import sys
import time

import numpy as np

import fastvi
from studies.wpd.peer_runs import peer_starts
from time_transform_steps import steps_at  # the script's own folder

LEVELS = (1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6)
CASES = {
    "P2L-Q3G": dict(fixed=(0.0125, 0.0166666666666666667, 0.02, 0.025, 0.03125),
                    adaptive=(0.03, 0.04, 0.05, 0.0625, 0.08)),
    "P3L-Q4G": dict(fixed=(0.0125, 0.0166666666666666667, 0.02, 0.025, 0.03125, 0.04),
                    adaptive=(0.03, 0.04, 0.05, 0.0625, 0.08)),
    "P4L-Q4G": dict(fixed=(0.0125, 0.0166666666666666667, 0.02, 0.025),
                    adaptive=(0.025, 0.03, 0.04, 0.05, 0.0625)),
}
#: (method, ε of the adaptive step, h of the fixed step): about equal max|ΔH| over 1000 s
COST = (("P2L-Q3G", 0.07, 0.025), ("P3L-Q4G", 0.055, 0.02), ("P4L-Q4G", 0.05, 0.02))


def run(method, h, theta, T, Kr=None):
    """(steps, max|ΔH| over every step, Newton iterations a step) of one run."""
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(*theta)
    res = fastvi.integrate(dp, q0, v0, h=h, t_end=T, method=method, adaptive=Kr,
                           on_failure="return")
    k = res.stats["steps"]
    dH = float(np.max(np.abs(res.energy - res.energy[0]))) if res.success else np.inf
    return k, dH, res.stats["newton_iterations"] / max(k, 1)


def median_over_starts(fn, starts):
    out = [fn(th) for th in starts]
    return out[0][0], float(np.median([o[1] for o in out])), out[0][2]


def cost(rounds=5, T=200.0, Kr=3.0, methods=None):
    """µs a step (process CPU, best of ``rounds``, the two kinds interleaved) of the adaptive
    and the fixed step at the settings of ``COST``, size-specialized."""
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(np.pi / 2, np.pi / 2)
    print("| method | adaptive ε | µs a step | its a step | fixed h | µs a step | its a step "
          "| adaptive / fixed, a step |")
    print("|---|---|---|---|---|---|---|---|")
    for method, eps, h in COST:
        if methods and method not in methods:
            continue
        kinds = {"adaptive": dict(h=eps, adaptive=Kr), "fixed": dict(h=h)}
        best = {}
        for kind, kw in kinds.items():  # compile, warm
            fastvi.integrate(dp, q0, v0, t_end=1.0, method=method, specialize=True, **kw)
            best[kind] = [np.inf, None]
        for _ in range(rounds):
            for kind, kw in kinds.items():
                c0 = time.process_time()
                res = fastvi.integrate(dp, q0, v0, t_end=T, method=method, specialize=True,
                                       save_every=1 << 30, **kw)
                c = time.process_time() - c0
                k = res.stats["steps"]
                if c / k < best[kind][0]:
                    best[kind] = [c / k, res.stats["newton_iterations"] / k]
        (ua, ia), (uf, jf) = best["adaptive"], best["fixed"]
        print(f"| {method} | {eps:g} | {ua * 1e6:.3f} | {ia:.2f} | {h:g} | {uf * 1e6:.3f} | "
              f"{jf:.2f} | {ua / uf:.3f} |", flush=True)


#: (method, ε, h): about as many adaptive as fixed steps, for the growth with T
DRIFT = (("P2L-Q3G", 0.05, 0.02), ("P3L-Q4G", 0.05, 0.02), ("P4L-Q4G", 0.04, 0.02))


def drift(starts=3, T=1e4, Kr=3.0):
    """max|ΔH| over [0, t] at t = 10, 100, 1000, 10⁴ s, adaptive and fixed, per start: how
    the energy error of the reversible (not symplectic) step grows with T against the
    symplectic fixed step's."""
    dp = fastvi.scenes.double_pendulum()
    marks = (10.0, 100.0, 1000.0, 1e4)
    print("| method | start | adaptive ε | steps | max\\|ΔH\\| to 10 / 100 / 1000 / 10⁴ s | "
          "fixed h | steps | max\\|ΔH\\| to 10 / 100 / 1000 / 10⁴ s |")
    print("|---|---|---|---|---|---|---|---|")
    for method, eps, h in DRIFT:
        for i, th in enumerate(peer_starts(starts)):
            q0, v0 = dp.initial_state(*th)
            cells = []
            for kw in (dict(h=eps, adaptive=Kr), dict(h=h)):
                res = fastvi.integrate(dp, q0, v0, t_end=T, method=method, **kw)
                dH = np.abs(res.energy - res.energy[0])
                cells.append(f"{kw['h']:g} | {res.stats['steps']} | "
                             + " / ".join(f"{dH[res.t <= t].max():.2e}" for t in marks))
            print(f"| {method} | {i} | " + " | ".join(cells) + " |", flush=True)


def main(argv):
    opts = dict(a.lstrip("-").split("=") if "=" in a else (a.lstrip("-"), "1") for a in argv)
    if "drift" in opts:
        drift(int(opts.get("starts", 3)))
        return
    if "cost" in opts:
        cost(int(opts.get("rounds", 5)),
             methods=opts["methods"].split(",") if "methods" in opts else None)
        return
    T = float(opts.get("T", 1000.0))
    Kr = float(opts.get("Kr", 3.0))
    starts = peer_starts(int(opts.get("starts", 8)))
    methods = opts.get("methods", ",".join(CASES)).split(",")
    print(f"double pendulum from π/2, π/2 at rest, T = {T:g} s, max|ΔH| over every step, "
          f"median over {len(starts)} starts; adaptive K_r = {Kr:g}")
    for method in methods:
        cfg = CASES[method]
        fronts = {"fixed": [], "adaptive": []}
        for kind, hs in (("fixed", cfg["fixed"]), ("adaptive", cfg["adaptive"])):
            for h in hs:
                k, dH, its = median_over_starts(
                    lambda th: run(method, h, th, T, Kr if kind == "adaptive" else None), starts)
                fronts[kind].append((k, dH))
                print(f"{method} {kind} {'ε' if kind == 'adaptive' else 'h'} = {h:.5g}: {k} steps, "
                      f"max|ΔH| {dH:.3e}, {its:.2f} Newton iterations a step", flush=True)
        print(f"\n{method}: steps to reach max|ΔH| over T = {T:g} s (— outside a front)")
        print("| max\\|ΔH\\| (J) | fixed h | adaptive | fixed / adaptive |")
        print("|---|---|---|---|")
        for E in LEVELS:
            kf, ka = steps_at(fronts["fixed"], E), steps_at(fronts["adaptive"], E)
            cells = " | ".join("—" if not np.isfinite(x) else f"{x:.0f}" for x in (kf, ka))
            ratio = f"{kf / ka:.2f}" if np.isfinite(kf / ka) else "—"
            print(f"| {E:.0e} | {cells} | {ratio} |", flush=True)
        print()


if __name__ == "__main__":
    main(sys.argv[1:])
