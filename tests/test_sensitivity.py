"""Forward sensitivities and the discrete adjoint are the derivatives of the discrete flow.

References are independent of the linearised step: central differences of whole runs of
``fastvi.integrate`` (the very map being differentiated), SciPy's DOP853 in angle
coordinates for the convergence order, and theory (the symplectic form, the tangent space,
the identity ⟨λ0, δx0⟩ = δJ).
"""

import warnings

import numpy as np
import pytest

import fastvi
from fastvi.scenes.double_pendulum import angles, state_from_angles
from fastvi.studies.convergence import observed_order
from studies.sensitivities import angle_directions, reference_jacobian

from . import models

N_FD = 20  # steps of the runs compared with differences (h = 0.05: t = 1)


# a point on a circle (Cartesian, one constraint) under gravity and a quartic well, with
# neither Hessian given: the finite-difference second derivatives of the kernels
def circle_V(q, p):
    return p[0] * q[1] + 0.25 * p[1] * q[0] ** 4


def circle_dV(q, p, out):
    out[0] = p[1] * q[0] ** 3
    out[1] = p[0]


def circle_g(q, p, out):
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] - p[2] * p[2])


def circle_G(q, p, out):
    out[0, 0] = q[0]
    out[0, 1] = q[1]


def _circle():
    return fastvi.Model(2, 1, params=(9.81, 3.0, 1.2), mass=[1.0, 1.0], potential=circle_V,
                        potential_grad=circle_dV, constraint=circle_g,
                        constraint_jacobian=circle_G, name="circle")


def _cases():
    dp = fastvi.scenes.double_pendulum(damping=0.3)
    q, v = dp.initial_state(0.9, -0.4, 0.3, 1.1)
    rr = fastvi.scenes.rotary_rod_slider(k=100.0)
    qr = np.array([0.3, 1.1, 0.3])
    vr = np.array([0.5, 0.2, 0.5])
    pp = models.polar_pendulum(exact=False)
    kp = fastvi.scenes.kapitza_pendulum(a=0.2, omega=3.0)
    a = 1.2 * np.array([np.sin(0.7), -np.cos(0.7)])
    return [
        ("damped_double_pendulum", dp, q, v, "P2L-Q3G"),
        ("rotary_rod_slider", rr, qr, vr, "P2L-Q3G"),  # M(q, θ) with exact derivatives
        ("polar_pendulum_fd", pp, np.array([1.0, 0.6]), np.array([0.0, 1.3]), "P3L-Q4G"),
        ("circle_fd", _circle(), a, np.array([1.0, a[0] / a[1] * -1.0]) * 0.8, "P2L-Q3G-NE-CE"),
        # a rheonomic constraint (the pivot driven slowly): ∂g_t/∂q in the hidden constraint
        ("driven_pivot", kp, *kp.initial_state(2.5, 1.0), "P2L-Q3G"),
    ]


CASES = _cases()


def _end(model, q0, v0, prm, method, h=0.05, n=N_FD):
    with warnings.catch_warnings():  # the perturbed starts are projected: that is the point
        warnings.simplefilter("ignore")
        r = fastvi.integrate(model, q0, v0, h=h, n_steps=n, params=prm, method=method)
    return np.concatenate([r.q[-1], r.v[-1]])


@pytest.mark.parametrize("label,model,q,v,method", CASES, ids=[c[0] for c in CASES])
def test_whole_run_derivatives_match_differences_of_runs(label, model, q, v, method):
    q0, v0 = fastvi.consistent_state(model, q, v)
    S = fastvi.sensitivity(model, q0, v0, h=0.05, n_steps=N_FD, method=method,
                           wrt=("q0", "v0", "params"))
    n, k = model.n, model.params.size
    assert S.dq.shape == (N_FD + 1, n, 2 * n + k)
    worst = 0.0
    for j in range(2 * n + k):
        e = np.zeros(2 * n + k)
        scale = 1.0 if j < 2 * n else max(1.0, abs(model.params[j - 2 * n]))
        e[j] = 3e-7 * scale
        fp = _end(model, q0 + e[:n], v0 + e[n:2 * n], model.params + e[2 * n:], method)
        fm = _end(model, q0 - e[:n], v0 - e[n:2 * n], model.params - e[2 * n:], method)
        fd = (fp - fm) / (2 * e[j])
        an = np.concatenate([S.dq[-1, :, j], S.dv[-1, :, j]])
        worst = max(worst, np.abs(an - fd).max() / max(1.0, np.abs(fd).max()))
    # the differences' own error is ≈ 1e-9 (measured 2e-9 … 8e-9 on these cases)
    assert worst < 2e-7


@pytest.mark.parametrize("label,model,q,v,method", CASES, ids=[c[0] for c in CASES])
def test_derivatives_stay_in_the_tangent_space(label, model, q, v, method):
    q0, v0 = fastvi.consistent_state(model, q, v)
    S = fastvi.sensitivity(model, q0, v0, h=0.05, n_steps=40, method=method,
                           wrt=("q0", "v0", "params"))
    g, gv = S.tangent_residual()
    size = max(1.0, np.abs(S.dq).max(), np.abs(S.dp).max())
    assert g.max() < 1e-12 * size  # measured ≤ 6e-17
    # the parameters' part of the check is a five-point difference (measured ≤ 1.3e-13)
    assert gv.max() < 1e-10 * size
    # a raw perturbation off the constraints is projected: the q0 columns have rank n − m
    sv = np.linalg.svd(S.dq[0][:, :model.n], compute_uv=False)
    assert np.sum(sv > 1e-12 * sv[0]) == model.n - model.m


def test_the_trajectory_is_the_one_integrate_computes_bit_for_bit(double_pendulum, dp_start):
    q0, v0 = dp_start
    S = fastvi.sensitivity(double_pendulum, q0, v0, h=0.01, n_steps=300, save_every=7,
                           wrt=("v0",))
    r = fastvi.integrate(double_pendulum, q0, v0, h=0.01, n_steps=300, save_every=7)
    assert np.array_equal(S.result.q, r.q) and np.array_equal(S.result.p, r.p)
    assert np.array_equal(S.t, r.t) and S.dq.shape == (len(r.t), 4, 4)


def test_the_tangent_map_is_symplectic_on_the_constraint_manifold(double_pendulum):
    model = double_pendulum
    q0, v0 = model.initial_state(0.3, 0.2)
    Z = fastvi.tangent_space(model, q0, v0)  # (8, 4): 2(n − m)
    assert Z.shape == (8, 4)
    M = model.mass_matrix(q0)
    D = np.vstack([Z[:4], np.linalg.solve(M, Z[4:]), np.zeros((5, 4))])  # (δq0, δv0, δθ)
    N = 10_000
    S = fastvi.sensitivity(model, q0, v0, h=0.01, n_steps=N, wrt=D, save_every=N)
    Y = np.vstack([S.dq[-1], S.dp[-1]])
    J = np.block([[np.zeros((4, 4)), np.eye(4)], [-np.eye(4), np.zeros((4, 4))]])
    W0, W1 = Z.T @ J @ Z, Y.T @ J @ Y
    assert np.abs(W0).max() > 0.5  # the form is not degenerate on the tangent space
    # measured 8.6e-13 with |Y| ≈ 37 after 10⁴ steps: round-off of |Y|²
    assert np.abs(W1 - W0).max() < 1e-13 * np.abs(Y).max() ** 2
    assert np.abs(Y).max() > 10  # the map did move the vectors


def test_sensitivities_converge_at_the_methods_order(double_pendulum):
    a0, T, L = np.array([np.pi / 2, np.pi / 2, 0.0, 0.0]), 1.0, [1.0, 1.0]
    ref = reference_jacobian(a0, T, L)  # differences of DOP853 runs in angles
    D = angle_directions(a0, L, 5)  # ∂(q0, v0)/∂(θ0, ω0), exact
    q0, v0 = double_pendulum.initial_state(np.pi / 2, np.pi / 2)
    # measured 2.03, 4.08, 6.72 (errors 1.7e-1 … 2.5e-3, 1.6e-2 … 3.2e-6, 1.6e-3 … 1.2e-9)
    for name, hs, order in [("P1L-Q2G", [0.05, 0.025, 0.0125, 0.00625], 2),
                            ("P2L-Q3G", [0.1, 0.05, 0.025, 0.0125], 4),
                            ("P3L-Q4G", [0.1, 0.05, 0.025, 0.0125], 6)]:
        errs = []
        for h in hs:
            S = fastvi.sensitivity(double_pendulum, q0, v0, h=h, t_end=T, wrt=D, method=name,
                                   save_every=10**6)
            errs.append(np.abs(np.vstack([S.dq[-1], S.dv[-1]]) - ref).max())
        slope, used = observed_order(hs, errs)
        assert used.sum() >= 3 and abs(slope - order) < 0.8, (name, errs)


def test_adjoint_gradient_equals_the_forward_derivative():
    model = fastvi.scenes.double_pendulum(damping=0.3)
    q0, v0 = model.initial_state(0.9, -0.4, 0.3, 1.1)
    rng = np.random.default_rng(1)
    N, every = 200, 3
    K = N // every + 2
    Lq, Lv = rng.normal(size=(K, 4)), rng.normal(size=(K, 4))
    A = fastvi.adjoint(model, q0, v0, lambda r: (Lq, Lv), h=0.02, n_steps=N,
                       save_every=every, checkpoint_every=7)  # 29 segments, the last short
    assert A.stats["checkpoints"] == 29 and len(A.result.t) == K
    D = rng.normal(size=(14, 2))
    S = fastvi.sensitivity(model, q0, v0, h=0.02, n_steps=N, save_every=every, wrt=D)
    forward = np.einsum("kn,knd->d", Lq, S.dq) + np.einsum("kn,knd->d", Lv, S.dv)
    grad = np.concatenate([A.grad_q0, A.grad_v0, A.grad_params])
    assert np.allclose(grad @ D, forward, rtol=1e-12, atol=0)  # measured 7.7e-15
    assert np.array_equal(A.result.q, S.result.q)
    # the default keeps every step's records (nothing retaken): the same gradient, bit for bit
    kept = fastvi.adjoint(model, q0, v0, lambda r: (Lq, Lv), h=0.02, n_steps=N,
                          save_every=every)
    assert kept.stats["checkpoints"] == 1 and kept.stats["segment"] == N
    assert np.array_equal(np.concatenate([kept.grad_q0, kept.grad_v0, kept.grad_params]), grad)


def test_adjoint_with_a_configuration_dependent_mass():
    model = fastvi.scenes.rotary_rod_slider(k=100.0)
    q0, v0 = fastvi.consistent_state(model, [0.3, 1.1, 0.3], [0.5, 0.2, 0.5])
    rng = np.random.default_rng(2)
    Lq, Lv = rng.normal(size=(31, 3)), rng.normal(size=(31, 3))
    A = fastvi.adjoint(model, q0, v0, lambda r: (Lq, Lv), h=0.02, n_steps=30,
                       param_index=[2, 3])
    D = np.zeros((12, 1))
    D[:6, 0] = rng.normal(size=6)
    D[6 + 2, 0], D[6 + 3, 0] = 0.7, -0.4
    S = fastvi.sensitivity(model, q0, v0, h=0.02, n_steps=30, wrt=D)
    forward = np.sum(Lq * S.dq[:, :, 0]) + np.sum(Lv * S.dv[:, :, 0])
    grad = np.concatenate([A.grad_q0, A.grad_v0, A.grad_params])
    assert abs(grad @ D[[0, 1, 2, 3, 4, 5, 8, 9], 0] - forward) < 1e-11 * abs(forward)


def _angles(t, q, v):
    return np.stack(angles(q), axis=-1)


def _start(prm):
    return state_from_angles(1.0, 0.5, 0.0, 0.0, prm[2], prm[3])


def test_trajectory_fit_recovers_damping_and_rod_length():
    from scipy.optimize import least_squares

    model = fastvi.scenes.double_pendulum(damping=0.3)
    true = model.params.copy()
    true[3] = 0.8
    h, N, every = 0.01, 500, 5
    q0, v0 = _start(true)
    r = fastvi.integrate(model, q0, v0, h=h, n_steps=N, save_every=every, params=true)
    data = _angles(r.t, r.q, r.v) + 0.01 * np.random.default_rng(0).normal(size=(len(r.t), 2))
    fit = fastvi.TrajectoryFit(model, data, _angles, param_index=[5, 3], initial_state=_start,
                               h=h, n_steps=N, save_every=every)
    x0 = np.array([0.1, 1.0])
    J = fit.jacobian(x0)
    fd = np.column_stack([(fit.residuals(x0 + e) - fit.residuals(x0 - e)) / 2e-6
                          for e in 1e-6 * np.eye(2)])
    assert np.abs(J - fd).max() < 1e-7 * np.abs(J).max()  # measured 5e-10
    value, grad = fit.cost(x0)
    assert np.allclose(grad, J.T @ fit.residuals(x0), rtol=1e-10)
    sol = least_squares(fit.residuals, x0, jac=fit.jacobian)
    assert sol.success and np.allclose(sol.x, [0.3, 0.8], atol=0.01)
    assert sol.cost < 0.5 * len(data.ravel()) * 0.01 ** 2 * 1.2  # the noise's own level


def test_errors_name_what_is_not_defined(double_pendulum, dp_start):
    q0, v0 = dp_start
    with pytest.raises(ValueError, match="whole number of steps"):
        fastvi.sensitivity(double_pendulum, q0, v0, h=0.3, t_end=1.0)
    with pytest.raises(ValueError, match="`wrt` entries"):
        fastvi.sensitivity(double_pendulum, q0, v0, h=0.01, n_steps=2, wrt=("x0",))
    with pytest.raises(ValueError, match="shape"):
        fastvi.sensitivity(double_pendulum, q0, v0, h=0.01, n_steps=2, wrt=np.ones((3, 2)))
    with pytest.raises(fastvi.IntegrationError, match="sensitivity is not defined") as info:
        fastvi.sensitivity(double_pendulum, q0, v0, h=0.01, n_steps=5, max_iter=1)
    assert info.value.result.status < 0
    with pytest.raises(TypeError, match="does not take `events`: an event crossing makes the flow non-smooth"):
        fastvi.sensitivity(double_pendulum, q0, v0, h=0.01, n_steps=2, events=[lambda t, q, v, p: q[0]])
    with pytest.raises(TypeError, match="does not take `recover`"):
        fastvi.adjoint(double_pendulum, q0, v0, lambda r: (np.ones((2, 4)), None), h=0.01,
                       n_steps=2, recover=3)
    with pytest.raises(TypeError, match="unexpected keyword argument 'hh'"):
        fastvi.sensitivity_ensemble(double_pendulum, q0[None], v0[None], h=0.01, n_steps=2, hh=1)
    with pytest.raises(ValueError, match="dJ_dq"):
        fastvi.adjoint(double_pendulum, q0, v0, lambda r: (np.ones((2, 4)), None), h=0.01,
                       n_steps=5)


def test_a_plan_kept_dense_gives_the_dense_linearised_step():
    # a chain of 4 links with P3L-Q4G: its plan is analysed (patterns detected) but keeps
    # every solve dense, so its workspace is not structured and the linearised step must
    # not take the structured paths (they are compiled for structured workspaces only)
    chain4 = fastvi.scenes.chain(4)
    q0 = np.concatenate([[np.sin(0.4 * (i + 1)), -np.cos(0.4 * (i + 1))] for i in range(4)])
    q0 = np.cumsum(q0.reshape(4, 2), axis=0).ravel()
    v0 = np.zeros(8)
    run = dict(h=0.02, n_steps=20, save_every=10, method="P3L-Q4G", wrt=("q0",))
    S = fastvi.sensitivity(chain4, q0, v0, **run)
    R = fastvi.sensitivity(chain4, q0, v0, solver="dense", **run)
    assert np.array_equal(S.dq, R.dq) and np.array_equal(S.dv, R.dv)
