"""The triple pendulum scene: consistent data, exact derivatives, and DOP853 agreement."""

import pickle

import numpy as np
import pytest

import fastvi
from fastvi.scenes import SCENES, triple_pendulum
from fastvi.studies.reference import chain_cartesian, chain_pendulum_reference

from .derivatives import constraint_derivative_errors, fd_jacobian, slot_value

MASSES = (1.0, 2.0, 0.5)
LENGTHS = (1.0, 0.7, 1.3)


@pytest.fixture(scope="module")
def tp():
    return triple_pendulum()


@pytest.fixture(scope="module")
def tp_uneven():
    return triple_pendulum(m=MASSES, l=LENGTHS, g=9.81)


def test_triple_pendulum_is_registered_by_name():
    assert SCENES["triple_pendulum"] is triple_pendulum
    assert "triple_pendulum" in fastvi.scenes.__all__


def test_initial_state_is_consistent_and_angles_round_trip(tp_uneven):
    rng = np.random.default_rng(1)
    for _ in range(10):
        th = rng.uniform(-np.pi, np.pi, 3)
        om = rng.normal(size=3)
        q, v = tp_uneven.initial_state(*th, *om)
        assert np.max(np.abs(tp_uneven.constraint_value(q))) < 1e-14  # measured 3.3e-16
        assert np.max(np.abs(tp_uneven.constraint_jacobian_value(q) @ v)) < 1e-14  # measured 2.2e-16
        back = np.array(tp_uneven.angles(q))
        assert np.max(np.abs(np.angle(np.exp(1j * (back - th))))) < 1e-14  # measured 5.6e-17


def test_initial_state_matches_the_reference_chain_geometry(tp_uneven):
    th, om = np.array([0.3, -1.2, 2.0]), np.array([0.5, -0.1, 1.5])
    q, v = tp_uneven.initial_state(*th, *om)
    qr, vr = chain_cartesian(th, om, LENGTHS)
    assert np.max(np.abs(q - qr[0])) < 1e-15 and np.max(np.abs(v - vr[0])) < 1e-15  # measured 0


def test_constraint_jacobian_and_hessian_are_the_derivatives_of_g(tp_uneven):
    rng = np.random.default_rng(2)
    for _ in range(5):
        q = rng.normal(size=6)
        eta = rng.normal(size=3)
        # Σ η_a ∇²g_a = ∂(Gᵀη)/∂q, through the compiled Hessian callback
        G_err, H_err, H = constraint_derivative_errors(tp_uneven, q, eta)
        assert G_err < 1e-8  # measured 5.2e-10 (FD error)
        assert H_err < 1e-8  # measured 2.1e-10
        assert np.array_equal(H, H.T)


def test_potential_gradient_and_hessian_are_exact(tp_uneven):
    q = np.random.default_rng(3).normal(size=6)
    grad = slot_value(tp_uneven, "potential_grad", q, q, (6,))
    gfd = fd_jacobian(lambda x: np.atleast_1d(tp_uneven.potential_energy(x)), q)[0]
    assert np.max(np.abs(grad - gfd)) < 3e-8  # measured 3.3e-9
    # V = g Σ m_i y_i
    assert tp_uneven.potential_energy(q) == pytest.approx(9.81 * np.dot(MASSES, q[1::2]), rel=1e-15)
    assert np.all(slot_value(tp_uneven, "potential_hessian", q, q, (6, 6)) == 0.0)


def test_p3_trajectory_matches_dop853_in_angles(tp_uneven):
    """Uneven masses and lengths: the params vector reaches every callback."""
    th0, om0 = np.array([np.pi / 2, np.pi / 3, -np.pi / 4]), np.array([0.0, 1.0, 0.0])
    q0, v0 = tp_uneven.initial_state(*th0, *om0)
    res = fastvi.integrate(tp_uneven, q0, v0, h=1 / 128, t_end=1.0, method="P3L-Q4G")
    th, om = chain_pendulum_reference(th0, om0, res.t, MASSES, LENGTHS)
    qr, vr = chain_cartesian(th, om, LENGTHS)
    assert np.max(np.abs(res.q - qr)) < 3e-9  # measured 3.7e-10
    assert np.max(np.abs(res.v - vr)) < 5e-8  # measured 5.5e-9
    assert np.max(res.constraint_residual) < 1e-14  # measured 5.6e-16
    assert np.max(res.velocity_residual) < 1e-14  # measured 1.8e-15
    assert np.max(np.abs(res.energy_error)) < 2e-7  # measured 2.3e-8


def test_model_pickles_as_its_recipe(tp_uneven):
    back = pickle.loads(pickle.dumps(tp_uneven))
    assert np.array_equal(back.params, tp_uneven.params)
    q0, v0 = back.initial_state(1.0, 0.5, -0.5)
    a = fastvi.integrate(tp_uneven, q0, v0, h=0.02, n_steps=20)
    b = fastvi.integrate(back, q0, v0, h=0.02, n_steps=20)
    assert np.array_equal(a.q, b.q)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(m=(1.0, 1.0)), r"`m` must have three entries"),
        (dict(l=(1.0, -1.0, 1.0)), r"`l\[1\]` must be positive"),
        (dict(m=1.0), r"`m` must be a sequence"),
        (dict(g=0.0), r"`g` must be positive"),
    ],
)
def test_rejects_bad_parameters_naming_them(kwargs, match):
    with pytest.raises((ValueError, TypeError), match=match):
        triple_pendulum(**kwargs)


def test_default_parameters_are_unit_masses_and_lengths(tp):
    assert np.array_equal(tp.params, [1, 1, 1, 1, 1, 1, 9.81])
    assert (tp.n, tp.m) == (6, 3)
