"""A constant mass matrix that is only positive semidefinite, definite on ker G.

The model: a pendulum (mass m at (x, y), rod l) carrying a massless point (u, w) rigidly at
the offset (c, 0), so ``M = diag(m, m, 0, 0)``: singular, but definite on the tangent space
of the three constraints. Its motion is the simple pendulum's, which SciPy integrates in the
angle at tight tolerance; a variant with a pivot moving as ``A sin ωt`` checks rheonomic
constraints. The step never inverts M (``M + Gᵀ W G`` in the iteration and the momentum
projection), so the converged step must solve the residual written with M itself.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fastvi

from . import reference
from .kernel_helpers import one_step

M_, G_, L_, C_ = 1.3, 9.81, 0.8, 0.5
A_, W_ = 0.05, 7.0  # the moving pivot: x_p = A sin(W t)


def _V(q, p):
    return p[0] * p[1] * q[1]


def _dV(q, p, out):
    out[:] = 0.0
    out[1] = p[0] * p[1]


def _g(q, p, out):
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] - p[2] * p[2])
    out[1] = q[2] - q[0] - p[3]
    out[2] = q[3] - q[1]


def _G(q, p, out):
    out[:, :] = 0.0
    out[0, 0] = q[0]
    out[0, 1] = q[1]
    out[1, 0] = -1.0
    out[1, 2] = 1.0
    out[2, 1] = -1.0
    out[2, 3] = 1.0


def _H(q, eta, p, out):
    out[:, :] = 0.0
    out[0, 0] = eta[0]
    out[1, 1] = eta[0]


def _g_free(q, p, out):  # the massless point's w left free: singular on ker G
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] - p[2] * p[2])
    out[1] = q[2] - q[0] - p[3]


def _G_free(q, p, out):
    out[:, :] = 0.0
    out[0, 0] = q[0]
    out[0, 1] = q[1]
    out[1, 0] = -1.0
    out[1, 2] = 1.0


def _V_t(t, q, p):
    return p[0] * p[1] * q[1]


def _dV_t(t, q, p, out):
    out[:] = 0.0
    out[1] = p[0] * p[1]


def _g_t(t, q, p, out):
    dx = q[0] - p[4] * np.sin(p[5] * t)
    out[0] = 0.5 * (dx * dx + q[1] * q[1] - p[2] * p[2])
    out[1] = q[2] - q[0] - p[3]
    out[2] = q[3] - q[1]


def _G_t(t, q, p, out):
    out[:, :] = 0.0
    out[0, 0] = q[0] - p[4] * np.sin(p[5] * t)
    out[0, 1] = q[1]
    out[1, 0] = -1.0
    out[1, 2] = 1.0
    out[2, 1] = -1.0
    out[2, 3] = 1.0


def _gt_t(t, q, p, out):
    out[:] = 0.0
    out[0] = -(q[0] - p[4] * np.sin(p[5] * t)) * p[4] * p[5] * np.cos(p[5] * t)


def _H_t(t, q, eta, p, out):
    out[:, :] = 0.0
    out[0, 0] = eta[0]
    out[1, 1] = eta[0]


MASS = np.diag([M_, M_, 0.0, 0.0])


def _follower():
    return fastvi.Model(4, 3, params=[M_, G_, L_, C_], mass=MASS, potential=_V, potential_grad=_dV,
                        potential_hessian=0, constraint=_g, constraint_jacobian=_G,
                        constraint_hessian=_H, name="pendulum with a massless follower")


def _driven_follower():
    return fastvi.Model(4, 3, params=[M_, G_, L_, C_, A_, W_], mass=MASS, potential=_V_t,
                        potential_grad=_dV_t, potential_hessian=0, constraint=_g_t,
                        constraint_jacobian=_G_t, constraint_hessian=_H_t, time_dependent=True,
                        constraint_time_derivative=_gt_t,
                        name="driven pendulum with a massless follower")


def _state(theta, omega, xp=0.0, vp=0.0):
    x, y = xp + L_ * np.sin(theta), -L_ * np.cos(theta)
    vx, vy = vp + L_ * np.cos(theta) * omega, L_ * np.sin(theta) * omega
    return np.array([x, y, x + C_, y]), np.array([vx, vy, vx, vy])


def _theta_reference(theta0, omega0, T, driven=False):
    def rhs(t, y):
        acc = -A_ * W_ * W_ * np.sin(W_ * t) if driven else 0.0
        return [y[1], -(G_ / L_) * np.sin(y[0]) - acc / L_ * np.cos(y[0])]
    sol = solve_ivp(rhs, (0.0, T), [theta0, omega0], method="DOP853", rtol=1e-13, atol=1e-14)
    return sol.y[0, -1]


def test_a_singular_mass_is_accepted_with_constraints_and_refused_without():
    assert _follower().mass_singular
    with pytest.raises(ValueError, match=r"`mass` is singular \(zero along coordinates \[2, 3\]\)"):
        fastvi.Model(4, 0, params=[M_, G_, L_, C_], mass=MASS, potential=_V, potential_grad=_dV)
    with pytest.raises(ValueError, match="`mass` must be positive definite, or positive semidefinite"):
        fastvi.Model(4, 3, params=[M_, G_, L_, C_], mass=np.diag([M_, M_, -1.0, 0.0]), potential=_V,
                     potential_grad=_dV, constraint=_g, constraint_jacobian=_G)


def test_a_mass_singular_on_the_tangent_space_is_refused_naming_the_coordinate():
    model = fastvi.Model(4, 2, params=[M_, G_, L_, C_], mass=MASS, potential=_V, potential_grad=_dV,
                         constraint=_g_free, constraint_jacobian=_G_free)
    q0, v0 = _state(0.4, 0.0)
    with pytest.raises(ValueError, match=r"singular on the tangent space.*\['q\[3\]'\]"):
        fastvi.integrate(model, q0, v0, h=0.01, n_steps=2)


@pytest.mark.parametrize("name", ["P1L-Q2G", "P2L-Q3G", "P3L-Q4G"])
def test_the_converged_step_solves_the_residual_of_the_singular_mass(name):
    """The iteration inverts M + Gᵀ W G, the NumPy twin writes the equations with M: the
    converged unknowns must solve the latter, and the end state satisfy G v1 = 0, p1 = M v1."""
    model, meth, h = _follower(), fastvi.method(name), 0.05
    q, v = _state(0.9, 1.7)
    st, q1, p1, v1, _, ws = one_step(model, meth, h, q, MASS @ v, v)
    assert st == 0
    R = reference.residual(model, meth, h, q, MASS @ v, ws.X)
    assert np.abs(R).max() <= 1e-13
    G1 = model.constraint_jacobian_value(q1)
    assert np.abs(G1 @ v1).max() <= 1e-14
    assert np.allclose(p1, MASS @ v1, rtol=0, atol=1e-14)


@pytest.mark.parametrize("name,s", [("P1L-Q2G", 1), ("P2L-Q3G", 2), ("P3L-Q4G", 3)])
def test_a_singular_mass_keeps_the_order_constraints_and_energy(name, s):
    theta0, omega0, T = 1.2, 0.0, 2.0
    ref = _theta_reference(theta0, omega0, T)
    q0, v0 = _state(theta0, omega0)
    model = _follower()
    errors = []
    steps = {1: (100, 200), 2: (25, 50), 3: (20, 40)}[s]
    for N in steps:
        res = fastvi.integrate(model, q0, v0, h=T / N, n_steps=N, method=name)
        x, y = res.q[-1, 0], res.q[-1, 1]
        errors.append(abs(np.arctan2(x, -y) - ref))
        assert res.constraint_residual.max() <= 1e-14
        assert res.velocity_residual.max() <= 1e-13
    order = np.log2(errors[0] / errors[1])
    assert abs(order - 2 * s) < 0.2, (errors, order)
    # energy: bounded, no drift over 20 000 steps
    res = fastvi.integrate(model, q0, v0, h=0.05, n_steps=20_000, method=name, save_every=100)
    err = np.abs(res.energy_error)
    half = len(err) // 2
    assert err[half:].max() <= 1.5 * err[:half].max() + 1e-13


def test_a_singular_mass_with_a_driven_constraint_follows_the_driven_pendulum():
    """Rheonomic constraints: the momentum of the singular mass is M v1, whose multiplier
    differs from that of M + Gᵀ W G by W g_t (fastvi.kernels.step.end_momentum)."""
    theta0, omega0, T = 0.3, 0.0, 1.0
    ref = _theta_reference(theta0, omega0, T, driven=True)
    q0, v0 = _state(theta0, omega0, 0.0, A_ * W_)
    model = _driven_follower()
    errors = []
    for N in (40, 80):
        res = fastvi.integrate(model, q0, v0, h=T / N, n_steps=N, method="P2L-Q3G")
        x, y = res.q[-1, 0] - A_ * np.sin(W_ * T), res.q[-1, 1]
        errors.append(abs(np.arctan2(x, -y) - ref))
        assert res.constraint_residual.max() <= 1e-14
        assert res.velocity_residual.max() <= 1e-12
        assert np.allclose(res.p[-1], MASS @ res.v[-1], rtol=0, atol=1e-13)
    assert abs(np.log2(errors[0] / errors[1]) - 4.0) < 0.25, errors
