"""The rotary rod–slider scene: the configuration-dependent mass-matrix path, checked against
an independent reference (SciPy DOP853 on hand-written equations in the minimal coordinates
(θ, r)) and against the same mechanism written in Cartesian coordinates with a constant
mass matrix."""

import importlib
import pickle

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fastvi
from fastvi.baselines import rk4
from fastvi.baselines.rk4 import acceleration, make_workspace
from fastvi.studies.convergence import observed_order

# the scene function shadows its module as an attribute of fastvi.scenes
slider_module = importlib.import_module("fastvi.scenes.rotary_rod_slider")

L, MA, MB, K, R0, G = 2.0, 2.0, 5.0, 1000.0, 1.0, 9.81
I_O = MA * L * L / 3.0


def minimal_rhs(t, y):
    """Euler–Lagrange equations in (θ, r), written from T and V by hand (not from fastvi)."""
    th, r, thd, rd = y
    thdd = (-2.0 * MB * r * rd * thd - (MA * G * L / 2 + MB * G * r) * np.cos(th)) / (I_O + MB * r * r)
    rdd = r * thd * thd - G * np.sin(th) - K / MB * (r - R0)
    return [thd, rd, thdd, rdd]


def minimal_reference(theta0, r0, omega0, rdot0, t_eval):
    sol = solve_ivp(minimal_rhs, (0.0, t_eval[-1]), [theta0, r0, omega0, rdot0], method="DOP853",
                    rtol=1e-13, atol=1e-13, t_eval=t_eval)
    return sol.y.T


# ------------------------------------------------ the same slider, Cartesian, constant mass
# q = (θ, x, y): rod angle and the slider's Cartesian position; constraint x sin θ − y cos θ = 0
# (B on the line of the rod); second derivatives left to fastvi's finite differences.
# params = (l, mA, mB, k, r0, g)


def _c_V(q, p):
    rho = np.sqrt(q[1] * q[1] + q[2] * q[2])
    return p[1] * p[5] * 0.5 * p[0] * np.sin(q[0]) + p[2] * p[5] * q[2] + 0.5 * p[3] * (rho - p[4]) ** 2


def _c_dV(q, p, out):
    rho = np.sqrt(q[1] * q[1] + q[2] * q[2])
    f = p[3] * (rho - p[4]) / rho
    out[0] = p[1] * p[5] * 0.5 * p[0] * np.cos(q[0])
    out[1] = f * q[1]
    out[2] = p[2] * p[5] + f * q[2]


def _c_g(q, p, out):
    out[0] = q[1] * np.sin(q[0]) - q[2] * np.cos(q[0])


def _c_G(q, p, out):
    s, c = np.sin(q[0]), np.cos(q[0])
    out[0, 0] = q[1] * c + q[2] * s
    out[0, 1] = s
    out[0, 2] = -c


@pytest.fixture(scope="module")
def cartesian_slider():
    return fastvi.Model(3, 1, params=(L, MA, MB, K, R0, G), mass=np.diag([I_O, MB, MB]),
                        potential=_c_V, potential_grad=_c_dV, constraint=_c_g,
                        constraint_jacobian=_c_G, name="cartesian_slider")


@pytest.fixture(scope="module")
def slider():
    return fastvi.scenes.rotary_rod_slider()


P = np.array([L, MA, MB, K, R0, G])


def _fd(f, q, eps=1e-6):
    """Central differences of a vector function of q, column b = ∂f/∂q_b."""
    cols = []
    for b in range(len(q)):
        dq = np.zeros_like(q)
        dq[b] = eps
        cols.append((np.asarray(f(q + dq)) - np.asarray(f(q - dq))) / (2 * eps))
    return np.array(cols).T


def _out(fn, *args, shape):
    out = np.zeros(shape)
    fn(*args, out)
    return out


def test_scene_derivatives_match_finite_differences():
    rng = np.random.default_rng(3)
    q = np.array([0.7, 1.3, 0.7]) + 0.1 * rng.standard_normal(3)
    v = rng.standard_normal(3)

    def T(qq):
        M = _out(slider_module._mass, qq, P, shape=(3, 3))
        return 0.5 * v @ M @ v

    grad_V = _fd(lambda x: [slider_module._V(x, P)], q)[0]
    np.testing.assert_allclose(_out(slider_module._dV, q, P, shape=3), grad_V, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(_out(slider_module._ddV, q, P, shape=(3, 3)),
                               _fd(lambda x: _out(slider_module._dV, x, P, shape=3), q), atol=1e-5)
    np.testing.assert_allclose(_out(slider_module._dT, q, v, P, shape=3), _fd(lambda x: [T(x)], q)[0],
                               atol=1e-7)
    np.testing.assert_allclose(_out(slider_module._ddT, q, v, P, shape=(3, 3)),
                               _fd(lambda x: _out(slider_module._dT, x, v, P, shape=3), q), atol=1e-6)
    Mv = lambda x: _out(slider_module._mass, x, P, shape=(3, 3)) @ v  # noqa: E731
    np.testing.assert_allclose(_out(slider_module._dMv, q, v, P, shape=(3, 3)), _fd(Mv, q), atol=1e-7)
    np.testing.assert_allclose(_out(slider_module._G, q, P, shape=(1, 3)),
                               _fd(lambda x: _out(slider_module._g, x, P, shape=1), q), atol=1e-9)


def test_index1_acceleration_matches_minimal_coordinates(slider):
    """The constrained, q-dependent-mass equations reduce to the hand-written (θ, r) ones."""
    rng = np.random.default_rng(7)
    fns, flags, Mc = slider.kernel_arguments()
    ws = make_workspace(3, 1)
    for _ in range(5):
        th, r, thd, rd = rng.uniform(-3, 3), rng.uniform(0.5, 1.8), rng.normal(), rng.normal()
        a = np.zeros(3)
        assert acceleration(fns, flags, Mc, slider.params, np.array([th, r, th]),
                            np.array([thd, rd, thd]), a, ws) == 0
        ref = minimal_rhs(0, [th, r, thd, rd])
        np.testing.assert_allclose(a, [ref[2], ref[3], ref[2]], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("method, order", [("P1L-Q2G", 2), ("P2L-Q3G", 4)])
def test_slider_converges_to_minimal_reference_at_the_method_order(slider, method, order):
    T = 1.0
    ref = minimal_reference(0.0, R0, 0.0, 0.0, [T])[-1]
    hs = np.array([0.02, 0.01, 0.005])
    errs = []
    for h in hs:
        res = fastvi.integrate(slider, *slider.initial_state(), h=h, t_end=T, method=method)
        q, v = res.q[-1], res.v[-1]
        errs.append(np.max(np.abs(np.array([q[0], q[1], v[0], v[1]]) - ref)))
    got, used = observed_order(hs, errs)
    assert used.sum() == 3
    assert abs(got - order) < 0.25  # measured 1.91 (P1L-Q2G), 4.00 (P2L-Q3G)


def test_slider_constraint_residual_stays_at_roundoff(slider):
    """Paper B's run: P1L-Q2G, h = 0.01, T = 100 s (10^4 steps)."""
    res = fastvi.integrate(slider, *slider.initial_state(), h=0.01, t_end=100.0, method="P1L-Q2G")
    assert res.success
    assert np.max(res.constraint_residual) < 1e-14  # measured 4.4e-16
    assert np.max(res.velocity_residual) < 1e-14  # measured 4.4e-16
    assert np.max(np.abs(res.energy_error)) < 5e-3  # measured 2.5e-3: bounded, order 2


def test_q_dependent_mass_path_agrees_with_cartesian_constant_mass_variant(slider, cartesian_slider):
    """Two codings of one mechanism, integrated by P2L-Q3G, meet at the method's accuracy."""
    T = 1.0
    t_ref = np.linspace(0.0, T, 11)
    ref = minimal_reference(0.0, R0, 0.0, 0.0, t_ref)
    x_ref, y_ref = ref[:, 1] * np.cos(ref[:, 0]), ref[:, 1] * np.sin(ref[:, 0])
    diffs, errs_cart = [], []
    for h in (0.01, 0.005):
        every = round(0.1 / h)
        a = fastvi.integrate(slider, *slider.initial_state(), h=h, t_end=T, save_every=every)
        b = fastvi.integrate(cartesian_slider, np.array([0.0, R0, 0.0]), np.zeros(3), h=h,
                             t_end=T, save_every=every)
        xa, ya = slider.slider_position(a.q)
        diffs.append(max(np.max(np.abs(xa - b.q[:, 1])), np.max(np.abs(ya - b.q[:, 2])),
                         np.max(np.abs(a.q[:, 0] - b.q[:, 0]))))
        errs_cart.append(max(np.max(np.abs(b.q[:, 1] - x_ref)), np.max(np.abs(b.q[:, 2] - y_ref))))
        assert np.max(np.abs(b.energy_error)) < 1e-6  # measured 3.8e-7 (h = 0.01)
    assert diffs[0] < 1e-7  # measured 2.6e-8
    # the difference is discretisation error: it falls like h^4, as each one's error does
    assert diffs[0] / diffs[1] > 12.0  # measured 16.0
    assert errs_cart[1] < 1e-8  # measured 1.8e-9


def test_energy_parts_sum_to_the_model_energy(slider):
    q = np.array([0.4, 1.2, 0.4])
    v = np.array([0.3, -0.8, 0.3])
    parts = slider.energy_parts(q, v)
    assert sum(parts.values()) == pytest.approx(slider.energy(q, v), rel=1e-14)
    assert slider.mass_matrix(q)[2, 2] == pytest.approx(MB * 1.2**2)  # diag(mA l²/3, mB, mB r²)


def test_initial_state_is_consistent_and_defaults_to_the_documented_start(slider):
    q0, v0 = slider.initial_state()
    np.testing.assert_array_equal(q0, [0.0, R0, 0.0])
    np.testing.assert_array_equal(v0, [0.0, 0.0, 0.0])
    q1, v1 = slider.initial_state(theta=0.3, r=1.1, omega=2.0, r_dot=-1.0)
    assert slider.constraint_value(q1)[0] == 0.0
    assert slider.constraint_jacobian_value(q1) @ v1 == pytest.approx([0.0])


def test_slider_is_registered_and_pickles_as_a_recipe(slider):
    assert fastvi.scenes.SCENES["rotary_rod_slider"] is fastvi.scenes.rotary_rod_slider
    other = pickle.loads(pickle.dumps(fastvi.scenes.rotary_rod_slider(k=500.0)))
    assert other.name == "rotary_rod_slider"
    np.testing.assert_array_equal(other.params, [L, MA, MB, 500.0, R0, G])


@pytest.mark.parametrize("bad", [dict(k=0.0), dict(mB=-1.0), dict(r0=float("nan"))])
def test_rejects_nonpositive_parameters(bad):
    key = next(iter(bad))
    with pytest.raises(ValueError, match=f"`{key}` must be positive and finite"):
        fastvi.scenes.rotary_rod_slider(**bad)


@pytest.mark.slow  # the RK4 kernel's compile (tests/test_baselines.py)
def test_rk4_matches_reference_on_both_codings(slider, cartesian_slider):
    """The RK4 baseline's q-dependent-mass path (slider) and its finite-difference ∇²g path
    (the Cartesian variant gives no constraint Hessian) reach the same reference."""
    T = 1.0
    ref = minimal_reference(0.0, R0, 0.0, 0.0, [T])[-1]
    a = rk4(slider, *slider.initial_state(), h=0.005, t_end=T)
    b = rk4(cartesian_slider, np.array([0.0, R0, 0.0]), np.zeros(3), h=0.005, t_end=T)
    x, y = ref[1] * np.cos(ref[0]), ref[1] * np.sin(ref[0])
    # both errors fall 16-fold at h/2 (1.2e-9, 3.8e-9): discretisation, not finite differences
    assert abs(a.q[-1, 0] - ref[0]) + abs(a.q[-1, 1] - ref[1]) < 2e-7  # measured 2.0e-8
    assert abs(b.q[-1, 1] - x) + abs(b.q[-1, 2] - y) < 2e-7  # measured 6.1e-8
