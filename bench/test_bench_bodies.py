"""Cost growth of rigid bodies in director coordinates: a step of ``P2L-Q3G`` on a chain of N rods
on spherical joints, N = 16 … 256 (``fastvi.bodies.scenes.body_chain``).

Each rod has 12 coordinates and 9 rows (6 of its own, 3 of its joint): ``n = 12 N``,
``m = 9 N``. The rows of ``G`` touch at most 24 columns whatever N is, and the model declares
that pattern (``constraint_jacobian_pattern``), so the kernels' structured solves (banded or
sparse LU after an ordering, :mod:`fastvi.structure`) make a step cost O(N) up to the
conditioning of the Newton iteration. The time per step is the integration loop's
(``stats["integration_time"]``, median of three runs; set-up — pattern, ordering, initial
projection — reported apart), and its CPU time: the process time of a run of 2K steps less
that of a run of K steps, over K (best of three; on a loaded machine the wall time is not
the cost). The report prints the rows, the plan, iterations per step, both times and the
least-squares exponents of the CPU cost against N, per step and per Newton iteration. ``FASTVI_BODY_SIZES``
(comma-separated) overrides the sizes: the kernels' workspace holds the dense Newton matrix
(``(s n + J m)²`` floats, 0.9 GB at N = 256), so the largest size needs about 2 GB.

Run with ``.venv/bin/python -m pytest bench/test_bench_bodies.py --benchmark-only``.
"""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

import fastvi
from fastvi import structure
from fastvi.bodies import scenes
from studies.wpd.growth import fit_exponent

SIZES = tuple(int(x) for x in os.environ.get("FASTVI_BODY_SIZES", "16,32,64,128,256").split(","))
METHOD = "P2L-Q3G"
H = 0.01
STEP_BUDGET = 6400  # steps(N) ≈ budget / N

_rows: dict[int, dict] = {}


@pytest.fixture(scope="module", autouse=True)
def report(print_uncaptured):
    yield
    if len(_rows) >= 2:
        print_uncaptured(_print_report)


def _print_report(write):
    write.sep(f"fastvi cost growth: body_chain(N), {METHOD}, h = {H:g}")
    write(f"{'N':>4} {'n':>5} {'m':>5} {'Newton rows':>11} {'schur':>7} {'steps':>6} {'ms/step':>9} "
          f"{'CPU ms':>8} {'its/step':>8} {'setup s':>8} {'max|g|':>8}")
    for N in sorted(_rows):
        r = _rows[N]
        write(f"{N:>4} {r['n']:>5} {r['m']:>5} {r['rows']:>11} {r['schur']:>7} {r['steps']:>6} "
              f"{1e3 * r['per_step']:>9.3f} {1e3 * r['cpu']:>8.3f} {r['iterations']:>8.2f} "
              f"{r['setup']:>8.2f} {r['g']:>8.1e}")
    f = fit_exponent(_rows, "cpu")
    write(f"fitted exponent of the CPU cost per step vs N, N = {f['sizes'][0]}…{f['sizes'][-1]}: "
          f"{f['exponent']:.2f}; local slopes " + ", ".join(f"{k}: {v:.2f}" for k, v in f["local"].items()))
    g = fit_exponent({N: dict(c=r["cpu"] / r["iterations"]) for N, r in _rows.items()}, "c")
    write(f"per Newton iteration: exponent {g['exponent']:.2f}")


def _cpu_per_step(model, q0, v0, steps):
    """CPU seconds a step: process time of 2K steps less that of K steps, over K (best of 3)."""
    best = np.inf
    for _ in range(3):
        t0 = time.process_time()
        fastvi.integrate(model, q0, v0, h=H, n_steps=steps, method=METHOD, save_every=steps)
        t1 = time.process_time()
        fastvi.integrate(model, q0, v0, h=H, n_steps=2 * steps, method=METHOD, save_every=2 * steps)
        best = min(best, (time.process_time() - t1 - (t1 - t0)) / steps)
    return best


@pytest.mark.parametrize("N", SIZES)
def test_body_chain_cost_per_step(benchmark, N):
    model = scenes.body_chain(N)
    q0, v0 = model.initial_state()
    steps = max(25, STEP_BUDGET // N)
    first = fastvi.integrate(model, q0, v0, h=H, n_steps=2, method=METHOD)  # compile, plan
    benchmark.group = f"body_chain(N), {METHOD}, cost per step"
    benchmark.pedantic(lambda: fastvi.integrate(model, q0, v0, h=H, n_steps=steps, method=METHOD,
                                                save_every=steps),
                       rounds=1, iterations=1, warmup_rounds=0)
    times, res = [], None
    for _ in range(3):
        res = fastvi.integrate(model, q0, v0, h=H, n_steps=steps, method=METHOD, save_every=steps)
        times.append(res.stats["integration_time"] / steps)
    meth = fastvi.method(METHOD)
    plan = structure.plan(model, meth)
    _rows[N] = dict(n=model.n, m=model.m, rows=meth.s * model.n + meth.J * model.m, steps=steps,
                    per_step=float(np.median(times)), cpu=_cpu_per_step(model, q0, v0, steps),
                    iterations=res.stats["newton_iterations"] / res.stats["steps"],
                    setup=first.stats["setup_time"], schur=plan.solvers["schur"],
                    g=float(np.max(res.constraint_residual)))
    benchmark.extra_info.update(N=N, n=model.n, m=model.m, seconds_per_step=_rows[N]["per_step"],
                                cpu_seconds_per_step=_rows[N]["cpu"],
                                newton_per_step=_rows[N]["iterations"], solvers=plan.solvers)
    if len(_rows) >= 2 and N == SIZES[-1]:
        benchmark.extra_info["cost_growth"] = fit_exponent(_rows, "cpu")
    assert res.success and plan.solvers["schur"] != "dense"
    assert np.max(res.constraint_residual) < 1e-12


@pytest.mark.parametrize("h", [1e-2, 1e-3])
def test_spatial_slider_crank_ten_seconds(benchmark, print_uncaptured, h):
    """The IFToMM spatial slider–crank (R–S–U–P, driven crank) over 10 s: CPU time of the
    whole public call, median of 3."""
    model = scenes.spatial_slider_crank()
    q0, v0 = model.initial_state()
    fastvi.integrate(model, q0, v0, h=h, n_steps=2, method=METHOD)  # compile, plan
    cpus, res = [], None
    for _ in range(3):
        t0 = time.process_time()
        res = fastvi.integrate(model, q0, v0, h=h, t_end=10.0, method=METHOD, save_every=100)
        cpus.append(time.process_time() - t0)
    cpu = float(np.median(cpus))
    benchmark.group = "spatial slider-crank, 10 s"
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)
    benchmark.extra_info.update(h=h, cpu=cpu, steps=res.stats["steps"])
    assert res.success and res.constraint_residual.max() < 1e-13
    print_uncaptured(lambda write: write(
        f"spatial slider-crank, 10 s, {METHOD}, h = {h:g}: {cpu:.3f} s CPU "
        f"({1e6 * cpu / res.stats['steps']:.1f} µs a step, "
        f"{res.stats['newton_iterations'] / res.stats['steps']:.2f} Newton iterations a step)"))


def test_lamina_against_a_thick_top_newton_iterations(print_uncaptured):
    """The singular mass (Brüls' lamina, E₂ = 0) against the same top made thicker (definite
    mass): Newton iterations a step and CPU time a step, side by side, over 2 s (a first step
    that falls back to the full Newton keeps it for ``FULL_HOLD`` steps: a short run would
    mostly time those)."""
    rows = []
    for label, inertia in (("lamina", scenes.BRULS_INERTIA), ("thick", (0.234375, 0.4, 0.234375))):
        model = scenes.heavy_top(inertia=inertia)
        q0, v0 = model.initial_state()
        for method, N in (("P1L-Q2G", 8000), ("P2L-Q3G", 4000), ("P3L-Q4G", 1000)):
            fastvi.integrate(model, q0, v0, h=2.0 / N, n_steps=2, method=method)
            res = fastvi.integrate(model, q0, v0, h=2.0 / N, n_steps=N, method=method, save_every=N)
            rows.append((label, method, res.stats["newton_iterations"] / N,
                         1e6 * res.stats["integration_time"] / N, model.mass_singular))
    assert [r[4] for r in rows] == [True] * 3 + [False] * 3

    def report(write):
        write.sep("heavy top over 2 s (|Ω| = 150): singular against definite mass")
        for label, method, its, us, _ in rows:
            write(f"{label:<7} {method}: {its:.2f} Newton iterations a step, {us:.1f} µs a step")

    print_uncaptured(report)
