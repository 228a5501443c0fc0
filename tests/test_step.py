"""The step kernel computes exactly the equations of docs/method.md, and their derivative.

Differential tests against the NumPy twin in tests/reference.py (absolute form, raw tables)
and against finite differences of the kernel's own residual.
"""

import numpy as np
import pytest

import fastvi
from fastvi.kernels.layout import make_workspace
from fastvi.kernels.step import assemble_at, linear_force

from . import models, reference

METHODS = ["P1L-Q2G", "P2L-Q3G", "P3L-Q4G", "P2L-Q3G-NE-CE", "P3L-Q3L-NC-CG2", "P4L-Q5G-NE-CL3"]


def _models():
    dp = fastvi.scenes.double_pendulum(m1=1.3, l2=0.7)
    q, v = dp.initial_state(0.9, -0.4, 0.3, 1.1)
    pp = models.polar_pendulum()
    sp = models.polar_pendulum(spring=50.0)
    qu = models.quartic()
    return [
        ("double_pendulum", dp, q, v),
        ("polar_pendulum", pp, np.array([1.0, 0.7]), np.array([0.0, 1.3])),
        ("spring_pendulum", sp, np.array([1.1, 0.7]), np.array([0.4, 1.3])),
        ("quartic", qu, np.array([0.8, -0.3]), np.array([0.2, 0.5])),
    ]


MODELS = _models()


def _kernel(model, meth, h, qk, pk, X, jac=True):
    md = model.kernel_data()
    ws = make_workspace(model.n, model.m, meth.s, meth.r, meth.J)
    ws.X[:] = X
    if model.m:
        ws.G[0][:, :] = model.constraint_jacobian_value(qk)
    linear_force(md, ws, qk)  # what a step does first (∇V once a step for a linear V)
    st = assemble_at(md, meth.kernel_tables, h, qk, pk, ws, jac)
    assert st == 0
    return ws.R.copy(), ws.A.copy()


def _random_unknowns(model, meth, h, v, seed):
    rng = np.random.default_rng(seed)
    s, n = meth.s, model.n
    dQ = np.outer(meth.tau[1:], v) * h + 1e-3 * rng.normal(size=(s, n))
    eta = 0.1 * rng.normal(size=meth.J * model.m)
    return np.concatenate([dQ.ravel(), eta])


@pytest.mark.parametrize("name", METHODS)
@pytest.mark.parametrize("label,model,q,v", MODELS, ids=[m[0] for m in MODELS])
def test_kernel_residual_equals_the_numpy_twin(label, model, q, v, name):
    meth = fastvi.method(name)
    h = 0.05
    pk = model.mass_matrix(q) @ v
    X = _random_unknowns(model, meth, h, v, 1)
    R, _ = _kernel(model, meth, h, q, pk, X, jac=False)
    Rt = reference.residual(model, meth, h, q, pk, X)
    scale = max(1.0, np.abs(Rt).max())
    # the twin uses the uncorrected tables in absolute form: agreement to rounding, not bits
    assert np.abs(R - Rt).max() <= 5e-13 * scale  # measured ≤ 6.7e-14 (relative)


def _chain_start():
    from studies.wpd.growth import chain_angles

    ch = fastvi.scenes.chain(6)  # n = 12: the constant-mass part's loops over the coordinates
    q, v = ch.initial_state(chain_angles(6))
    return ("chain6", ch, q, v + 0.3)


@pytest.mark.parametrize("name", ["P2L-Q3G", "P3L-Q4G", "P2L-Q3G-NE-CE", "P3L-Q3L-NC-CG2"])
@pytest.mark.parametrize("label,model,q,v", MODELS + [_chain_start()],
                         ids=[m[0] for m in MODELS] + ["chain6"])
def test_mechanics_residual_equals_the_numpy_twin(label, model, q, v, name):
    """The residual of the mechanics iteration (its own loop order; for a constant M the mass
    part from the method's quadratic form, ``tables._mass_block``) is the same equations."""
    meth = fastvi.method(name)
    h = 0.05
    pk = model.mass_matrix(q) @ v
    X = _random_unknowns(model, meth, h, v, 3)
    ws = make_workspace(model.n, model.m, meth.s, meth.r, meth.J)
    ws.X[:] = X
    if model.m:
        ws.G[0][:, :] = model.constraint_jacobian_value(q)  # the step starts with G(q_k)
    md = model.kernel_data()
    linear_force(md, ws, q)
    assert assemble_at(md, meth.kernel_tables, h, q, pk, ws, False) == 0
    Rt = reference.residual(model, meth, h, q, pk, X)
    scale = max(1.0, np.abs(Rt).max())
    assert np.abs(ws.R - Rt).max() <= 5e-13 * scale


@pytest.mark.parametrize("name", METHODS)
@pytest.mark.parametrize("label,model,q,v", MODELS, ids=[m[0] for m in MODELS])
def test_kernel_jacobian_is_the_derivative_of_its_residual(label, model, q, v, name):
    meth = fastvi.method(name)
    h = 0.05
    pk = model.mass_matrix(q) @ v
    X = _random_unknowns(model, meth, h, v, 2)
    _, A = _kernel(model, meth, h, q, pk, X)
    N = X.size
    Afd = np.zeros((N, N))
    for k in range(N):
        d = 1e-6 * max(1.0, abs(X[k]))
        Xp, Xm = X.copy(), X.copy()
        Xp[k] += d
        Xm[k] -= d
        Afd[:, k] = (_kernel(model, meth, h, q, pk, Xp, False)[0] - _kernel(model, meth, h, q, pk, Xm, False)[0]) / (2 * d)
    assert np.abs(A - Afd).max() <= 1e-6 * max(1.0, np.abs(A).max())  # measured ≤ 8e-12


def test_finite_difference_second_derivatives_match_the_exact_ones():
    """A model without second derivatives gets the same Newton matrix up to FD error."""
    exact = models.polar_pendulum(exact=True)
    fd = models.polar_pendulum(exact=False)
    assert not any(fd.has_exact_second_derivatives.values())
    meth = fastvi.method("P3L-Q4G")
    q, v, h = np.array([1.0, 0.7]), np.array([0.0, 1.3]), 0.05
    pk = exact.mass_matrix(q) @ v
    X = _random_unknowns(exact, meth, h, v, 3)
    Re, Ae = _kernel(exact, meth, h, q, pk, X)
    Rf, Af = _kernel(fd, meth, h, q, pk, X)
    np.testing.assert_array_equal(Re, Rf)  # the residual never uses second derivatives
    assert np.abs(Ae - Af).max() <= 1e-8 * np.abs(Ae).max()  # measured 2e-13


def test_exact_and_fd_models_give_the_same_trajectory():
    """Second derivatives only steer Newton: the solution agrees to Newton tolerance."""
    q, v = np.array([1.0, 2.0]), np.array([0.0, 0.0])
    r1 = fastvi.integrate(models.polar_pendulum(exact=True), q, v, h=0.02, n_steps=300)
    r2 = fastvi.integrate(models.polar_pendulum(exact=False), q, v, h=0.02, n_steps=300)
    assert np.abs(r1.q - r2.q).max() < 1e-12  # measured 6e-15
