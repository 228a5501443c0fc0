"""fastvi.consistent_state: consistent initial data for any model from a rough guess.

Two mechanisms: a slider–crank in redundant Cartesian coordinates (``tests/models.py``, n = 6,
m = 5, one degree of freedom) and the double pendulum scene. The independent reference is
the state built from the natural coordinates (crank angle and speed, pendulum angles), where
the fixed coordinates pin the answer down completely.
"""

import warnings

import numpy as np
import pytest

import fastvi
from fastvi.scenes.double_pendulum import state_from_angles

from .models import slider_crank, slider_crank_state

ROUND_OFF = 1e-13


@pytest.fixture(scope="module")
def crank():
    return slider_crank()


@pytest.fixture(scope="module")
def dp():
    return fastvi.scenes.double_pendulum()


def _rough(x, rng, fixed=()):
    """``x`` moved by 0.1 … 0.3 (random sign) in every entry not in ``fixed``."""
    out = x + rng.choice([-1.0, 1.0], x.size) * rng.uniform(0.1, 0.3, x.size)
    out[list(fixed)] = x[list(fixed)]
    return out


def _residuals(model, q, v):
    return (float(np.abs(model.constraint_value(q)).max()),
            float(np.abs(model.constraint_jacobian_value(q) @ v).max()))


@pytest.mark.parametrize("seed", range(5))
def test_rough_guesses_become_consistent_to_round_off(crank, dp, seed):
    rng = np.random.default_rng(seed)
    for model, (q, v) in ((crank, slider_crank_state(0.4 + seed, 2.0 - seed)),
                          (dp, state_from_angles(0.3 + 0.5 * seed, -1.0 + 0.4 * seed, 1.0, -2.0))):
        qg, vg = _rough(q, rng), _rough(v, rng)
        assert _residuals(model, qg, vg)[0] > 1e-2  # really inconsistent
        q0, v0 = fastvi.consistent_state(model, qg, vg)
        g, gv = _residuals(model, q0, v0)
        assert g <= ROUND_OFF and gv <= ROUND_OFF, (model.name, g, gv)
        # the velocity changed least in the metric of M: v0 − vg ∈ range(M⁻¹ Gᵀ)
        G, M = model.constraint_jacobian_value(q0), model.mass_matrix(q0)
        B = np.linalg.solve(M, G.T)
        coef = np.linalg.lstsq(B, v0 - vg, rcond=None)[0]
        assert np.abs(B @ coef - (v0 - vg)).max() < 1e-12


@pytest.mark.parametrize("phi, omega", [(0.7, 2.0), (2.5, -1.0), (-1.2, 3.0), (4.0, 0.5), (-2.8, -2.5)])
def test_slider_crank_from_the_crank_pin_matches_the_exact_state(crank, phi, omega):
    # fixing the crank pin's x coordinate (position and velocity) leaves one solution near the
    # guess: the state with crank angle phi (the guess's sign of ya picks the branch)
    q, v = slider_crank_state(phi, omega)
    rng = np.random.default_rng(int(100 * phi) % 97)
    qg, vg = _rough(q, rng, fixed=[0]), _rough(v, rng, fixed=[0])
    qg[1] = np.copysign(max(abs(qg[1]), 0.05), q[1])
    q0, v0 = fastvi.consistent_state(crank, qg, vg, fixed=[0])
    assert q0[0] == q[0] and v0[0] == v[0]  # bit for bit
    assert np.abs(q0 - q).max() < 1e-13 and np.abs(v0 - v).max() < 1e-12
    g, gv = _residuals(crank, q0, v0)
    assert g <= ROUND_OFF and gv <= ROUND_OFF


@pytest.mark.parametrize("angles", [(0.5, 1.0, 1.0, -2.0), (2.0, -1.0, 3.0, -4.0), (-0.7, 0.4, 0.0, 0.0),
                                    (1.3, 2.9, -1.5, 0.5), (-2.2, -0.3, 2.0, 2.0)])
def test_double_pendulum_from_the_x_coordinates_matches_the_state_from_angles(dp, angles):
    q, v = state_from_angles(*angles)
    rng = np.random.default_rng(3)
    fixed = (0, 2)  # x1, x2 and their velocities; y1, y2 follow (sign from the guess)
    qg, vg = q.copy(), _rough(v, rng, fixed)
    # y1, y2 are off by 0.1 … 0.3 but on the branch of the answer (y1 = ±√(l1² − x1²), and the
    # same for y2 − y1): each moved away from the other branch
    d1, d2 = rng.uniform(0.1, 0.3, 2)
    qg[1] = q[1] + np.sign(q[1]) * d1
    qg[3] = q[3] + np.sign(q[1]) * d1 + np.sign(q[3] - q[1]) * d2
    q0, v0 = fastvi.consistent_state(dp, qg, vg, fixed=fixed)
    assert all(q0[i] == q[i] and v0[i] == v[i] for i in fixed)
    assert np.abs(q0 - q).max() < 1e-12 and np.abs(v0 - v).max() < 1e-11, (q0 - q, v0 - v)


def test_consistent_data_integrate_without_warnings(crank, dp):
    rng = np.random.default_rng(11)
    for model, (q, v) in ((crank, slider_crank_state(0.9, 2.0)), (dp, state_from_angles(1.0, 2.0, 0.5, 0.0))):
        q0, v0 = fastvi.consistent_state(model, _rough(q, rng), _rough(v, rng))
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no projection warning, nothing else either
            res = fastvi.integrate(model, q0, v0, h=0.01, n_steps=20)
        assert res.success
        # integrate's own projection (silent below 1e-12) has nothing left to do
        assert np.abs(res.q[0] - q0).max() < 1e-15 and np.abs(res.v[0] - v0).max() < 1e-15
        assert res.constraint_residual.max() < 1e-12


def test_fixed_entries_are_kept_bit_for_bit(crank):
    q, v = slider_crank_state(1.1, -0.7)
    qg, vg = _rough(q, np.random.default_rng(5)), _rough(v, np.random.default_rng(6))
    qg[0], vg[0] = 0.1 + 1e-17 * 3, 0.123456789012345  # arbitrary reachable values, last bits set
    q0, v0 = fastvi.consistent_state(crank, qg, vg, fixed=np.array([0]))
    assert q0[0].tobytes() == qg[0].tobytes() and v0[0].tobytes() == vg[0].tobytes()
    assert max(_residuals(crank, q0, v0)) <= ROUND_OFF


def test_singular_choices_are_refused_naming_the_coordinates(crank, dp):
    q, v = slider_crank_state(0.7, 2.0)
    qg, vg = _rough(q, np.random.default_rng(1)), _rough(v, np.random.default_rng(2))
    # the slider's height is set by the constraint yb = 0: fixing it leaves G_F singular
    with pytest.raises(ValueError, match=r"`fixed` leaves the constraints singular.*The constraints "
                                         r"determine coordinate q\[5\]: do not fix it"):
        fastvi.consistent_state(crank, qg, vg, fixed=[5])
    with pytest.raises(ValueError, match=r"fixing coordinates q\[0\], q\[1\] over-determines"):
        fastvi.consistent_state(crank, qg, vg, fixed=[0, 1])
    # fixing both coordinates of the first bob: the first rod's constraint has no free coordinate
    q, v = state_from_angles(0.5, 1.0)
    with pytest.raises(ValueError, match=r"with coordinates q\[0\], q\[1\] fixed.*rank 1 < m = 2.*"
                                         r"determine coordinates q\[0\], q\[1\]"):
        fastvi.consistent_state(dp, q + 0.1, v, fixed=(0, 1))


def test_unreachable_fixed_values_report_the_residual(crank):
    q, v = slider_crank_state(0.7, 2.0)
    qg = q.copy()
    qg[0] = 0.5  # beyond the crank radius 0.3: no consistent state has xa = 0.5
    with pytest.raises(ValueError, match=r"(?s)did not converge.*with coordinate q\[0\] fixed: max\|g\| = "
                                         r"[0-9.]+e-0[0-2].*better guess"):
        fastvi.consistent_state(crank, qg, v, fixed=[0])


def test_time_is_accepted_and_unused_for_time_independent_constraints(dp):
    q, v = state_from_angles(0.5, 1.0, 1.0, -1.0)
    a = fastvi.consistent_state(dp, q + 0.2, v + 0.2)
    b = fastvi.consistent_state(dp, q + 0.2, v + 0.2, t=7.5)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))


def test_bad_arguments_are_named(dp):
    q, v = state_from_angles(0.5, 1.0)
    with pytest.raises(ValueError, match="`fixed` index 4 is out of range for n = 4"):
        fastvi.consistent_state(dp, q, v, fixed=[4])
    with pytest.raises(TypeError, match="`fixed` must hold coordinate indices"):
        fastvi.consistent_state(dp, q, v, fixed=[0.5])
    with pytest.raises(ValueError, match="`q` must have shape"):
        fastvi.consistent_state(dp, q[:3], v)
    with pytest.raises(ValueError, match="`t` must be a finite float"):
        fastvi.consistent_state(dp, q, v, t=np.nan)
    with pytest.raises(TypeError, match="`model`"):
        fastvi.consistent_state("dp", q, v)


def test_unconstrained_models_are_returned_unchanged():
    from .models import quartic

    q, v = np.array([0.3, -0.2]), np.array([1.0, 2.0])
    q0, v0 = fastvi.consistent_state(quartic(), q, v)
    assert np.array_equal(q0, q) and np.array_equal(v0, v)


def test_inconsistent_data_errors_point_to_consistent_state(dp):
    q, v = state_from_angles(0.5, 1.0, 1.0, 0.0)
    with pytest.raises(ValueError, match=r"`q0` violates the constraints.*fastvi\.consistent_state"):
        fastvi.integrate(dp, q + 0.1, v, h=0.01, n_steps=1)
    with pytest.raises(ValueError, match=r"`v0` violates the hidden constraint.*fastvi\.consistent_state"):
        fastvi.integrate(dp, q, v + 0.1, h=0.01, n_steps=1)
