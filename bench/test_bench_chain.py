"""Cost growth (issue 6, item 4): cost per step of ``P2L-Q3G`` on an N-link chain, N = 2 … 64.

``fastvi.scenes.chain(N)``: n = 2N Cartesian coordinates, m = N constraints, unit masses and
links, released at rest from a smooth arc of angles. fastvi solves each Newton iteration with
a dense LU of the ``N_rows = s·n + J·m = 6N`` rows of ``P2L-Q3G`` (s = J = 2), whose cost
grows as ``N_rows³``; the assembly grows as ``N²`` (dense n×n blocks), the callbacks as ``N``.

Each size runs enough steps of h = 0.01 to take ~0.1–1 s (fewer steps for large N:
:func:`fastvi.studies.wpd.growth_steps`). The report at the end prints, per N, the wall time
per step (median over the benchmark's rounds), the CPU time per step of this thread (best of
two more runs: insensitive to other jobs on a shared machine), Newton iterations per step,
the CPU time of one dense LU factorisation of the actual Newton matrix and its share of a
step (``its × LU / CPU step``), the local log–log slopes between consecutive N and the
least-squares exponent over N = 2 … 64, and stores them in the JSON (``extra_info`` of the
N = 64 benchmark, key ``cost_growth``). ``python -m fastvi wpd`` writes the same table into
``docs/wpd.md``. Run with ``make bench`` or
``.venv/bin/python -m pytest bench/test_bench_chain.py --benchmark-only``.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

import fastvi
from fastvi.studies.wpd import (GROWTH_H, GROWTH_METHOD, chain_angles, fit_exponent, growth_steps,
                                lu_factor_cost, newton_matrix)

SIZES = (2, 4, 8, 16, 32, 64)
METHOD = GROWTH_METHOD  # P2L-Q3G
H = GROWTH_H

_rows: dict[int, dict] = {}


@pytest.fixture(scope="module", autouse=True)
def report(print_uncaptured):
    yield
    if len(_rows) >= 2:
        print_uncaptured(_print_report)


def _print_report(write):
    write.sep(f"fastvi cost growth: chain(N), {METHOD}, h = {H:g}")
    write(f"{'N':>3} {'rows':>5} {'fill':>5} {'steps':>6} {'us/step':>10} {'CPU us/step':>11} "
          f"{'its/step':>8} {'LU us':>9} {'LU share':>8}")
    for N in sorted(_rows):
        r = _rows[N]
        write(f"{N:>3} {r['rows']:>5} {r['fill']:>5.2f} {r['steps']:>6} {1e6 * r['per_step']:>10.1f} "
              f"{1e6 * r['cpu_per_step']:>11.1f} {r['iterations']:>8.2f} {1e6 * r['lu']:>9.1f} "
              f"{100 * r['lu_share']:>7.0f}%")
    for key, what in (("per_step", "wall time (median)"), ("cpu_per_step", "CPU time (best of 2)")):
        f = fit_exponent(_rows, key)
        write(f"fitted exponent of cost per step vs N, N = {f['sizes'][0]}…{f['sizes'][-1]}, "
              f"{what}: {f['exponent']:.2f}; local slopes "
              + ", ".join(f"{k}: {v:.2f}" for k, v in f["local"].items()))
    over = [N for N in sorted(_rows) if _rows[N]["lu_share"] > 0.5]
    if over:
        write(f"the dense LU is more than half of a step from N = {over[0]} "
              f"({_rows[over[0]]['rows']} rows): a banded/block-tridiagonal solve pays from there")


@pytest.mark.parametrize("N", SIZES)
def test_chain_cost_per_step(benchmark, N):
    model = fastvi.scenes.chain(N)
    q0, v0 = model.initial_state(chain_angles(N))
    steps = growth_steps(N)
    fastvi.integrate(model, q0, v0, h=H, n_steps=2, method=METHOD)  # compile / cache load
    benchmark.group = f"chain(N), {METHOD}, cost per step"
    rounds = 5 if N < 64 else 3
    res = benchmark.pedantic(lambda: fastvi.integrate(model, q0, v0, h=H, n_steps=steps,
                                                      method=METHOD),
                             rounds=rounds, iterations=1, warmup_rounds=0)
    meth = fastvi.method(METHOD)
    rows = meth.s * model.n + meth.J * model.m
    per_step = benchmark.stats.stats.median / steps
    its = res.stats["newton_iterations"] / res.stats["steps"]
    # CPU time of this thread, best of two: neither the other jobs on the shared machine nor
    # OpenBLAS threads busy-waiting after integrate's initial projection (numpy.linalg) enter;
    # the LU is timed the same way, so the LU share is a ratio of like with like
    cpu = []
    for _ in range(2):
        c0 = time.thread_time()
        fastvi.integrate(model, q0, v0, h=H, n_steps=steps, method=METHOD)
        cpu.append((time.thread_time() - c0) / steps)
    A = newton_matrix(model, res.q[-1], res.p[-1], res.v[-1], METHOD, H)
    assert A.shape == (rows, rows)
    lu = lu_factor_cost(A)
    fill = float(np.count_nonzero(A)) / A.size
    _rows[N] = dict(rows=rows, steps=steps, per_step=per_step, cpu_per_step=min(cpu),
                    iterations=its, lu=lu, lu_share=its * lu / min(cpu), fill=fill)
    benchmark.extra_info.update(N=N, newton_rows=rows, n_steps=steps, seconds_per_step=per_step,
                                newton_per_step=its, lu_seconds=lu, newton_matrix_fill=fill,
                                max_constraint_residual=float(np.max(res.constraint_residual)),
                                max_energy_error=float(np.max(np.abs(res.energy_error))))
    if N == SIZES[-1] and len(_rows) == len(SIZES):
        benchmark.extra_info["cost_growth"] = dict(wall=fit_exponent(_rows, "per_step"), cpu=fit_exponent(_rows, "cpu_per_step"),
                                                   lu_share={n: r["lu_share"] for n, r in _rows.items()})

    assert res.success
    assert rows == 6 * N
    # constraints at round-off for every N (measured 3e-16 … 1.1e-14, growing with N)
    assert np.max(res.constraint_residual) < 1e-12
