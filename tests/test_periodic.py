"""Periodic orbits of the discrete flow and their Floquet multipliers (fastvi.periodic_orbit).

References are independent of the code under test: the nonlinear normal modes of the
double pendulum as brake orbits in angle coordinates with SciPy's DOP853 and its
variational equations (``studies/periodic.py``), the exact period of the simple pendulum
(a complete elliptic integral), and theory (symplecticity: reciprocal pairs, det = 1, two
trivial multipliers; similarity of monodromies along one orbit).
"""

import numpy as np
import pytest
from scipy.special import ellipk

import fastvi
from studies.periodic import linear_modes, measure, pair_errors

from . import models

W2, RATIO = linear_modes()["in-phase"]
T_LIN = 2 * np.pi / np.sqrt(W2)
PERIOD = 1.01 * T_LIN  # the softening mode: amplitude θ1 ≈ 0.35 rad
GUESS = (0.3, 0.3 * RATIO)


@pytest.fixture(scope="module")
def mode(double_pendulum):
    q0, v0 = double_pendulum.initial_state(*GUESS)
    return fastvi.periodic_orbit(double_pendulum, q0, v0, period=PERIOD, n_steps=100,
                                 phase=("v", 0))


def test_the_mode_closes_to_round_off_on_the_constraints(double_pendulum, mode):
    dp = double_pendulum
    assert mode.n_steps == 100 and mode.h == pytest.approx(PERIOD / 100, rel=1e-15)
    assert mode.residual < 1e-12  # measured 3.9e-16 … 2.6e-15
    # a run of fastvi.integrate, not the solver's own, comes back to the start
    r = fastvi.integrate(dp, mode.q0, mode.v0, h=mode.h, n_steps=mode.n_steps)
    assert np.abs(r.q[-1] - mode.q0).max() < 1e-12 and np.abs(r.v[-1] - mode.v0).max() < 1e-12
    assert np.abs(dp.constraint_value(mode.q0)).max() < 1e-14
    assert np.abs(dp.constraint_jacobian_value(mode.q0) @ mode.v0).max() < 1e-13
    assert np.abs(mode.v0[0]) < 1e-14  # the phase condition
    th1, th2 = dp.angles(mode.result.q)
    assert th1.max() > 0.34 and th1.min() < -0.34  # a real oscillation, not the equilibrium
    assert th2[0] / th1[0] == pytest.approx(RATIO, rel=0.1)  # near the linear mode's shape
    wide = np.abs(th1) > 0.05
    assert np.all(np.sign(th1[wide]) == np.sign(th2[wide]))  # in phase
    assert mode.result.t[-1] == pytest.approx(PERIOD, rel=1e-14)


def test_multipliers_are_symplectic(mode):
    lam = mode.multipliers
    assert lam.shape == (4,) and mode.monodromy.shape == (4, 4) and mode.basis.shape == (8, 4)
    pair, det, trivial = pair_errors(lam)
    assert pair < 1e-12 and det < 1e-12  # measured 1.8e-14, 2.4e-14
    assert trivial < 1e-6  # a Jordan block at 1 splits like √(round-off): measured 1.5e-8
    assert np.abs(lam[0] - 1) > 0.1  # the nontrivial pair is well apart from the trivial
    assert np.abs(np.abs(lam[:2]) - 1).max() < 1e-12  # elliptic: on the unit circle
    # the monodromy keeps the symplectic form restricted to the tangent space
    Z, Mo = mode.basis, mode.monodromy
    J = np.block([[np.zeros((4, 4)), np.eye(4)], [-np.eye(4), np.zeros((4, 4))]])
    W = Z.T @ J @ Z
    assert np.abs(Mo.T @ W @ Mo - W).max() < 1e-12 * np.abs(Mo).max() ** 2


def test_the_default_section_finds_another_point_of_the_same_orbit(double_pendulum, mode):
    q0, v0 = double_pendulum.initial_state(*GUESS)
    v0 = v0 + 0.05 * np.array([np.cos(0.3), np.sin(0.3), 0.0, 0.0])  # off the turning point
    o = fastvi.periodic_orbit(double_pendulum, q0, v0, period=PERIOD, n_steps=100)
    assert o.residual < 1e-12 and np.abs(o.v0).max() > 1e-3  # not the turning point
    # the same orbit: the energy, and monodromies at two of its points are similar matrices
    e0 = double_pendulum.energy(mode.q0, mode.v0)
    assert double_pendulum.energy(o.q0, o.v0) == pytest.approx(e0, abs=1e-9)
    assert np.abs(o.multipliers[:2] - mode.multipliers[:2]).max() < 1e-9


def test_the_pendulum_in_polar_coordinates_has_the_elliptic_integral_period():
    # q = (r, φ): M(q) = diag(m, m r²) moves with q (the ∂(M v)/∂q path);
    # the exact period T(α) = 4 K(sin²(α/2)) / √(g/l)
    pp = models.polar_pendulum()
    alpha = 1.0
    T = 4 * ellipk(np.sin(alpha / 2) ** 2) / np.sqrt(9.81)
    amp = []
    for N in (50, 100):
        o = fastvi.periodic_orbit(pp, [1.0, 0.8], [0.0, 0.0], period=T, n_steps=N, phase=("v", 1))
        assert o.residual < 1e-12 and np.abs(o.multipliers - 1).max() < 1e-6
        amp.append(abs(o.q0[1] - alpha))
    assert amp[1] < 1e-7 and 12 < amp[0] / amp[1] < 20  # measured 1.03e-6 → 6.4e-8


def test_bad_arguments_are_named(double_pendulum):
    q0, v0 = double_pendulum.initial_state(*GUESS)
    run = dict(period=PERIOD, n_steps=100)
    with pytest.raises(ValueError, match="`period`.*whole number of steps"):
        fastvi.periodic_orbit(double_pendulum, q0, v0, period=PERIOD, h=0.03)
    with pytest.raises(ValueError, match="exactly one of `n_steps`"):
        fastvi.periodic_orbit(double_pendulum, q0, v0, period=PERIOD, n_steps=100, h=PERIOD / 100)
    with pytest.raises(ValueError, match="`period` must be positive"):
        fastvi.periodic_orbit(double_pendulum, q0, v0, period=-1.0, n_steps=100)
    with pytest.raises(ValueError, match="`phase` must be"):
        fastvi.periodic_orbit(double_pendulum, q0, v0, phase=("w", 0), **run)
    with pytest.raises(ValueError, match="`phase` index 7"):
        fastvi.periodic_orbit(double_pendulum, q0, v0, phase=("q", 7), **run)
    with pytest.raises(ValueError, match="`save_every`"):
        fastvi.periodic_orbit(double_pendulum, q0, v0, save_every=3, **run)
    rest = double_pendulum.initial_state(0.0, 0.0)
    with pytest.raises(ValueError, match="equilibrium"):
        fastvi.periodic_orbit(double_pendulum, *rest, **run)


def test_newton_failures_raise_with_the_last_iterate(double_pendulum):
    q0, v0 = double_pendulum.initial_state(*GUESS)
    with pytest.raises(fastvi.PeriodicOrbitError, match="did not converge in `max_iter` = 2") as err:
        fastvi.periodic_orbit(double_pendulum, q0, v0, period=PERIOD, n_steps=100, max_iter=2)
    assert 1e-12 < err.value.residual < 1e-2 and err.value.iterations == 2
    assert err.value.q.shape == (4,)
    # shorter than the linear period: the softening mode has no such orbit, only the
    # equilibrium, which is refused rather than returned
    with pytest.raises(fastvi.PeriodicOrbitError, match="equilibrium"):
        fastvi.periodic_orbit(double_pendulum, q0, v0, period=0.9 * T_LIN, n_steps=100,
                              phase=("v", 0))
    # a damped pendulum has no periodic orbit at all
    damped = fastvi.scenes.double_pendulum(damping=0.3)
    with pytest.raises(fastvi.PeriodicOrbitError):
        fastvi.periodic_orbit(damped, q0, v0, period=PERIOD, n_steps=100, phase=("v", 0))


@pytest.mark.parametrize("name,amplitude", [("in-phase", 0.3), ("anti-phase", 0.1)])
def test_multipliers_and_mode_converge_to_scipys_at_order_four(name, amplitude):
    # the brake orbit of the same period in angles, DOP853 with the variational equations
    T, theta_ref, lam_ref, rows = measure(name, amplitude, 1.01, steps=(50, 100, 200))
    assert np.abs(lam_ref[2:] - 1).max() < 1e-6  # the reference is periodic too
    assert np.abs(lam_ref[0] - 1) > 0.1
    for what in ("multipliers", "angles"):
        errs = np.array([getattr(r, what) for r in rows])
        assert errs[-1] < 1e-6
        rates = np.log2(errs[:-1] / errs[1:])
        assert np.all(np.abs(rates - 4) < 0.2), (what, rates)  # measured 3.99 … 4.01
    assert max(r.residual for r in rows) < 1e-13 and max(r.det for r in rows) < 1e-12
