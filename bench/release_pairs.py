"""Two fastvi trees side by side, over several pairs of fresh processes.

    .venv/bin/python bench/release_pairs.py TREE_A TREE_B [PAIRS]

Each tree runs in its own child process (``bench/release_runner.py`` with ``PYTHONPATH`` set
to the tree); the two are asked in ABBA order, 6 rounds of 20 000 double-pendulum steps per
method, and the per-step medians are compared. A new pair of processes is started ``PAIRS``
times (default 5): the code layout of one process can make identical builds differ by up
to ±7 %, so the ratio reported is the median over pairs. Both trees must have compiled
their kernels once before (run any ``fastvi.integrate`` with that ``PYTHONPATH``).
Used for ``docs/benchmarks.md`` ("Forces and time"); ``bench/test_bench_release.py`` does
one pair against the release tag inside pytest-benchmark.
"""

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

RUNNER = Path(__file__).resolve().parent / "release_runner.py"
METHODS = ("P2L-Q3G", "P3L-Q4G", "P1L-Q2G")
N_STEPS, ROUNDS = 20_000, 6


def _child(tree):
    proc = subprocess.Popen([sys.executable, str(RUNNER)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, cwd=tree,
                            env=dict(os.environ, PYTHONPATH=str(tree)))
    proc.stdout.readline()  # ready
    return proc


def _ask(proc, cmd):
    proc.stdin.write(cmd + "\n")
    proc.stdin.flush()
    return json.loads(proc.stdout.readline())


def main(tree_a, tree_b, pairs=5):
    res = {m: ([], []) for m in METHODS}
    iters = {m: [None, None] for m in METHODS}
    for _ in range(pairs):
        a, b = _child(tree_a), _child(tree_b)
        for meth in METHODS:
            ta, tb = [], []
            for r in range(ROUNDS):
                for p in ((a, b) if r % 2 == 0 else (b, a)):
                    out = _ask(p, f"{meth} {N_STEPS} auto")
                    (ta if p is a else tb).append(out["cpu"] / N_STEPS * 1e6)
                    iters[meth][0 if p is a else 1] = out["iterations"]
            res[meth][0].append(statistics.median(ta))
            res[meth][1].append(statistics.median(tb))
        a.kill()
        b.kill()
    for meth, (ta, tb) in res.items():
        ratios = [y / x for x, y in zip(ta, tb)]
        print(f"{meth}: A {statistics.median(ta):.2f} µs  B {statistics.median(tb):.2f} µs  "
              f"B/A per pair {' '.join(f'{r:.3f}' for r in ratios)}  median {statistics.median(ratios):.3f}"
              f"  (Newton iterations/step A {iters[meth][0]:.2f}, B {iters[meth][1]:.2f})")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 5)
