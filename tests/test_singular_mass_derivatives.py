"""Derivatives of the discrete flow for a constant mass matrix that is only semidefinite.

The model of ``test_singular_mass``: a pendulum carrying a massless point rigidly, so
``M = diag(m, m, 0, 0)`` is singular but definite on the tangent space of the constraints.
On the constraints ``p = M v = M̄(q) v`` with the definite ``M̄ = M + Gᵀ W G``, and the
linearised step differentiates the projection of that configuration-dependent mass; where
the pivot moves, ``p = M̄ v + Gᵀ W g_t``. Also Brüls' lamina (the heavy top). The
references are independent of that code: differences of whole runs (the step alone), the
simple pendulum's angle and period from SciPy, the adjoint's identity with the forward
derivative, and the symplectic form.
"""

import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fastvi

from .test_sensitivity import adjoint_gap
from .test_singular_mass import A_, C_, G_, L_, W_, _driven_follower, _follower, _state

N_FD = 20  # steps of h = 0.05 (t = 1)


def _end(model, q0, v0, prm, method, h=0.05, n=N_FD):
    with warnings.catch_warnings():  # the perturbed starts are projected: that is the point
        warnings.simplefilter("ignore")
        r = fastvi.integrate(model, q0, v0, h=h, n_steps=n, params=prm, method=method)
    return np.concatenate([r.q[-1], r.v[-1], r.p[-1]])


def _against_differences(model, q0, v0, method, eps):
    """The largest error, relative, of the forward derivatives of ``(q, v, p)`` at the end
    of ``N_FD`` steps by ``(q0, v0, θ)`` against central differences of whole runs with
    steps ``eps`` (times ``max(1, |θ_l|)``), and the sensitivity result."""
    S = fastvi.sensitivity(model, q0, v0, h=0.05, n_steps=N_FD, method=method,
                           wrt=("q0", "v0", "params"))
    n, k = model.n, model.params.size
    worst = 0.0
    for j in range(2 * n + k):
        e = np.zeros(2 * n + k)
        e[j] = eps * (1.0 if j < 2 * n else max(1.0, abs(model.params[j - 2 * n])))
        fp = _end(model, q0 + e[:n], v0 + e[n:2 * n], model.params + e[2 * n:], method)
        fm = _end(model, q0 - e[:n], v0 - e[n:2 * n], model.params - e[2 * n:], method)
        fd = (fp - fm) / (2 * e[j])
        an = np.concatenate([S.dq[-1, :, j], S.dv[-1, :, j], S.dp[-1, :, j]])
        worst = max(worst, np.abs(an - fd).max() / max(1.0, np.abs(fd).max()))
    return worst, S


@pytest.fixture(scope="module")
def follower():
    return _follower()


@pytest.mark.parametrize("method", ["P2L-Q3G", "P3L-Q4G"])
def test_derivatives_of_a_singular_mass_match_differences_of_whole_runs(follower, method):
    model = follower
    q0, v0 = _state(0.9, 1.2)
    worst, _ = _against_differences(model, q0, v0, method, 3e-7)
    # the differences' own error is ≈ 1e-9. δp too: an error of δp along Gᵀ leaves the
    # next steps' δq and δv alone (the multiplier at the step's start absorbs it)
    assert worst < 2e-7


def test_derivatives_of_a_singular_mass_stay_in_the_tangent_space(follower):
    model = follower
    q0, v0 = _state(0.9, 1.2)
    S = fastvi.sensitivity(model, q0, v0, h=0.05, n_steps=40, wrt=("q0", "v0", "params"))
    g, gv = S.tangent_residual()
    size = max(1.0, np.abs(S.dq).max(), np.abs(S.dp).max())
    assert g.max() < 1e-12 * size
    assert gv.max() < 1e-10 * size  # its parameters' part is a five-point difference
    # the massless point follows the pendulum, (u, w) = (x + c, y): δ(u, w) = δ(x, y), plus
    # (1, 0) in the direction of c
    shift = np.zeros((2, 2 * model.n + 4))
    shift[0, -1] = 1.0
    assert np.abs(S.dq[:, 2:] - S.dq[:, :2] - shift).max() < 1e-12 * size
    # the start's q0 columns are projected onto ker G: rank n − m = 1
    sv = np.linalg.svd(S.dq[0][:, :model.n], compute_uv=False)
    assert np.sum(sv > 1e-12 * sv[0]) == model.n - model.m


def _angle_derivative(model, theta0, omega0, h, method, T=1.0):
    """∂θ(T)/∂(θ0, ω0) of the run: the pendulum's angle θ = atan2(x, −y)."""
    c, s = np.cos(theta0), np.sin(theta0)
    dq = np.array([[L_ * c, 0.0], [L_ * s, 0.0], [L_ * c, 0.0], [L_ * s, 0.0]])
    dv = np.array([[-L_ * s * omega0, L_ * c], [L_ * c * omega0, L_ * s],
                   [-L_ * s * omega0, L_ * c], [L_ * c * omega0, L_ * s]])
    D = np.vstack([dq, dv, np.zeros((model.params.size, 2))])
    S = fastvi.sensitivity(model, *_state(theta0, omega0), h=h, t_end=T, wrt=D, method=method,
                           save_every=10**6)
    x, y = S.result.q[-1, :2]
    return (-y * S.dq[-1, 0] + x * S.dq[-1, 1]) / (x * x + y * y)


def _angle_reference(theta0, omega0, T=1.0):
    """∂θ(T)/∂(θ0, ω0) of the simple pendulum: SciPy's variational equations, DOP853."""
    def rhs(t, y):
        th, om, a, b, c, d = y
        k = -(G_ / L_) * np.cos(th)
        return [om, -(G_ / L_) * np.sin(th), c, d, k * a, k * b]
    sol = solve_ivp(rhs, (0.0, T), [theta0, omega0, 1.0, 0.0, 0.0, 1.0], method="DOP853",
                    rtol=1e-13, atol=1e-14)
    return sol.y[2:4, -1]


def test_derivatives_of_a_singular_mass_converge_at_the_methods_order(follower):
    ref = _angle_reference(1.1, 0.4)
    for method, order in [("P2L-Q3G", 4), ("P3L-Q4G", 6)]:
        errs = [np.abs(_angle_derivative(follower, 1.1, 0.4, h, method) - ref).max()
                for h in (0.1, 0.05, 0.025)]
        rates = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
        assert errs[-1] < 1e-5
        assert np.all(rates > order - 0.4), (method, errs, rates)


def test_the_adjoint_of_a_singular_mass_is_the_forward_derivative(follower):
    assert adjoint_gap(follower, *_state(0.9, 1.2), h=0.05, n_steps=60) < 1e-11


def test_the_tangent_map_of_a_singular_mass_is_symplectic_on_the_constraints(follower):
    model = follower
    q0, v0 = _state(0.9, 1.2)
    Z = fastvi.tangent_space(model, q0, v0)
    assert Z.shape == (8, 2)  # 2(n − m)
    # δv0 of each (δq0, δp0): p = M̄(q) v on the constraints
    M = model.mass_matrix(q0)
    Gq = model.constraint_jacobian_value(q0)
    from fastvi._validate import mass_metric

    Mb = mass_metric(M, Gq)
    assert np.linalg.matrix_rank(M) == 2 and np.allclose(Mb @ v0, M @ v0, atol=1e-14)
    # ∂(M̄ v0)/∂q by central differences, a reference independent of the kernels
    Cq = np.empty((4, 4))
    for j in range(4):
        e = np.zeros(4)
        e[j] = 1e-6
        Cq[:, j] = (mass_metric(M, model.constraint_jacobian_value(q0 + e)) @ v0
                    - mass_metric(M, model.constraint_jacobian_value(q0 - e)) @ v0) / 2e-6
    dv = np.linalg.solve(Mb, Z[4:] - Cq @ Z[:4])
    D = np.vstack([Z[:4], dv, np.zeros((model.params.size, 2))])
    S = fastvi.sensitivity(model, q0, v0, h=0.01, n_steps=2000, wrt=D, save_every=2000)
    # the directions were tangent: the start keeps them (to the differences' error)
    assert np.abs(np.vstack([S.dq[0], S.dp[0]]) - Z).max() < 1e-8
    Y = np.vstack([S.dq[-1], S.dp[-1]])
    J = np.block([[np.zeros((4, 4)), np.eye(4)], [-np.eye(4), np.zeros((4, 4))]])
    W0 = np.vstack([S.dq[0], S.dp[0]]).T @ J @ np.vstack([S.dq[0], S.dp[0]])
    W1 = Y.T @ J @ Y
    assert np.abs(W0).max() > 0.1
    assert np.abs(W1 - W0).max() < 1e-12 * max(1.0, np.abs(Y).max()) ** 2


def test_the_heavy_top_a_lamina_has_derivatives_matching_differences_of_runs():
    from fastvi.bodies import scenes

    top = scenes.heavy_top()  # one director of zero inertia
    assert top.mass_singular
    q0, v0 = top.initial_state()
    n, h, N = top.n, 0.002, 25
    S = fastvi.sensitivity(top, q0, v0, h=h, n_steps=N, wrt=("v0",))
    worst = 0.0
    for j in range(n):
        e = np.zeros(n)
        e[j] = 1e-6
        fp = _end(top, q0, v0 + e, top.params, "P2L-Q3G", h=h, n=N)
        fm = _end(top, q0, v0 - e, top.params, "P2L-Q3G", h=h, n=N)
        fd = (fp - fm) / 2e-6
        an = np.concatenate([S.dq[-1, :, j], S.dv[-1, :, j], S.dp[-1, :, j]])
        worst = max(worst, np.abs(an - fd).max() / max(1.0, np.abs(fd).max()))
    assert worst < 1e-6


@pytest.fixture(scope="module")
def driven():
    return _driven_follower()


def test_derivatives_of_a_singular_mass_with_moving_constraints_match_differences(driven):
    """The pivot moves as ``A sin ωt``: the step's impulse is that of ``M̄``, larger than
    ``M``'s by ``W g_t``, and ``p = M̄ v + Gᵀ W g_t`` on the constraints."""
    model = driven
    q0, v0 = _state(0.9, 1.2, 0.0, A_ * W_)
    method = "P2L-Q3G"
    # small steps: a move of the pivot's frequency leaves v0 off the hidden constraint by
    # about A t ω δω, which the start projects only below its consistency tolerance
    worst, S = _against_differences(model, q0, v0, method, 3e-8)
    assert worst < 2e-7
    g, gv = S.tangent_residual()
    size = max(1.0, np.abs(S.dq).max(), np.abs(S.dp).max())
    assert g.max() < 1e-12 * size and gv.max() < 1e-10 * size
    assert adjoint_gap(model, q0, v0, h=0.05, n_steps=N_FD, method=method) < 1e-11


def test_the_structured_solves_of_a_singular_mass_are_refused_by_name(follower):
    q0, v0 = _state(0.9, 1.2)
    for call in (lambda: fastvi.sensitivity(follower, q0, v0, h=0.05, n_steps=2, solver="banded"),
                 lambda: fastvi.adjoint(follower, q0, v0, lambda r: (r.q, None), h=0.05,
                                        n_steps=2, solver="banded")):
        with pytest.raises(ValueError, match='structured solves.*singular.*solver="dense"'):
            call()


def test_the_follower_is_the_simple_pendulum(follower):
    """The reference above is the right one: the run's angle is SciPy's pendulum's."""
    r = fastvi.integrate(follower, *_state(1.1, 0.4), h=0.01, t_end=1.0, method="P3L-Q4G")
    x, y = r.q[-1, :2]
    sol = solve_ivp(lambda t, z: [z[1], -(G_ / L_) * np.sin(z[0])], (0.0, 1.0), [1.1, 0.4],
                    method="DOP853", rtol=1e-13, atol=1e-14)
    assert abs(np.arctan2(x, -y) - sol.y[0, -1]) < 1e-9
    assert np.abs(r.q[:, 2] - r.q[:, 0] - C_).max() < 1e-12


@pytest.mark.slow
def test_an_ensembles_members_of_a_singular_mass_are_the_single_runs(follower):
    model = follower
    starts = [_state(0.9, 1.2), _state(-0.4, 0.3)]
    Q0, V0 = np.array([s[0] for s in starts]), np.array([s[1] for s in starts])
    kw = dict(h=0.05, n_steps=30, wrt=("q0", "v0", "params"), save_every=5)
    ens = fastvi.sensitivity_ensemble(model, Q0, V0, threads=2, **kw)
    for i in range(2):
        one = fastvi.sensitivity(model, Q0[i], V0[i], **kw)
        assert np.array_equal(one.result.q, ens.q[i])
        for name in ("dq", "dv", "dp"):
            assert np.array_equal(getattr(one, name), getattr(ens, name)[i]), (i, name)
    assert np.abs(ens.dq[0, -1] - ens.dq[1, -1]).max() > 0.1


def _pendulum_period(amplitude):
    """The simple pendulum's period from rest at ``amplitude``: SciPy, twice the time to the
    far turning point."""
    def turn(t, y):
        return y[1]
    turn.direction = 1
    sol = solve_ivp(lambda t, y: [y[1], -(G_ / L_) * np.sin(y[0])], (0.0, 10.0),
                    [amplitude, 0.0], events=turn, rtol=1e-13, atol=1e-14)
    return 2.0 * sol.t_events[0][0]


def test_a_periodic_orbit_of_a_singular_mass_is_the_pendulums(follower):
    T = _pendulum_period(0.8)
    orb = fastvi.periodic_orbit(follower, *_state(0.8, 0.02), period=T, n_steps=400)
    assert orb.residual < 1e-12
    # its amplitude, from its energy per unit mass: cos θ_max = cos θ0 − L ω0² / (2 g)
    x, y = orb.q0[:2]
    theta0, omega0 = np.arctan2(x, -y), (x * orb.v0[1] - y * orb.v0[0]) / L_ ** 2
    amplitude = np.arccos(np.cos(theta0) - L_ * omega0 ** 2 / (2 * G_))
    assert abs(amplitude - 0.8) < 1e-6  # the method's error at h = T / 400
    # one degree of freedom, conservative: a pair of multipliers 1 (λ and 1/λ)
    lam = np.sort(np.abs(orb.multipliers))
    assert abs(lam[0] * lam[1] - 1.0) < 1e-10 and np.abs(lam - 1.0).max() < 1e-5
