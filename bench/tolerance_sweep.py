"""Fixed cost and cost per Newton iteration of a step, from a tolerance sweep.

    .venv/bin/python bench/tolerance_sweep.py [--specialize]

Loosening ``tol`` changes only how many iterations a step takes, so a straight-line fit of
time per step against iterations per step splits a step into the part that each iteration
costs and the part that does not depend on the count (docs/benchmarks.md, "Fixed cost and
cost per iteration"). Double pendulum from θ1 = θ2 = π/2 at rest, h = 0.01, best of 7 runs
of 50 000 steps, thread CPU time, one process. ``--specialize``: the size-specialized
kernels (``integrate(..., specialize=True)``).
"""

import sys
import time

import numpy as np

import fastvi

N_STEPS, REPEAT = 50_000, 7
TOLS = (1e-14, 1e-12, 1e-10, 1e-8, 1e-6)


def main():
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
