"""This tree against the previous release (``v0.2.0``), side by side in one session.

Two versions of ``fastvi`` cannot share a process, so each runs in a child process
(``bench/release_runner.py``): this tree, and a git worktree of the release tag created in
``bench/.release`` on first use (its kernels compile once — its size-specialized ones take
minutes and several GB — then load from its own numba cache). The children are asked in turn — release, current, current, release, … — to
integrate the double pendulum (θ1 = θ2 = π/2 at rest, h = 0.01, ``N_STEPS`` steps, nothing
saved but the end), each timing only the integration in its own thread CPU time. Both trees
run with their defaults and with ``specialize=True`` every round, this tree also with
``specialize=False`` (its default picks the sized stages once they are compiled). The per-step medians and their ratios are printed and stored in the
benchmark JSON under ``"fastvi_release"``; the default path's trajectory must equal the
release's bit for bit. Skipped when git or the tag is not available (e.g. a source tarball).
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
from pathlib import Path

import pytest

RELEASE = "v0.2.0"
#: the commit the tag names (CHANGELOG "0.2.0"): a clone without tags (CI clones, `git clone`
#: of main without --tags) still has it in main's history
RELEASE_COMMIT = "48b04e67fa3470eba4603211e9103a91c0f1d5ae"
ROOT = Path(__file__).resolve().parent.parent
WORKTREE = ROOT / "bench" / ".release"
RUNNER = ROOT / "bench" / "release_runner.py"
METHODS = ("P1L-Q2G", "P2L-Q3G", "P3L-Q4G")
N_STEPS = 50_000
ROUNDS = 6  # per contender and method, in ABBA order


def _release_tree() -> Path:
    if shutil.which("git") is None:
        pytest.skip("git is needed to check out the previous release")
    tags = subprocess.run(["git", "-C", str(ROOT), "tag", "--list", RELEASE], capture_output=True,
                          text=True)
    rev = RELEASE
    if RELEASE not in tags.stdout.split():
        known = subprocess.run(["git", "-C", str(ROOT), "cat-file", "-e", RELEASE_COMMIT + "^{commit}"],
                               capture_output=True)
        if known.returncode != 0:
            pytest.skip(f"neither tag {RELEASE} nor its commit {RELEASE_COMMIT[:10]} is in this "
                        "clone (a shallow clone? git fetch --tags --unshallow)")
        rev = RELEASE_COMMIT
    if not (WORKTREE / "fastvi").is_dir():
        subprocess.run(["git", "-C", str(ROOT), "worktree", "prune"], check=True)
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "--force",
                        str(WORKTREE), rev], check=True, capture_output=True)
    return WORKTREE


class _Child:
    """A runner process importing fastvi from ``tree``."""

    def __init__(self, tree: Path):
        env = dict(os.environ, PYTHONPATH=str(tree), OMP_NUM_THREADS="1",
                   OPENBLAS_NUM_THREADS="1")
        self.proc = subprocess.Popen([sys.executable, str(RUNNER)], cwd=str(tree), env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        ready = json.loads(self.proc.stdout.readline())
        assert str(tree) in ready["ready"], (tree, ready)  # the intended package, not another

    def run(self, method: str, n_steps: int, newton: str = "auto", sized=None) -> dict:
        """``sized``: None (the default), True (``specialize=True``) or False (``=False``)."""
        flag = {None: "", True: " sized", False: " generic"}[sized]
        self.proc.stdin.write(f"{method} {n_steps} {newton}{flag}\n")
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def close(self):
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


@pytest.fixture(scope="module")
def children():
    old = _Child(_release_tree())
    new = _Child(ROOT)
    yield old, new
    old.close()
    new.close()


_rows: list[dict] = []


@pytest.mark.parametrize("method", METHODS)
def test_step_cost_against_the_previous_release(benchmark, children, method, print_uncaptured):
    old, new = children
    contenders = (("release", old, None), ("release sized", old, True), ("generic", new, False),
                  ("current", new, None), ("sized", new, True))
    times = {name: [] for name, _, _ in contenders}
    iters = {}
    finals = {}
    for r in range(ROUNDS):
        for name, child, sized in (contenders if r % 2 == 0 else contenders[::-1]):
            out = child.run(method, N_STEPS, sized=sized)
            times[name].append(out["cpu"] / N_STEPS)
            iters[name] = out["iterations"]
            finals[name] = out["q"]
    # a speed-up that changed the result would not be one: same trajectory, bit for bit
    assert (finals["sized"] == finals["current"] == finals["generic"] == finals["release"]
            == finals["release sized"])
    med = {k: statistics.median(v) for k, v in times.items()}
    ratio = med["release"] / med["sized"]
    row = dict(method=method, release_us=med["release"] * 1e6,
               release_sized_us=med["release sized"] * 1e6, current_us=med["current"] * 1e6,
               generic_us=med["generic"] * 1e6,
               sized_us=med["sized"] * 1e6, ratio_generic=med["release"] / med["current"],
               ratio_sized=med["release sized"] / med["sized"],
               default_vs_release_sized=med["current"] / med["release sized"],
               ratio=ratio, iterations=iters, rounds=ROUNDS)
    _rows.append(row)
    benchmark.extra_info["fastvi_release"] = row
    benchmark.group = f"per step vs {RELEASE}"
    # pytest-benchmark wants a timed callable: one short current run (the table is the result)
    benchmark.pedantic(new.run, args=(method, 100), rounds=1, iterations=1)

    def report(write):
        write.sep(f"fastvi: this tree vs {RELEASE}, double pendulum, thread CPU per step (medians)")
        write("(speed-up = release / current; 'default / release sized' compares today's default "
              "path with the release's specialize=True; 'generic' is specialize=False)")
        for row in _rows:
            write(f"{row['method']:<9} default: {RELEASE} {row['release_us']:7.3f} µs, current "
                  f"{row['current_us']:7.3f} µs ({row['ratio_generic']:5.2f}x) | specialized: "
                  f"{RELEASE} {row['release_sized_us']:7.3f} µs, current {row['sized_us']:7.3f} µs "
                  f"(generic {row['generic_us']:7.3f} µs) "
                  f"({row['ratio_sized']:5.2f}x) | default / release sized "
                  f"{row['default_vs_release_sized']:5.2f} | Newton iterations/step "
                  f"{row['iterations']['current']:.2f}")

    if method == METHODS[-1]:
        print_uncaptured(report)
    assert ratio > 0
