"""What derivatives of the discrete flow cost per step, beside a plain run.

The damped double pendulum (c = 0.3, ``P2L-Q3G``, h = 0.01, 5 000 steps, only the end
saved, everything compiled first, the stages sized for the model included) from
θ1 = 1, θ2 = 0.5, side by side in one session:

* ``integrate`` with default settings, and with the generic stages (``specialize=False``);
* ``sensitivity`` along 1 direction (q0[0]) and the 2n = 8 directions of (q0, v0);
* ``adjoint``: the gradient by q0 and v0 of a cost of the final state, and by q0, v0 and
  the k = 6 parameters: with the scene's derivatives by θ, and with the same model given
  none (the step differenced in each θ_l, ``tests/models.py``);
* the derivatives with default settings use the linearised step compiled for the model's
  sizes (compiled first, with ``specialize=True``); the same with ``specialize=False``, the
  generic kernels. The two give the same numbers bit for bit (asserted before timing).

The medians per step and their ratios to the plain run are printed at the end. Run with
``make bench`` or ``.venv/bin/python -m pytest bench/test_bench_sensitivity.py
--benchmark-only``.
"""

from __future__ import annotations

import statistics

import numpy as np
import pytest

import fastvi
from tests.models import damped_double_pendulum_by_differences

N_STEPS = 5_000
ROUNDS = 7
_times: dict = {}


def _model():
    dp = fastvi.scenes.double_pendulum(damping=0.3)
    return dp, *dp.initial_state(1.0, 0.5)


def _cases():
    dp, q0, v0 = _model()
    twin = damped_double_pendulum_by_differences(0.3)
    n, k = dp.n, dp.params.size
    one = np.zeros((2 * n + k, 1))
    one[0, 0] = 1.0
    run = dict(h=0.01, n_steps=N_STEPS, save_every=N_STEPS)

    def final_cost(res):
        return np.ones((len(res.t), n)), None

    return {
        "integrate (default)": lambda: fastvi.integrate(dp, q0, v0, **run),
        "integrate (specialize=False)": lambda: fastvi.integrate(dp, q0, v0, specialize=False,
                                                                 **run),
        "sensitivity, 1 direction": lambda: fastvi.sensitivity(dp, q0, v0, wrt=one, **run),
        "sensitivity, 2n directions": lambda: fastvi.sensitivity(dp, q0, v0, **run),
        "adjoint, by q0 and v0": lambda: fastvi.adjoint(dp, q0, v0, final_cost, param_index=[],
                                                        **run),
        "adjoint, + 6 params": lambda: fastvi.adjoint(dp, q0, v0, final_cost, **run),
        "adjoint, + 6 params (diff.)": lambda: fastvi.adjoint(twin, q0, v0, final_cost, **run),
        "sensitivity, 1 direction, generic": lambda: fastvi.sensitivity(
            dp, q0, v0, wrt=one, specialize=False, **run),
        "adjoint, + 6 params, generic": lambda: fastvi.adjoint(
            dp, q0, v0, final_cost, specialize=False, **run),
    }


CASES = list(_cases())


@pytest.fixture(scope="module", autouse=True)
def _compiled():
    dp, q0, v0 = _model()
    fastvi.integrate(dp, q0, v0, h=0.01, n_steps=2, specialize=True)  # the sized stages too
    # the sized linearised steps, which the default then takes
    fastvi.sensitivity(dp, q0, v0, h=0.01, n_steps=2, specialize=True)
    fastvi.adjoint(dp, q0, v0, lambda r: (np.ones_like(r.q), None), h=0.01, n_steps=2,
                   specialize=True)
    out = {label: call() for label, call in _cases().items()}
    assert np.array_equal(out["sensitivity, 1 direction"].dq,
                          out["sensitivity, 1 direction, generic"].dq)
    assert np.array_equal(out["adjoint, + 6 params"].gradient,
                          out["adjoint, + 6 params, generic"].gradient)


@pytest.mark.parametrize("label", CASES)
def test_derivative_cost(benchmark, label):
    call = _cases()[label]
    benchmark.pedantic(call, rounds=ROUNDS, iterations=1)
    _times[label] = 1e6 * statistics.median(benchmark.stats.stats.data) / N_STEPS
    benchmark.extra_info["us_per_step"] = _times[label]


@pytest.fixture(scope="module", autouse=True)
def _report(print_uncaptured):
    yield
    plain = _times.get("integrate (default)")
    if not plain:
        return

    def show(write):
        write.sep("derivatives of the discrete flow (damped double pendulum, P2L-Q3G, medians)")
        for label, t in _times.items():
            write(f"{label:<36} {t:6.2f} µs a step   {t / plain:5.2f} × integrate")

    print_uncaptured(show)
