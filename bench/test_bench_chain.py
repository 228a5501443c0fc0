"""Cost growth: cost per step of ``P2L-Q3G`` on an N-link chain, N = 16 … 256,
structured (banded) and dense linear solves side by side.

``fastvi.scenes.chain(N)``: n = 2N Cartesian coordinates, m = N constraints, unit masses and
links, released at rest from a smooth arc of angles. ``solver="auto"`` (the default) solves
the Schur complement of the mechanics iteration, the end projection and (in the full Newton)
the ``6N``-row Newton matrix with a banded LU after a reverse Cuthill–McKee ordering
(:mod:`fastvi.structure`); ``solver="dense"`` is the dense LU everywhere (v0.1's path, O(N³)),
timed up to N = 64 only (≈ 200 ms a step at N = 128).

The time per step is the integration loop's (``stats["integration_time"]``, median over the
rounds; the set-up — pattern detection, ordering, initial projection — is reported apart).
The report prints, per N, both paths, their ratio, Newton iterations per step, the local
log–log slopes and the least-squares exponent over N = 16 … 256. ``test_tree_sparse_against_banded`` times trees (a hub with
branches, a pattern no narrow band fits) on the banded and the sparse LU side by side and
prints the ratio. Run with ``make bench`` or
``.venv/bin/python -m pytest bench/test_bench_chain.py --benchmark-only``.
"""

from __future__ import annotations

import numpy as np
import pytest

import fastvi
from fastvi import structure
from studies.wpd.growth import GROWTH_H, GROWTH_METHOD, chain_angles, fit_exponent, growth_steps

SIZES = (16, 32, 64, 128, 256)
DENSE_UP_TO = 64
METHOD = GROWTH_METHOD  # P2L-Q3G
H = GROWTH_H
STEP_BUDGET = 20_000  # structured path: steps(N) ≈ budget / N (≈ 10–50 ms a run)

_rows: dict[int, dict] = {}


@pytest.fixture(scope="module", autouse=True)
def report(print_uncaptured):
    yield
    if len(_rows) >= 2:
        print_uncaptured(_print_report)


def _print_report(write):
    write.sep(f"fastvi cost growth: chain(N), {METHOD}, h = {H:g}, structured vs dense solves")
    write(f"{'N':>4} {'rows':>5} {'band kl,ku':>10} {'steps':>6} {'us/step':>10} {'dense us':>10} "
          f"{'dense/str':>9} {'its/step':>8} {'setup ms':>9}")
    for N in sorted(_rows):
        r = _rows[N]
        d = r.get("dense")
        per = r["per_step"]
        dense = f"{1e6 * d:.1f}" if d else "-"
        ratio = f"{d / per:.1f}x" if d else "-"
        write(f"{N:>4} {r['rows']:>5} {str(r['band']):>10} {r['steps']:>6} {1e6 * per:>10.1f} "
              f"{dense:>10} {ratio:>9} {r['iterations']:>8.2f} {1e3 * r['setup']:>9.0f}")
    f = fit_exponent(_rows, "per_step")
    write(f"fitted exponent of cost per step vs N, N = {f['sizes'][0]}…{f['sizes'][-1]}: "
          f"{f['exponent']:.2f}; local slopes "
          + ", ".join(f"{k}: {v:.2f}" for k, v in f["local"].items()))
    dense = {N: r for N, r in _rows.items() if r.get("dense")}
    if len(dense) >= 2:
        fd = fit_exponent(dense, "dense")
        write(f"dense path, N = {fd['sizes'][0]}…{fd['sizes'][-1]}: exponent {fd['exponent']:.2f}")


def _loop_time(model, q0, v0, steps, solver, rounds):
    times, res = [], None
    for _ in range(rounds):
        res = fastvi.integrate(model, q0, v0, h=H, n_steps=steps, method=METHOD, solver=solver,
                               save_every=steps)
        times.append(res.stats["integration_time"] / steps)
    return float(np.median(times)), res


@pytest.mark.parametrize("N", SIZES)
def test_chain_cost_per_step(benchmark, N):
    model = fastvi.scenes.chain(N)
    q0, v0 = model.initial_state(chain_angles(N))
    steps = max(20, STEP_BUDGET // N)
    fastvi.integrate(model, q0, v0, h=H, n_steps=2, method=METHOD)  # compile, check, plan
    benchmark.group = f"chain(N), {METHOD}, cost per step"
    res = benchmark.pedantic(lambda: fastvi.integrate(model, q0, v0, h=H, n_steps=steps,
                                                      method=METHOD, save_every=steps),
                             rounds=3, iterations=1, warmup_rounds=0)
    per_step, res = _loop_time(model, q0, v0, steps, "auto", 3)
    meth = fastvi.method(METHOD)
    plan = structure.plan(model, meth)
    row = dict(rows=meth.s * model.n + meth.J * model.m, steps=steps, per_step=per_step,
               iterations=res.stats["newton_iterations"] / res.stats["steps"],
               setup=res.stats["setup_time"], band=plan.bandwidths.get("schur"))
    if N <= DENSE_UP_TO:
        dsteps = growth_steps(N)
        fastvi.integrate(model, q0, v0, h=H, n_steps=2, method=METHOD, solver="dense")
        row["dense"], dres = _loop_time(model, q0, v0, dsteps, "dense", 3)
        assert np.allclose(dres.q[-1], fastvi.integrate(model, q0, v0, h=H, n_steps=dsteps,
                                                        method=METHOD).q[-1], rtol=0, atol=1e-11)
    _rows[N] = row
    benchmark.extra_info.update(N=N, newton_rows=row["rows"], n_steps=steps,
                                seconds_per_step=per_step, dense_seconds_per_step=row.get("dense"),
                                newton_per_step=row["iterations"], solvers=plan.solvers,
                                max_constraint_residual=float(np.max(res.constraint_residual)))
    if N == SIZES[-1] and len(_rows) == len(SIZES):
        benchmark.extra_info["cost_growth"] = fit_exponent(_rows, "per_step")

    assert res.success
    assert plan.solvers["schur"] == "banded" and plan.solvers["projection"] == "banded"
    # constraints at round-off for every N (measured 3e-15 … 5e-14, growing with |q| ~ N)
    assert np.max(res.constraint_residual) < 1e-12


TREES = ((8, 8), (16, 8), (16, 16))


@pytest.mark.parametrize("shape", TREES, ids=lambda s: f"tree{s[0]}x{s[1]}")
def test_tree_sparse_against_banded(benchmark, print_uncaptured, shape):
    """A tree (a hub with branches: no narrow band) steps faster on the sparse LU than on the
    banded one (``docs/decisions/scripts/solver_crossover.py`` has the whole crossover table)."""
    b, L = shape
    model = fastvi.scenes.tree(b, L)
    N = 1 + b * L
    q0, v0 = model.initial_state(0.3 + 0.6 * np.sin(np.arange(N)))
    steps = max(20, STEP_BUDGET // N)
    for solver in ("banded", "sparse"):
        fastvi.integrate(model, q0, v0, h=H, n_steps=2, method=METHOD, solver=solver)
    benchmark.group = f"tree(b, L), {METHOD}, cost per step"
    benchmark.pedantic(lambda: fastvi.integrate(model, q0, v0, h=H, n_steps=steps, method=METHOD,
                                                save_every=steps),
                       rounds=3, iterations=1, warmup_rounds=0)
    banded, rb = _loop_time(model, q0, v0, steps, "banded", 3)
    sparse, rs = _loop_time(model, q0, v0, steps, "sparse", 3)
    plan = structure.plan(model, fastvi.method(METHOD))
    benchmark.extra_info.update(bodies=N, banded_seconds_per_step=banded,
                                sparse_seconds_per_step=sparse, solvers=plan.solvers)
    print_uncaptured(lambda w: w(f"tree({b},{L}), {N} bodies: banded {1e6 * banded:.1f} µs, "
                                 f"sparse {1e6 * sparse:.1f} µs a step ({banded / sparse:.2f}x); "
                                 f"auto: {plan.solvers['schur']}"))
    assert plan.solvers["schur"] == "sparse" and plan.solvers["projection"] == "sparse"
    assert np.abs(rb.q[-1] - rs.q[-1]).max() < 1e-10  # the same trajectory (round-off)
    assert np.max(rs.constraint_residual) < 1e-12
