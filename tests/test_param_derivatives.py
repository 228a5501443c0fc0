"""Derivatives of a model's callbacks by its parameters θ (``Model(param_derivatives=...)``).

Every derivative is compared with central differences in each θ_l of the plain callback
(``Model.callback_value``): an independent computation through the other compiled function.
"""

import pickle

import numba
import numpy as np
import pytest

import fastvi
from tests.models import td_potential, td_potential_grad
from fastvi.check import ModelCheckError
from fastvi.kernels.layout import PARAM_SLOTS
from fastvi.scenes import (chain, closed_chain, double_pendulum, four_bar, pendulum,
                           rotary_rod_slider, slider_crank, spherical_pendulum, triple_pendulum)

sp = pytest.importorskip("sympy")
from fastvi.symbolic import model_from_lagrangian, velocities  # noqa: E402


def fd_by_params(model, slot, q, v, t=0.0):
    """``[l] = ∂f/∂θ_l`` of the callback ``slot`` by central differences in θ_l."""
    theta = model.params
    rows = []
    for l in range(theta.shape[0]):
        h = 1e-6 * max(1.0, abs(theta[l]))
        up, down = theta.copy(), theta.copy()
        up[l] += h
        down[l] -= h
        rows.append((model.callback_value(slot, q, v, params=up, t=t)
                     - model.callback_value(slot, q, v, params=down, t=t)) / (2 * h))
    return np.array(rows)


def assert_matches_differences(model, q, v, t=0.0):
    """Every slot the model has a derivative by θ for, against differences; returns them."""
    for slot in model.param_derivatives:
        exact = model.param_derivative_value(slot, q, v, t=t)
        ref = fd_by_params(model, slot, q, v, t)
        assert exact.shape == (model.params.shape[0],) + model.output_shape(slot)
        scale = max(1.0, np.abs(ref).max())
        assert np.abs(exact - ref).max() <= 1e-7 * scale, slot
    return model.param_derivatives


# ----------------------------------------------------------------------------- scenes
SCENES = {
    "pendulum": lambda: pendulum(m=1.3, l=0.9, g=9.7),
    "double_pendulum": lambda: double_pendulum(m1=1.2, m2=0.7, l1=0.8, l2=1.1),
    "double_pendulum-damped": lambda: double_pendulum(m1=1.2, m2=0.7, damping=0.3),
    "triple_pendulum": lambda: triple_pendulum(m=(1.0, 2.0, 0.5), l=(1.0, 0.7, 1.2)),
    "chain4-damped": lambda: chain(4, m=(1.0, 2.0, 0.5, 1.5), damping=0.2),
    "spherical_pendulum": lambda: spherical_pendulum(m=1.3, l=0.9, g=9.7),
    "four_bar": lambda: four_bar(mB=1.2, mC=0.7, a=0.8, L=1.3),
    "closed_chain6": lambda: closed_chain(6, m=1.1, l=0.9, d=3.0),
    "rotary_rod_slider": lambda: rotary_rod_slider(l=1.7, mA=2.5, mB=4.0, k=800.0, r0=0.9),
    "slider_crank": lambda: slider_crank(r=0.35, L=1.1, m_a=0.6, m_c=1.2, m_b=1.7, g=9.7),
}
#: which slots fns holds (in PARAM_SLOTS order: mass, kinetic_grad, potential_grad,
#: constraint, constraint_jacobian, force): a constant M is data, so no mass or kinetic_grad;
#: G moves with θ where a length sits inside it (the four-bar's and closed chain's pivot
#: distance), else it is declared 0; the damping force moves with c; the rod–slider's mass
#: function moves, its constraint φ − θ does not (declared 0)
GIVEN = {"pendulum": [0, 0, 1, 1, 0, 0], "double_pendulum": [0, 0, 1, 1, 0, 0],
         "double_pendulum-damped": [0, 0, 1, 1, 0, 1], "triple_pendulum": [0, 0, 1, 1, 0, 0],
         "chain4-damped": [0, 0, 1, 1, 0, 1], "spherical_pendulum": [0, 0, 1, 1, 0, 0],
         "four_bar": [0, 0, 1, 1, 1, 0], "closed_chain6": [0, 0, 1, 1, 1, 0],
         "rotary_rod_slider": [1, 1, 1, 0, 0, 0], "slider_crank": [0, 0, 1, 1, 0, 0]}


@pytest.mark.parametrize("name", sorted(SCENES))
def test_scene_derivatives_by_the_parameters_match_differences_and_are_exact(name):
    model = SCENES[name]()
    rng = np.random.default_rng(4)
    q, v = rng.standard_normal(model.n), rng.standard_normal(model.n)
    slots = assert_matches_differences(model, q, v, t=0.4)
    data = model.param_derivative_data()
    assert data.exact == 1 and type(data.exact) is int
    assert data.given.dtype == np.int64 and data.given.tolist() == GIVEN[name]
    assert "constraint_jacobian" in slots  # given, or declared 0: still covered
    if not GIVEN[name][PARAM_SLOTS.index("constraint_jacobian")]:
        assert not model.param_derivative_value("constraint_jacobian", q).any()
    assert model.check(q, v, n_random=1).ok and model.param_derivatives_checked


# ----------------------------------------------------------------------------- symbolic models
@pytest.fixture(scope="module")
def spring_pendulum():
    """An elastic pendulum in polar coordinates: M = diag(m, m r²) depends on q and θ."""
    r, phi = sp.symbols("r phi")
    m, k, l, g = sp.symbols("m k l g", positive=True)
    return model_from_lagrangian([r, phi], sp.diag(m, m * r**2),
                                 k * (r - l) ** 2 / 2 - m * g * r * sp.cos(phi),
                                 params={m: 0.7, k: 30.0, l: 1.3, g: 9.81}, name="spring_pendulum")


@pytest.fixture(scope="module")
def curve():
    """A bead on a sphere cut by a saddle: G depends on θ (through c) and ∇V does too."""
    x, y, z = sp.symbols("x y z")
    mass, l, c, g = sp.symbols("mass l c g", positive=True)
    return model_from_lagrangian([x, y, z], sp.eye(3) * mass, mass * g * z + x**2 * y**2,
                                 [(x**2 + y**2 + z**2 - l**2) / 2, z - c * x * y],
                                 params={mass: 1.5, l: 1.2, c: 0.4, g: 9.81}, name="curve")


def test_symbolic_q_dependent_mass_generates_every_derivative_by_the_parameters(spring_pendulum):
    model = spring_pendulum
    assert "def mass_by_params" in model.source and "def kinetic_grad_by_params" in model.source
    q, v = np.array([1.1, 0.7]), np.array([0.2, -0.4])
    assert assert_matches_differences(model, q, v) == {"mass", "kinetic_grad", "potential_grad"}
    data = model.param_derivative_data()
    assert data.exact == 1 and data.given.tolist() == [1, 1, 1, 0, 0, 0]
    # M is linear in m: ∂M/∂m = diag(1, r²)
    assert np.array_equal(model.param_derivative_value("mass", q)[0], np.diag([1.0, 1.1**2]))


def test_symbolic_constrained_model_generates_constraint_derivatives(curve):
    q, v = np.array([0.6, -0.5, 0.8]), np.array([0.1, 0.2, -0.3])
    assert assert_matches_differences(curve, q, v) == {"potential_grad", "constraint",
                                                        "constraint_jacobian"}
    data = curve.param_derivative_data()
    assert data.exact == 1 and data.given.tolist() == [0, 0, 1, 1, 1, 0]
    assert curve.check(q, v, n_random=1).ok


def test_the_linearised_steps_output_of_a_derivative_by_theta_fits_the_models_largest(
        curve, spring_pendulum):
    """The buffer a derivative callback by θ writes into holds the largest ``out`` of the
    model's own derivatives (the shapes of ``Model``'s table): k × n × n where ∂M/∂θ is
    given, k × m × n where ∂G/∂θ is, else k × n or k × m. It held k × n² whatever the
    model: a gigabyte for a chain of 256 links, whose M and G do not depend on θ."""
    from fastvi.kernels.tangent import make_tangent_work

    meth = fastvi.tables.method("P2L-Q3G")
    # chain(4): ∂(∇V)/∂θ, ∂F/∂θ (10, 8), ∂g/∂θ (10, 4); spring pendulum: ∂M/∂θ (4, 2, 2);
    # curve: ∂G/∂θ (4, 2, 3)
    for model, size in ((chain(4, damping=0.3), 10 * 8), (spring_pendulum, 4 * 2 * 2),
                        (curve, 4 * 2 * 3)):
        k = model.params.shape[0]
        tw = make_tangent_work(model.n, model.m, meth.s, meth.r, meth.J, 1, list(range(k)),
                               model.param_derivative_data(), k)
        assert tw.tho.shape == (size,), model.name


def test_symbolic_derivatives_by_the_parameters_declare_their_structural_non_zeros(curve, spring_pendulum):
    rng = np.random.default_rng(4)
    for model, slots in ((curve, {"potential_grad", "constraint"}),
                         (spring_pendulum, {"kinetic_grad", "potential_grad"})):
        assert set(model.param_patterns) == slots
        q, v = rng.uniform(0.3, 1.2, model.n), rng.uniform(-1.0, 1.0, model.n)
        for slot, mask in model.param_patterns.items():
            assert (np.abs(fd_by_params(model, slot, q, v)) > 1e-9).tolist() == mask.tolist(), slot
            body = model.source.split(f"def {slot}_by_params")[1].split("\ndef ")[0]
            assert "= 0.0" not in body  # writes the pattern only, no zero fill
        back = pickle.loads(pickle.dumps(model))
        assert {s: m.tolist() for s, m in back.param_patterns.items()} == \
            {s: m.tolist() for s, m in model.param_patterns.items()}


def test_symbolic_model_declares_zero_where_no_callback_moves_with_the_parameters():
    x, y = sp.symbols("x y")
    m, g = sp.symbols("m g", positive=True)
    model = model_from_lagrangian([x, y], sp.eye(2) * m, m * g * y, [(x**2 + y**2 - 1) / 2],
                                  params={m: 1.0, g: 9.81}, compile=False)
    assert "constraint_by_params = 0" in model.source
    assert "constraint_jacobian_by_params = 0" in model.source
    assert model.param_derivatives == {"potential_grad", "constraint", "constraint_jacobian"}
    assert model.param_derivative_data().exact == 1
    assert not model.param_derivative_value("constraint", np.array([0.6, -0.8])).any()
    plain = model_from_lagrangian([x, y], sp.eye(2) * m, m * g * y, params={m: 1.0, g: 9.81},
                                  param_derivatives=False, compile=False)
    assert plain.param_derivatives == frozenset() and "_by_params" not in plain.source


# ----------------------------------------------------------------------------- user models
# params = (k1, k2, a, c): V = ½ k1 x² + ½ k2 (y − a sin t)², F = −c (x², 1) ⊙ v
def td_potential_grad_by_params(t, q, p, out):
    out[:, :] = 0.0
    out[0, 0] = q[0]
    out[1, 1] = q[1] - p[2] * np.sin(t)
    out[2, 1] = -p[1] * np.sin(t)


def td_force(t, q, v, p, out):
    out[0] = -p[3] * q[0] ** 2 * v[0]
    out[1] = -p[3] * v[1]


def td_force_by_params(t, q, v, p, out):
    out[:, :] = 0.0
    out[3, 0] = -q[0] ** 2 * v[0]
    out[3, 1] = -v[1]


def time_dependent_model(**given):
    by_params = dict(potential_grad=td_potential_grad_by_params, force=td_force_by_params)
    return fastvi.Model(2, params=(2.0, 3.0, 0.5, 0.1), mass=[1.0, 2.0], potential=td_potential,
                        potential_grad=td_potential_grad, force=td_force, time_dependent=True,
                        param_derivatives={**by_params, **given}, name="td")


def test_time_dependent_potential_and_force_take_the_time_first():
    model = time_dependent_model()
    q, v = np.array([0.4, -0.3]), np.array([0.5, 0.2])
    for t in (0.0, 1.1):
        assert_matches_differences(model, q, v, t)
    assert model.param_derivative_data().exact == 1
    moved = model.param_derivative_value("potential_grad", q, t=1.1)
    assert moved[2, 1] == pytest.approx(-3.0 * np.sin(1.1), rel=1e-14)


def test_model_without_param_derivatives_falls_back_and_shares_the_numba_type(double_pendulum):
    model = fastvi.Model(2, params=(2.0, 3.0, 0.5, 0.1), mass=[1.0, 2.0], potential=td_potential,
                         potential_grad=td_potential_grad, force=td_force, time_dependent=True)
    data = model.param_derivative_data()
    assert data.exact == 0 and not data.given.any() and model.param_derivatives == frozenset()
    assert numba.typeof(data) == numba.typeof(double_pendulum.param_derivative_data())
    assert numba.typeof(data.fns) == numba.typeof(model.kernel_data().fns[:len(PARAM_SLOTS)])
    with pytest.raises(ValueError, match="given: none"):
        model.param_derivative_value("potential_grad", np.zeros(2))
    partial = time_dependent_model()
    partial = fastvi.Model(2, params=partial.params, mass=[1.0, 2.0], potential=td_potential,
                           potential_grad=td_potential_grad, force=td_force, time_dependent=True,
                           param_derivatives=dict(potential_grad=td_potential_grad_by_params))
    assert partial.param_derivative_data().exact == 0  # the force is not covered
    assert partial.param_derivative_data().given.tolist() == [0, 0, 1, 0, 0, 0]


def test_derivatives_by_the_parameters_compile_only_when_asked(pendulum):
    model = time_dependent_model()
    model.kernel_arguments()
    model.check(np.array([0.4, -0.3]), param_derivatives=False)
    assert model._param_data is None and not model.param_derivatives_checked
    model.check(np.array([0.4, -0.3]))
    assert model._param_data is not None and model.param_derivatives_checked


# ----------------------------------------------------------------------------- validation
@pytest.mark.parametrize("given, error, match", [
    ({"potential": td_potential_grad_by_params}, ValueError, "unknown slot 'potential'.*mass, kinetic_grad"),
    ({"mass": td_potential_grad_by_params}, ValueError, "mass matrix is constant"),
    ({"constraint": 0}, ValueError, "m = 0"),
    ({"kinetic_grad": 0}, ValueError, "no `kinetic_grad`"),
    ({"force": 1.0}, TypeError, "function or 0"),
])
def test_bad_param_derivatives_are_rejected_by_name(given, error, match):
    with pytest.raises(error, match=match):
        time_dependent_model(**given)


def test_param_derivatives_need_parameters_force_and_scleronomic_constraints():
    base = dict(mass=[1.0, 1.0], potential=lambda q, p: 0.0, potential_grad=lambda q, p, o: None)
    with pytest.raises(ValueError, match="no parameters"):
        fastvi.Model(2, param_derivatives={"potential_grad": 0}, **base)
    with pytest.raises(ValueError, match="no `force`"):
        fastvi.Model(2, params=(1.0,), param_derivatives={"force": 0}, **base)
    with pytest.raises(ValueError, match="time_dependent model with constraints"):
        fastvi.Model(2, 1, params=(1.0,), mass=[1.0, 1.0], potential=td_potential,
                     potential_grad=td_potential_grad, constraint=lambda t, q, p, o: None,
                     constraint_jacobian=lambda t, q, p, o: None, time_dependent=True,
                     param_derivatives={"potential_grad": 0})
    with pytest.raises(TypeError, match="mapping"):
        fastvi.Model(2, params=(1.0,), param_derivatives=["potential_grad"], **base)


# ----------------------------------------------------------------------------- the check
def wrong_sign_by_params(t, q, p, out):
    out[:, :] = 0.0
    out[0, 0] = -q[0]  # the sign
    out[1, 1] = q[1] - p[2] * np.sin(t)
    out[2, 1] = -p[1] * np.sin(t)


def too_long_by_params(t, q, p, out):
    for i in range(5):
        for j in range(2):
            out[i, j] = 0.0


def test_check_names_a_wrong_derivative_by_the_parameters():
    q = np.array([0.4, -0.3])
    with pytest.raises(ModelCheckError) as err:
        time_dependent_model(potential_grad=wrong_sign_by_params).check(q)
    assert err.value.callback == "potential_grad/θ"
    with pytest.raises(ModelCheckError) as err:  # declared 0, but the force moves with c
        time_dependent_model(force=0).check(q)
    assert err.value.callback == "force/θ"
    with pytest.raises(ModelCheckError, match="wrote past the end"):
        time_dependent_model(potential_grad=too_long_by_params).check(q)


def test_a_wrong_derivative_by_the_parameters_is_pinned_alike_in_blocks(monkeypatch):
    q = np.array([0.4, -0.3])
    wrong = {}
    for budget in (fastvi.check.FD_BLOCK_BYTES, 1):  # all parameters at once; one a block
        monkeypatch.setattr(fastvi.check, "FD_BLOCK_BYTES", budget)
        for slot, model in (("potential_grad", time_dependent_model(potential_grad=wrong_sign_by_params)),
                            ("force", time_dependent_model(force=0))):
            row = model.check(q, raise_on_error=False).worst(f"{slot}/θ")
            wrong.setdefault(slot, []).append((row.status, row.index, row.error, row.allowed))
    for slot, (whole, blocks) in wrong.items():
        assert whole == blocks and whole[0] == "wrong", (slot, whole, blocks)
    assert wrong["force"][0][1][0] == 3  # ∂F/∂θ_3 (F = −θ_3 …): found past the first block


# ----------------------------------------------------------------------------- pickling
def test_models_pickle_with_their_derivatives_by_the_parameters(spring_pendulum):
    q, v = np.array([0.4, -0.3]), np.array([0.5, 0.2])
    for model in (time_dependent_model(), spring_pendulum, double_pendulum(damping=0.3)):
        q0 = np.resize(q, model.n)
        v0 = np.resize(v, model.n)
        back = pickle.loads(pickle.dumps(model))
        assert back.param_derivatives == model.param_derivatives
        for slot in model.param_derivatives:
            assert np.array_equal(back.param_derivative_value(slot, q0, v0, t=0.7),
                                  model.param_derivative_value(slot, q0, v0, t=0.7))
