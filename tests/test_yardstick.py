"""The benchmark yardstick (``tests/yardstick.py``) runs the generic kernel's algorithm.

The yardstick inlines the double pendulum into the step kernel; the speed ratio reported by
``make bench`` only means something if both kernels compute the same trajectory. The
double pendulum from θ1 = θ2 = π/2 is chaotic, so any difference in the algorithm (predictor,
stopping rule, projection) or in the model would show up far above round-off within 1000
steps.
"""

from __future__ import annotations

import numpy as np
import pytest

import fastvi
from tests import yardstick

# the yardstick is a benchmark tool: compiling it costs ≈ 13 s of a cold `make test`, whose
# 8-minute budget the kernels' own compile nearly fills; `make test-slow` runs these
pytestmark = pytest.mark.slow

METHODS = ("P1L-Q2G", "P2L-Q3G", "P3L-Q4G")
# other tables through the same compiled yardstick: ends-only constraints (J = 1), Lobatto
# quadrature with Chebyshev nodes, Gauss constraint points (ℓ_ν(d_j) not 0/1), degree 4
OTHER_TABLES = ("P2L-Q3G-NE-CE", "P3L-Q3L-NC", "P3L-Q4G-CG2", "P4L-Q5G")
H = 0.01
N_STEPS = 1000


@pytest.mark.parametrize("method", METHODS + OTHER_TABLES)
def test_yardstick_trajectory_equals_fastvi_integrate(double_pendulum, dp_start, method):
    q0, v0 = dp_start
    ref = fastvi.integrate(double_pendulum, q0, v0, h=H, n_steps=N_STEPS, method=method, newton="full")
    # start from the state integrate starts from (its projection moves q0 by round-off)
    out = yardstick.integrate_double_pendulum(
        ref.q[0], ref.v[0], h=H, n_steps=N_STEPS, tabs=fastvi.method(method).kernel_tables,
        params=tuple(double_pendulum.params))
    assert out["steps"] == N_STEPS
    # measured 0.0 for every method here (same floating-point operations, same order)
    assert np.max(np.abs(out["qs"] - ref.q)) <= 1e-12
    assert np.max(np.abs(out["ps"] - ref.p)) <= 1e-12
    assert np.max(np.abs(out["vs"] - ref.v)) <= 1e-12
    assert np.max(np.abs(out["energy"] - ref.energy)) <= 1e-12
    # same Newton iteration count at every step: same predictor and stopping rule (measured equal)
    assert np.array_equal(out["newton_iterations"][1:], ref.newton_iterations[1:])
    assert out["iterations"] == ref.stats["newton_iterations"]


def test_yardstick_keeps_constraints_at_newton_tolerance(double_pendulum, dp_start):
    """Independent of fastvi: |g| and |G v| recomputed here in NumPy from the yardstick's states."""
    q0, v0 = dp_start
    out = yardstick.integrate_double_pendulum(q0, v0, h=H, n_steps=N_STEPS,
                                              tabs=fastvi.method("P2L-Q3G").kernel_tables)
    q, v = out["qs"], out["vs"]
    d = q[:, 2:] - q[:, :2]
    g1 = 0.5 * (q[:, 0] ** 2 + q[:, 1] ** 2 - 1.0)
    g2 = 0.5 * (d[:, 0] ** 2 + d[:, 1] ** 2 - 1.0)
    gv1 = q[:, 0] * v[:, 0] + q[:, 1] * v[:, 1]
    gv2 = d[:, 0] * (v[:, 2] - v[:, 0]) + d[:, 1] * (v[:, 3] - v[:, 1])
    assert np.max(np.abs(np.r_[g1, g2])) < 1e-13  # measured 3.3e-16
    assert np.max(np.abs(np.r_[gv1, gv2])) < 1e-12  # measured 1.3e-15


_STALE = ("fastvi.integrate did not take the straight-line retry: if fastvi/kernels/step.py changed "
          "after drive.run was cached, numba loads a stale drive.run (see docs/decisions/0005-cache-stamp.md)")


def test_yardstick_retries_like_fastvi(double_pendulum, dp_start):
    """Retry path: with max_iter = 3, a few P1L-Q2G steps need the straight-line restart."""
    q0, v0 = dp_start
    tabs = fastvi.method("P1L-Q2G").kernel_tables
    ref = fastvi.integrate(double_pendulum, q0, v0, h=H, n_steps=N_STEPS, method="P1L-Q2G", newton="full",
                           max_iter=3, on_failure="return")
    assert ref.success, _STALE
    # 5 retried steps (3 + 3 iterations), measured at steps 995–999
    assert np.sum(ref.newton_iterations[1:] > 3) == 5
    out = yardstick.integrate_double_pendulum(ref.q[0], ref.v[0], h=H, n_steps=N_STEPS,
                                              tabs=tabs, max_iter=3)
    assert np.array_equal(out["newton_iterations"][1:], ref.newton_iterations[1:])
    assert np.max(np.abs(out["qs"] - ref.q)) <= 1e-12  # measured 0.0


def test_yardstick_fails_where_fastvi_fails(double_pendulum, dp_start):
    """Give-up path: at h = 0.02 with max_iter = 3 both the extrapolated and the straight-line
    start fail at some step; the yardstick must give up at the same step, same count."""
    q0, v0 = dp_start
    ref = fastvi.integrate(double_pendulum, q0, v0, h=0.02, n_steps=N_STEPS, method="P1L-Q2G", newton="full",
                           max_iter=3, on_failure="return")
    assert ref.status == fastvi.Status.NEWTON_NOT_CONVERGED  # measured at step 107
    assert ref.stats["newton_iterations"] > 3 * ref.failed_step + 3, _STALE  # measured 417
    with pytest.raises(yardstick.YardstickError, match="NEWTON_NOT_CONVERGED") as info:
        yardstick.integrate_double_pendulum(ref.q[0], ref.v[0], h=0.02, n_steps=N_STEPS,
                                            tabs=fastvi.method("P1L-Q2G").kernel_tables,
                                            max_iter=3)
    assert info.value.step == ref.failed_step
    assert info.value.iterations == ref.stats["newton_iterations"]
