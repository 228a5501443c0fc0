"""Sized ensembles of the tree on ``PYTHONPATH``: one line per call, for side-by-side pairs.

    PYTHONPATH=TREE .venv/bin/python bench/ensemble_tree.py P1L-Q2G,P2L-Q3G [REPS]

256 double-pendulum members (angles uniform in [-1.5, 1.5]², at rest, seed 2024, as
``bench/test_bench_ensemble.py``) × 1000 steps, h = 0.01, ``save="final"``, 2 threads,
``specialize=True``; after a warm-up call (the compile), the median and minimum wall time of
``REPS`` (default 5) calls, and the sum of |q| of the final states to all digits (two trees
whose members are equal bit for bit print the same sum). Alternate fresh processes of two
trees (e.g. a ``git worktree`` of the commit before) and compare medians
(``docs/benchmarks.md``, 2026-11-25 afternoon).
"""

import sys
import time

import numpy as np

import fastvi


def main(argv):
    model = fastvi.scenes.double_pendulum()
    angles = np.random.default_rng(2024).uniform(-1.5, 1.5, size=(256, 2))
    states = [model.initial_state(a, b) for a, b in angles]
    Q0 = np.array([s[0] for s in states])
    V0 = np.array([s[1] for s in states])
    reps = int(argv[1]) if len(argv) > 1 else 5
    out = []
    for method in argv[0].split(","):
        kw = dict(h=0.01, n_steps=1000, method=method, save="final", threads=2, specialize=True)
        fastvi.integrate_ensemble(model, Q0, V0, **kw)
        times = []
        for _ in range(reps):
            t = time.perf_counter()
            r = fastvi.integrate_ensemble(model, Q0, V0, **kw)
            times.append(time.perf_counter() - t)
        out.append(f"{method} {np.median(times) * 1e3:.1f} ms (min {min(times) * 1e3:.1f}) "
                   f"sum|q| {np.abs(r.q).sum():.17g}")
    print(" | ".join(out))


if __name__ == "__main__":
    main(sys.argv[1:] or ["P2L-Q3G"])
