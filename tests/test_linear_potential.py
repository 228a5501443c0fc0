"""``potential_hessian=0``: a potential linear in q (uniform gravity in Cartesian coordinates).

The kernels then evaluate ∇V once a trajectory instead of at every quadrature point of every Newton
iteration, and drop the potential-Hessian block of the full Newton matrix. The equations are
the same: the reference is the same model with an ordinary (zero-writing) Hessian callback,
which takes the general path of every kernel.
"""

import importlib
import pickle

import numpy as np
import pytest

import fastvi
from fastvi.kernels.layout import F_LINPOT, make_workspace
from fastvi.kernels.step import assemble_at, linear_force

dp_module = importlib.import_module("fastvi.scenes.double_pendulum")  # the scene's module, not its function


def zero_hessian(q, p, out):
    out[:, :] = 0.0


def _double_pendulum(declared):
    """The scene's own callbacks; ∇²V declared zero, or given as a callback."""
    return fastvi.Model(4, 2, params=(1.3, 1.0, 1.0, 0.7, 9.81), mass=np.array([1.3, 1.3, 1.0, 1.0]),
                        potential=dp_module.potential, potential_grad=dp_module.potential_grad,
                        potential_hessian=0 if declared else zero_hessian,
                        constraint=dp_module._g, constraint_jacobian=dp_module._G,
                        constraint_hessian=dp_module._ddg, name="dp-" + ("linear" if declared else "callback"))


LINEAR, GENERAL = _double_pendulum(True), _double_pendulum(False)


def _start():
    return dp_module.state_from_angles(0.9, -0.4, 0.3, 1.1, 1.0, 0.7)


def test_the_scenes_declare_it_and_the_models_differ_only_there():
    assert LINEAR.linear_potential and not GENERAL.linear_potential
    assert fastvi.scenes.double_pendulum().linear_potential
    assert fastvi.scenes.chain(4).linear_potential
    assert not fastvi.scenes.rotary_rod_slider().linear_potential  # a spring: ∇²V ≠ 0
    assert LINEAR.has_exact_second_derivatives["potential_hessian"]
    assert LINEAR.kernel_arguments()[1][F_LINPOT] == 1
    assert GENERAL.kernel_arguments()[1][F_LINPOT] == 0


@pytest.mark.parametrize("name", ["P1L-Q2G", "P2L-Q3G", "P3L-Q4G", "P2L-Q3G-NE-CE"])
def test_residual_and_newton_matrix_equal_the_general_paths(name):
    """Both kernels' residuals (the full Newton's assembly and the mechanics residual) and
    the Newton matrix, at random unknowns: equal to round-off (the potential's part is
    summed in another order)."""
    meth = fastvi.method(name)
    q, v = _start()
    h = 0.05
    pk = LINEAR.mass_matrix(q) @ v
    rng = np.random.default_rng(5)
    X = np.concatenate([(np.outer(meth.tau[1:], v) * h + 1e-3 * rng.normal(size=(meth.s, 4))).ravel(),
                        0.1 * rng.normal(size=meth.J * 2)])
    out = {}
    for label, model in (("linear", LINEAR), ("general", GENERAL)):
        md = model.kernel_data()
        for kind in ("assemble", "residual"):
            ws = make_workspace(4, 2, meth.s, meth.r, meth.J)
            ws.X[:] = X
            ws.G[0][:, :] = model.constraint_jacobian_value(q)
            linear_force(md, ws, q)
            if kind == "assemble":
                assert assemble_at(md, meth.kernel_tables, h, q, pk, ws, True) == 0
                out[label, "A"] = ws.A.copy()
            else:
                assert assemble_at(md, meth.kernel_tables, h, q, pk, ws, False) == 0
            out[label, kind] = ws.R.copy()
    for key in ("assemble", "residual", "A"):
        a, b = out["linear", key], out["general", key]
        assert np.abs(a - b).max() <= 1e-14 * max(1.0, np.abs(b).max()), key
    # and the potential's part is really there: without ∇V the residual differs at O(h g)
    md = LINEAR.kernel_data()
    ws = make_workspace(4, 2, meth.s, meth.r, meth.J)
    ws.X[:] = X
    ws.G[0][:, :] = LINEAR.constraint_jacobian_value(q)
    assert assemble_at(md, meth.kernel_tables, h, q, pk, ws, False) == 0  # ws.Fg never set: zero
    assert np.abs(ws.R - out["linear", "residual"]).max() > 1e-3


@pytest.mark.parametrize("name", ["P1L-Q2G", "P2L-Q3G", "P3L-Q4G"])
@pytest.mark.parametrize("newton", ["auto", "full"])
def test_trajectories_agree_to_round_off(name, newton):
    q0, v0 = _start()
    kw = dict(h=0.01, n_steps=300, method=name, newton=newton)
    a = fastvi.integrate(LINEAR, q0, v0, **kw)
    b = fastvi.integrate(GENERAL, q0, v0, **kw)
    assert np.max(np.abs(a.q - b.q)) < 1e-12  # the same equations, summed in another order
    assert np.max(np.abs(a.p - b.p)) < 1e-11
    assert np.max(np.abs(a.energy_error - b.energy_error)) < 1e-12
    assert a.constraint_residual.max() < 1e-14


@pytest.mark.slow  # compiles the sized stages for another size
def test_specialized_kernels_take_the_same_path_bit_for_bit():
    q0, v0 = _start()
    kw = dict(h=0.01, n_steps=100, method="P2L-Q3G")
    a = fastvi.integrate(LINEAR, q0, v0, specialize=False, **kw)
    b = fastvi.integrate(LINEAR, q0, v0, specialize=True, **kw)
    assert np.array_equal(a.q, b.q) and np.array_equal(a.p, b.p)


@pytest.mark.parametrize("bad", [1.0, "0", False, np.zeros((4, 4))])
def test_only_the_number_zero_declares_it(bad):
    with pytest.raises(TypeError, match=r"`potential_hessian` must be a function, 0 \(∇V does not depend on q\) or None"):
        fastvi.Model(4, 2, params=(1.0,), mass=np.ones(4), potential=dp_module.potential,
                     potential_grad=dp_module.potential_grad, potential_hessian=bad,
                     constraint=dp_module._g, constraint_jacobian=dp_module._G)


def test_the_declaration_travels_with_a_pickled_model():
    back = pickle.loads(pickle.dumps(LINEAR))
    assert back.linear_potential
    q0, v0 = _start()
    a = fastvi.integrate(LINEAR, q0, v0, h=0.01, n_steps=20)
    b = fastvi.integrate(back, q0, v0, h=0.01, n_steps=20)
    assert np.array_equal(a.q, b.q)


def spring_potential(q, p):
    return 0.5 * p[0] * q[0] * q[0] + p[1] * q[1]


def spring_potential_grad(q, p, out):
    out[0] = p[0] * q[0]
    out[1] = p[1]


def test_check_catches_a_false_declaration():
    """½ k x² is not linear: the check compares the declared zero Hessian with finite
    differences of ∇V and names the declaration."""
    model = fastvi.Model(2, 0, params=(4.0, 9.81), mass=np.ones(2), potential=spring_potential,
                         potential_grad=spring_potential_grad, potential_hessian=0, name="spring")
    with pytest.raises(fastvi.ModelCheckError, match="callback `potential_hessian` disagrees") as err:
        model.check([0.3, 1.1], [0.7, -1.3])
    assert "declared 0" in str(err.value)
    # a random direction finds it, the differences by each coordinate name ∂²V/∂x² = k
    assert err.value.report.worst("potential_hessian").index == (0, 0)
    honest = fastvi.Model(2, 0, params=(0.0, 9.81), mass=np.ones(2), potential=spring_potential,
                          potential_grad=spring_potential_grad, potential_hessian=0, name="no spring")
    report = honest.check([0.3, 1.1], [0.7, -1.3])
    assert report.ok and "random direction" in report.worst("potential_hessian").note


def test_symbolic_models_declare_a_linear_potential():
    sp = pytest.importorskip("sympy")
    from fastvi.symbolic import model_from_lagrangian

    x, y, g, k = sp.symbols("x y g k")
    lin = model_from_lagrangian([x, y], sp.eye(2), g * y, [(x**2 + y**2 - 1) / 2], params={g: 9.81})
    quad = model_from_lagrangian([x, y], sp.eye(2), g * y + k * x**2 / 2, [(x**2 + y**2 - 1) / 2],
                                 params={g: 9.81, k: 2.0})
    assert lin.linear_potential and "potential_hessian = 0" in lin.source
    assert not quad.linear_potential
    assert pickle.loads(pickle.dumps(lin)).linear_potential
