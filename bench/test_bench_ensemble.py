"""Ensemble benchmark: 256 double-pendulum members × 1000 steps of P2L-Q3G, h = 0.01.

Contenders, all on the same members (angles uniform in [-1.5, 1.5]², at rest, seed 2024),
over the same time span t ∈ [0, 10]:

* ``ensemble-1thread`` / ``ensemble-2threads``: ``fastvi.integrate_ensemble(save="final")``
  with ``threads=1`` and ``threads=2`` (setup included: validation and projection of each
  member, as ``integrate`` does it too);
* ``integrate-loop``: a Python loop of ``fastvi.integrate`` calls (every step saved, as its
  default);
* ``scipy-baseline``: a loop of ``fastvi.baselines.solve_ivp`` (SciPy DOP853 on the index-1
  right-hand side of the same Model callbacks), on the first ``SCIPY_MEMBERS`` members only;
* ``scipy-numpy-angles``: a loop of SciPy DOP853 on
  ``fastvi.studies.reference.chain_pendulum_rhs`` (NumPy, angle coordinates), first
  ``SCIPY_MEMBERS`` members.

The SciPy tolerance ``rtol = 1e-7, atol = 1e-9`` was chosen for comparable accuracy: the
report prints the median final-position error of fastvi and of both SciPy loops against a
DOP853 reference at tolerance 1e-13 on the first ``SCIPY_MEMBERS`` members. Throughput is
member-steps per second, a SciPy "member-step" being 1/1000 of one member's time span.

``test_specialized_members_interleaved`` times ``specialize=True`` against the generic
kernels (2 threads, rounds alternated) and asserts equal final states.

The report at the end prints the thread speed-up, median(1 thread) / median(2 threads)
and every throughput; run with
``.venv/bin/python -m pytest bench/test_bench_ensemble.py --benchmark-only`` (or ``make bench``).
Everything is compiled (or loaded from numba's cache) before timing.
"""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
from scipy.integrate import solve_ivp as scipy_solve_ivp

import fastvi
from fastvi.baselines import solve_ivp as baseline_solve_ivp
from fastvi.studies.reference import chain_cartesian, chain_pendulum_reference, chain_pendulum_rhs

N_MEMBERS = 256
N_STEPS = 1000
H = 0.01
T_END = N_STEPS * H
METHOD = "P2L-Q3G"
SCIPY_MEMBERS = 8
RTOL, ATOL = 1e-7, 1e-9
ROUNDS = 5

_results: dict[str, dict] = {}  # contender -> {median, member_steps, q (final positions)}


@pytest.fixture(scope="module")
def members():
    model = fastvi.scenes.double_pendulum()
    angles = np.random.default_rng(2024).uniform(-1.5, 1.5, (N_MEMBERS, 2))
    states = [model.initial_state(a, b) for a, b in angles]
    Q0 = np.array([s[0] for s in states])
    V0 = np.array([s[1] for s in states])
    return model, angles, Q0, V0


@pytest.fixture(scope="module", autouse=True)
def report(members, print_uncaptured):
    yield
    if _results:
        print_uncaptured(lambda write: _print_report(write, members))


def _contender(name, members):
    model, angles, Q0, V0 = members
    if name.startswith("ensemble"):
        threads = 1 if name == "ensemble-1thread" else 2

        def run():
            res = fastvi.integrate_ensemble(model, Q0, V0, h=H, n_steps=N_STEPS, method=METHOD,
                                            threads=threads)
            assert res.success.all()
            return res.q
        return run, N_MEMBERS * N_STEPS
    if name == "integrate-loop":
        def run():
            return np.array([fastvi.integrate(model, q, v, h=H, n_steps=N_STEPS, method=METHOD).q[-1]
                             for q, v in zip(Q0, V0)])
        return run, N_MEMBERS * N_STEPS
    if name == "scipy-baseline":
        def run():
            return np.array([baseline_solve_ivp(model, Q0[i], V0[i], t_end=T_END, method="DOP853",
                                                rtol=RTOL, atol=ATOL, n_samples=2).q[-1]
                             for i in range(SCIPY_MEMBERS)])
        return run, SCIPY_MEMBERS * N_STEPS
    assert name == "scipy-numpy-angles"
    rhs = chain_pendulum_rhs([1.0, 1.0], [1.0, 1.0], 9.81)

    def run():
        out = []
        for i in range(SCIPY_MEMBERS):
            sol = scipy_solve_ivp(rhs, (0.0, T_END), np.r_[angles[i], 0.0, 0.0], method="DOP853",
                                  rtol=RTOL, atol=ATOL, t_eval=[T_END])
            out.append(chain_cartesian(sol.y[:2, -1], sol.y[2:, -1], [1.0, 1.0])[0][0])
        return np.array(out)
    return run, SCIPY_MEMBERS * N_STEPS


CONTENDERS = ["ensemble-1thread", "ensemble-2threads", "integrate-loop", "scipy-baseline",
              "scipy-numpy-angles"]


@pytest.mark.parametrize("name", CONTENDERS)
def test_ensemble_256_members_1000_steps(benchmark, members, name):
    benchmark.group = "double pendulum ensemble, P2L-Q3G, 1000 steps"
    run, member_steps = _contender(name, members)
    model, _, Q0, V0 = members
    # compile (or load from the cache) outside the timing
    fastvi.integrate_ensemble(model, Q0[:2], V0[:2], h=H, n_steps=2, method=METHOD, threads=1)
    fastvi.integrate(model, Q0[0], V0[0], h=H, n_steps=2, method=METHOD)
    baseline_solve_ivp(model, Q0[0], V0[0], t_end=H, rtol=RTOL, atol=ATOL, n_samples=2)
    rounds = ROUNDS if name.startswith("ensemble") else 3
    q = benchmark.pedantic(run, rounds=rounds, iterations=1, warmup_rounds=0)
    median = benchmark.stats.stats.median
    benchmark.extra_info.update(member_steps=member_steps,
                                member_steps_per_s=member_steps / median)
    _results[name] = dict(median=median, member_steps=member_steps, q=np.asarray(q))
    assert np.all(np.isfinite(q))


def test_thread_speedup_interleaved(benchmark, members):
    """1 and 2 threads alternated round by round, so that on a shared machine the load weighs
    on both alike (the rounds of one pytest-benchmark contender run in a row).

    pytest-benchmark times the 2-thread run; the 1-thread run is the round's ``setup``,
    timed here with ``perf_counter``.
    """
    benchmark.group = "thread speed-up, interleaved rounds"
    model, _, Q0, V0 = members
    one, load = [], []

    def run(threads):
        res = fastvi.integrate_ensemble(model, Q0, V0, h=H, n_steps=N_STEPS, method=METHOD,
                                        threads=threads)
        assert res.success.all()

    def setup():
        t0 = time.perf_counter()
        run(1)
        one.append(time.perf_counter() - t0)
        load.append(os.getloadavg()[0])

    run(2)  # compiled / loaded from the cache outside the timing
    benchmark.pedantic(run, args=(2,), setup=setup, rounds=ROUNDS, iterations=1, warmup_rounds=0)
    two = benchmark.stats.stats.median
    benchmark.extra_info.update(median_1thread=float(np.median(one)), speedup=float(np.median(one)) / two)
    _results["interleaved"] = dict(one=float(np.median(one)), two=two, load=float(np.median(load)))


def test_specialized_members_interleaved(benchmark, members):
    """``specialize=True`` against the generic kernels, 2 threads, alternated round by round
    (the generic run is the round's ``setup``); the final states must be equal bit for bit."""
    benchmark.group = "specialized members, interleaved rounds"
    model, _, Q0, V0 = members
    generic, finals = [], {}

    def run(specialize):
        res = fastvi.integrate_ensemble(model, Q0, V0, h=H, n_steps=N_STEPS, method=METHOD,
                                        threads=2, specialize=specialize)
        assert res.success.all()
        finals[specialize] = res.q

    def setup():
        t0 = time.perf_counter()
        run(False)
        generic.append(time.perf_counter() - t0)

    run(True)  # compiled / loaded from the cache outside the timing
    run(False)
    benchmark.pedantic(run, args=(True,), setup=setup, rounds=ROUNDS, iterations=1,
                       warmup_rounds=0)
    sized = benchmark.stats.stats.median
    assert np.array_equal(finals[False], finals[True])
    benchmark.extra_info.update(median_generic=float(np.median(generic)),
                                speedup=float(np.median(generic)) / sized)
    _results["specialized"] = dict(generic=float(np.median(generic)), sized=sized)


def _print_report(write, members):
    write.sep("fastvi ensembles: 256 members x 1000 steps, double pendulum, P2L-Q3G")
    _write_report(write, members)


def _write_report(write, members):
    _, angles, _, _ = members
    ref = np.array([chain_cartesian(*chain_pendulum_reference(angles[i], [0.0, 0.0], [T_END],
                                                              [1.0, 1.0], [1.0, 1.0], g=9.81),
                                    [1.0, 1.0])[0][0] for i in range(SCIPY_MEMBERS)])
    if "ensemble-1thread" in _results and "ensemble-2threads" in _results:
        ratio = _results["ensemble-1thread"]["median"] / _results["ensemble-2threads"]["median"]
        write(f"thread speed-up median(1 thread)/median(2 threads) = {ratio:.2f}")
    if "interleaved" in _results:
        r = _results["interleaved"]
        ratio = r["one"] / r["two"]
        write(f"interleaved rounds: median(1 thread) = {r['one']:.3f} s, median(2 threads) = "
              f"{r['two']:.3f} s, speed-up = {ratio:.2f} (1-min load average during the rounds "
              f"{r['load']:.1f} on {os.cpu_count()} CPUs)")
    if "specialized" in _results:
        r = _results["specialized"]
        write(f"specialize=True, interleaved rounds (2 threads): median generic = "
              f"{r['generic']:.3f} s, specialized = {r['sized']:.3f} s, speed-up = "
              f"{r['generic'] / r['sized']:.2f} (final states equal bit for bit)")
    write(f"{'contender':<20} {'median s':>10} {'member-steps/s':>16} {'median |q - q_ref|':>20}")
    for name in CONTENDERS:
        r = _results.get(name)
        if r is None:
            continue
        err = np.median(np.abs(r["q"][:SCIPY_MEMBERS] - ref).max(axis=1))
        write(f"{name:<20} {r['median']:>10.3f} {r['member_steps'] / r['median']:>16.3g} {err:>20.2e}")
    write(f"(SciPy loops: first {SCIPY_MEMBERS} members, DOP853 rtol={RTOL:g}, atol={ATOL:g}; "
          f"errors: final positions at t = {T_END:g} vs DOP853 at 1e-13, first {SCIPY_MEMBERS} members)")
