"""What a force or a time-dependent constraint costs per step.

Pairs of the same mechanism, conservative and forced / rheonomic, integrated side by side
in one session (``P2L-Q3G``, 5 000 steps, only the end saved, everything compiled first):

* the double pendulum, and the same with damping ``−c ṙ_i`` on both masses (exact force
  Jacobians from :mod:`fastvi.scenes.damping`), from θ1 = θ2 = π/2, h = 0.01;
* the pendulum, and Kapitza's pendulum (pivot driven, a rheonomic constraint with exact
  ``∂g/∂t``), from 0.3 rad off the top, h = 1e-3.

The medians per step, per Newton iteration (the drive of Kapitza's pendulum makes its
predictor worse: more iterations for the same motion), and the ratios forced/conservative
are printed at the end (damping is light, c = 0.02, so that both runs swing alike). Run with
``make bench`` or ``.venv/bin/python -m pytest bench/test_bench_forces.py --benchmark-only``.
"""

from __future__ import annotations

import statistics

import numpy as np
import pytest

import fastvi

N_STEPS = 5_000
ROUNDS = 7
PAIRS = {
    "double pendulum, damped": ("double_pendulum", dict(), dict(damping=0.02), (np.pi / 2, np.pi / 2), 0.01),
    "pendulum, driven pivot": ("pendulum", dict(), None, (np.pi - 0.3,), 1e-3),
}
_times: dict = {}


def _case(label, forced):
    scene, kw, kw_forced, angles, h = PAIRS[label]
    if label.startswith("pendulum"):
        model = fastvi.scenes.kapitza_pendulum() if forced else fastvi.scenes.pendulum()
    else:
        model = fastvi.scenes.SCENES[scene](**(kw_forced if forced else kw))
    q0, v0 = model.initial_state(*angles)
    return model, q0, v0, h


@pytest.mark.parametrize("forced", [False, True], ids=["conservative", "forced"])
@pytest.mark.parametrize("label", list(PAIRS))
def test_forced_step_cost(benchmark, label, forced):
    model, q0, v0, h = _case(label, forced)
    kw = dict(h=h, n_steps=N_STEPS, save_every=N_STEPS)
    fastvi.integrate(model, q0, v0, **{**kw, "n_steps": 10, "save_every": 10})  # compile, check
    res = benchmark.pedantic(fastvi.integrate, args=(model, q0, v0), kwargs=kw, rounds=ROUNDS,
                             iterations=1)
    benchmark.extra_info["us_per_step"] = 1e6 * benchmark.stats.stats.median / N_STEPS
    benchmark.extra_info["iterations_per_step"] = res.stats["newton_iterations"] / N_STEPS
    _times[(label, forced)] = (1e6 * statistics.median(benchmark.stats.stats.data) / N_STEPS,
                               res.stats["newton_iterations"] / N_STEPS)


@pytest.fixture(scope="module", autouse=True)
def _report(print_uncaptured):
    yield
    if not _times:
        return

    def show(write):
        write.sep("cost of a forced / rheonomic step (P2L-Q3G, medians)")
        for label in PAIRS:
            if (label, False) in _times and (label, True) in _times:
                (c, ic), (f, i_f) = _times[(label, False)], _times[(label, True)]
                write(f"{label:<26} conservative {c:6.2f} µs ({ic:.2f} it)   forced {f:6.2f} µs "
                      f"({i_f:.2f} it)   ratio per step {f / c:.2f}, per iteration "
                      f"{(f / i_f) / (c / ic):.2f}")

    print_uncaptured(show)
