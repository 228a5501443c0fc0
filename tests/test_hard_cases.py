"""Hard problems give a correct run or a clear error: never NaN, never a hang."""

import numpy as np
import pytest

import fastvi
from fastvi import IntegrationError, Status
from fastvi.kernels import layout as lay
from tests.kernel_helpers import one_step

from . import models


@pytest.mark.parametrize("name", ["P2L-Q3G", "P1L-Q1G", "P3L-Q3G"])
def test_stiff_spring_slider_with_omega_h_far_above_one(name):
    """k = 10^6: ω h = √(k/mB)·h ≈ 4.5 at h = 0.01. Gauss-collocation-like choices (r = s)
    and the default P2L-Q3G stay stable; paper B's P1L-Q2G is only stable for ωh < √12."""
    model = fastvi.scenes.rotary_rod_slider(k=1e6)
    q0, v0 = model.initial_state(theta=0.0)
    r = fastvi.integrate(model, q0, v0, h=0.01, n_steps=10_000, method=name, save_every=10)
    assert r.success
    err = np.abs(r.energy_error)
    # measured max|ΔH|: P2L-Q3G 8e-8, P1L-Q1G 3e-3, P3L-Q3G 1e-11 (H0 = 0 for this start)
    assert err.max() < 1e-2 and err[-100:].max() < 2 * err[:100].max() + 1e-9  # no growth beyond round-off
    assert r.constraint_residual.max() < 1e-13  # measured 4e-16


def test_conditionally_stable_method_beyond_its_limit_ends_in_an_error_not_nan():
    model = fastvi.scenes.rotary_rod_slider(k=1e6)
    q0, v0 = model.initial_state(theta=0.0)
    with pytest.raises(IntegrationError):
        fastvi.integrate(model, q0, v0, h=0.01, n_steps=10_000, method="P1L-Q2G")


def test_a_million_steps_keep_memory_and_energy_bounded(double_pendulum, dp_start):
    r = fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=1_000_000, save_every=1000)
    assert r.q.shape == (1001, 4) and r.stats["steps"] == 1_000_000
    assert np.abs(r.energy_error).max() < 1e-3  # measured 6e-5, the same as over 10^4 steps
    assert r.constraint_residual.max() < 1e-13  # max over every step, not only the samples


@pytest.mark.parametrize("h", [0.002, 0.005, 0.01])
def test_fast_spinning_double_pendulum(double_pendulum, h):
    """20 rad/s: the kinetic energy dwarfs gravity and Newton starts far from the solution."""
    q0, v0 = double_pendulum.initial_state(0.5, -0.3, 20.0, -20.0)
    r = fastvi.integrate(double_pendulum, q0, v0, h=h, n_steps=2000, method="P2L-Q3G")
    rel = np.abs(r.energy_error).max() / abs(r.energy[0])
    # measured relative energy error 4e-7, 2e-5, 1.1e-3 (order 4 in h); |g| 3e-16
    assert rel < {0.002: 1e-5, 0.005: 1e-4, 0.01: 5e-3}[h] and r.constraint_residual.max() < 1e-12


@pytest.mark.parametrize("h", [0.05, 0.1, 0.2, 0.4, 0.8])
@pytest.mark.parametrize("name", ["P1L-Q2G", "P2L-Q3G", "P3L-Q4G"])
def test_large_steps_converge_or_raise_never_nan(double_pendulum, h, name):
    q0, v0 = double_pendulum.initial_state(2.0, 2.0, 5.0, -5.0)
    try:
        r = fastvi.integrate(double_pendulum, q0, v0, h=h, n_steps=200, method=name, max_iter=15)
    except IntegrationError as err:
        assert err.status < 0 and np.all(np.isfinite(err.result.q))
        return
    assert np.all(np.isfinite(r.q)) and np.all(np.isfinite(r.energy))
    assert r.constraint_residual.max() < 1e-10


def test_recovery_retakes_failing_steps_as_substeps(double_pendulum):
    q0, v0 = double_pendulum.initial_state(2.0, 2.0, 15.0, -15.0)
    with pytest.raises(IntegrationError, match="NEWTON_NOT_CONVERGED"):
        fastvi.integrate(double_pendulum, q0, v0, h=0.2, n_steps=20, max_iter=4)
    r = fastvi.integrate(double_pendulum, q0, v0, h=0.2, n_steps=20, max_iter=4, recover=4)
    assert r.success and len(r.stats["recovered_steps"]) > 0
    np.testing.assert_allclose(r.t, 0.2 * np.arange(21))  # the saved grid is unchanged
    assert r.constraint_residual.max() < 1e-13
    with pytest.raises(ValueError, match="`recover` must be at most 10"):
        fastvi.integrate(double_pendulum, q0, v0, h=0.2, n_steps=2, recover=11)


# ----------------------------------------------------------------------------- four-bar
def test_four_bar_passes_through_its_singular_positions():
    """Crank turning through the aligned (singular) positions twice per turn: plain LU on the
    Newton matrix passes through (G loses rank only *at* the crossing), energy and
    constraints are kept, and the linkage stays on the parallelogram branch."""
    fb = fastvi.scenes.four_bar()
    q0, v0 = fb.initial_state(np.pi / 2, 8.0)
    r = fastvi.integrate(fb, q0, v0, h=0.01, n_steps=5000, method="P3L-Q4G")
    turns = (np.unwrap(fb.crank_angle(r.q))[-1] - fb.crank_angle(q0)) / (2 * np.pi)
    assert turns > 50  # measured 72 turns: 144 singular crossings
    assert np.abs(r.energy_error).max() < 1e-8  # measured 7e-10
    assert r.constraint_residual.max() < 1e-14  # measured 9e-16
    assert np.abs(fb.coupler_tilt(r.q)).max() < 1e-10  # parallelogram branch kept (measured 7e-13)


@pytest.mark.parametrize("theta0", [1e-8, 1e-13])
def test_four_bar_started_next_to_the_singular_position(theta0):
    fb = fastvi.scenes.four_bar()
    q0, v0 = fb.initial_state(theta0, 8.0)
    r = fastvi.integrate(fb, q0, v0, h=0.01, n_steps=300, method="P2L-Q3G")
    assert np.abs(r.energy_error).max() < 1e-5 and np.abs(fb.coupler_tilt(r.q)).max() < 1e-10


def test_four_bar_started_on_the_singular_position_is_refused_by_name():
    fb = fastvi.scenes.four_bar()
    q0, v0 = fb.initial_state(0.0, 8.0)
    with pytest.raises(ValueError, match="constraint Jacobian at `q0` must have full row rank 3"):
        fastvi.integrate(fb, q0, v0, h=0.01, n_steps=10)


def test_a_step_from_an_exactly_singular_state_reports_a_status_not_nan():
    fb = fastvi.scenes.four_bar()
    q, v = fb.initial_state(0.0, 8.0)
    meth = fastvi.method("P2L-Q3G")
    st, q1, p1, v1, out, ws = one_step(fb, meth, 0.01, q, fb.mass_matrix(q) @ v, v)
    assert st in (0, Status.SINGULAR_JACOBIAN, Status.SINGULAR_CONSTRAINTS, Status.NEWTON_NOT_CONVERGED)
    if st == 0:
        assert np.all(np.isfinite(q1)) and np.all(np.isfinite(p1))


# ----------------------------------------------------------------------------- bad callbacks
def _nan_grad(q, p, out):
    out[0] = 0.0
    out[1] = p[0] * p[1] if q[1] > -0.9 else np.nan


def _V(q, p):
    return p[0] * p[1] * q[1]


def _g(q, p, out):
    out[0] = 0.5 * (q[0] ** 2 + q[1] ** 2 - 1.0)


def _G(q, p, out):
    out[0, 0] = q[0]
    out[0, 1] = q[1]


def test_a_callback_returning_nan_mid_run_is_named():
    model = fastvi.Model(2, 1, params=(1.0, 9.81), mass=np.eye(2), potential=_V, potential_grad=_nan_grad,
                         constraint=_g, constraint_jacobian=_G, name="bad")
    q0 = np.array([np.sin(1.0), -np.cos(1.0)])
    with pytest.raises(IntegrationError, match=r"NONFINITE.*callback `potential_grad` returned") as info:
        fastvi.integrate(model, q0, [0.0, 0.0], h=0.01, n_steps=500, check=False)
    assert info.value.status == Status.NONFINITE and info.value.step > 0


def test_mass_matrix_not_positive_definite_at_q0_is_refused():
    model = models.polar_pendulum(spring=10.0)
    with pytest.raises(ValueError, match="mass matrix at `q0` must be symmetric positive definite"):
        fastvi.integrate(model, [0.0, 0.3], [0.0, 0.0], h=0.01, n_steps=5)


def test_a_method_beyond_its_stability_limit_is_stopped_before_it_overflows():
    """P1L-Q2G at ωh ≈ 4.5 > √12: every step converges, the energy explodes (6e55 after 100
    steps, measured without the monitor), and the run ends as UNRELIABLE where the energy
    error passes a tenth of the kinetic energy (step 15), not as a success."""
    model = fastvi.scenes.rotary_rod_slider(k=1e6)
    q0, v0 = model.initial_state(theta=0.0)
    blind = fastvi.integrate(model, q0, v0, h=0.01, n_steps=100, method="P1L-Q2G", monitor=False)
    assert blind.success and np.max(np.abs(blind.energy_error)) > 1e40
    with pytest.raises(IntegrationError, match="reliability monitor.*energy error") as err:
        fastvi.integrate(model, q0, v0, h=0.01, n_steps=100, method="P1L-Q2G")
    assert err.value.status == Status.UNRELIABLE and 5 < err.value.step < 30
    part = err.value.result
    assert np.max(np.abs(part.energy_error)) < 0.1 * np.max(0.5 * np.sum(part.v * part.p, axis=1))


@pytest.mark.parametrize("name", ["P2L-Q3G", "P1L-Q1G", "P3L-Q3G"])
def test_stable_runs_do_not_trip_the_monitor(name, double_pendulum, dp_start):
    """The stiff slider at ωh ≈ 4.5 with the stable methods (the fast mode aliased, the energy
    kept) and 200 s of the chaotic double pendulum: the monitor lets both pass."""
    model = fastvi.scenes.rotary_rod_slider(k=1e6)
    for r in (fastvi.integrate(model, *model.initial_state(theta=0.0), h=0.01, n_steps=2000, method=name),
              fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=20_000, method=name)):
        assert r.status == Status.SUCCESS
        assert r.stats["monitor_energy"] < 0.5 and r.stats["monitor_displacement"] < 0.5


def test_the_full_newton_compiled_on_first_need_gives_the_same_run(monkeypatch):
    """A run that first meets the full Newton mid-way (the stiff rod–slider: the mechanics
    iteration fails there) retakes that step once the stage is compiled, or, compiled
    already, once its workspace has the stage's fields: the same samples, events and dense
    output, bit for bit, as a run that had the stage from the start."""
    from fastvi.kernels import step as step_kernels
    from studies import peers

    k = 1e8
    model = fastvi.scenes.rotary_rod_slider(k=k)
    q0, v0 = model.initial_state(0.0, peers.SLIDER_R0 + peers.slider_stretch(k))

    def crossing(t, q, v, p):
        return q[0] + 1.0  # the angle passes −1 rad

    kw = dict(h=0.01, n_steps=300, method="P2L-Q2G", events=crossing, dense_output=True)
    fastvi.integrate(model, q0, v0, **kw)  # compiles the full Newton (lazily, if first)
    lazy = fastvi.integrate(model, q0, v0, **kw)  # its workspace is made without its fields
    # with every field, a compiled full Newton is taken from the start
    monkeypatch.setattr(lay, "unused_fields", lambda flags, si, newton: frozenset())
    eager = fastvi.integrate(model, q0, v0, **kw)
    assert eager.stats["full_newton_steps"] > 0
    # forget that the full Newton was compiled: the next run starts with the placeholder
    monkeypatch.setattr(step_kernels, "_OPTIONAL", {
        key: stage for key, stage in step_kernels._OPTIONAL.items() if key[1] != "newton_full"})
    lazy_compiled = fastvi.integrate(model, q0, v0, **kw)
    assert any(key[1] == "newton_full" for key in step_kernels._OPTIONAL)
    ts = np.linspace(0.0, float(eager.t[-1]), 37)
    for run in (lazy, lazy_compiled):
        for name in ("t", "q", "v", "p", "energy", "newton_iterations"):
            assert np.array_equal(getattr(run, name), getattr(eager, name)), name
        assert run.stats["full_newton_steps"] == eager.stats["full_newton_steps"]
        assert np.array_equal(run.t_events[0], eager.t_events[0]) and len(eager.t_events[0]) > 0
        assert np.array_equal(run.sol(ts)[0], eager.sol(ts)[0])


@pytest.mark.parametrize("what", ["sensitivity", "adjoint"])
def test_derivatives_compile_the_full_newton_on_first_need_with_the_same_results(
        what, monkeypatch):
    """``sensitivity`` and ``adjoint`` compile the full Newton when a step first needs it, as
    ``integrate`` does: the stiff rod–slider's run retakes that step, and gives the same
    trajectory and derivatives, bit for bit, as a run that had the stage from the start."""
    from fastvi.kernels import step as step_kernels
    from studies import peers

    k = 1e8
    model = fastvi.scenes.rotary_rod_slider(k=k)
    q0, v0 = model.initial_state(0.0, peers.SLIDER_R0 + peers.slider_stretch(k))
    kw = dict(h=0.01, n_steps=300, method="P2L-Q2G")
    if what == "sensitivity":
        def derive():
            S = fastvi.sensitivity(model, q0, v0, **kw)
            return S.result, (S.dq, S.dv, S.dp)
    else:
        def derive():
            A = fastvi.adjoint(model, q0, v0, lambda r: (r.q, r.v), **kw)
            return A.result, (A.grad_q0, A.grad_v0, A.grad_params)
    derive()  # compiles the full Newton (lazily, if first)
    with monkeypatch.context() as patch:  # every field: a compiled full Newton from the start
        patch.setattr(lay, "unused_fields", lambda flags, si, newton: frozenset())
        eager, eager_d = derive()
    assert eager.stats["full_newton_steps"] > 0
    monkeypatch.setattr(step_kernels, "_OPTIONAL", {
        key: stage for key, stage in step_kernels._OPTIONAL.items() if key[1] != "newton_full"})
    lazy, lazy_d = derive()
    assert any(key[1] == "newton_full" for key in step_kernels._OPTIONAL)
    assert lazy.stats["full_newton_steps"] == eager.stats["full_newton_steps"]
    assert np.array_equal(lazy.q, eager.q)
    for x, y in zip(lazy_d, eager_d):
        assert np.abs(y).max() > 0 and np.array_equal(x, y)
