"""Order of accuracy, measured: log–log slope over a sequence of h, round-off plateau trimmed.

Nonlinear constrained problems only (a linear oscillator lets methods super-converge), against
an independent reference: SciPy DOP853 at rtol = atol = 1e-13 in angle coordinates.
"""

import numpy as np
import pytest

import fastvi
from fastvi.studies.convergence import observed_order
from fastvi.studies.reference import chain_pendulum_reference

from . import models

T = 1.0


@pytest.fixture(scope="module")
def dp_reference():
    th, om = chain_pendulum_reference([np.pi / 2, np.pi / 2], [0.0, 0.0], [T], [1.0, 1.0], [1.0, 1.0])
    return th[0], om[0]


def _dp_errors(model, name, steps, ref):
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    hs, errs = [], []
    for N in steps:
        r = fastvi.integrate(model, q0, v0, h=T / N, n_steps=N, method=name)
        th = np.array(model.angles(r.q[-1]))
        hs.append(T / N)
        errs.append(np.abs(th - ref[0]).max())
    return np.array(hs), np.array(errs)


# (method, expected order, step counts that stay above the round-off plateau)
CASES = [
    ("P1L-Q2G", 2, [20, 40, 80, 160, 320]),
    ("P2L-Q3G", 4, [10, 20, 40, 80, 160]),
    ("P3L-Q4G", 6, [20, 28, 40, 56, 80]),
]


@pytest.mark.parametrize("name,order,steps", CASES)
def test_order_is_2s_on_the_double_pendulum(double_pendulum, dp_reference, name, order, steps):
    hs, errs = _dp_errors(double_pendulum, name, steps, dp_reference)
    measured, used = observed_order(hs, errs)
    assert used.sum() >= 5
    # measured: 2.06, 4.09, 6.0x
    assert abs(measured - order) <= 0.3, (measured, errs)


def test_paper_b_variant_is_order_2_whatever_the_degree(double_pendulum, dp_reference):
    """Constraints at the step ends only: every degree collapses to RATTLE (method.md §7)."""
    steps = [20, 40, 80, 160, 320]
    _, e1 = _dp_errors(double_pendulum, "P1L-Q2G-NE-CE", steps, dp_reference)
    hs, e3 = _dp_errors(double_pendulum, "P3L-Q4G-NE-CE", steps, dp_reference)
    assert abs(observed_order(hs, e3)[0] - 2) <= 0.3  # measured 2.06
    np.testing.assert_allclose(e3, e1, rtol=1e-6)  # same trajectory up to rounding


@pytest.mark.parametrize("name,order,steps", [("P2L-Q3G", 4, [16, 24, 32, 48, 64, 96]),
                                              ("P3L-Q4G", 6, [16, 24, 32, 48, 64])])
def test_order_holds_with_a_configuration_dependent_mass_matrix(name, order, steps):
    """Polar-coordinate pendulum: M(q) = diag(m, m r²), constraint r = l, sin potential."""
    model = models.polar_pendulum()
    T2 = 2.0
    th, _ = chain_pendulum_reference([2.5], [0.0], [T2], [1.0], [1.0])
    hs, errs = [], []
    for N in steps:
        r = fastvi.integrate(model, [1.0, 2.5], [0.0, 0.0], h=T2 / N, n_steps=N, method=name)
        hs.append(T2 / N)
        errs.append(abs(r.q[-1, 1] - th[0, 0]))
    measured, used = observed_order(hs, errs)
    assert used.sum() >= 5 and abs(measured - order) <= 0.3, (measured, errs)
