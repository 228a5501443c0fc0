"""Yardstick benchmark: generic cfunc kernel vs hand-specialized kernel.

Double pendulum (Cartesian, paper B's parameters), θ1 = θ2 = π/2 at rest, 10⁴ steps at
h = 0.01, for ``P1L-Q2G``, ``P2L-Q3G``, ``P3L-Q4G``:

* ``generic``: the public ``fastvi.integrate`` with ``newton="full"`` (validation, projection of the initial state,
  the compiled loop with cfunc callbacks, every step saved, the ``Result``);
* ``sized``: the same public call with ``specialize=True`` (the generic kernels compiled for
  the model's sizes: still cfunc callbacks and dense generic assembly);
* ``specialized``: ``tests/yardstick.py``, the same algorithm with the model inlined, driven
  from Python the same way (every step saved).

Each method is one pytest-benchmark group. The shared machine's load changes within
seconds, so the two contenders are timed in interleaved blocks (generic, specialized,
specialized, generic, generic, specialized: ``BLOCKS`` × ``ROUNDS`` rounds each) rather
than one after the other, and the timer is the process's CPU time (``time.process_time``),
which does not count the time spent waiting for a core. ``bench/conftest.py`` pools the
rounds of each contender and prints the ratio of the pooled medians per method. Run with
``make bench``.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

import fastvi

from tests import yardstick  # the repository root is on sys.path (pyproject: pythonpath)

RATIO_KEY = "fastvi_yardstick"  # the tag bench/conftest.py builds its ratio table from

METHODS = ("P1L-Q2G", "P2L-Q3G", "P3L-Q4G")
H = 0.01
N_STEPS = 10_000
BLOCKS = 3  # interleaved blocks per contender (ABBA order: drifting load cancels)
ROUNDS = 5  # rounds per block (pytest-benchmark median of >= 5), 15 pooled per contender

_finals: dict[str, np.ndarray] = {}  # generic final q per method, for the cross-check


@pytest.fixture(scope="module")
def scene():
    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    # the state fastvi.integrate starts from after its projection (moves q0 by round-off);
    # the yardstick starts from the same bits, so both trajectories can be compared exactly
    start = fastvi.integrate(model, q0, v0, h=H, n_steps=1, method=METHODS[0])
    return model, q0, v0, start.q[0].copy(), start.v[0].copy()


def _runner(impl, method, scene):
    model, q0, v0, qs, vs = scene
    if impl in ("generic", "sized"):
        def run():
            # the yardstick hand-specializes the full Newton: compare the same algorithm
            res = fastvi.integrate(model, q0, v0, h=H, n_steps=N_STEPS, method=method,
                                   newton="full", specialize=impl == "sized")
            return res.q[-1], res.energy
    else:
        tabs = fastvi.method(method).kernel_tables
        prm = tuple(model.params)

        def run():
            out = yardstick.integrate_double_pendulum(qs, vs, h=H, n_steps=N_STEPS, tabs=tabs,
                                                      params=prm)
            return out["q"], out["energy"]
    return run


def _order(block):
    return ("generic", "sized", "specialized") if block % 2 == 0 else \
        ("specialized", "sized", "generic")


CASES = [(m, b, impl) for m in METHODS for b in range(BLOCKS) for impl in _order(b)]


# CPU time of the process, not wall time: on the shared 2-core machine a wall-clock round
# also counts the time this process waits for a core (rounds varied 2x within a block)
@pytest.mark.benchmark(timer=time.process_time)
@pytest.mark.parametrize("method,block,impl", CASES, ids=[f"{m}-{i}-{b}" for m, b, i in CASES])
def test_double_pendulum_1e4_steps(benchmark, scene, method, block, impl):
    benchmark.group = f"double pendulum, 1e4 steps, {method}"
    benchmark.extra_info[RATIO_KEY] = dict(method=method, impl=impl, block=block)
    run = _runner(impl, method, scene)
    # compile (or load from numba's cache) and warm up outside the timing
    q_end, energy = benchmark.pedantic(run, rounds=ROUNDS, iterations=1, warmup_rounds=1)

    assert energy.shape == (N_STEPS + 1,)
    # the run is the real one: energy error of the expected size over t = 100
    # (measured max|ΔH| 0.124 (P1), 6.6e-5 (P2), 3.4e-7 (P3); H0 = 0, potential scale m g l ≈ 10)
    assert np.max(np.abs(energy - energy[0])) < {"P1L-Q2G": 0.3, "P2L-Q3G": 2e-4,
                                                  "P3L-Q4G": 1e-6}[method]
    if impl == "generic":
        _finals[method] = np.array(q_end)
    if impl == "sized" and method in _finals:
        # the size-specialized kernels change no operation: bit for bit
        assert np.array_equal(q_end, _finals[method])
    if impl == "specialized" and method in _finals:
        # same algorithm, same floating-point operations: same end state (measured 0.0)
        assert np.max(np.abs(q_end - _finals[method])) <= 1e-12
