"""The two Newton variants of the step kernel: the mechanics matrix and the full Newton.

The mechanics solve is checked against a dense solve of the mechanics matrix built here
from its definition (``docs/method.md`` §10), independently of the kernel's Schur
elimination; both variants must solve the same step equations, and the fallback must take
over where the mechanics matrix stops contracting (a stiff spring).
"""

import numpy as np
import pytest

import fastvi
from fastvi.kernels import layout as lay
from fastvi.kernels.step import _mech_solve
from fastvi.tables import lagrange_basis
from tests.kernel_helpers import one_step

from . import models


def _mechanics_matrix(meth, h, M, Gs):
    """K̃ = [(1/h) A ⊗ M, −B; C, 0] from the basis at the quadrature and constraint points
    (evaluated afresh, not from the kernel's tables); Gs[j] = G at constraint point j."""
    s, J = meth.s, meth.J
    n = M.shape[0]
    m = Gs[0].shape[0]
    _, dl = lagrange_basis(meth.tau, meth.c)  # ℓ'_ν(c_i), (s+1, r)
    lc, _ = lagrange_basis(meth.tau, meth.d)  # ℓ_ν(d_j), (s+1, J+1)
    N = s * n + J * m
    K = np.zeros((N, N))
    for nu in range(s):
        for mu in range(1, s + 1):
            a = np.sum(meth.b * dl[nu] * dl[mu])
            K[nu * n:(nu + 1) * n, (mu - 1) * n:mu * n] = a / h * M
        for j in range(J):
            K[nu * n:(nu + 1) * n, s * n + j * m:s * n + (j + 1) * m] = -lc[nu, j] * Gs[j].T
    for j in range(1, J + 1):
        for mu in range(1, s + 1):
            K[s * n + (j - 1) * m:s * n + j * m, (mu - 1) * n:mu * n] = lc[mu, j] * Gs[j]
    return K


@pytest.mark.parametrize("inverse", [True, False], ids=["inverted", "factored"])
@pytest.mark.parametrize("name", ["P2L-Q3G", "P3L-Q4G", "P2L-Q3G-NE-CE", "P3L-Q4G-CG2"])
def test_mechanics_solve_equals_a_dense_solve_of_the_mechanics_matrix(double_pendulum, dp_start, name,
                                                                       inverse):
    """Both forms of the impulses' solve: the Schur complement inverted (kept for a step) or
    factored (rebuilt at every iteration where the iteration is Newton's method)."""
    meth = fastvi.method(name)
    model = double_pendulum
    q, v = dp_start
    p = model.mass_matrix(q) @ v
    # a real step leaves M̄⁻¹, the G_j and the factored Schur complement in the workspace
    st, *_, ws = one_step(model, meth, 0.01, q, p, v)
    assert st == 0
    n, m, s, J = model.n, model.m, meth.s, meth.J
    N = s * n + J * m
    Gs = [ws.G[j].copy() for j in range(J + 1)]
    rhs = np.random.default_rng(1).normal(size=N)
    # the kernel's Schur complement is the one of the step's first iterate: rebuild it from
    # the G_j the workspace holds now, as newton_mech does on its first iteration
    from fastvi.kernels.step import _mech_rows, _schur

    md = model.kernel_data()
    for j in range(J):
        _mech_rows(md, ws, j, n, m)
    assert _schur(meth.kernel_tables, 0.01, ws, n, m, J, inverse) == 0
    ws.R[:N] = rhs
    _mech_solve(md, meth.kernel_tables, 0.01, ws, n, m, s, J, inverse)
    expected = np.linalg.solve(_mechanics_matrix(meth, 0.01, model.mass_matrix(q), Gs), rhs)
    assert np.max(np.abs(ws.R[:N] - expected)) < 1e-12 * np.max(np.abs(expected))


def test_a_vanishing_pivot_of_the_schur_complement_takes_row_interchanges(double_pendulum, dp_start):
    """The Schur complement is inverted without row interchanges where its pivots allow it.
    With the constraint rows at q_k made M̄⁻¹-orthogonal to those at the first constraint
    point, its first pivot vanishes: the pivot-free inverse refuses it, the kernel rebuilds it
    and inverts it with partial pivoting, and the mechanics solve still equals the dense
    solve of the mechanics matrix."""
    from fastvi.kernels.linalg import invert_unpivoted
    from fastvi.kernels.step import _mech_rows, _schur, _schur_build

    meth = fastvi.method("P2L-Q3G")
    model = double_pendulum
    q, v = dp_start
    M = model.mass_matrix(q)
    st, *_, ws = one_step(model, meth, 0.01, q, M @ v, v)
    assert st == 0
    n, m, s, J = model.n, model.m, meth.s, meth.J
    N = s * n + J * m
    Minv = np.linalg.inv(M)
    g1, u = ws.G[1][0].copy(), ws.G[0][0].copy()
    ws.G[0][0] = u - (g1 @ Minv @ u) / (g1 @ Minv @ g1) * g1
    Gs = [ws.G[j].copy() for j in range(J + 1)]
    md = model.kernel_data()
    for j in range(J):
        _mech_rows(md, ws, j, n, m)
    _schur_build(meth.kernel_tables, 0.01, ws, n, m, J)
    assert abs(ws.Sc[0, 0]) < 1e-15 * np.abs(ws.Sc[:J * m, :J * m]).max()
    assert invert_unpivoted(ws.Sc.copy(), J * m) == 1
    assert _schur(meth.kernel_tables, 0.01, ws, n, m, J, True) == 0
    rhs = np.random.default_rng(2).normal(size=N)
    ws.R[:N] = rhs
    _mech_solve(md, meth.kernel_tables, 0.01, ws, n, m, s, J, True)
    expected = np.linalg.solve(_mechanics_matrix(meth, 0.01, M, Gs), rhs)
    assert np.max(np.abs(ws.R[:N] - expected)) < 1e-11 * np.max(np.abs(expected))


@pytest.mark.parametrize("name", ["P2L-Q3G", "P3L-Q4G", "P4L-Q5G"])
def test_both_variants_solve_the_same_step_equations(double_pendulum, dp_start, name):
    """100 steps of this chaotic motion: the trajectories agree to round-off growth
    (measured ≤ 1e-12), each keeps the constraints at round-off, and "auto" never falls back."""
    q0, v0 = dp_start
    ra = fastvi.integrate(double_pendulum, q0, v0, h=0.01, n_steps=100, method=name)
    rf = fastvi.integrate(double_pendulum, q0, v0, h=0.01, n_steps=100, method=name, newton="full")
    assert np.max(np.abs(ra.q - rf.q)) < 1e-10
    assert np.max(np.abs(ra.p - rf.p)) < 1e-9
    assert ra.stats["full_newton_steps"] == 0
    assert ra.constraint_residual.max() < 1e-14 and rf.constraint_residual.max() < 1e-14
    assert ra.velocity_residual.max() < 1e-13


def test_configuration_dependent_mass_uses_the_mechanics_matrix_too():
    """M(q) frozen at q_k in the matrix: still the same solution as the full Newton."""
    model = models.polar_pendulum(spring=50.0)
    q0, v0 = np.array([1.1, 0.7]), np.array([0.4, 1.3])
    ra = fastvi.integrate(model, q0, v0, h=0.01, n_steps=500, method="P2L-Q3G")
    rf = fastvi.integrate(model, q0, v0, h=0.01, n_steps=500, method="P2L-Q3G", newton="full")
    assert ra.stats["full_newton_steps"] == 0
    assert np.max(np.abs(ra.q - rf.q)) < 1e-11
    assert np.max(np.abs(ra.energy - rf.energy)) < 1e-11


def test_stiff_spring_falls_back_to_the_full_newton():
    """k = 10^6, ωh ≈ 4.5: the mechanics matrix (Hessians dropped) cannot contract, every
    step ends on the full Newton, and the run is as accurate as with newton="full"."""
    model = fastvi.scenes.rotary_rod_slider(k=1e6)
    q0, v0 = model.initial_state(theta=0.0)
    ra = fastvi.integrate(model, q0, v0, h=0.01, n_steps=2000, method="P2L-Q3G", save_every=10)
    rf = fastvi.integrate(model, q0, v0, h=0.01, n_steps=2000, method="P2L-Q3G", save_every=10,
                          newton="full")
    assert ra.success and ra.stats["full_newton_steps"] > 0
    assert ra.stats["full_newton_steps"] <= 2000 // lay_full_hold() + 1  # one detour per hold
    assert np.abs(ra.energy_error).max() < 1e-6  # measured 8e-8, as the full Newton
    assert np.max(np.abs(ra.q - rf.q)) < 1e-8


def lay_full_hold():
    from fastvi.kernels.step import FULL_HOLD

    return FULL_HOLD


def test_only_underintegrated_methods_lack_the_mechanics_matrix():
    assert not fastvi.method("P3L-Q2G").kernel_tables.mech  # r < s: A singular
    assert not fastvi.method("P2L-Q1G").kernel_tables.mech
    assert fastvi.method("P2L-Q3G").kernel_tables.mech
    assert fastvi.method("P2L-Q2G").kernel_tables.mech
    assert fastvi.method("P1L-Q2G").kernel_tables.mech  # s = 1 as well: measured faster
    assert fastvi.method("P1L-Q1G").kernel_tables.mech


def test_degree_one_mechanics_iteration_is_newtons_method_for_a_linear_potential(double_pendulum, dp_start):
    """s = 1 under "auto" takes the mechanics iteration. For a linear potential and a constant
    mass its matrix, with the Schur complement rebuilt at every iteration, is the exact
    Newton matrix: the same iterations as newton="full", each far cheaper, the same
    equations to the same tolerance (trajectories agree to round-off over a short stretch)."""
    q0, v0 = dp_start
    ra = fastvi.integrate(double_pendulum, q0, v0, h=0.01, n_steps=200, method="P1L-Q2G")
    rf = fastvi.integrate(double_pendulum, q0, v0, h=0.01, n_steps=200, method="P1L-Q2G", newton="full")
    assert ra.stats["full_newton_steps"] == 0
    assert ra.stats["newton_iterations"] == rf.stats["newton_iterations"]  # measured 600 and 600
    assert np.max(np.abs(ra.q - rf.q)) < 1e-11
    assert np.max(np.abs(ra.p - rf.p)) < 1e-10
    assert np.max(ra.constraint_residual) < 1e-14


def test_degree_one_mechanics_iteration_with_a_nonlinear_potential_converges_linearly():
    """With a spring (∇²V ≠ 0) the s = 1 mechanics matrix drops the potential Hessian: more
    iterations than the full Newton, the strict stop, the same solution."""
    model = fastvi.scenes.rotary_rod_slider()
    q0, v0 = model.initial_state()
    ra = fastvi.integrate(model, q0, v0, h=0.01, n_steps=200, method="P1L-Q2G")
    rf = fastvi.integrate(model, q0, v0, h=0.01, n_steps=200, method="P1L-Q2G", newton="full")
    assert ra.stats["full_newton_steps"] == 0
    assert ra.stats["newton_iterations"] > 1.5 * rf.stats["newton_iterations"]  # measured 7.4 and 2.75 a step
    assert np.max(np.abs(ra.q - rf.q)) < 1e-11
    assert np.max(ra.constraint_residual) < 1e-14


def test_newton_option_is_validated(double_pendulum, dp_start):
    with pytest.raises(ValueError, match="`newton` must be one of"):
        fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=1, newton="quasi")


def _sphere_and_spring():
    """Body A (1 kg) on the unit sphere, body B (0.5 kg) hung from it by a stiff spring of
    rest length 0.5 m, gravity along −z: symmetric about the z axis, so L_z is conserved."""
    sp = pytest.importorskip("sympy")
    from fastvi.symbolic import model_from_lagrangian, velocities

    q = sp.symbols("xa ya za xb yb zb")
    v = velocities(q)
    k, g = sp.symbols("k g", positive=True)
    T = (v[0]**2 + v[1]**2 + v[2]**2) / 2 + (v[3]**2 + v[4]**2 + v[5]**2) / 4
    d = sp.sqrt((q[3] - q[0])**2 + (q[4] - q[1])**2 + (q[5] - q[2])**2)
    V = k / 2 * (d - sp.Rational(1, 2))**2 + g * (q[2] + q[5] / 2)
    return model_from_lagrangian(list(q), T, V, [(q[0]**2 + q[1]**2 + q[2]**2 - 1) / 2],
                                 v=list(v), params={k: 1e6, g: 9.81}, name="sphere_spring")


def _lz(r):
    q, v = r.q, r.v
    return q[:, 0] * v[:, 1] - q[:, 1] * v[:, 0] + 0.5 * (q[:, 3] * v[:, 4] - q[:, 4] * v[:, 3])


def test_stiff_fallback_conserves_noethers_momentum():
    """ωh ≈ 14: the mechanics iteration does not contract on the stiff spring and steps
    fall back to the full Newton (152 of 5000 measured). Both must stop on converged
    unknowns: L_z (the model is symmetric about the z axis) is held to round-off, as with
    newton="full"."""
    model = _sphere_and_spring()
    q0, v0 = np.array([1.0, 0, 0, 1.5, 0, 0]), np.array([0, 1.0, 0, 0, 1.2, 0.3])
    kw = dict(h=0.01, n_steps=5000, method="P3L-Q3G", save_every=50)
    ra = fastvi.integrate(model, q0, v0, **kw)
    rf = fastvi.integrate(model, q0, v0, newton="full", **kw)
    assert ra.stats["full_newton_steps"] > 0
    la, lf = _lz(ra), _lz(rf)
    assert np.abs(lf - lf[0]).max() < 1e-12  # measured 1.1e-13
    assert np.abs(la - la[0]).max() < 1e-12  # measured 1.1e-13
    # the same energy behaviour on a diverging (chaotic) path: measured max|ΔH| 3.0e-6 for both
    assert np.abs(ra.energy_error).max() < 2.0 * np.abs(rf.energy_error).max()
    assert ra.constraint_residual.max() < 1e-14 and ra.velocity_residual.max() < 1e-12


@pytest.mark.parametrize("name, h", [("P2L-Q3G", 0.01), ("P4L-Q4G", 0.01)])
def test_the_two_step_guess_is_the_hermite_interpolant_of_the_last_two_steps(name, h):
    """After three steps the kernel's guess for the fourth is the polynomial (SciPy's Krogh
    interpolator, built here) through the node τ_{s−1} − 1 of the step before last, the last
    step's control points and with the slope v_k at t_k, at the new step's nodes; and it is
    closer to the step's solution than the one-step extrapolation."""
    from scipy.interpolate import KroghInterpolator

    from fastvi.kernels.step import predict

    model = fastvi.scenes.double_pendulum()
    meth = fastvi.method(name)
    n, m, s = model.n, model.m, meth.s
    q, v = model.initial_state(1.0, 0.5)
    p = model.mass_matrix(q) @ v
    ws = None
    for k in range(3):
        st, q, p, v, out, ws = one_step(model, meth, h, q, p, v, ws=ws, first=k == 0)
        assert st == 0
    guesses = []
    for order in (2, 1):
        w = lay.make_workspace(n, m, s, meth.r, meth.J)
        for name_ in ws._fields:
            a = getattr(ws, name_)
            if isinstance(a, np.ndarray):
                getattr(w, name_)[...] = a
        predict(meth.kernel_tables, n, m, h, v, w, order)
        guesses.append(w.X[:s * n].reshape(s, n).copy())
    # positions of the last two steps relative to q_{k−1} (local time of the last step)
    Xp, Xpp = ws.Xprev[:s * n].reshape(s, n), ws.Xpp[:s * n].reshape(s, n)
    tau = meth.tau
    before = (Xpp[s - 2] if s >= 2 else 0.0) - Xpp[s - 1]
    last = np.vstack([np.zeros(n), Xp])
    xi = np.concatenate([[tau[s - 1] - 1.0], tau, [1.0]])  # 1.0 twice: value, then slope
    order = np.argsort(xi, kind="stable")
    yi = np.vstack([before, last, h * v])[order]
    ref = KroghInterpolator(xi[order], yi)(1.0 + tau[1:]) - Xp[s - 1]
    assert np.abs(guesses[0] - ref).max() < 1e-12 * max(1.0, np.abs(ref).max())
    st, q1, *_ = one_step(model, meth, h, q, p, v, ws=ws, first=False)
    assert st == 0
    solved = ws.Xprev[:s * n].reshape(s, n)
    err2, err1 = np.abs(guesses[0] - solved).max(), np.abs(guesses[1] - solved).max()
    assert err2 < 0.2 * err1, (err2, err1)
