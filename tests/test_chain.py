"""The N-link chain scene: consistent initial data, exact derivatives, constraints held to
round-off, the N = 2 chain is the double pendulum, and agreement with an independent
reference (SciPy DOP853 in angle coordinates)."""

import pickle

import numpy as np
import pytest

import fastvi
from fastvi.scenes import SCENES, chain
from fastvi.studies.reference import chain_cartesian, chain_pendulum_reference

from .derivatives import constraint_derivative_errors, slot_value

MASSES = (1.0, 2.0, 0.5, 1.5)
LENGTHS = (1.0, 0.7, 1.3, 0.9)


@pytest.fixture(scope="module")
def chain4():
    return chain(4, m=MASSES, l=LENGTHS)


def test_chain_is_registered_by_name_and_pickles():
    assert SCENES["chain"] is chain
    assert "chain" in fastvi.scenes.__all__
    model = pickle.loads(pickle.dumps(chain(3, m=(1.0, 2.0, 3.0), l=0.5)))
    assert (model.n, model.m) == (6, 3)
    assert np.array_equal(model.params, [1.0, 2.0, 3.0, 0.5, 0.5, 0.5, 9.81])


@pytest.mark.parametrize("N", [1, 3, 7])
def test_initial_state_is_consistent_and_angles_round_trip(N):
    model = chain(N, m=np.linspace(0.5, 2.0, N), l=np.linspace(1.2, 0.6, N))
    rng = np.random.default_rng(N)
    for _ in range(5):
        th = rng.uniform(-np.pi, np.pi, N)
        om = rng.normal(size=N)
        q, v = model.initial_state(th, om)
        assert np.max(np.abs(model.constraint_value(q))) < 1e-14  # measured 1.1e-16
        assert np.max(np.abs(model.constraint_jacobian_value(q) @ v)) < 1e-14  # measured 4.4e-16
        back = model.angles(q)
        assert np.max(np.abs(np.angle(np.exp(1j * (back - th))))) < 1e-14  # measured 2.2e-16
    q, v = model.initial_state(np.zeros(N))  # omegas default: at rest, hanging straight down
    assert np.all(v == 0.0) and np.all(q[0::2] == 0.0) and np.all(np.diff(q[1::2]) < 0)


def test_initial_state_matches_the_reference_chain_geometry(chain4):
    th, om = np.array([0.3, -1.2, 2.0, 0.1]), np.array([0.5, -0.1, 1.5, -2.0])
    q, v = chain4.initial_state(th, om)
    qr, vr = chain_cartesian(th, om, LENGTHS)
    assert np.max(np.abs(q - qr[0])) < 1e-15 and np.max(np.abs(v - vr[0])) < 1e-15  # measured 0


def test_constraint_jacobian_and_hessian_are_the_derivatives_of_g(chain4):
    rng = np.random.default_rng(2)
    for _ in range(5):
        q = rng.normal(size=8)
        eta = rng.normal(size=4)
        G_err, H_err, H = constraint_derivative_errors(chain4, q, eta)
        assert G_err < 1e-8  # measured 1.2e-9 (FD error)
        assert H_err < 1e-8  # measured 7.9e-10
        assert np.array_equal(H, H.T)


def test_potential_is_gravity_with_exact_gradient(chain4):
    q = np.random.default_rng(3).normal(size=8)
    assert chain4.potential_energy(q) == pytest.approx(9.81 * np.dot(MASSES, q[1::2]), rel=1e-15)
    grad = slot_value(chain4, "potential_grad", q, q, (8,))
    assert np.array_equal(grad[0::2], np.zeros(4))
    assert np.allclose(grad[1::2], 9.81 * np.array(MASSES), rtol=1e-15, atol=0)
    assert chain4.linear_potential  # ∇²V = 0, declared (potential_hessian=0); Model.check verifies it
    assert np.array_equal(chain4.mass_matrix(q), np.diag(np.repeat(MASSES, 2)))


def test_constraints_hold_to_round_off_along_a_chain8_trajectory():
    model = chain(8)
    q0, v0 = model.initial_state(np.linspace(1.2, -0.4, 8), np.linspace(0.0, 1.0, 8))
    res = fastvi.integrate(model, q0, v0, h=0.01, n_steps=300, method="P2L-Q3G")
    assert res.success
    assert np.max(res.constraint_residual) < 1e-13  # measured 1.4e-15
    assert np.max(res.velocity_residual) < 1e-12  # measured 1.9e-15
    assert np.max(np.abs(res.energy_error)) < 1e-3  # measured 9.0e-05 (bounded, order 4)


def test_chain2_is_the_double_pendulum_to_round_off():
    m1, m2, l1, l2 = 1.3, 0.7, 1.1, 0.8
    dp = fastvi.scenes.double_pendulum(m1=m1, m2=m2, l1=l1, l2=l2)
    ch = chain(2, m=(m1, m2), l=(l1, l2))
    q0, v0 = dp.initial_state(np.pi / 2, np.pi / 2, 0.3, -0.2)
    qc, vc = ch.initial_state([np.pi / 2, np.pi / 2], [0.3, -0.2])
    assert np.max(np.abs(q0 - qc)) < 1e-15 and np.max(np.abs(v0 - vc)) < 1e-15  # measured 0
    a = fastvi.integrate(dp, q0, v0, h=0.01, n_steps=500, method="P3L-Q4G")
    b = fastvi.integrate(ch, qc, vc, h=0.01, n_steps=500, method="P3L-Q4G")
    # the same equations evaluated with the same operations: the trajectories agree bit for
    # bit today; the tolerance allows a reordered sum (round-off, amplified by the chaotic
    # motion over 5 s, stays orders of magnitude below the method's own error ~1e-8)
    assert np.max(np.abs(a.q - b.q)) < 1e-12  # measured 0.0
    assert np.max(np.abs(a.energy - b.energy)) < 1e-12  # measured 0.0


def test_chain4_converges_to_the_angle_coordinate_reference(chain4):
    th0 = np.array([0.8, -0.5, 1.1, 0.2])
    q0, v0 = chain4.initial_state(th0)
    T = 1.0
    th, om = chain_pendulum_reference(th0, np.zeros(4), [T], MASSES, LENGTHS)
    q_ref = chain_cartesian(th, om, LENGTHS)[0][0]
    errs = []
    for h in (0.01, 0.005):
        res = fastvi.integrate(chain4, q0, v0, h=h, t_end=T, method="P2L-Q3G")
        errs.append(np.max(np.abs(res.q[-1] - q_ref)))
    assert errs[1] < 1e-6  # measured 1.2e-07
    # order 4: halving h divides the error by 2^4 = 16
    assert 12.0 < errs[0] / errs[1] < 21.0  # measured 16.0


@pytest.mark.parametrize("bad, match", [
    (dict(N=0), "`N` must be >= 1"),
    (dict(N=2.5), "`N` must be an integer"),
    (dict(N=3, m=(1.0, 2.0)), "`m` must be a number or have N = 3 entries"),
    (dict(N=2, l=(1.0, -1.0)), r"`l\[1\]` must be positive"),
    (dict(N=2, g=0.0), "`g` must be positive"),
])
def test_rejects_bad_arguments_naming_them(bad, match):
    with pytest.raises((TypeError, ValueError), match=match):
        chain(**bad)


def test_initial_state_rejects_wrong_number_of_angles(chain4):
    with pytest.raises(ValueError, match="`thetas` must have N = 4 entries"):
        chain4.initial_state([0.1, 0.2])
    with pytest.raises(ValueError, match="`omegas` must have the shape"):
        chain4.initial_state([0.1, 0.2, 0.3, 0.4], [1.0])
