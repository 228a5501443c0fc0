"""Forward sensitivities and the discrete adjoint are the derivatives of the discrete flow.

References are independent of the linearised step: central differences of whole runs of
``fastvi.integrate`` (the very map being differentiated), SciPy's DOP853 in angle
coordinates for the convergence order, and theory (the symplectic form, the tangent space,
the identity ⟨λ0, δx0⟩ = δJ).
"""

import dataclasses
import functools
import warnings

import numpy as np
import pytest

import fastvi
from fastvi import AdjointResult, EnsembleSensitivityResult, Result, SensitivityResult
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


def _symbolic():
    """Two models whose derivatives by θ SymPy writes, together every slot of them: an
    elastic pendulum in polar coordinates (``M(q, θ)``, ``∂T/∂q``, ``∇V``) and a bead on a
    sphere cut by a saddle (``g``, ``G`` and ``∇V`` by θ)."""
    import sympy as sp
    from fastvi.symbolic import model_from_lagrangian

    r, phi, x, y, z = sp.symbols("r phi x y z")
    m, k, l, g, c = sp.symbols("m k l g c", positive=True)
    spring = model_from_lagrangian([r, phi], sp.diag(m, m * r**2),
                                   k * (r - l) ** 2 / 2 - m * g * r * sp.cos(phi),
                                   params={m: 0.7, k: 30.0, l: 1.3, g: 9.81}, name="spring")
    bead = model_from_lagrangian([x, y, z], sp.eye(3) * 1.5, 1.5 * g * z + x**2 * y**2,
                                 [(x**2 + y**2 + z**2 - l**2) / 2, z - c * x * y],
                                 params={l: 1.2, c: 0.4, g: 9.81}, name="bead")
    zb = 0.4 * 0.6 * 0.5
    xb = np.array([0.6, 0.5, zb]) * 1.2 / np.linalg.norm([0.6, 0.5, zb])
    return spring, bead, xb


@functools.cache
def _cases():
    spring, bead, xb = _symbolic()
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
        # the model's own derivatives by θ, every slot (SymPy)
        ("spring_exact_theta", spring, np.array([1.4, 0.6]), np.array([0.3, -0.5]), "P2L-Q3G"),
        ("bead_exact_theta", bead, xb, np.array([0.3, -0.2, 0.1]), "P3L-Q4G"),
    ]


# the models are built when a test first asks for one, not at collection: every pytest-xdist
# worker collects every file, and SymPy's two models compile for seconds
CASE_LABELS = ["damped_double_pendulum", "rotary_rod_slider", "polar_pendulum_fd", "circle_fd",
               "driven_pivot", "spring_exact_theta", "bead_exact_theta"]


def _case(label):
    case, = (c for c in _cases() if c[0] == label)
    return case[1:]


def _end(model, q0, v0, prm, method, h=0.05, n=N_FD):
    with warnings.catch_warnings():  # the perturbed starts are projected: that is the point
        warnings.simplefilter("ignore")
        r = fastvi.integrate(model, q0, v0, h=h, n_steps=n, params=prm, method=method)
    return np.concatenate([r.q[-1], r.v[-1]])


@pytest.mark.parametrize("label", CASE_LABELS)
def test_whole_run_derivatives_match_differences_of_runs(label):
    model, q, v, method = _case(label)
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


@pytest.mark.parametrize("label", CASE_LABELS)
def test_derivatives_stay_in_the_tangent_space(label):
    model, q, v, method = _case(label)
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
                       save_every=every, checkpoint_every=7)  # 29 segments, the first short
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


@pytest.mark.parametrize("label", CASE_LABELS)
def test_adjoint_equals_the_forward_derivative_on_every_case(label):
    """Moving constraints included: the pull back to the start reads ``H_v`` (with
    ``∂G/∂t``) at t0, though the sweep has left the model's time at the first step's end."""
    model, q, v, method = _case(label)
    q0, v0 = fastvi.consistent_state(model, q, v)
    # measured ≤ 6e-14 relative (≤ 3e-15 but the spring's parameters); the start read at
    # the first step's end gave 1.8e-3 on the driven pivot
    assert adjoint_gap(model, q0, v0, h=0.05, n_steps=N_FD, method=method) < 1e-12


def adjoint_gap(model, q0, v0, **kw):
    """The largest difference, relative, between the adjoint gradient of
    ``J = ½ Σ_k (|q_k|² + |v_k|²)`` by ``(q0, v0, θ)`` and the same read off the forward
    derivatives: ``Σ_k q_k·δq_k + v_k·δv_k``."""
    S = fastvi.sensitivity(model, q0, v0, wrt=("q0", "v0", "params"), **kw)
    A = fastvi.adjoint(model, q0, v0, lambda r: (r.q, r.v), **kw)
    forward = (np.einsum("kn,knd->d", S.result.q, S.dq)
               + np.einsum("kn,knd->d", S.result.v, S.dv))
    grad = np.concatenate([A.grad_q0, A.grad_v0, A.grad_params])
    return np.abs(grad - forward).max() / np.abs(forward).max()


def test_adjoint_default_schedule_takes_the_longest_segments_that_fit(monkeypatch):
    import sys

    from fastvi.kernels.adjoint import make_checkpoints, make_records

    module = sys.modules["fastvi.adjoint"]
    model = fastvi.scenes.double_pendulum(damping=0.3)
    q0, v0 = model.initial_state(0.9, -0.4, 0.3, 1.1)
    n, m, N = 4, 2, 2 * 4 + 2 * 2  # P2L-Q3G: s = 2 stages of q, J = 2 of the impulses
    rec, ck = make_records(1, n, m, N), make_checkpoints(1, n, m, N, m * n)
    r, c = module._record_bytes(n, m, N), module._checkpoint_bytes(n, N, m * n)
    assert (r, c) == (sum(a.nbytes for a in rec), sum(a.nbytes for a in ck))
    cost = lambda res: (np.sin(res.q), res.v)  # noqa: E731
    kw = dict(h=0.02, n_steps=200, save_every=3)
    kept = fastvi.adjoint(model, q0, v0, cost, **kw)
    assert kept.stats["segment"] == 200
    # room for 90 steps' records and three checkpoints: segments of 20, 90 and 90 steps
    cut = fastvi.adjoint(model, q0, v0, cost, max_memory=90 * r + 3 * c, **kw)
    assert (cut.stats["segment"], cut.stats["checkpoints"]) == (90, 3)
    assert cut.stats["memory"] == 90 * r + 3 * c and kept.stats["memory"] == 200 * r + c
    assert np.array_equal(cut.gradient, kept.gradient)  # 110 steps retaken, bit for bit
    # the default budget is the module's
    monkeypatch.setattr(module, "KEEP_ALL_BYTES", 90 * r + 3 * c)
    by_default = fastvi.adjoint(model, q0, v0, cost, **kw)
    assert (by_default.stats["segment"], by_default.stats["checkpoints"]) == (90, 3)
    # no room even for the segment of least memory, ⌈√(200 c / r)⌉ = 17 steps: that one
    tiny = fastvi.adjoint(model, q0, v0, cost, max_memory=1024, **kw)
    assert (tiny.stats["segment"], tiny.stats["checkpoints"]) == (17, 12)
    assert np.array_equal(tiny.gradient, kept.gradient)
    with pytest.raises(ValueError, match="`checkpoint_every`.*or `max_memory`.*not both"):
        fastvi.adjoint(model, q0, v0, cost, checkpoint_every=10, max_memory=2**20, **kw)
    with pytest.raises(ValueError, match="`max_memory` must be >= 1"):
        fastvi.adjoint(model, q0, v0, cost, max_memory=0, **kw)


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


def test_the_models_derivatives_by_theta_agree_with_differences_of_the_step():
    exact = fastvi.scenes.double_pendulum(damping=0.3)
    twin = models.damped_double_pendulum_by_differences(0.3)
    assert exact.param_derivatives_exact and not twin.param_derivatives_exact
    q0, v0 = exact.initial_state(0.9, -0.4, 0.3, 1.1)
    run = dict(h=0.02, n_steps=100, wrt=("params",))
    a = fastvi.sensitivity(exact, q0, v0, **run)
    b = fastvi.sensitivity(twin, q0, v0, **run)
    assert np.array_equal(a.result.q, b.result.q)
    for x, y in ((a.dq, b.dq), (a.dv, b.dv), (a.dp, b.dp)):
        # the five-point differences' own error, about ε^(4/5) (measured 3e-13)
        assert np.abs(x - y).max() < 1e-11 * np.abs(y).max()


def test_a_run_compiles_only_the_parts_by_the_parameters_it_differentiates(monkeypatch):
    """A run by the initial state alone compiles no part by θ; one by θ compiles the model's
    derivatives (forward), their contraction (adjoint) or the differences of the step (a
    model without them), each beside the others for the same step: the columns by θ of a
    run after one by the state alone are still right."""
    from fastvi.kernels import tangent

    monkeypatch.setattr(tangent, "_THETA", {})  # what the runs below compile
    exact = fastvi.scenes.double_pendulum(damping=0.3)
    twin = models.damped_double_pendulum_by_differences(0.3)
    q0, v0 = exact.initial_state(0.9, -0.4, 0.3, 1.1)
    run = dict(h=0.02, n_steps=60)

    def kinds():
        return sorted({kind for _, kind in tangent._THETA})

    fastvi.sensitivity(exact, q0, v0, **run)
    assert kinds() == [tangent.THETA_NONE]
    a = fastvi.sensitivity(exact, q0, v0, wrt=("params",), **run)
    assert kinds() == [tangent.THETA_NONE, tangent.THETA_BY_MODEL]
    fastvi.adjoint(exact, q0, v0, lambda r: (np.ones((len(r.t), exact.n)), None), **run)
    assert kinds() == [tangent.THETA_NONE, tangent.THETA_BY_MODEL, tangent.THETA_PULL_BY_MODEL]
    b = fastvi.sensitivity(twin, q0, v0, wrt=("params",), **run)
    assert tangent.THETA_BY_DIFFERENCES in kinds()
    assert np.abs(b.dq).max() > 0.1
    assert np.abs(a.dq - b.dq).max() < 1e-11 * np.abs(b.dq).max()


@pytest.mark.parametrize("which", ["spring", "bead"])
def test_adjoint_by_theta_from_the_models_derivatives_equals_the_forward_derivative(which):
    spring, bead, xb = _symbolic()  # M(q, θ) and ∂T/∂q; g and G by θ
    model, q, v = ((spring, [1.4, 0.6], [0.3, -0.5]) if which == "spring"
                   else (bead, xb, [0.3, -0.2, 0.1]))
    assert model.param_derivatives_exact
    q0, v0 = fastvi.consistent_state(model, q, v)
    n, k = model.n, model.params.size
    rng = np.random.default_rng(3)
    Lq, Lv = rng.normal(size=(41, n)), rng.normal(size=(41, n))
    A = fastvi.adjoint(model, q0, v0, lambda r: (Lq, Lv), h=0.02, n_steps=40)
    D = rng.normal(size=(2 * n + k, 1))
    S = fastvi.sensitivity(model, q0, v0, h=0.02, n_steps=40, wrt=D)
    forward = np.sum(Lq * S.dq[:, :, 0]) + np.sum(Lv * S.dv[:, :, 0])
    grad = np.concatenate([A.grad_q0, A.grad_v0, A.grad_params])
    assert abs(grad @ D[:, 0] - forward) < 1e-11 * abs(forward)


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


def test_misused_arguments_are_named_before_or_after_the_run_never_ignored(double_pendulum,
                                                                            dp_start):
    """Each mistake raises an error that names the argument and says what to do: NaN is
    not reported as a shape, a complex cotangent is not cut to its real part, a direction
    argument that nothing reads is not dropped, and a member of an ensemble is named."""
    q0, v0 = dp_start
    dp, kw = double_pendulum, dict(h=0.01, n_steps=3)
    raw = np.zeros((8 + dp.params.size, 1))
    raw[2, 0] = np.nan
    with pytest.raises(ValueError, match=r"`wrt` as an array must be finite; column\(s\) \[0\]"):
        fastvi.sensitivity(dp, q0, v0, wrt=raw, **kw)
    with pytest.raises(ValueError, match="`param_index` chooses among .* add 'params' to `wrt`"):
        fastvi.sensitivity(dp, q0, v0, wrt=("q0",), param_index=[4], **kw)
    with pytest.raises(ValueError, match="no direction of `wrt` moves a parameter"):
        fastvi.sensitivity(dp, q0, v0, wrt=("q0", "v0"), initial_state=lambda p: (q0, v0), **kw)
    with pytest.raises(TypeError, match="`initial_state` must be a function"):
        fastvi.sensitivity(dp, q0, v0, wrt=("params",), initial_state=3, **kw)
    with pytest.raises(TypeError, match=r"`initial_state\(params\)` must return a pair"):
        fastvi.sensitivity(dp, q0, v0, wrt=("params",), initial_state=lambda p: (q0,), **kw)
    with pytest.raises(TypeError, match="`cotangent` must be a function"):
        fastvi.adjoint(dp, q0, v0, np.ones((4, 4)), **kw)
    with pytest.raises(ValueError, match="`param_index` names none"):
        fastvi.adjoint(dp, q0, v0, lambda r: (r.q, None), param_index=[],
                       initial_state=lambda p: (q0, v0), **kw)
    with pytest.raises(TypeError, match="must give `dJ_dq` as a real array"):
        fastvi.adjoint(dp, q0, v0, lambda r: (r.q * (1 + 1j), None), **kw)
    with pytest.raises(ValueError, match=r"`dJ_dv` with NaN or inf in 2 row\(s\), the first at "
                                         r"sample 2"):
        fastvi.adjoint(dp, q0, v0, lambda r: (r.q, np.where(r.t[:, None] > 0.015, np.nan, r.v)),
                       **kw)
    Q0, V0 = np.array([q0, q0, q0]), np.array([v0, v0, v0])
    Q0[2, 0] += 1e-3
    with pytest.raises(ValueError, match=r"member 2 \(`Q0\[2\]`, `V0\[2\]`, `params\[2\]`\): "
                                         r"`q0` violates the constraints"):
        fastvi.sensitivity_ensemble(dp, Q0, V0, **kw)


def test_fixed_parameters_are_left_out_and_naming_one_is_an_error():
    """A tree keeps each body's parent in ``params`` (what the callbacks read): a difference
    there changes the tree's shape, and the linearised step would find G M⁻¹ Gᵀ singular.
    The derivatives leave such entries out; naming one is an error before any run."""
    tree = fastvi.scenes.tree(2, 2)
    N = 5
    par = list(range(2 * N + 1, 3 * N + 1))
    assert tree.fixed_params == tuple(par)
    from fastvi.scenes.tree import parents

    assert np.array_equal(tree.params[par], parents(2, 2))
    q0, v0 = tree.initial_state(np.linspace(0.2, 0.6, N))
    k, n = tree.params.size, tree.n
    D, labels = fastvi._discrete.directions(("params",), n, k, None, tree.fixed_params)
    assert labels == [f"params[{l}]" for l in range(k) if l not in par]
    # errors come before the run: these calls compile nothing
    with pytest.raises(ValueError, match=r"names params\[12\], which the model marks fixed"):
        fastvi.sensitivity(tree, q0, v0, h=0.01, n_steps=2, wrt=("params",), param_index=[0, 12])
    with pytest.raises(ValueError, match=r"names params\[11\].*leave it out"):
        fastvi.adjoint(tree, q0, v0, lambda r: (r.q, None), h=0.01, n_steps=2, param_index=[11])
    raw = np.zeros((2 * n + k, 1))
    raw[2 * n + 13, 0] = 1.0
    with pytest.raises(ValueError, match=r"moves params\[13\]"):
        fastvi.sensitivity(tree, q0, v0, h=0.01, n_steps=2, wrt=raw)
    with pytest.raises(ValueError, match="marks fixed"):
        fastvi.TrajectoryFit(tree, np.zeros((3, 1)), lambda r: r.q[:, :1], param_index=[14],
                             h=0.01, q0=q0, v0=v0)
    with pytest.raises(ValueError, match="out of range"):
        fastvi.Model(1, params=(1.0,), mass=[1.0], potential=circle_V, potential_grad=circle_dV,
                     fixed_params=[1])
    with pytest.raises(TypeError, match="parameter indices"):
        fastvi.Model(1, params=(1.0,), mass=[1.0], potential=circle_V, potential_grad=circle_dV,
                     fixed_params=[0.0])
    import pickle

    assert pickle.loads(pickle.dumps(tree)).fixed_params == tree.fixed_params
    # a mechanism's tables: the header and every record's kind and bodies are fixed, its
    # geometry and loads are not
    from fastvi.bodies import packing, scenes

    top = scenes.heavy_top()
    fixed = set(top.fixed_params)
    assert set(range(packing.HEADER)) <= fixed and len(fixed) < top.params.size // 4
    rows = int(top.params[packing.H_ROWS])
    assert rows + packing.R_KIND in fixed and rows + packing.R_C0 not in fixed


def test_a_trees_derivatives_by_its_quantities_match_differences_of_runs():
    """The tree's parameters but the parents (fixed): lengths and masses (which move its
    potential), g and the damping, against central differences of whole runs; the adjoint
    by the same default parameters is the transpose (⟨λ, δx⟩ = δJ)."""
    tree = fastvi.scenes.tree(2, 2, damping=0.2)
    q0, v0 = tree.initial_state(np.linspace(0.3, 0.9, 5), np.linspace(0.5, -0.5, 5))
    method = "P2L-Q3G"
    S = fastvi.sensitivity(tree, q0, v0, h=0.05, n_steps=N_FD, method=method, wrt=("params",))
    free = [l for l in range(tree.params.size) if l not in tree.fixed_params]
    assert S.labels == [f"params[{l}]" for l in free]
    worst = 0.0
    for j, l in enumerate(free):
        e = np.zeros(tree.params.size)
        e[l] = 3e-7 * max(1.0, abs(tree.params[l]))
        fd = (_end(tree, q0, v0, tree.params + e, method)
              - _end(tree, q0, v0, tree.params - e, method)) / (2 * e[l])
        an = np.concatenate([S.dq[-1, :, j], S.dv[-1, :, j]])
        worst = max(worst, np.abs(an - fd).max() / max(1.0, np.abs(fd).max()))
    assert worst < 2e-7  # the differences' own error is ≈ 1e-9
    A = fastvi.adjoint(tree, q0, v0, lambda r: (r.q, r.v), h=0.05, n_steps=N_FD, method=method)
    assert A.param_index == free
    forward = sum(np.einsum("kn,knd->d", x, y) for x, y in ((S.result.q, S.dq), (S.result.v, S.dv)))
    assert np.allclose(A.grad_params, forward, rtol=1e-11, atol=0)


def nan_potential_grad_by_params(q, p, out):
    out[:, :] = np.nan


def circle_g_by_params(q, p, out):
    out[:, :] = 0.0
    out[2, 0] = -p[2]


def test_a_non_finite_derivative_by_theta_raises_never_a_nan_gradient():
    model = fastvi.Model(2, 1, params=(9.81, 3.0, 1.2), mass=[1.0, 1.0], potential=circle_V,
                         potential_grad=circle_dV, constraint=circle_g,
                         constraint_jacobian=circle_G, name="circle-nan",
                         param_derivatives=dict(potential_grad=nan_potential_grad_by_params,
                                                constraint=circle_g_by_params,
                                                constraint_jacobian=0))
    a = 1.2 * np.array([np.sin(0.7), -np.cos(0.7)])
    q0, v0 = a, np.array([-a[1], a[0]])
    run = dict(h=0.05, n_steps=4, check=False)  # the model check would name it first
    with pytest.raises(fastvi.IntegrationError, match="sensitivity is not defined"):
        fastvi.sensitivity(model, q0, v0, wrt=("params",), **run)
    with pytest.raises(fastvi.IntegrationError):
        fastvi.adjoint(model, q0, v0, lambda r: (np.ones((len(r.t), 2)), None), **run)
    with pytest.raises(fastvi.check.ModelCheckError, match="potential_grad/θ"):
        model.check(q0, v0)


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


# ----------------------------------------------------------------------------- saved results
# The derivative results are saved and read back bit for bit, and summarised in one line:
# each writes one ``.npz`` (no pickle) holding its trajectory ``Result``; the model is not
# written and ``load(path, model=…)`` gives it back. Ten steps of the damped double pendulum,
# in this file so that the kernels compile once in `make test` (one process a file).
H, STEPS, EVERY = 0.02, 10, 5
WRT, INDEX = ("q0", "v0", "params"), [5, 3]  # by the damping and the outer rod's length


@pytest.fixture(scope="module")
def damped():
    return fastvi.scenes.double_pendulum(damping=0.3)


@pytest.fixture(scope="module")
def start(damped):
    return damped.initial_state(0.9, -0.4, 0.3, 1.1)


@pytest.fixture(scope="module")
def sens(damped, start):
    return fastvi.sensitivity(damped, *start, h=H, n_steps=STEPS, save_every=EVERY, wrt=WRT,
                              param_index=INDEX)


@pytest.fixture(scope="module")
def adj(damped, start):
    rng = np.random.default_rng(3)
    K = STEPS // EVERY + 1
    Lq, Lv = rng.normal(size=(K, 4)), rng.normal(size=(K, 4))
    return fastvi.adjoint(damped, *start, lambda r: (Lq, Lv), h=H, n_steps=STEPS,
                          save_every=EVERY, param_index=INDEX)


def _same_array(a, b, what):
    assert isinstance(b, np.ndarray), what
    assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b), what


def _same_stats(a: dict, b: dict, what):
    """Equal dicts of scalars, NaN equal to NaN (a monitor that measured nothing)."""
    assert set(a) == set(b), what
    for k, x in a.items():
        y = b[k]
        same = type(x) is type(y) and (x == y or (x != x and y != y))
        assert same, f"{what}[{k!r}]: {x!r} != {y!r}"


def _same_result(a: Result, b: Result):
    """Every field of two trajectories equal, arrays bit for bit."""
    for f in dataclasses.fields(Result):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name == "sol":  # no dense output in these runs: nothing to save
            assert not x and not y
        elif f.name == "drawing":  # a scene's drawing is rebuilt from its recipe
            assert (x is None) == (y is None) and (x is None or x.scene == y.scene)
        elif isinstance(x, np.ndarray):
            _same_array(x, y, f"result.{f.name}")
        elif f.name == "stats":
            _same_stats(x, y, "result.stats")
        else:
            assert x == y and type(x) is type(y), f"result.{f.name}: {x!r} != {y!r}"


def _same_sensitivity(a: SensitivityResult, b: SensitivityResult):
    _same_result(a.result, b.result)
    for name in ("t", "dq", "dv", "dp", "params", "_dth"):
        _same_array(getattr(a, name), getattr(b, name), name)
    assert b.labels == a.labels and all(type(x) is str for x in b.labels)
    assert b._pidx == a._pidx and all(type(x) is int for x in b._pidx)
    assert b.t is b.result.t


# ------------------------------------------------------------------ SensitivityResult
def test_sensitivity_round_trips_bit_for_bit(sens, damped, tmp_path):
    assert sens._pidx == [3, 5] and sens._dth.shape == (10, 2)  # the saved private fields
    sens.save(tmp_path / "sens.npz")
    back = SensitivityResult.load(tmp_path / "sens.npz", model=damped)
    _same_sensitivity(sens, back)
    assert back._model is damped
    g0, gv0 = sens.tangent_residual()
    g1, gv1 = back.tangent_residual()
    assert np.array_equal(g0, g1) and np.array_equal(gv0, gv1)
    assert repr(back) == repr(sens) and back.summary() == sens.summary()


def test_tangent_residual_without_the_model_says_to_pass_it(sens, tmp_path):
    sens.save(tmp_path / "sens.npz")
    back = SensitivityResult.load(tmp_path / "sens.npz")
    _same_sensitivity(sens, back)  # all but the model is there
    with pytest.raises(ValueError,
                       match=r"needs the model.*SensitivityResult.load\(path, model=model\)"):
        back.tangent_residual()


def test_load_checks_the_model_against_the_run(sens, tmp_path):
    sens.save(tmp_path / "sens.npz")
    with pytest.raises(ValueError, match=r"`model` .*'double_pendulum' .*'double_pendulum-damped'"):
        SensitivityResult.load(tmp_path / "sens.npz", model=fastvi.scenes.double_pendulum())
    with pytest.raises(TypeError, match=r"`model` .*fastvi.Model.*got str"):
        SensitivityResult.load(tmp_path / "sens.npz", model="double_pendulum-damped")


def test_sensitivity_plot_draws_each_direction_and_the_tangent_residual(sens, tmp_path):
    matplotlib = pytest.importorskip("matplotlib")
    before = matplotlib.get_backend()
    fig = sens.plot(tmp_path / "sens.png")
    assert matplotlib.get_backend() == before
    assert (tmp_path / "sens.png").stat().st_size > 1000
    assert len(fig.axes) == 3  # δq, δp, the tangent residual
    lines = fig.axes[1].get_lines()
    assert [line.get_label() for line in lines] == sens.labels
    j = sens.labels.index("params[5]")
    drawn = np.asarray(lines[j].get_ydata(), dtype=float)
    norm = np.linalg.norm(sens.dp[:, :, j], axis=1)
    # p0 = M v0 with a constant M does not move with a parameter: an exact 0, no log to draw
    assert norm[0] == 0.0 and np.all(norm[1:] > 0)
    assert np.array_equal(drawn, np.where(norm > 0, norm, np.nan), equal_nan=True)
    residual = np.concatenate([np.asarray(x.get_ydata(), float) for x in fig.axes[2].get_lines()])
    assert np.nanmax(residual) < 1e-10
    fig = sens.plot(tmp_path / "two.png", directions=["params[5]", 0])
    assert [x.get_label() for x in fig.axes[0].get_lines()] == ["params[5]", sens.labels[0]]
    sens.save(tmp_path / "sens.npz")
    fig = SensitivityResult.load(tmp_path / "sens.npz").plot(tmp_path / "loaded.png")
    assert len(fig.axes) == 2  # no model: no tangent residual
    with pytest.raises(ValueError, match=r"`directions`: no direction is labelled 'q0\[9\]'"):
        sens.plot(tmp_path / "bad.png", directions=["q0[9]"])
    with pytest.raises(ValueError, match=r"`directions` entries .* indices from"):
        sens.plot(tmp_path / "bad.png", directions=[len(sens.labels)])
    with pytest.raises(ValueError, match=r"`directions` is empty"):
        sens.plot(tmp_path / "bad.png", directions=[])


def test_sensitivity_repr_and_summary_are_one_line(sens):
    text = repr(sens)
    assert "\n" not in text and len(text) < 200, text
    assert text == ("SensitivityResult(model='double_pendulum-damped', method='P2L-Q3G-NL-CN', "
                    "h=0.02, steps=10, samples=3, directions=10, status=SUCCESS)")
    line = sens.summary()
    assert "\n" not in line
    assert "3 samples × 10 directions (4 q0, 4 v0, 2 params)" in line and "status SUCCESS" in line
    assert f"max |∂q(t_end)| = {np.abs(sens.dq[-1]).max():.3e}" in line
    assert sens.success is True and sens.message == sens.result.message


# ------------------------------------------------------------------ AdjointResult
def test_adjoint_round_trips_bit_for_bit(adj, damped, tmp_path):
    adj.save(tmp_path / "adj.npz")
    back = AdjointResult.load(tmp_path / "adj.npz", model=damped)
    _same_result(adj.result, back.result)
    for name in ("grad_q0", "grad_v0", "grad_params", "lam_q", "lam_p"):
        _same_array(getattr(adj, name), getattr(back, name), name)
    assert back.param_index == adj.param_index == INDEX
    assert set(adj.stats) == {"checkpoints", "segment", "memory", "backward_time"}
    _same_stats(adj.stats, back.stats, "stats")
    assert repr(back) == repr(adj) and back.summary() == adj.summary()
    with pytest.raises(ValueError, match="`model`"):
        AdjointResult.load(tmp_path / "adj.npz", model=fastvi.scenes.pendulum())


def test_adjoint_summary_gives_the_gradients_norm(adj):
    norm = np.sqrt(sum(np.sum(g ** 2) for g in (adj.grad_q0, adj.grad_v0, adj.grad_params)))
    assert norm > 0
    line = adj.summary()
    assert "\n" not in line and f"|∇J| = {norm:.3e}" in line, line
    assert "3 samples, 2 parameters" in line and "status SUCCESS" in line
    assert f"{adj.stats['memory'] / 2**20:.3g} MiB" in line, line
    text = repr(adj)
    assert "\n" not in text and len(text) < 200 and f"|grad|={norm:.3g}" in text, text


# ------------------------------------------------------------------ EnsembleSensitivityResult
def _ensemble_of(members, stats):
    """An ensemble result put together from single runs, as sensitivity_ensemble stacks them
    (its own loop compiles for the slow tests only)."""
    runs = [s.result for s in members]
    stack = lambda objs, name: np.stack([getattr(o, name) for o in objs])  # noqa: E731
    return EnsembleSensitivityResult(
        members[0].t, stack(runs, "q"), stack(runs, "v"), stack(runs, "p"), stack(members, "dq"),
        stack(members, "dv"), stack(members, "dp"), members[0].labels,
        np.stack([s.params for s in members]), members, stats)


def _same_ensemble(a, b):
    assert len(b) == len(a) and b.labels == a.labels
    _same_stats(a.stats, b.stats, "stats")
    for name in ("t", "q", "v", "p", "dq", "dv", "dp", "params"):
        _same_array(getattr(a, name), getattr(b, name), name)
    for x, y in zip(a.members, b.members):
        _same_sensitivity(x, y)


def test_ensemble_round_trips_bit_for_bit(sens, damped, tmp_path):
    q0, v0 = damped.initial_state(2.0, 1.0)
    prm = damped.params.copy()
    prm[5] *= 1.5
    other = fastvi.sensitivity(damped, q0, v0, h=H, n_steps=STEPS, save_every=EVERY, wrt=WRT,
                               param_index=INDEX, params=prm)
    ens = _ensemble_of([sens, other], dict(members=2, threads=1, integration_time=0.25,
                                           compile_time=0.0, setup_time=0.5, wall_time=0.75))
    ens.save(tmp_path / "ens.npz")
    back = EnsembleSensitivityResult.load(tmp_path / "ens.npz", model=damped)
    _same_ensemble(ens, back)
    assert np.abs(back.dq[0, -1] - back.dq[1, -1]).max() > 1e-3  # two members, not one twice
    assert np.array_equal(back.members[1].tangent_residual()[1], other.tangent_residual()[1])
    assert repr(back) == repr(ens) and back.summary() == ens.summary()
    assert repr(ens) == ("EnsembleSensitivityResult(model='double_pendulum-damped', members=2, "
                         "method='P2L-Q3G-NL-CN', h=0.02, steps=10, samples=3, directions=10, "
                         "status=SUCCESS)")
    line = ens.summary()
    assert "ensemble of 2 members" in line and "SUCCESS, 1 threads, integration 0.25 s" in line
    assert ens.success.tolist() == [True, True]
    with pytest.raises(ValueError, match="model="):
        EnsembleSensitivityResult.load(tmp_path / "ens.npz").members[0].tangent_residual()


@pytest.mark.slow
def test_a_computed_ensemble_round_trips_bit_for_bit(damped, tmp_path):
    starts = [damped.initial_state(0.9, -0.4, 0.3, 1.1), damped.initial_state(2.0, 1.0)]
    Q0, V0 = np.array([q for q, _ in starts]), np.array([v for _, v in starts])
    ens = fastvi.sensitivity_ensemble(damped, Q0, V0, h=H, n_steps=STEPS, save_every=EVERY,
                                      wrt=WRT, param_index=INDEX, threads=2)
    ens.save(tmp_path / "ens.npz")
    back = EnsembleSensitivityResult.load(tmp_path / "ens.npz", model=damped)
    _same_ensemble(ens, back)
    assert repr(back) == repr(ens) and back.summary() == ens.summary()


# ------------------------------------------------------------------ files of another kind
def test_a_file_of_another_kind_names_the_class_that_wrote_it(sens, adj, tmp_path):
    sens.result.save(tmp_path / "run.npz")
    sens.save(tmp_path / "sens.npz")
    adj.save(tmp_path / "adj.npz")
    with pytest.raises(ValueError, match=r"was written by Result.save, not by SensitivityResult"
                                         r".save: read it with fastvi.Result.load"):
        SensitivityResult.load(tmp_path / "run.npz")
    with pytest.raises(ValueError, match=r"by SensitivityResult.save, not by Result.save"):
        Result.load(tmp_path / "sens.npz")
    with pytest.raises(ValueError, match=r"by AdjointResult.save.*fastvi.AdjointResult.load"):
        EnsembleSensitivityResult.load(tmp_path / "adj.npz")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(ValueError, match="no fastvi result wrote"):
        AdjointResult.load(tmp_path / "other.npz")
    np.save(tmp_path / "bare.npy", np.zeros(3))
    with pytest.raises(ValueError, match=r"one bare array"):
        Result.load(tmp_path / "bare.npy")


def test_a_result_file_without_its_class_name_is_a_result(sens, tmp_path):
    """Files that Result.save wrote before it named the class: the same arrays, no tag."""
    sens.result.save(tmp_path / "run.npz")
    with np.load(tmp_path / "run.npz") as data:
        old = {k: data[k] for k in data.files if k != "fastvi_kind"}
    assert "fastvi_kind" not in old and len(old) > 10
    np.savez_compressed(tmp_path / "old.npz", **old)
    _same_result(sens.result, Result.load(tmp_path / "old.npz"))
    with pytest.raises(ValueError, match=r"written by Result.save.*fastvi.Result.load"):
        SensitivityResult.load(tmp_path / "old.npz")


def test_progress_reports_the_steps_and_changes_no_bit(damped, start, capsys):
    quiet_run = fastvi.sensitivity(damped, *start, h=H, n_steps=120, save_every=7, wrt=WRT)
    shown = fastvi.sensitivity(damped, *start, h=H, n_steps=120, save_every=7, wrt=WRT,
                               progress=True)
    err = capsys.readouterr().err
    assert "fastvi sensitivity: 120/120 steps (100%)" in err and "t = 2.4" in err, err
    for name in ("dq", "dv", "dp"):
        assert np.array_equal(getattr(quiet_run, name), getattr(shown, name)), name
    assert np.array_equal(quiet_run.result.q, shown.result.q)
    with pytest.raises(TypeError, match="`progress` must be True or False"):
        fastvi.sensitivity(damped, *start, h=H, n_steps=3, progress="yes")


@pytest.mark.parametrize("checkpoint_every", [None, 13])
def test_adjoint_progress_reports_both_sweeps_and_changes_no_bit(damped, start, capsys,
                                                                 checkpoint_every):
    def cost(res):
        return np.cos(res.q), res.v

    kw = dict(h=H, n_steps=120, save_every=7, checkpoint_every=checkpoint_every)
    quiet_run = fastvi.adjoint(damped, *start, cost, **kw)
    shown = fastvi.adjoint(damped, *start, cost, progress=True, **kw)
    err = capsys.readouterr().err
    assert "fastvi adjoint: 240/240 steps (100%)" in err and "backward, t = 0" in err, err
    assert "forward, t = " in err, err
    assert np.array_equal(quiet_run.gradient, shown.gradient)
    assert np.array_equal(quiet_run.result.q, shown.result.q)
    with pytest.raises(TypeError, match="`progress` must be True or False"):
        fastvi.adjoint(damped, *start, cost, h=H, n_steps=3, progress="yes")


def test_a_large_models_start_terms_take_one_constraint_hessian_a_group():
    """The initial tangent of a large model takes ∂(G v)/∂q by the linearised step's groups
    of constraints that share no coordinate, one Hessian a group (a chain: two),
    and M⁻¹Gᵀ by the mass's reciprocals: the same terms, bit for bit, as one Hessian a
    constraint (``point``), which costs O(m n²)."""
    from fastvi import _discrete as disc
    from fastvi.kernels.tangent import point_terms
    N = 24
    ch = fastvi.scenes.chain(N, damping=0.3)
    q0, v0 = ch.initial_state(np.linspace(0.2, 1.4, N), 0.3 * np.sin(np.arange(N)))
    run = disc.prepare(ch, q0, v0, h=0.01, t_end=None, n_steps=2, t0=0.0, t_span=None,
                       method="P2L-Q3G", save_every=1, tol=1e-14, max_iter=50, newton="auto",
                       params=None, solver="auto", check=False, monitor=True, what="the test")
    assert run.ws.structured
    calls = []
    value = ch.callback_value
    ch.callback_value = lambda slot, *a, **k: calls.append(slot) or value(slot, *a, **k)
    try:
        M, G, Hv, Cq = disc._start_terms(run)
    finally:
        del ch.callback_value
    assert calls.count("constraint_hessian") == 2 < ch.m
    M0, G0, _, Hv0, Cq0 = point_terms(run.model_data, run.q0, run.v0, np.zeros(ch.m))
    assert np.abs(Hv0).max() > 0.1  # a moving chain: H_v matters
    for x, y in ((M, M0), (G, G0), (Hv, Hv0), (Cq, Cq0)):
        assert np.array_equal(x, y)


@pytest.mark.parametrize("scene", ["double_pendulum", "rotary_rod_slider"])
def test_the_initial_cotangent_is_the_transpose_of_the_initial_tangent(scene):
    """The adjoint pulls its cotangent on the consistent start back to the raw data and the
    parameters by the transposed formulas (``_discrete.initial_cotangent``), in O(m n),
    instead of forming the (2n + k) × n initial tangent: ⟨λ, T d⟩ = ⟨Tᵀ λ, d⟩ to round-off
    for random ``d`` and ``λ``, with a start defined by the parameters, constraints that
    the parameters move, and a configuration-dependent mass."""
    from fastvi import _discrete as disc

    if scene == "double_pendulum":
        model = fastvi.scenes.double_pendulum(damping=0.3)
        q0, v0 = _start(model.params)
        initial_state, pidx = _start, [2, 3, 5]  # the rod lengths move the start too
    else:
        model = fastvi.scenes.rotary_rod_slider(k=100.0)
        q0, v0 = fastvi.consistent_state(model, [0.3, 1.1, 0.3], [0.5, 0.2, 0.5])
        initial_state, pidx = None, [2, 3]
    n, k = model.n, len(model.params)
    run = disc.prepare(model, q0, v0, h=0.01, t_end=None, n_steps=2, t0=0.0, t_span=None,
                       method="P2L-Q3G", save_every=1, tol=1e-14, max_iter=50, newton="auto",
                       params=None, solver="auto", check=False, monitor=True, what="x")
    rng = np.random.default_rng(7)
    D = np.zeros((5, 2 * n + k))
    D[:, :2 * n] = rng.normal(size=(5, 2 * n))
    D[:, [2 * n + l for l in pidx]] = rng.normal(size=(5, len(pidx)))
    dq, dp, moved, _ = disc.initial_tangent(run, D, initial_state)
    assert moved == pidx
    lq, lp = rng.normal(size=n), rng.normal(size=n)
    pulled = disc.initial_cotangent(run, lq, lp, pidx, initial_state)
    forward = dq @ lq + dp @ lp
    backward = D[:, list(range(2 * n)) + [2 * n + l for l in pidx]] @ pulled
    assert np.abs(dq).max() > 0.1 and np.abs(pulled[2 * n:]).max() > 0.01  # θ moves the start
    assert np.allclose(backward, forward, rtol=1e-12, atol=1e-13 * np.abs(forward).max())


def test_the_start_takes_the_models_derivative_of_the_constraint_by_theta():
    """The tangent of the consistent start reads ``g_θ`` from the model's derivatives by θ
    (and drops ``G_θ v`` for ``constraint_jacobian=0``), as the steps do: it agrees with
    the twin model without derivatives, whose start takes five-point differences, and its
    tangent satisfies ``G δq + g_θ δθ = 0`` with the model's own ``g_θ`` to round-off."""
    from fastvi import _discrete as disc

    exact = fastvi.scenes.double_pendulum(damping=0.3)
    twin = models.damped_double_pendulum_by_differences(0.3)
    assert {"constraint", "constraint_jacobian"} <= exact.param_derivatives
    assert "constraint_jacobian" in exact.param_derivatives_zero and not twin.param_derivatives
    q0, v0 = exact.initial_state(0.9, -0.4, 0.3, 1.1)
    D = np.random.default_rng(3).normal(size=(4, 2 * exact.n + len(exact.params)))
    tangents = []
    for model in (exact, twin):
        run = disc.prepare(model, q0, v0, h=0.01, t_end=None, n_steps=2, t0=0.0, t_span=None,
                           method="P2L-Q3G", save_every=1, tol=1e-14, max_iter=50,
                           newton="auto", params=None, solver="auto", check=False,
                           monitor=True, what="x")
        tangents.append(disc.initial_tangent(run, D))
    (dq, dp, pidx, dth), (dq2, dp2, _, _) = tangents
    assert np.allclose(dq, dq2, rtol=0, atol=1e-9) and np.allclose(dp, dp2, rtol=0, atol=1e-9)
    g_th = exact.param_derivative_value("constraint", q0)[pidx]  # (k, m)
    G = exact.constraint_jacobian_value(q0)
    assert np.abs(dq @ G.T + dth @ g_th).max() < 1e-14 * np.abs(dq).max()


def test_the_terms_at_every_sample_are_those_of_one_point_at_a_time(monkeypatch):
    """``_discrete.sample_terms_by_chunk`` (one compiled loop over a chunk of samples) gives
    ``M``, ``G``, ``H_v`` and ``C_q`` of ``point_terms`` called at each sample on its own —
    the time of a time-dependent model set sample by sample, chunks of one sample or of
    all — and a sensitivity saved at every step of a configuration-dependent mass costs
    about the run, where a call a sample cost 1 ms (23 times the run)."""
    import time

    from fastvi import _discrete as disc
    from fastvi.kernels.tangent import point_terms

    from .test_singular_mass import A_, W_, _driven_follower, _state

    cases = [(models.polar_pendulum(), np.array([1.0, 0.5]), np.array([0.0, 0.3])),
             (_driven_follower(), *_state(0.9, 1.2, 0.0, A_ * W_))]
    for model, q0, v0 in cases:
        r = fastvi.integrate(model, q0, v0, h=0.01, n_steps=40)
        for size in (1, disc._SAMPLE_BYTES):
            monkeypatch.setattr(disc, "_SAMPLE_BYTES", size)
            starts = []
            for start, *terms in disc.sample_terms_by_chunk(model, model.params, r):
                starts.append(start)
                for j in range(terms[0].shape[0]):
                    i = start + j
                    M, G, _, Hv, Cq = point_terms(model.kernel_data(model.params, r.t[i]),
                                                  r.q[i], r.v[i], np.zeros(model.m))
                    for got, want in zip(terms, (M, G, Hv, Cq)):
                        assert np.array_equal(got[j], want)
            assert starts == (list(range(41)) if size == 1 else [0])
    model, q0, v0 = cases[0]

    def cost(every):
        fastvi.sensitivity(model, q0, v0, h=0.01, n_steps=2000, save_every=every)
        best = np.inf
        for _ in range(3):
            t = time.process_time()
            fastvi.sensitivity(model, q0, v0, h=0.01, n_steps=2000, save_every=every)
            best = min(best, time.process_time() - t)
        return best

    assert cost(1) < 4 * cost(2000)  # measured 1.93 s against 0.083 s before


def test_the_callbacks_and_their_differences_by_theta_at_every_sample_are_those_of_one_sample_at_a_time():
    """``kernels.tangent.sample_callback`` (one compiled loop over the samples) gives the
    model's constraint, its Jacobian and ``g_t`` — given, or five-point differences in time
    — of :class:`fastvi.Model`'s evaluation at each sample on its own, bit for bit; the
    differences by θ of :meth:`SensitivityResult.tangent_residual` and of the momentum built
    on them are those of one sample at a time (``theta_derivative`` of the model's own
    evaluations) to round-off."""
    import importlib

    from fastvi import _discrete as disc
    from fastvi.kernels import layout as lay
    from fastvi.kernels.tangent import sample_callback

    from .test_singular_mass import A_, W_, _driven_follower, _state

    kap = importlib.import_module("fastvi.scenes.kapitza")
    pk = fastvi.scenes.kapitza_pendulum()
    unrated = fastvi.Model(2, 1, params=pk.params, mass=pk.mass_matrix_constant, potential=kap._V,
                           potential_grad=kap._dV, potential_hessian=0, constraint=kap._g,
                           constraint_jacobian=kap._G, constraint_hessian=kap._ddg,
                           time_dependent=True)  # g_t by differences in time
    cases = [(models.polar_pendulum(), np.array([1.0, 0.5]), np.array([0.0, 0.3])),
             (_driven_follower(), *_state(0.9, 1.2, 0.0, A_ * W_)),
             (unrated, *fastvi.consistent_state(unrated, np.array([0.6, -0.8]),
                                                np.array([0.5, 0.3]), fixed=[0]))]
    for model, q0, v0 in cases:
        prm, n, m = model.params, model.n, model.m
        r = fastvi.integrate(model, q0, v0, h=0.01, n_steps=40)
        md = model.kernel_data(prm, float(r.t[0]))
        con = sample_callback(md, lay.CON, r.q, r.t, (m,))
        jac = sample_callback(md, lay.CJAC, r.q, r.t, (m, n))
        rate = disc._constraint_rates(model, md, r.q, r.t)
        gth, hth = disc.constraints_by_theta(model, prm, r, 0, r.t.shape[0], range(len(prm)))
        pth = disc.momentum_by_theta(model, prm, r, 0, r.t.shape[0], range(len(prm)))
        for i, (q, p, v, t) in enumerate(zip(r.q, r.p, r.v, r.t)):
            assert np.array_equal(con[i], model.constraint_value(q, prm, t))
            assert np.array_equal(jac[i], model.constraint_jacobian_value(q, prm, t))
            assert np.array_equal(rate[i], model.constraint_time_derivative_value(q, prm, t))
            for c in range(len(prm)):
                want_g = disc.theta_derivative(lambda th: model.constraint_value(q, th, t), prm, c)
                want_h = disc.theta_derivative(
                    lambda th: model.constraint_jacobian_value(q, th, t)
                    @ disc.velocity(model, q, p, th, t)
                    + model.constraint_time_derivative_value(q, th, t), prm, c)
                want_p = disc.theta_derivative(lambda th: disc.momentum(model, q, v, th, t), prm, c)
                assert np.array_equal(gth[i, c], want_g)
                scale = 1.0 + np.abs(want_h).max()
                assert np.abs(hth[i, c] - want_h).max() < 1e-9 * scale, (model.name, i, c)
                assert np.abs(pth[i, c] - want_p).max() < 1e-9 * (1.0 + np.abs(want_p).max())


def test_the_tangent_residual_by_the_parameters_costs_about_the_derivative():
    """The differences by θ of ``tangent_residual`` take the callbacks at every sample in
    one compiled loop a point in θ: on a configuration-dependent mass saved at every step,
    checking the derivatives by all parameters costs about as much as computing them,
    where a Python call a sample and callback cost 15 s on 10⁴ steps (250 runs)."""
    import time

    model = models.polar_pendulum()
    q0, v0 = np.array([1.0, 0.5]), np.array([0.0, 0.3])
    kw = dict(h=0.01, n_steps=2000, wrt=("q0", "v0", "params"))
    S = fastvi.sensitivity(model, q0, v0, **kw)
    S.tangent_residual()
    best_s = best_r = np.inf
    for _ in range(3):
        t = time.process_time()
        S = fastvi.sensitivity(model, q0, v0, **kw)
        best_s = min(best_s, time.process_time() - t)
        t = time.process_time()
        g, gv = S.tangent_residual()
        best_r = min(best_r, time.process_time() - t)
    assert max(g.max(), gv.max()) < 1e-12
    assert best_r < 4 * best_s
