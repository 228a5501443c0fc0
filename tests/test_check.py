"""Model.check: every supplied derivative is compared with finite differences.

Two small models carry every kind of callback: a pendulum on a spring-loaded cart in
coordinates q = (x, θ) (q-dependent mass: kinetic_grad, kinetic_hessian, momentum_jacobian)
and a point on the curve where a sphere meets the saddle z = c·x·y (two nonlinear
constraints with a nontrivial constraint Hessian, nonlinear potential). Each test that
plants a mistake uses the kind of error people make: a sign, a factor, a transposed or
swapped index, a forgotten term or constraint.
"""

import functools
import importlib
import time

import numpy as np
import pytest

import fastvi
from fastvi.check import CheckReport, check_model
from fastvi.scenes import SCENES
from tests.models import chain_constraint_hessian_dense

CHAIN = importlib.import_module("fastvi.scenes.chain")  # the module: `fastvi.scenes.chain` is its scene

# ----------------------------------------------------------------------------- cart pendulum
# params = (M, m, l, g, k): cart mass, bob mass, rod length, gravity, cart spring stiffness
# T = ½(M+m)ẋ² + m l cosθ ẋθ̇ + ½ m l² θ̇²,  V = ½ k x² − m g l cosθ


def cart_mass(q, p, out):
    c = np.cos(q[1])
    out[0, 0] = p[0] + p[1]
    out[0, 1] = p[1] * p[2] * c
    out[1, 0] = p[1] * p[2] * c
    out[1, 1] = p[1] * p[2] * p[2]


def cart_kinetic_grad(q, v, p, out):
    out[0] = 0.0
    out[1] = -p[1] * p[2] * np.sin(q[1]) * v[0] * v[1]


def cart_kinetic_hessian(q, v, p, out):
    out[:, :] = 0.0
    out[1, 1] = -p[1] * p[2] * np.cos(q[1]) * v[0] * v[1]


def cart_momentum_jacobian(q, v, p, out):
    s = np.sin(q[1])
    out[:, :] = 0.0
    out[0, 1] = -p[1] * p[2] * s * v[1]
    out[1, 1] = -p[1] * p[2] * s * v[0]


def cart_potential(q, p):
    return 0.5 * p[4] * q[0] * q[0] - p[1] * p[3] * p[2] * np.cos(q[1])


def cart_potential_grad(q, p, out):
    out[0] = p[4] * q[0]
    out[1] = p[1] * p[3] * p[2] * np.sin(q[1])


def cart_potential_hessian(q, p, out):
    out[:, :] = 0.0
    out[0, 0] = p[4]
    out[1, 1] = p[1] * p[3] * p[2] * np.cos(q[1])


# planted mistakes
def bad_mass_not_symmetric(q, p, out):  # forgot the lower triangle
    out[0, 0] = p[0] + p[1]
    out[0, 1] = p[1] * p[2] * np.cos(q[1])
    out[1, 0] = 0.0
    out[1, 1] = p[1] * p[2] * p[2]


def bad_kinetic_grad_sign(q, v, p, out):  # d(cos)/dθ = +sin
    out[0] = 0.0
    out[1] = p[1] * p[2] * np.sin(q[1]) * v[0] * v[1]


def bad_kinetic_hessian_sign(q, v, p, out):
    out[:, :] = 0.0
    out[1, 1] = p[1] * p[2] * np.cos(q[1]) * v[0] * v[1]


def bad_momentum_jacobian_transposed(q, v, p, out):  # [b, a] instead of [a, b]
    s = np.sin(q[1])
    out[:, :] = 0.0
    out[1, 0] = -p[1] * p[2] * s * v[1]
    out[1, 1] = -p[1] * p[2] * s * v[0]


def bad_potential_grad_missing_term(q, p, out):  # forgot the spring
    out[0] = 0.0
    out[1] = p[1] * p[3] * p[2] * np.sin(q[1])


def bad_potential_grad_spring_sign(q, p, out):  # wrong only where x != 0
    out[0] = -p[4] * q[0]
    out[1] = p[1] * p[3] * p[2] * np.sin(q[1])


def bad_potential_hessian_factor(q, p, out):  # d²(½kx²)/dx² "= 2k"
    out[:, :] = 0.0
    out[0, 0] = 2.0 * p[4]
    out[1, 1] = p[1] * p[3] * p[2] * np.cos(q[1])


CART = dict(mass=cart_mass, kinetic_grad=cart_kinetic_grad, kinetic_hessian=cart_kinetic_hessian,
            momentum_jacobian=cart_momentum_jacobian, potential=cart_potential,
            potential_grad=cart_potential_grad, potential_hessian=cart_potential_hessian)
CART_PARAMS = (2.0, 1.0, 0.8, 9.81, 3.0)
CART_Q, CART_V = np.array([0.3, 1.1]), np.array([0.7, -1.3])


def cart(**wrong):
    return _cart(tuple(wrong.items()))


@functools.lru_cache(maxsize=None)
def _cart(wrong):  # compiled once per variant (compiling the callbacks dominates the run time)
    return fastvi.Model(2, 0, params=CART_PARAMS, name="cart", **{**CART, **dict(wrong)})


# ----------------------------------------------------------------------------- sphere ∩ saddle
# params = (mass, l, c, g); g1 = ½(x²+y²+z²−l²), g2 = z − c x y;  V = mass g z + x² y²


def curve_potential(q, p):
    return p[0] * p[3] * q[2] + q[0] * q[0] * q[1] * q[1]


def curve_potential_grad(q, p, out):
    out[0] = 2.0 * q[0] * q[1] * q[1]
    out[1] = 2.0 * q[0] * q[0] * q[1]
    out[2] = p[0] * p[3]


def curve_potential_hessian(q, p, out):
    out[:, :] = 0.0
    out[0, 0] = 2.0 * q[1] * q[1]
    out[1, 1] = 2.0 * q[0] * q[0]
    out[0, 1] = 4.0 * q[0] * q[1]
    out[1, 0] = 4.0 * q[0] * q[1]


def curve_constraint(q, p, out):
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] - p[1] * p[1])
    out[1] = q[2] - p[2] * q[0] * q[1]


def curve_constraint_jacobian(q, p, out):
    out[0, 0] = q[0]
    out[0, 1] = q[1]
    out[0, 2] = q[2]
    out[1, 0] = -p[2] * q[1]
    out[1, 1] = -p[2] * q[0]
    out[1, 2] = 1.0


def curve_constraint_hessian(q, eta, p, out):
    out[:, :] = 0.0
    out[0, 0] = eta[0]
    out[1, 1] = eta[0]
    out[2, 2] = eta[0]
    out[0, 1] = -p[2] * eta[1]
    out[1, 0] = -p[2] * eta[1]


def bad_potential_hessian_offdiag(q, p, out):  # 2xy instead of 4xy
    out[:, :] = 0.0
    out[0, 0] = 2.0 * q[1] * q[1]
    out[1, 1] = 2.0 * q[0] * q[0]
    out[0, 1] = 2.0 * q[0] * q[1]
    out[1, 0] = 2.0 * q[0] * q[1]


def bad_constraint_jacobian_swapped(q, p, out):  # ∂(cxy)/∂x written as c x
    out[0, 0] = q[0]
    out[0, 1] = q[1]
    out[0, 2] = q[2]
    out[1, 0] = -p[2] * q[0]
    out[1, 1] = -p[2] * q[1]
    out[1, 2] = 1.0


def bad_constraint_hessian_forgets_second(q, eta, p, out):  # only η₀ ∇²g₁
    out[:, :] = 0.0
    out[0, 0] = eta[0]
    out[1, 1] = eta[0]
    out[2, 2] = eta[0]


def bad_potential_grad_nan(q, p, out):  # e.g. sqrt of a negative number
    out[0] = np.sqrt(-1.0 - q[0] * q[0])
    out[1] = 0.0
    out[2] = p[0] * p[3]


CURVE = dict(potential=curve_potential, potential_grad=curve_potential_grad,
             potential_hessian=curve_potential_hessian, constraint=curve_constraint,
             constraint_jacobian=curve_constraint_jacobian, constraint_hessian=curve_constraint_hessian)
CURVE_PARAMS = (1.5, 1.0, 0.7, 9.81)
CURVE_Q = np.array([0.6, -0.5, -0.21])  # near (not on) the curve: the check does not need g = 0


def curve(**wrong):
    return _curve(tuple(wrong.items()))


@functools.lru_cache(maxsize=None)
def _curve(wrong):
    return fastvi.Model(3, 2, params=CURVE_PARAMS, mass=1.5 * np.eye(3), name="curve",
                        **{**CURVE, **dict(wrong)})


# ----------------------------------------------------------------------------- correct models pass
def test_correct_cart_model_passes_every_derivative_check():
    model = cart()
    report = model.check(CART_Q, CART_V)
    assert isinstance(report, CheckReport) and report.ok
    assert report.checked == ["mass", "kinetic_grad", "momentum_jacobian", "potential_grad",
                              "kinetic_hessian", "potential_hessian"]
    worst = max(r.relative_error for r in report.rows)
    assert worst < 1e-10  # measured 7e-13: Richardson-extrapolated differences are this accurate
    assert len(report.states) == 4 and model.checked


def test_correct_constrained_model_passes_every_derivative_check():
    report = curve().check(CURVE_Q)
    assert report.ok
    assert report.checked == ["potential_grad", "constraint_jacobian", "potential_hessian",
                              "constraint_hessian"]
    # the constraint Hessian is compared for η = e_0, e_1 and a random η at every state
    assert sum(r.callback == "constraint_hessian" for r in report.rows) == 3 * 4
    assert max(r.relative_error for r in report.rows) < 1e-10  # measured 4e-13


def test_report_prints_one_line_per_callback_with_verdict():
    text = str(cart().check(CART_Q, CART_V))
    for cb in fastvi.model.SLOTS:
        if cb in CART and cb not in ("potential",):
            assert cb in text
    assert "FD of kinetic_grad" in text and text.count(" ok") == 6


# scenes without defaults for every argument; Brüls' heavy top is a lamina (singular M) by default
SCENE_ARGS = {"chain": dict(N=4), "heavy_top": dict(inertia=(0.234375, 0.4, 0.234375))}


@pytest.mark.parametrize("name", sorted(SCENES))
def test_shipped_scene_passes_the_check_at_random_states(name):
    model = SCENES[name](**SCENE_ARGS.get(name, {}))
    rng = np.random.default_rng(7)
    for _ in range(2):
        q = rng.uniform(-1.0, 1.0, model.n)
        report = model.check(q, rng.standard_normal(model.n), seed=int(rng.integers(100)))
        assert report.ok, str(report)


# ----------------------------------------------------------------------------- wrong ones are named
WRONG = [
    (cart, "kinetic_grad", bad_kinetic_grad_sign),
    (cart, "kinetic_hessian", bad_kinetic_hessian_sign),
    (cart, "momentum_jacobian", bad_momentum_jacobian_transposed),
    (cart, "potential_grad", bad_potential_grad_missing_term),
    (cart, "potential_hessian", bad_potential_hessian_factor),
    (curve, "potential_hessian", bad_potential_hessian_offdiag),
    (curve, "constraint_jacobian", bad_constraint_jacobian_swapped),
    (curve, "constraint_hessian", bad_constraint_hessian_forgets_second),
]


@pytest.mark.parametrize("build, slot, bad", WRONG, ids=[f"{b.__name__}-{f.__name__}" for b, _, f in WRONG])
def test_check_names_the_one_wrong_derivative(build, slot, bad):
    model = build(**{slot: bad})
    q, v = (CART_Q, CART_V) if build is cart else (CURVE_Q, None)
    with pytest.raises(fastvi.ModelCheckError, match=f"callback `{slot}` disagrees") as err:
        model.check(q, v)
    assert err.value.callback == slot
    assert err.value.callbacks == [slot]  # second derivatives of a wrong first one are skipped
    report = err.value.report
    assert report.worst(slot).relative_error > 1e-2  # measured: 0.5 to 2 (a genuine mistake is O(1))
    assert not model.checked
    second = {"kinetic_grad": "kinetic_hessian", "potential_grad": "potential_hessian",
              "constraint_jacobian": "constraint_hessian"}.get(slot)
    if second:  # compared with FD of a wrong function: skipped, not blamed
        assert report.worst(second).status == "skipped"


def test_report_without_raising_lists_the_failures():
    report = cart(potential_grad=bad_potential_grad_missing_term).check(CART_Q, CART_V, raise_on_error=False)
    assert not report.ok and report.failures == ["potential_grad"]
    assert "WRONG" in str(report)


def test_constraint_hessian_error_names_the_constraint():
    with pytest.raises(fastvi.ModelCheckError, match="η = e_1"):
        curve(constraint_hessian=bad_constraint_hessian_forgets_second).check(CURVE_Q)


def test_asymmetric_mass_matrix_is_caught():
    with pytest.raises(fastvi.ModelCheckError) as err:
        cart(mass=bad_mass_not_symmetric).check(CART_Q, CART_V)
    assert err.value.callback == "mass"


def test_random_nearby_states_catch_a_mistake_invisible_at_the_given_state():
    # (without the exact Hessian, which would disagree with the wrong gradient even here)
    model = cart(potential_grad=bad_potential_grad_spring_sign, potential_hessian=None)
    q0 = np.array([0.0, 1.1])  # x = 0: the wrong spring sign gives the right value here
    assert model.check(q0, CART_V, n_random=0).ok
    model.checked = False
    with pytest.raises(fastvi.ModelCheckError, match="potential_grad"):
        model.check(q0, CART_V, n_random=1)


def test_non_finite_derivative_at_the_given_state_is_wrong():
    with pytest.raises(fastvi.ModelCheckError, match="`potential_grad`.*non-finite") as err:
        curve(potential_grad=bad_potential_grad_nan).check(CURVE_Q)
    assert err.value.callback == "potential_grad"


def test_check_rejects_bad_arguments_by_name():
    model = curve()
    with pytest.raises(ValueError, match="`q` must have shape"):
        model.check([1.0, 2.0])
    with pytest.raises(ValueError, match="`rtol`"):
        model.check(CURVE_Q, rtol=0.0)
    with pytest.raises(ValueError, match="`n_random`"):
        model.check(CURVE_Q, n_random=-1)
    with pytest.raises(TypeError, match="`model`"):
        check_model("not a model", CURVE_Q)


# ----------------------------------------------------------------------------- integrate
def test_integrate_runs_the_check_before_the_first_step():
    model = cart(kinetic_grad=bad_kinetic_grad_sign)
    with pytest.raises(fastvi.ModelCheckError, match="kinetic_grad.*check=False"):
        fastvi.integrate(model, CART_Q, CART_V, h=0.01, n_steps=10)
    # the check is skippable; the run then integrates a different Lagrangian, whose energy
    # the monitor sees drift from the model's (0.11 of the kinetic energy at step 5)
    with pytest.raises(fastvi.IntegrationError, match="UNRELIABLE.*energy error"):
        fastvi.integrate(model, CART_Q, CART_V, h=0.01, n_steps=10, check=False)
    # and without the monitor too, the wrong model runs silently
    res = fastvi.integrate(model, CART_Q, CART_V, h=0.01, n_steps=10, check=False, monitor=False)
    assert res.success


def test_integrate_checks_a_constraint_derivative_before_projecting():
    model = curve(constraint_jacobian=bad_constraint_jacobian_swapped)
    with pytest.raises(fastvi.ModelCheckError, match="constraint_jacobian"):
        fastvi.integrate(model, CURVE_Q, np.zeros(3), h=0.01, n_steps=10)


def test_integrate_checks_a_model_only_once(monkeypatch, pendulum):
    import fastvi.check

    calls = []
    original = fastvi.check.check_model
    monkeypatch.setattr(fastvi.check, "check_model", lambda *a, **k: calls.append(1) or original(*a, **k))
    monkeypatch.setattr(pendulum, "checked", False)  # the session fixture may have been checked
    q0, v0 = pendulum.initial_state(0.5)
    fastvi.integrate(pendulum, q0, v0, h=0.01, n_steps=5, check=False)
    assert calls == [] and not pendulum.checked
    fastvi.integrate(pendulum, q0, v0, h=0.01, n_steps=5)
    fastvi.integrate(pendulum, q0, v0, h=0.01, n_steps=5)
    assert len(calls) == 1 and pendulum.checked


def test_automatic_check_costs_a_fraction_of_the_model_setup(monkeypatch):
    cart().check(CART_Q, CART_V, n_random=1)  # warm the Python-side evaluator
    # the callbacks' compile caches (in-process and on disk) would make the set-up ~0: compare
    # with a real compile, what a model of new functions pays
    monkeypatch.setattr(fastvi.model, "_CALLBACKS", {})
    monkeypatch.setattr(fastvi.model, "_JITTED", {})
    monkeypatch.setattr(fastvi.model, "_fingerprint", lambda fn: None)
    model = fastvi.Model(2, 0, params=CART_PARAMS, name="cart", **CART)  # fresh, uncompiled
    t0 = time.perf_counter()
    model.kernel_arguments()  # compiling the callbacks: the set-up every new model pays
    setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    report = model.check(CART_Q, CART_V, n_random=1)  # what integrate runs
    cost = time.perf_counter() - t0
    assert report.ok
    assert cost < 0.1 * setup, (cost, setup)  # measured 3.7 ms vs 1.5 s (ratio 0.0025)


# ----------------------------------------------------------------------------- blame order
def bad_constraint_jacobian_sign_z(q, p, out):  # ∂g1/∂z = −z: invisible where z = 0
    out[0, 0] = q[0]
    out[0, 1] = q[1]
    out[0, 2] = -q[2]
    out[1, 0] = -p[2] * q[1]
    out[1, 1] = -p[2] * q[0]
    out[1, 2] = 1.0


def bad_constraint_forgets_last(q, p, out):  # g2 never written
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] - p[1] * p[1])


def _starting_states(k=6):
    """Random states, half of them with z = 0, where the planted sign error in G vanishes
    (there the exact Hessian disagrees with finite differences of the wrong G first)."""
    rng = np.random.default_rng(2024)
    for i in range(k):
        q = rng.uniform(-1.0, 1.0, 3)
        if i % 2 == 0:
            q[2] = 0.0
        yield q


@pytest.mark.parametrize("q", list(_starting_states()), ids=lambda q: f"z={q[2]:.2f}")
def test_a_wrong_jacobian_is_blamed_not_the_hessian_compared_with_it(q):
    model = curve(constraint_jacobian=bad_constraint_jacobian_sign_z)
    with pytest.raises(fastvi.ModelCheckError, match="callback `constraint_jacobian` disagrees") as err:
        model.check(q)
    assert err.value.callbacks == ["constraint_jacobian"]
    skipped = err.value.report.worst("constraint_hessian")
    assert skipped.status == "skipped"
    assert skipped.note == "not checked: depends on `constraint_jacobian`, which is wrong"
    assert "Also wrong" not in str(err.value)


@pytest.mark.parametrize("q", list(_starting_states()), ids=lambda q: f"z={q[2]:.2f}")
def test_an_unwritten_constraint_entry_is_blamed_on_the_constraint(q):
    model = curve(constraint=bad_constraint_forgets_last)
    with pytest.raises(fastvi.ModelCheckError, match=r"`constraint` never wrote entry \[1\]") as err:
        model.check(q)
    assert err.value.callback == "constraint" and err.value.callbacks == ["constraint"]


def test_callback_value_evaluates_each_slot_as_the_kernels_call_it(double_pendulum):
    """Each callback by name, with its output shape; the derivatives against central
    differences of the values (an independent computation)."""
    model = double_pendulum
    assert {"potential", "potential_grad", "constraint", "constraint_jacobian"} <= model.callbacks
    assert "force" not in model.callbacks
    q = np.array([0.6, -0.8, 1.1, -0.3])
    eps = 1e-6
    basis = np.eye(4) * eps
    grad = model.callback_value("potential_grad", q)
    fd = [(model.callback_value("potential", q + e) - model.callback_value("potential", q - e)) / (2 * eps)
          for e in basis]
    assert grad.shape == (4,) and np.allclose(grad, fd, rtol=0, atol=1e-7)
    G = model.callback_value("constraint_jacobian", q)
    fdG = np.array([(model.callback_value("constraint", q + e) - model.callback_value("constraint", q - e))
                    / (2 * eps) for e in basis]).T
    assert G.shape == (2, 4) and np.allclose(G, fdG, rtol=0, atol=1e-8)
    with pytest.raises(ValueError, match="no `mass` callback.*constant: see `mass_matrix`"):
        model.callback_value("mass", q)
    with pytest.raises(ValueError, match="`slot` must be one of mass, kinetic_grad"):
        model.callback_value("gradient", q)


# ----------------------------------------------------------------------------- large models
def test_hessian_reference_by_groups_is_the_coordinate_by_coordinate_one():
    from fastvi.check import _fd, _fd_contracted_by_groups

    model = fastvi.scenes.chain(6)  # n = 12, m = 6: its declared pattern gives 4 groups
    rng = np.random.default_rng(3)
    q = rng.uniform(-1.0, 1.0, model.n)
    E = rng.standard_normal((3, model.m))

    def G(x):
        return model.constraint_jacobian_value(x)

    dG, est, fscale, hmin = _fd(G, q)
    contracted, fs, hm = _fd_contracted_by_groups(G, q, E, model.constraint_jacobian_pattern)
    refs, ests = (np.array(x) for x in zip(*map(contracted, range(3))))
    assert np.allclose(refs, np.einsum("jc,cab->jab", E, dG), rtol=0, atol=1e-12)
    assert np.allclose(ests, np.einsum("jc,cab->jab", np.abs(E), est), rtol=0, atol=1e-12)
    assert (fs, hm) == (fscale, hmin)
    # the theory: Σ_c η_c ∇²g_c of a chain, block tridiagonal (scene docstring)
    for j in range(3):
        exact = np.zeros((model.n, model.n))
        CHAIN.constraint_hessian(q, E[j], model.params, exact)
        assert np.abs(refs[j] - exact).max() < 1e-9


def test_checking_a_large_model_holds_a_few_n_squared_floats():
    """The check of a 128-link chain (n = 256) holds one guarded buffer for every callback,
    let go once every callback's size has passed, one contracted Hessian reference at a
    time, and of each group's differences of G only G's pattern: measured 12 n² floats at
    its peak (16 n² with the buffer kept and the groups' differences dense), where a buffer
    per callback and every reference at once took 92 n²."""
    import tracemalloc
    model = fastvi.scenes.chain(128)
    q, v = model.initial_state(np.linspace(0.2, 1.4, 128))
    model.kernel_arguments()
    tracemalloc.start()
    try:
        report = model.check(q, v, n_random=1, param_derivatives=False)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert report.ok and "constraint_hessian" in report.checked
    assert peak < 14 * 8 * model.n ** 2, peak / (8 * model.n ** 2)


def test_checking_the_derivatives_by_theta_holds_no_k_n_squared_buffer():
    """With the derivatives by θ (k = 130 parameters of a damped 64-link chain, n = 128) the
    check holds buffers for the callbacks it evaluates alone: measured 13 n² floats at its
    peak, where a buffer for every derivative by θ, those of the n × n callbacks the model
    does not give included, reserved 2.4 k n² (a 1024-link chain's check asked for 64 GiB)."""
    import tracemalloc
    model = fastvi.scenes.chain(64, damping=0.3)
    q, v = model.initial_state(np.linspace(0.2, 1.4, 64))
    model.kernel_arguments()
    tracemalloc.start()
    try:
        report = model.check(q, v, n_random=1)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert report.ok and any(name.endswith("/θ") for name in report.checked)
    assert peak < 64 * 8 * model.n ** 2, peak / (8 * model.n ** 2)


def _hessian_forgets_a_curvature(q, eta, p, out):  # the chain's, but for one entry
    chain_constraint_hessian_dense(q, eta, p, out)
    out[-1, -1] = 0.0  # ∂²g_last/∂y_last² = 1 forgotten


def test_a_wrong_constraint_hessian_of_a_patterned_model_is_named():
    chain = fastvi.scenes.chain(5)
    fns = {slot: getattr(CHAIN, slot)
           for slot in ("potential", "potential_grad", "constraint", "constraint_jacobian")}
    model = fastvi.Model(chain.n, chain.m, params=chain.params,
                         mass=chain.mass_matrix_constant, potential_hessian=0,
                         constraint_hessian=_hessian_forgets_a_curvature,
                         constraint_jacobian_pattern=chain.constraint_jacobian_pattern, **fns)
    q = np.random.default_rng(4).uniform(-1.0, 1.0, chain.n)
    with pytest.raises(fastvi.ModelCheckError, match="callback `constraint_hessian` disagrees") as err:
        model.check(q)
    assert err.value.callbacks == ["constraint_hessian"]
    good = fastvi.Model(chain.n, chain.m, params=chain.params,
                        mass=chain.mass_matrix_constant, potential_hessian=0,
                        constraint_hessian=CHAIN.constraint_hessian,
                        constraint_jacobian_pattern=chain.constraint_jacobian_pattern, **fns)
    assert good.check(q).ok


def test_derivatives_by_the_parameters_compared_in_blocks_are_compared_as_a_whole(monkeypatch):
    model = fastvi.scenes.double_pendulum(damping=0.3)
    q, v = model.initial_state(0.7, -0.4, 0.2, 0.9)
    whole = check_model(model, q, v, n_random=1)
    assert any(r.callback.endswith("/θ") for r in whole.rows)
    monkeypatch.setattr(fastvi.check, "FD_BLOCK_BYTES", 1)  # one parameter a block
    blocks = check_model(model, q, v, n_random=1)
    assert whole.ok and blocks.ok
    for a, b in zip(whole.rows, blocks.rows, strict=True):
        assert (a.callback, a.state, a.error, a.scale, a.allowed, a.index, a.status) == \
               (b.callback, b.state, b.error, b.scale, b.allowed, b.index, b.status), a.callback


def test_a_derivative_by_the_parameters_declared_zero_is_checked_along_a_random_direction():
    chain = fastvi.scenes.chain(4, damping=0.3)  # ∂G/∂θ declared 0: G has no length in it
    q, v = np.random.default_rng(5).uniform(-1.0, 1.0, (2, chain.n))
    row = chain.check(q, v, n_random=0).worst("constraint_jacobian/θ")
    assert row.status == "ok" and "random direction" in row.note
    # the length moves g but not G: a g whose derivative by θ is declared 0 is caught, and
    # pinned to the length l_i by the differences in each parameter
    plain = fastvi.scenes.chain(4)
    wrong = fastvi.Model(plain.n, plain.m, params=plain.params, mass=plain.mass_matrix_constant,
                         potential_hessian=0,
                         param_derivatives={**CHAIN.param_derivatives(), "constraint": 0},
                         param_patterns={s: p for s, p in CHAIN.param_patterns(4).items()
                                         if s != "constraint"},
                         constraint_jacobian_pattern=plain.constraint_jacobian_pattern,
                         **{s: getattr(CHAIN, s) for s in ("potential", "potential_grad",
                                                           "constraint", "constraint_jacobian")},
                         constraint_hessian=CHAIN.constraint_hessian)
    bad = wrong.check(q, v, n_random=0, raise_on_error=False).worst("constraint/θ")
    assert bad.status == "wrong" and chain.m <= bad.index[0] < 2 * chain.m  # a length l_i


@pytest.mark.parametrize("seed", [None, 3, np.random.default_rng(4)])
def test_check_takes_any_seed_numpy_takes(seed):
    model = fastvi.scenes.chain(3, damping=0.3)  # declared zeros: compared along directions
    q, v = np.random.default_rng(1).uniform(-1.0, 1.0, (2, model.n))
    assert model.check(q, v, n_random=1, seed=seed).ok
