"""The reliability monitor: a run whose every step converged but whose trajectory is broken
ends with a non-success status, whatever `recover` did, and correct runs pass untouched.

The case is the slider–crank of the issue in 8 body coordinates (tests/models.py), at a step
(h = 0.1) too large for its motion. The reference is independent of fastvi: SciPy's DOP853 at
rtol = atol = 1e-12 on the index-1 form of the same equations (M a + Gᵀλ = −∇V, G a = −Ġ v).
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fastvi
from fastvi import monitor
from fastvi.status import Status

from . import models

T_END = 20.0


def _reference(q0, v0, times):
    a, L, m1, m2, m3, g, k, xr = models.BAR_SC_PARAMS
    M = np.diag([m1, m1, m1 * a * a / 12, m2, m2, m2 * L * L / 12, m3, m3])
    n = 8

    def rhs(t, y):
        q, v = y[:n], y[n:]
        G = np.zeros((7, n))
        models.bsc_G(q, np.array(models.BAR_SC_PARAMS), G)
        dV = np.zeros(n)
        models.bsc_dV(q, np.array(models.BAR_SC_PARAMS), dV)
        c1, s1, c2, s2 = np.cos(q[2]), np.sin(q[2]), np.cos(q[5]), np.sin(q[5])
        w1, w2 = v[2] ** 2, v[5] ** 2  # Ġ v: the constraints are nonlinear in θ1, θ2 only
        gdot = 0.5 * np.array([a * c1 * w1, a * s1 * w1, -a * c1 * w1 - L * c2 * w2,
                               -a * s1 * w1 - L * s2 * w2, -L * c2 * w2, -L * s2 * w2, 0.0])
        K = np.block([[M, G.T], [G, np.zeros((7, 7))]])
        acc = np.linalg.solve(K, np.concatenate([-dV, -gdot]))[:n]
        return np.concatenate([v, acc])

    sol = solve_ivp(rhs, (0.0, times[-1]), np.concatenate([q0, v0]), method="DOP853", rtol=1e-12,
                    atol=1e-12, t_eval=times)
    assert sol.success
    return sol.y[:n].T


@pytest.fixture(scope="module")
def case():
    q0, v0 = models.bar_slider_crank_state(0.3, 5.0)
    return q0, v0


def test_the_case_starts_as_the_issue_says(case):
    q0, v0 = case
    model = models.bar_slider_crank()
    assert model.energy(q0, v0) == pytest.approx(14.4, abs=0.05)  # "the energy goes from 14.4 J"


@pytest.mark.parametrize("variant", ["exact", "no_constraint_hessian"])
def test_recover_cannot_turn_the_broken_slider_crank_into_a_success(case, variant):
    """h = 0.1, recover=3: without the monitor the run without the constraint Hessian returns
    SUCCESS with its crank far from the reference, and the one with it fails only at t = 3.4
    (after energy errors of 50 times the initial energy); with the monitor both stop at the
    first step whose energy error leaves the bounded regime, t = 0.4, and say so."""
    q0, v0 = case
    over = {} if variant == "exact" else dict(constraint_hessian=None)
    model = models.bar_slider_crank(**over)
    ref_end = _reference(q0, v0, np.array([T_END]))[-1]
    blind = fastvi.integrate(model, q0, v0, h=0.1, t_end=T_END, recover=3, monitor=False,
                             on_failure="return")
    if blind.success:  # the silent wrong answer of the issue
        assert abs(blind.q[-1, 2] - ref_end[2]) > 1.0
    else:
        assert np.max(np.abs(blind.energy_error)) > 50 * blind.energy[0]
    with pytest.raises(fastvi.IntegrationError, match="reliability monitor") as err:
        fastvi.integrate(model, q0, v0, h=0.1, t_end=T_END, recover=3)
    e = err.value
    assert e.status < 0
    assert e.status == Status.UNRELIABLE and "energy error" in str(e) and "→ 0.4" in str(e), str(e)
    part = e.result
    assert part.t[-1] <= 0.4 + 1e-12 and not part.success
    # what it kept is the motion: within 1e-2 rad of the reference up to there
    ref = _reference(q0, v0, part.t[1:])
    assert np.max(np.abs(part.q[1:, 2] - ref[:, 2])) < 1e-2


def test_the_monitor_result_on_failure_return(case):
    q0, v0 = case
    model = models.bar_slider_crank(constraint_hessian=None)
    r = fastvi.integrate(model, q0, v0, h=0.1, t_end=T_END, recover=3, on_failure="return")
    assert r.status == Status.UNRELIABLE and not r.success
    assert r.failed_step == r.stats["steps"] == len(r.t) - 1 == 3
    assert r.stats["monitor_breach"] == "energy"
    assert r.stats["monitor_breach_time"] == pytest.approx(0.4)
    assert "UNRELIABLE" in repr(r)


def test_a_resolved_run_of_the_same_case_passes_and_is_right(case):
    q0, v0 = case
    r = fastvi.integrate(models.bar_slider_crank(), q0, v0, h=0.01, t_end=T_END)
    assert r.status == Status.SUCCESS
    for key in ("monitor_energy", "monitor_constraint", "monitor_hidden_constraint", "monitor_displacement"):
        assert 0.0 <= r.stats[key] < 1.0, (key, r.stats[key])
    assert r.stats["monitor_energy"] < 1e-3  # far from the limit: |ΔH| ≈ 5e-5 J of ≈ 18 J kinetic
    ref = _reference(q0, v0, r.t[::100])
    assert np.max(np.abs(r.q[::100, 2] - ref[:, 2])) < 1e-3


# ----------------------------------------------------------------------------- the indicators
def _samples(K=50, n=2, h=0.1):
    """A harmonic oscillator's exact samples: every indicator well inside its limit."""
    t = h * np.arange(K)
    q = np.stack([np.cos(t), np.zeros(K)], axis=1)[:, :n]
    v = np.stack([-np.sin(t), np.zeros(K)], axis=1)[:, :n]
    H = 0.5 * np.sum(v * v, axis=1) + 0.5 * q[:, 0] ** 2
    return dict(t=t, q=q, v=v, p=v.copy(), energy=H, work=None, g=np.full(K, 1e-15),
                gv=np.full(K, 1e-16))


def _assess(s, one_step=True):
    return monitor.assess(s["t"], s["q"], s["v"], s["p"], s["energy"], s["work"], s["g"], s["gv"],
                          one_step=one_step, newton_tol=1e-14)


def test_exact_samples_pass():
    v = _assess(_samples())
    assert v.ok and v.indicators["energy"] < 1e-6 and v.indicators["displacement"] < 0.5


@pytest.mark.parametrize("indicator, spoil", [
    ("energy", lambda s: s["energy"].__setitem__(slice(20, None), s["energy"][0] + 0.2)),
    ("constraint", lambda s: s["g"].__setitem__(20, 1e-4)),
    ("hidden_constraint", lambda s: s["gv"].__setitem__(20, 1e-4)),
    ("displacement", lambda s: s["q"].__setitem__((slice(20, None), 1), 3.0)),
])
def test_each_indicator_names_the_first_bad_sample(indicator, spoil):
    s = _samples()
    spoil(s)
    v = _assess(s)
    assert not v.ok and v.indicator == indicator and v.sample == 20, v
    assert v.indicators[indicator] > 1.0


def test_the_displacement_needs_samples_one_step_apart():
    s = _samples()
    s["q"][20:, 1] = 3.0
    assert np.isnan(_assess(s, one_step=False).indicators["displacement"])


def test_a_forced_run_is_judged_by_its_energy_balance():
    s = _samples()
    s["energy"] = s["energy"] - 0.05 * s["t"]  # a damper took energy out
    assert not _assess(s).ok
    s["work"] = -0.05 * s["t"]  # ... and the work says so: the balance holds
    assert _assess(s).ok


def test_the_monitor_stats_survive_save_and_load(tmp_path, pendulum):
    r = fastvi.integrate(pendulum, *pendulum.initial_state(1.0), h=0.01, n_steps=100)
    r.save(tmp_path / "r.npz")
    back = fastvi.Result.load(tmp_path / "r.npz")
    assert back.stats["monitor_energy"] == r.stats["monitor_energy"] < 1e-3
