"""A constant mass matrix built from some of the parameters (``Model(mass_params=...)``):
the matrix is data of the model, so a run or a derivative that moves those parameters
says so instead of integrating a different system in silence."""
import pickle
import warnings

import numpy as np
import pytest

import fastvi


def test_a_run_that_moves_a_mass_parameter_warns_and_the_rebuilt_scene_is_the_physics():
    """A pendulum's motion does not depend on its mass: the scene built with m = 2 swings
    like the one with m = 1 (to round-off), while a run of the m = 1 scene with
    ``params`` m = 2 doubles the weight on the unchanged inertia and warns."""
    one, two = fastvi.scenes.pendulum(m=1.0), fastvi.scenes.pendulum(m=2.0)
    assert one.mass_params == (0,)
    q0, v0 = one.initial_state(1.0)
    kw = dict(h=0.01, n_steps=100)
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*constant mass matrix")  # own masses: silent
        a = fastvi.integrate(one, q0, v0, **kw)
        b = fastvi.integrate(two, q0, v0, **kw)
        fastvi.integrate(one, q0, v0, params=one.params.copy(), **kw)
    assert np.abs(a.q - b.q).max() < 1e-12
    with pytest.warns(UserWarning, match=r"`params` changes params\[0\], from which the model's "
                                         r"constant mass matrix was built"):
        c = fastvi.integrate(one, q0, v0, params=[2.0, 1.0, 9.81], **kw)
    assert np.abs(c.q - b.q).max() > 0.1  # the trap the warning names
    with pytest.warns(UserWarning, match=r"`params` changes params\[0\]"):
        fastvi.integrate_ensemble(one, np.array([q0, q0]), np.array([v0, v0]),
                                  params=np.array([[1.0, 1.0, 9.81], [2.0, 1.0, 9.81]]), **kw)


def test_a_derivative_that_names_a_mass_parameter_warns_and_the_default_is_silent():
    dp = fastvi.scenes.double_pendulum(damping=0.1)
    assert dp.mass_params == (0, 1)
    q0, v0 = dp.initial_state(0.5, 0.3)
    kw = dict(h=0.01, n_steps=2)
    with pytest.warns(UserWarning, match=r"`param_index` differentiates by params\[1\]"):
        fastvi._discrete.param_indices([1, 5], dp.params.size, dp.fixed_params, dp.mass_params)
    with pytest.warns(UserWarning, match=r"differentiates by params\[0\]"):
        fastvi.TrajectoryFit(dp, np.zeros((3, 1)), lambda r: r.q[:, :1], param_index=[0], h=0.01,
                             q0=q0, v0=v0)
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*constant mass matrix")
        fastvi.sensitivity(dp, q0, v0, wrt=("params",), param_index=[2, 5], **kw)
        fastvi._discrete.param_indices(None, dp.params.size, dp.fixed_params, dp.mass_params)


def test_mass_params_are_checked_and_survive_pickling():
    from tests.test_sensitivity import circle_dV, circle_V

    base = dict(params=(1.0, 2.0), potential=circle_V, potential_grad=circle_dV)
    model = fastvi.Model(1, mass=[1.0], mass_params=[0], **base)
    assert pickle.loads(pickle.dumps(model)).mass_params == (0,)
    assert pickle.loads(pickle.dumps(fastvi.scenes.chain(3))).mass_params == (0, 1, 2)
    with pytest.raises(ValueError, match="`mass_params` entry 2 is out of range"):
        fastvi.Model(1, mass=[1.0], mass_params=[2], **base)
    with pytest.raises(TypeError, match="`mass_params` must be parameter indices"):
        fastvi.Model(1, mass=[1.0], mass_params=["m"], **base)
    with pytest.raises(ValueError, match="a mass function reads `params` itself"):
        fastvi.Model(1, mass=lambda q, p, out: None, kinetic_grad=lambda q, v, p, out: None,
                     mass_params=[0], **base)
