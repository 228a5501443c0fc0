"""fastvi.bodies in motion, against exact solutions and independent SciPy references
(tests/bodies_reference.py): orders, the heavy top, Noether's momenta, Bricard's linkage, the
flyball governor's energy balance, and joints whose motion is known in closed form. The
longest, Bricard over 10 s and 10⁵ steps of the fast top, take 4 s and 1.3 s."""

import numpy as np
import pytest

import fastvi
from fastvi import bodies
from fastvi.bodies import outputs as out
from fastvi.bodies import scenes
from fastvi.studies.convergence import observed_order

from .bodies_reference import OpenChain, open_chain_reference, top_reference

#: the heavy top made a little thicker than Brüls' lamina (J₂ = J₁ + J₃ there)
THICK_TOP = (0.234375, 0.4, 0.234375)


# ----------------------------------------------------------------------------- orders
@pytest.mark.parametrize("method, hs", [
    ("P1L-Q2G", (0.02, 0.01, 0.005)),
    ("P2L-Q3G", (0.04, 0.02, 0.01)),
    ("P3L-Q4G", (0.1, 0.05, 0.025)),
])
def test_steady_precession_converges_at_order_2s(method, hs):
    model = scenes.lagrange_top()
    q0, v0 = model.initial_state()
    T = 1.0
    q_exact = model.exact([T])[0][0]
    errors = [np.abs(fastvi.integrate(model, q0, v0, h=h, t_end=T, method=method).q[-1] - q_exact).max()
              for h in hs]
    order, _ = observed_order(hs, errors)
    s = int(method[1])
    assert abs(order - 2 * s) < 0.15, (errors, order)


# ----------------------------------------------------------------------------- tops
def test_heavy_top_against_rotation_matrix_and_euler_equations():
    """Brüls' top (thickened): R(t) and Ω(t) against SciPy on (R, Ω), rtol 1e-12."""
    model = scenes.heavy_top(inertia=THICK_TOP)
    q0, v0 = model.initial_state()
    t_eval = np.array([0.5, 1.0, 1.5, 2.0])
    R_ref, W_ref = top_reference(15.0, THICK_TOP, (0, 1, 0), (0, 150, -4.61538), (0, 0, -9.81),
                                 np.concatenate([[0.0], t_eval]), rtol=1e-12)
    res = fastvi.integrate(model, q0, v0, h=2.5e-4, t_end=2.0, method="P3L-Q4G", save_every=2000)
    assert np.allclose(res.t[1:], t_eval)
    R = out.rotation(model, res, "top")[1:]
    W = out.angular_velocity(model, res, "top", frame="body")[1:]
    assert np.abs(R - R_ref[1:]).max() < 1e-9  # measured 7e-11 (7e-10 at h = 5e-4)
    assert np.abs(W - W_ref[1:]).max() < 1e-8  # |Ω| = 150; measured 3e-10
    assert res.constraint_residual.max() < 1e-13


def test_heavy_top_lamina_against_euler_equations():
    model = scenes.heavy_top()
    q0, v0 = model.initial_state()
    R_ref, _ = top_reference(15.0, scenes.BRULS_INERTIA, (0, 1, 0), (0, 150, -4.61538), (0, 0, -9.81),
                             [0.0, 2.0], rtol=1e-12)
    res = fastvi.integrate(model, q0, v0, h=2.5e-4, t_end=2.0, method="P3L-Q4G", save_every=8000)
    assert model.mass_singular  # E₂ = 0: solved with M + Gᵀ W G, never M⁻¹
    assert np.abs(out.rotation(model, res, "top")[-1] - R_ref[-1]).max() < 1e-9
    assert res.constraint_residual.max() < 1e-13


@pytest.mark.parametrize("method,s,steps", [("P1L-Q2G", 1, (200, 400)), ("P2L-Q3G", 2, (100, 200)),
                                             ("P3L-Q4G", 3, (25, 50))])
def test_heavy_top_lamina_converges_at_order_2s(method, s, steps):
    """The singular mass keeps the method's order: R(T) against SciPy on (R, Ω)."""
    model = scenes.heavy_top()
    q0, v0 = model.initial_state()
    T = 0.1
    R_ref, _ = top_reference(15.0, scenes.BRULS_INERTIA, (0, 1, 0), (0, 150, -4.61538), (0, 0, -9.81),
                             [0.0, T], rtol=1e-13)
    errors = []
    for N in steps:
        res = fastvi.integrate(model, q0, v0, h=T / N, n_steps=N, method=method, save_every=N)
        errors.append(np.abs(out.rotation(model, res, "top")[-1] - R_ref[-1]).max())
        assert res.constraint_residual.max() < 1e-13
    order = np.log2(errors[0] / errors[1])
    assert abs(order - 2 * s) < 0.15, (errors, order)  # measured 2.01, 4.00, 6.00


def test_fast_top_against_euler_equations():
    model = scenes.fast_top()
    q0, v0 = model.initial_state()
    R0 = out.rotation(model, q0, "top")
    R_ref, W_ref = top_reference(20.0, (5.0, 5.0, 1.0), (0, 0, 1.0), (0, 0, 50.0), (0, 0, -1.0),
                                 [0.0, 1.0, 2.0], R0=R0, rtol=1e-12)
    res = fastvi.integrate(model, q0, v0, h=1e-3, t_end=2.0, method="P3L-Q4G", save_every=1000)
    assert np.abs(out.rotation(model, res, "top") - R_ref).max() < 1e-9  # measured 4e-11
    assert np.abs(out.angular_velocity(model, res, "top", frame="body") - W_ref).max() < 1e-9


def _noether(res, model):
    """Angular momentum about the vertical through the fixed point and about the axis d₃."""
    L = out.angular_momentum(model, res)
    d3 = res.q[:, 9:12]
    return L[:, 2], np.einsum("ki,ki->k", L, d3)


def test_symmetric_top_keeps_its_two_momenta_over_1e5_steps():
    """Discrete Noether: rotations about the vertical through the fixed point and about the
    top's axis are symmetries of the discrete Lagrangian and of the constraints."""
    model = scenes.fast_top()
    q0, v0 = model.initial_state()
    res = fastvi.integrate(model, q0, v0, h=2e-3, n_steps=100_000, save_every=100)
    Lz, La = _noether(res, model)
    assert np.abs(Lz - Lz[0]).max() < 1e-12 * abs(La[0])  # J₃Ω₃ = 50; measured 5.4e-12 absolute
    assert np.abs(La - La[0]).max() < 1e-12 * abs(La[0])  # measured 5.4e-12 absolute
    assert abs(res.energy_error).max() < 1e-10 * res.energy[0]  # measured 1.6e-12 relative


# ----------------------------------------------------------------------------- Bricard
def _bricard_reference(t_eval):
    P = scenes.BRICARD_POINTS
    links = [P[0] - P[5]] + [P[k + 1] - P[k] for k in range(5)] + [P[0] - P[5]]
    axes = [np.cross(links[k], links[k + 1]) for k in range(6)]
    m, side = 1.0, 0.1
    Ja, Jt = m * 2 * side ** 2 / 12, m * (1 + side ** 2) / 12
    inertia = []
    for k in range(5):
        d = (P[k + 1] - P[k]) / np.linalg.norm(P[k + 1] - P[k])
        inertia.append(Jt * np.eye(3) + (Ja - Jt) * np.outer(d, d))
    chain = OpenChain(axes[:5], P[:5], [m] * 5, inertia, [0.5 * (P[k] + P[k + 1]) for k in range(5)],
                      (0, -9.81, 0), cut=(P[5], axes[5]), dof=1)
    return open_chain_reference(chain, np.zeros(5), np.zeros(5), t_eval, rtol=1e-12)[1]


def test_bricard_over_10_s_against_joint_coordinates():
    model = scenes.bricard()
    q0, v0 = model.initial_state()
    res = fastvi.integrate(model, q0, v0, h=0.01, t_end=10.0, save_every=10)
    centres = np.stack([out.position(model, res, f"rod{k + 1}") for k in range(5)], axis=1)
    ref = _bricard_reference(res.t)
    assert np.abs(centres - ref).max() < 1e-7  # measured 5.2e-9 (P2L-Q3G, h = 0.01)
    assert res.constraint_residual.max() <= 1e-12
    assert np.abs(res.energy_error).max() < 1e-8  # bounded: measured 7.4e-10


# ----------------------------------------------------------------------------- governor
def test_flyball_governor_energy_balance_at_the_method_error():
    model = scenes.flyball_governor()
    q0, v0 = model.initial_state()
    balances = []
    for h in (2e-3, 1e-3):
        res = fastvi.integrate(model, q0, v0, h=h, t_end=0.4)
        balances.append(np.abs(res.energy_balance).max())
        assert res.constraint_residual.max() < 1e-13
    # measured 2.4e-7 and 1.9e-8 (2.7e-9 at h = 5e-4) on H0 = 239 J; the dampers' work 2.4e-3 J
    assert balances[1] < 1e-9 * res.energy[0] and abs(res.work[-1]) > 1e3 * balances[1]
    assert balances[0] / balances[1] > 6


# ----------------------------------------------------------------------------- closed forms
def test_prismatic_slide_under_gravity_is_exact():
    """A block on an inclined slide: s(t) = ½ g (a·ĝ) t² is a quadratic, which every method
    reproduces to round-off."""
    axis = np.array([1.0, 0.0, -1.0]) / np.sqrt(2)
    mech = bodies.Mechanism(gravity=(0, 0, -9.81))
    blk = mech.body("block", mass=2.0, inertia=(0.2, 0.25, 0.3), position=(0, 0, 0))
    mech.prismatic("ground", blk, point=(0, 0, 0), axis=axis, name="slide")
    model = mech.build()
    q0, v0 = model.initial_state()
    res = fastvi.integrate(model, q0, v0, h=0.01, t_end=1.0)
    exact = 0.5 * 9.81 * (axis @ [0, 0, 1.0]) * -res.t ** 2
    assert np.abs(out.joint_coordinate(model, res, "slide") - exact).max() < 1e-13
    assert np.abs(out.rotation(model, res, "block") - np.eye(3)).max() < 1e-14


def test_fixed_joint_moves_like_one_body():
    """Two bodies welded together against one body with the combined mass and inertia
    (parallel-axis theorem), both swinging on a ball joint."""
    m1, m2 = 1.0, 2.0
    x1, x2 = np.array([0.5, 0.0, 0.0]), np.array([1.0, 0.3, 0.0])
    J1, J2 = np.diag([0.1, 0.2, 0.25]), np.diag([0.3, 0.15, 0.2])
    w = np.array([0.5, -1.0, 2.0])
    mech = bodies.Mechanism(gravity=(0, 0, -9.81))
    b1 = mech.body("b1", mass=m1, inertia=J1, position=x1, omega=w, velocity=np.cross(w, x1))
    b2 = mech.body("b2", mass=m2, inertia=J2, position=x2, omega=w, velocity=np.cross(w, x2))
    mech.spherical("ground", b1, point=(0, 0, 0))
    mech.fixed(b1, b2, point=(0.8, 0.1, 0.0))
    welded = mech.build()
    c = (m1 * x1 + m2 * x2) / (m1 + m2)
    J = sum(Jk + mk * ((xk - c) @ (xk - c) * np.eye(3) - np.outer(xk - c, xk - c))
            for mk, xk, Jk in ((m1, x1, J1), (m2, x2, J2)))
    one = bodies.Mechanism(gravity=(0, 0, -9.81))
    b = one.body("b", mass=m1 + m2, inertia=J, position=c, omega=w, velocity=np.cross(w, c))
    one.spherical("ground", b, point=(0, 0, 0))
    single = one.build()
    r1 = fastvi.integrate(welded, *welded.initial_state(), h=0.005, t_end=1.0)
    r2 = fastvi.integrate(single, *single.initial_state(), h=0.005, t_end=1.0)
    # the welded pair's centre of mass and rotation against the single body's (user frames)
    cw = (m1 * out.position(welded, r1, "b1") + m2 * out.position(welded, r1, "b2")) / (m1 + m2)
    assert np.abs(cw - out.position(single, r2, "b")).max() < 1e-6
    assert np.abs(out.rotation(welded, r1, "b1") - out.rotation(single, r2, "b")).max() < 1e-6


def test_driven_hinge_follows_its_profile_and_balances_energy():
    """A rod swung by a hinge whose angle is prescribed, θ(t) = 0.3 sin(4 t) + t: the
    angle holds to round-off and H − H0 − W stays at the method's error."""
    prof = bodies.Profile(rate=1.0, amplitude=0.3, frequency=4.0)
    mech = bodies.Mechanism(gravity=(0, 0, -9.81))
    rod = mech.body("rod", mass=1.0, inertia=(0.001, 0.08, 0.08), position=(0.5, 0, 0))
    mech.driven_revolute("ground", rod, prof, point=(0, 0, 0), axis=(0, 1, 0), name="motor")
    model = mech.build()
    q0, v0 = model.initial_state()
    res = fastvi.integrate(model, q0, v0, h=0.01, t_end=3.0)
    wrapped = np.angle(np.exp(1j * (out.joint_coordinate(model, res, "motor") - prof(res.t))))
    assert np.abs(wrapped).max() < 1e-13
    assert np.abs(res.energy_balance).max() < 1e-6 * np.abs(res.work).max()
