"""The RK4 and SciPy baselines (fastvi.baselines), checked against independent references.

References are SciPy DOP853 at rtol = atol = 1e-13 on equations of motion written by hand in
minimal coordinates, never the baselines' own output.
"""

import importlib

import numpy as np
import pytest
from scipy.integrate import solve_ivp as scipy_solve_ivp

import fastvi
from fastvi.baselines import rk4, solve_ivp
from fastvi.studies.convergence import drift_slope, observed_order
from fastvi.studies.reference import chain_cartesian, chain_pendulum_reference

from . import models

REF_TOL = 1e-13
# the package exports the function `rk4`, which shadows the submodule of the same name
rk4_module = importlib.import_module("fastvi.baselines.rk4")
# the tests that run the RK4 kernel: its first compile takes longer than the rest of this
# file, for a yardstick of the benchmarks rather than the product (`make test-slow`)
rk4_kernel = pytest.mark.slow

# ---------------------------------------------------------------- unconstrained test models
# Plane pendulum in its angle (n = 1, m = 0, constant mass): params = (m, l, g).


def _pend_V(q, p):
    return -p[0] * p[2] * p[1] * np.cos(q[0])


def _pend_dV(q, p, out):
    out[0] = p[0] * p[2] * p[1] * np.sin(q[0])


# Spring pendulum in polar coordinates q = (r, φ) (n = 2, m = 0, M = diag(m, m r²)):
# tests/models.py's polar_pendulum with a spring, params = (m, g, r0, k). Its mass matrix
# depends on q: the ∂T/∂q and ∂(Mv)/∂q path.
SP_PARAMS = (1.5, 9.81, 1.0, 40.0)


def _sp_rhs(t, y):
    """Hand-written Euler–Lagrange equations of the spring pendulum (independent of fastvi)."""
    m, g, r0, k = SP_PARAMS
    r, ph, rd, phd = y
    rdd = r * phd**2 + g * np.cos(ph) - k / m * (r - r0)
    phdd = (-2.0 * rd * phd - g * np.sin(ph)) / r
    return [rd, phd, rdd, phdd]


def _pend_rhs(t, y):
    return [y[1], -9.81 / 1.3 * np.sin(y[0])]


@pytest.fixture(scope="module")
def angle_pendulum():
    return fastvi.Model(1, params=(0.7, 1.3, 9.81), mass=[[0.7 * 1.3**2]], potential=_pend_V,
                        potential_grad=_pend_dV, name="angle_pendulum")


@pytest.fixture(scope="module", params=["exact", "finite-difference"])
def spring_pendulum(request):
    # "finite-difference": no second derivatives, so RK4 differences ∂(Mv)/∂q along v
    m, g, r0, k = SP_PARAMS
    return models.polar_pendulum(m=m, g=g, l=r0, spring=k, exact=request.param == "exact")


def _final_error(model, q0, v0, rhs, T, hs):
    ref = scipy_solve_ivp(rhs, (0, T), np.concatenate((q0, v0)), method="DOP853",
                          rtol=REF_TOL, atol=REF_TOL).y[:, -1]
    errs = []
    for h in hs:
        res = rk4(model, q0, v0, h=h, t_end=T)
        errs.append(np.max(np.abs(np.concatenate((res.q[-1], res.v[-1])) - ref)))
    return np.array(errs)


HS = np.array([0.04, 0.02, 0.01, 0.005])


@rk4_kernel
def test_rk4_order_is_4_on_unconstrained_angle_pendulum(angle_pendulum):
    errs = _final_error(angle_pendulum, np.array([2.0]), np.array([0.0]), _pend_rhs, 2.0, HS)
    order, used = observed_order(HS, errs)
    assert used.sum() == 4
    # large amplitude (2 rad): the slope still climbs towards 4 (3.83, 3.92, 3.96 pairwise)
    assert abs(order - 4.0) < 0.15  # measured 3.91


@rk4_kernel
def test_rk4_order_is_4_with_configuration_dependent_mass(spring_pendulum):
    q0, v0 = np.array([1.2, 1.0]), np.array([0.3, -0.5])
    errs = _final_error(spring_pendulum, q0, v0, _sp_rhs, 2.0, HS)
    order, used = observed_order(HS, errs)
    assert used.sum() == 4
    assert abs(order - 4.0) < 0.1  # measured 4.00 (exact and finite differences)
    assert errs[-1] < 1e-7  # measured 4.5e-8


@rk4_kernel
def test_rk4_order_is_4_on_constrained_double_pendulum(double_pendulum, dp_start):
    q0, v0 = dp_start
    T = 1.0
    th, om = chain_pendulum_reference([np.pi / 2] * 2, [0.0, 0.0], [T], [1.0, 1.0], [1.0, 1.0])
    qref, vref = chain_cartesian(th, om, [1.0, 1.0])
    hs = np.array([0.02, 0.01, 0.005])
    errs = []
    for h in hs:
        res = rk4(double_pendulum, q0, v0, h=h, t_end=T)
        errs.append(np.max(np.abs(np.concatenate((res.q[-1] - qref[0], res.v[-1] - vref[0])))))
    order, used = observed_order(hs, errs)
    assert used.sum() == 3
    assert abs(order - 4.0) < 0.2  # measured 3.99


@rk4_kernel
def test_rk4_without_projection_drifts_off_the_constraints(double_pendulum, dp_start):
    res = rk4(double_pendulum, *dp_start, h=0.01, n_steps=10_000)
    assert res.constraint_residual[-1] > 1e-6  # measured 0.17
    assert np.max(res.velocity_residual) > 1e-6  # measured 4.3e-3


@rk4_kernel
def test_rk4_with_projection_keeps_constraints_at_roundoff(double_pendulum, dp_start):
    res = rk4(double_pendulum, *dp_start, h=0.01, n_steps=10_000, project=True)
    assert np.max(res.constraint_residual) < 1e-14  # measured 7.8e-16
    assert np.max(res.velocity_residual) < 1e-13  # measured 1.9e-15


@rk4_kernel
def test_variational_energy_error_stays_bounded_while_rk4_grows(double_pendulum, dp_start):
    """Over 10^4 steps (h = 0.01, T = 100 s) on paper B's chaotic double pendulum, and the
    variational integrator alone over 10^5 steps."""
    q0, v0 = dp_start
    vi = fastvi.integrate(double_pendulum, q0, v0, h=0.01, n_steps=10_000, method="P2L-Q3G")
    rk = rk4(double_pendulum, q0, v0, h=0.01, n_steps=10_000)
    _, vi_win = drift_slope(vi.t, vi.energy_error)
    rk_slope, rk_win = drift_slope(rk.t, rk.energy_error)
    half = len(vi.t) // 2

    def late_over_early(err):
        return np.abs(err[half:]).max() / np.abs(err[:half]).max()

    # bounded: the second half of the run reaches no higher than the first, and over 10^5
    # steps the fitted trend of the per-window maxima is small against their size and the
    # maximum no higher than over 10^4 steps. The trend over 10^4 steps is no test: the
    # chaotic motion makes its 20 window maxima wander either way, and runs that differ only
    # by round-off measured −0.48, +0.20, +0.42 and +0.44 of their size (RK4: +0.99)
    assert late_over_early(vi.energy_error) < 2.0  # measured 0.75–1.12
    long = fastvi.integrate(double_pendulum, q0, v0, h=0.01, n_steps=100_000, method="P2L-Q3G")
    long_slope, long_win = drift_slope(long.t, long.energy_error)
    assert abs(long_slope) * 1000.0 < 0.25 * long_win.max()  # measured 0.03, 0.16, 0.03
    assert np.abs(long.energy_error).max() < 2.0 * np.abs(vi.energy_error).max()  # 1.03–1.12
    # RK4: the per-window maxima rise in every window, and by orders of magnitude
    assert rk_slope * 100.0 > 0.5 * rk_win.max()  # measured 0.99
    assert np.all(np.diff(rk_win) > 0)  # measured: strictly increasing
    assert rk_win[-1] > 100 * rk_win[0]  # measured 4.0e3
    assert late_over_early(rk.energy_error) > 3.0  # measured 7.4
    assert rk_win.max() > 1000 * vi_win.max()  # measured 7.8e4


@rk4_kernel
def test_rk4_and_variational_agree_with_each_other_on_the_slider():
    """Same physics: at small h both reach the same state (the slider's mass depends on q)."""
    model = fastvi.scenes.rotary_rod_slider()
    q0, v0 = model.initial_state()
    a = rk4(model, q0, v0, h=0.001, t_end=1.0)
    b = fastvi.integrate(model, q0, v0, h=0.001, t_end=1.0, method="P2L-Q3G")
    assert np.max(np.abs(a.q[-1] - b.q[-1])) < 1e-9  # measured 2.4e-11


def test_scipy_wrapper_matches_minimal_coordinate_reference(double_pendulum, dp_start):
    T = 1.0
    res = solve_ivp(double_pendulum, *dp_start, t_end=T, rtol=1e-12, atol=1e-12, n_samples=11)
    th, om = chain_pendulum_reference([np.pi / 2] * 2, [0.0, 0.0], res.t, [1.0, 1.0], [1.0, 1.0])
    qref, vref = chain_cartesian(th, om, [1.0, 1.0])
    assert res.success
    assert np.max(np.abs(res.q - qref)) < 1e-10  # measured 4.7e-13
    assert np.max(np.abs(res.v - vref)) < 1e-10  # measured 3.0e-12
    assert np.max(np.abs(res.energy_error)) < 1e-9  # measured 3.0e-11


@rk4_kernel
def test_rk4_kernels_compile_once_for_different_models(double_pendulum, dp_start, angle_pendulum):
    rk4(double_pendulum, *dp_start, h=0.01, n_steps=3, project=True)
    rk4(angle_pendulum, [1.0], [0.0], h=0.01, n_steps=3)
    rk4(fastvi.scenes.rotary_rod_slider(), *fastvi.scenes.rotary_rod_slider().initial_state(),
        h=0.01, n_steps=3)
    assert len(rk4_module.run.signatures) == 1
    assert len(rk4_module.observe.signatures) == 1  # the other entry point called from Python


@rk4_kernel
def test_rk4_result_records_every_step_and_stats(double_pendulum, dp_start):
    res = rk4(double_pendulum, *dp_start, h=0.01, n_steps=10, save_every=3)
    np.testing.assert_allclose(res.t, [0.0, 0.03, 0.06, 0.09, 0.10], rtol=0, atol=1e-15)
    assert res.stats["steps"] == 10 and res.stats["rhs_evaluations"] == 40
    assert res.name == "RK4" and "max |ΔH|" in res.summary()


@pytest.mark.parametrize(
    "kwargs, exc, match",
    [
        (dict(h=-0.1, n_steps=3), ValueError, "`h` must be positive"),
        (dict(h=0.1, t_end=0.25), ValueError, "`t_end` = 0.25 is not a whole number"),
        (dict(h=0.1, n_steps=3, project="yes"), TypeError, "`project` must be True or False"),
        (dict(h=0.1, n_steps=3, on_failure="ignore"), ValueError, "`on_failure` must be"),
    ],
)
def test_rk4_rejects_bad_arguments(double_pendulum, dp_start, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        rk4(double_pendulum, *dp_start, **kwargs)


def test_scipy_wrapper_rejects_unknown_method(double_pendulum, dp_start):
    with pytest.raises(ValueError, match="`method` must be one of"):
        solve_ivp(double_pendulum, *dp_start, t_end=1.0, method="Euler")


@rk4_kernel
@pytest.mark.parametrize("project", [False, True])
@pytest.mark.parametrize("scene", ["chain", "tree"])
def test_rk4_of_a_large_model_solves_over_the_pattern_of_G(scene, project):
    """Large models with a diagonal constant mass: G M⁻¹ Gᵀ banded (chain) or sparse (tree)
    instead of the dense saddle system, the same trajectory (issue 12, item 4)."""
    from fastvi import structure

    if scene == "chain":
        model = fastvi.scenes.chain(24)
        q0, v0 = model.initial_state(np.linspace(0.2, 1.0, 24))
    else:
        model = fastvi.scenes.tree(4, 3)
        q0, v0 = model.initial_state(0.3 + 0.6 * np.sin(np.arange(13)))
    expected = dict(chain="banded", tree="sparse")[scene]
    assert structure.plan(model, None).solvers["projection"] == expected
    runs = {s: rk4(model, q0, v0, h=0.002, n_steps=200, project=project, solver=s, save_every=20)
            for s in ("dense", "auto")}
    # measured ≤ 3e-14 (q) and ≤ 3e-13 (v): Ġ v by a central difference of a G linear in q
    assert np.abs(runs["dense"].q - runs["auto"].q).max() < 1e-11
    assert np.abs(runs["dense"].v - runs["auto"].v).max() < 1e-10
    assert np.allclose(runs["dense"].energy, runs["auto"].energy, rtol=0, atol=1e-10)
    if project:
        assert runs["auto"].constraint_residual.max() < 1e-13
