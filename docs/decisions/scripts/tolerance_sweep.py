"""Fixed cost and cost per Newton iteration of a step, from a tolerance sweep.

    .venv/bin/python docs/decisions/scripts/tolerance_sweep.py [--specialize]
    .venv/bin/python docs/decisions/scripts/tolerance_sweep.py --accuracy

Loosening ``tol`` changes only how many iterations a step takes, so a straight-line fit of
time per step against iterations per step splits a step into the part that each iteration
costs and the part that does not depend on the count (docs/decisions/0001-mechanics-newton.md). Double pendulum from θ1 = θ2 = π/2 at rest, h = 0.01, best of 7 runs
of 50 000 steps, thread CPU time, one process. ``--specialize``: the size-specialized
kernels (``integrate(..., specialize=True)``).

``--accuracy``: what a looser ``tol`` buys and costs at the speed study's settings
(docs/decisions/0001-mechanics-newton.md): for each method and step of ``ACCURACY`` and each
tol, the process CPU time of T = 1000 s saved every 0.1 s (best of 5, sized kernels, as the
study runs fastvi), the iterations a step, max|ΔH| over T (the median over 4 of the study's
starts, ``wpd.peer_starts``), max|g| over those runs, and the error of q at t = 10 s
against the study's independent reference (``wpd.reference_q``).
"""

import sys
import time

import numpy as np

import fastvi

N_STEPS, REPEAT = 50_000, 7
TOLS = (1e-14, 1e-12, 1e-10, 1e-8, 1e-6)
ACCURACY = (("P2L-Q3G", 0.025), ("P3L-Q4G", 0.025), ("P4L-Q4G", 0.0125))


def accuracy():
    from studies.wpd.peer_runs import peer_starts
    from studies.wpd.runs import reference_q

    dp = fastvi.scenes.double_pendulum()
    q_ref = reference_q(10.0)
    T = 1000.0
    print("| method, h | tol | CPU (s) | iterations a step | max\\|ΔH\\| (J) | max\\|g\\| | error of q at 10 s |")
    for meth, h in ACCURACY:
        every = max(1, int(round(0.1 / h)))

        def run(theta, tol, t_end=T):
            q0, v0 = dp.initial_state(*theta)
            return fastvi.integrate(dp, q0, v0, h=h, t_end=t_end, method=meth, tol=tol,
                                    save_every=every, specialize=True)

        starts = peer_starts(4)
        for tol in TOLS[:4]:
            runs = [run(th, tol) for th in starts]
            best = np.inf
            for _ in range(5):
                c0 = time.process_time()
                run(starts[0], tol)
                best = min(best, time.process_time() - c0)
            dH = np.median([np.max(np.abs(r.energy - r.energy[0])) for r in runs])
            g = max(np.max(r.constraint_residual) for r in runs)
            its = runs[0].stats["newton_iterations"] / runs[0].stats["steps"]
            eq = np.max(np.abs(run(starts[0], tol, 10.0).q[-1] - q_ref))
            print(f"| `{meth}`, {h:g} | {tol:.0e} | {best:.4f} | {its:.2f} | {dH:.1e} | {g:.1e} "
                  f"| {eq:.2e} |", flush=True)


def main():
    if "--accuracy" in sys.argv[1:]:
        accuracy()
        return
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(np.pi / 2, np.pi / 2)
    sized = "--specialize" in sys.argv[1:]
    for meth in ("P2L-Q3G", "P3L-Q4G"):
        rows = []
        for tol in TOLS:
            best = np.inf
            for _ in range(REPEAT):
                t = time.thread_time()
                r = fastvi.integrate(dp, q0, v0, h=0.01, n_steps=N_STEPS, method=meth,
                                     save_every=N_STEPS, tol=tol, specialize=sized)
                best = min(best, time.thread_time() - t)
            rows.append((r.stats["newton_iterations"] / N_STEPS, best / N_STEPS * 1e6))
            print(f"{meth} tol={tol:.0e}: {rows[-1][0]:.3f} iterations/step, {rows[-1][1]:.3f} µs/step",
                  flush=True)
        it, us = np.array(rows).T
        per_iteration, fixed = np.polyfit(it, us, 1)
        print(f"{meth} fit: {per_iteration:.3f} µs per iteration, {fixed:.3f} µs fixed")


if __name__ == "__main__":
    main()
