"""Where a step's time goes (``bench/step_profile.py``): each part of a step timed alone.

On the double pendulum from θ1 = θ2 = π/2, 2000 steps in, for ``P2L-Q3G``: the CPU time per
call of a whole step (default and full Newton) and of its parts, stored in ``extra_info``
and printed. The parts a full-Newton step calls (per Newton iteration: the residual with its
matrix, the LU factorisation and solve; per step: the end projection) must add up to no more
than the step costs: what is left is the predictor, bookkeeping and saving. Run with
``make bench`` or ``.venv/bin/python -m pytest bench/test_bench_step_parts.py --benchmark-only``.
"""

from __future__ import annotations

import numpy as np
import pytest

import fastvi
from bench.step_profile import profile_step

METHODS = ("P1L-Q2G", "P2L-Q3G", "P3L-Q4G")


@pytest.mark.parametrize("method", METHODS)
def test_step_parts(benchmark, print_uncaptured, method):
    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    parts = benchmark.pedantic(profile_step, args=(model, q0, v0, method), kwargs=dict(calls=5000),
                               rounds=1, iterations=1)
    benchmark.extra_info.update(parts)
    its = parts["iterations_full"]
    inside = its * (parts["residual_jacobian"] + parts["lu_factor"] + parts["lu_solve"])
    # the parts of a full-Newton step cannot cost much more than the step: 70–90 % of it on
    # an idle host, 1.0–1.5 times it on a busy 2-core one (each part is timed apart, its
    # best of 5 loops, and the Jacobian's assembly varies most); the margin is that noise
    assert 0 < inside + parts["end_momentum"] < 1.7 * parts["step_full"]
    assert parts["callback"] < parts["residual"]  # one ∇V call is a small part of a residual

    def show(write):
        write.sep(f"{method}: µs per call (N = {parts['N']}, Newton its/step auto "
                  f"{parts['iterations_auto']:.2f}, full {its:.2f})")
        for k, v in parts.items():
            if k != "N" and not k.startswith("iterations"):
                write(f"  {k:18s} {1e6 * v:8.3f}")

    print_uncaptured(show)
