"""Two fastvi trees side by side, over several pairs of fresh processes.

    .venv/bin/python docs/decisions/scripts/release_pairs.py TREE_A TREE_B [PAIRS] [--sized] [--methods=M,M]
        [--model=chainN] [--steps=K]

Each tree runs in its own child process (``bench/release_runner.py`` with ``PYTHONPATH`` set
to the tree); the two are asked in ABBA order, 6 rounds of 20 000 double-pendulum steps per
method, and the per-step medians are compared. A new pair of processes is started ``PAIRS``
times (default 5): the code layout of one process can make identical builds differ by up
to ±7 %, so the ratio reported is the median over pairs. Both trees must have compiled
their kernels once before (run any ``fastvi.integrate`` with that ``PYTHONPATH``).
``--sized`` times the size-specialized kernels (``specialize=True``) of both trees;
``--methods=M,M`` picks the methods (default ``P2L-Q3G,P3L-Q4G,P1L-Q2G``), ``--model=chainN``
times ``fastvi.scenes.chain(N)`` (the cost-growth study's start) and ``--model=sliderK`` the
stiff panel's rod–slider with stiffness K (e.g. ``slider1e8``) instead of the double
pendulum, ``--steps=K`` the steps of a round (default 20 000; ``--steps=2`` times the fixed
cost of a public call). The times are of the whole ``fastvi.integrate`` call.
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


def main(tree_a, tree_b, pairs=5, sized=False, methods=METHODS, model=None, n_steps=N_STEPS):
    extra = (" sized" if sized else "") + (f" model={model}" if model else "")
    res = {m: ([], []) for m in methods}
    iters = {m: [None, None] for m in methods}
    for _ in range(pairs):
        a, b = _child(tree_a), _child(tree_b)
        for meth in methods:
            ta, tb = [], []
            for r in range(ROUNDS):
                for p in ((a, b) if r % 2 == 0 else (b, a)):
                    out = _ask(p, f"{meth} {n_steps} auto{extra}")
                    (ta if p is a else tb).append(out["cpu"] / n_steps * 1e6)
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
    flags = [a for a in sys.argv[1:] if a.startswith("--")]
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    if len(args) < 2:
        sys.exit(__doc__)
    chosen, model, steps = METHODS, None, N_STEPS
    for f in flags:
        if f.startswith("--methods="):
            chosen = tuple(f.split("=", 1)[1].split(","))
        elif f.startswith("--model="):
            model = f.split("=", 1)[1]
        elif f.startswith("--steps="):
            steps = int(f.split("=", 1)[1])
    main(args[0], args[1], int(args[2]) if len(args) > 2 else 5, "--sized" in flags, chosen,
         model, steps)
