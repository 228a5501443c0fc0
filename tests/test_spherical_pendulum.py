"""Spherical pendulum scene: consistency, physics against SciPy in angles, Noether's L_z."""

import pickle

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fastvi
from fastvi.scenes.spherical_pendulum import angles, state_from_angles

# theta from the downward vertical, phi azimuth; L_z != 0 keeps theta away from the poles
START = dict(theta=1.0, phi=0.3, theta_dot=0.5, phi_dot=2.0)


@pytest.fixture(scope="module")
def sph():
    return fastvi.scenes.spherical_pendulum()


def test_spherical_pendulum_is_registered_and_pickles(sph):
    assert fastvi.scenes.SCENES["spherical_pendulum"] is fastvi.scenes.spherical_pendulum
    clone = pickle.loads(pickle.dumps(fastvi.scenes.spherical_pendulum(m=2.0, l=0.5)))
    assert clone.name == "spherical_pendulum" and np.allclose(clone.params, [2.0, 0.5, 9.81])
    assert all(sph.has_exact_second_derivatives[k] for k in ("potential_hessian", "constraint_hessian"))


def test_initial_state_is_consistent_and_angles_round_trip():
    model = fastvi.scenes.spherical_pendulum(l=1.7)
    q, v = model.initial_state(**START)
    assert abs(model.constraint_value(q)[0]) < 1e-15  # measured 0 to 2e-16
    assert abs(model.constraint_jacobian_value(q)[0] @ v) < 1e-14  # measured 1e-16
    th, ph = angles(q)
    assert np.isclose(th, START["theta"], atol=1e-14) and np.isclose(ph, START["phi"], atol=1e-14)
    # hanging straight down is theta = 0; theta = pi/2 is horizontal
    assert np.allclose(state_from_angles(0.0, 1.0, l=1.7)[0], [0, 0, -1.7])
    assert np.isclose(state_from_angles(np.pi / 2, 0.0)[0][2], 0.0, atol=1e-16)


def test_rejects_nonpositive_length():
    with pytest.raises(ValueError, match="`l` must be positive"):
        fastvi.scenes.spherical_pendulum(l=0.0)


def _reference(t_end, g=9.81, l=1.0):
    """SciPy DOP853 (rtol 1e-13) in the angles θ, φ: θ̈ = sinθ cosθ φ̇² − (g/l) sinθ,
    φ̈ = −2 cotθ θ̇ φ̇."""

    def rhs(t, y):
        th, ph, dth, dph = y
        return [dth, dph, np.sin(th) * np.cos(th) * dph**2 - g / l * np.sin(th),
                -2.0 * np.cos(th) / np.sin(th) * dth * dph]

    y0 = [START["theta"], START["phi"], START["theta_dot"], START["phi_dot"]]
    sol = solve_ivp(rhs, (0, t_end), y0, method="DOP853", rtol=1e-13, atol=1e-13)
    th, ph, dth, dph = sol.y[:, -1]
    return state_from_angles(th, ph, dth, dph, l)


def test_trajectory_matches_scipy_in_spherical_coordinates(sph):
    q0, v0 = sph.initial_state(**START)
    res = fastvi.integrate(sph, q0, v0, h=0.01, n_steps=300, method="P3L-Q4G")
    q_ref, v_ref = _reference(3.0)
    err = max(np.max(np.abs(res.q[-1] - q_ref)), np.max(np.abs(res.v[-1] - v_ref)))
    assert err < 1e-9  # measured 1.5e-12 (order 6, h = 0.01)


def test_angular_momentum_about_z_is_conserved_to_round_off_over_1e5_steps(sph):
    # Discrete Noether: the Galerkin discrete Lagrangian and the constraint are invariant
    # under rotations about z, so x p_y − y p_x is conserved to round-off — not merely to
    # the method's accuracy, which the energy error below measures (7.5e-9).
    q0, v0 = sph.initial_state(**START)
    res = fastvi.integrate(sph, q0, v0, h=0.01, n_steps=100_000, save_every=10)
    Lz = sph.angular_momentum(res.q, res.p)[:, 2]
    assert np.isclose(Lz[0], 2.0 * np.sin(1.0) ** 2)  # m l² sin²θ φ̇
    drift = np.max(np.abs(Lz - Lz[0]))
    assert drift < 1e-12  # measured 8.8e-14 over 1e5 steps (L_z = 1.42)
    dH = np.abs(res.energy_error)
    assert dH.max() < 2e-8  # measured 7.5e-9: bounded, order 4 (4.7e-6 at h = 0.05)
    assert drift < 1e-3 * dH.max()  # conservation is structural, not accuracy
    tenth = len(dH) // 10
    assert dH[-tenth:].max() < 1.5 * dH[:tenth].max()  # no drift: measured ratio 1.000
    assert res.constraint_residual.max() < 1e-14  # measured 2.2e-16
    assert res.velocity_residual.max() < 1e-14  # measured 4.4e-16


def test_angular_momentum_is_conserved_by_every_method_family(sph):
    q0, v0 = sph.initial_state(**START)
    for name in ("P1L-Q2G", "P3L-Q4G", "P2L-Q3G-NE-CE", "P2L-Q3L"):
        res = fastvi.integrate(sph, q0, v0, h=0.02, n_steps=5_000, method=name, save_every=50)
        Lz = sph.angular_momentum(res.q, res.p)[:, 2]
        assert np.max(np.abs(Lz - Lz[0])) < 1e-12, name  # measured 1e-14 to 8e-14
