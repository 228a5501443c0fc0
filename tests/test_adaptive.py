"""The time-reversible adaptive step (``integrate(..., adaptive=K_r)``, fastvi.kernels.adapt):
the predictor for steps of changing length, the step-size rule, order, energy and constraints,
and the errors of what it does not support."""

import importlib
import math

import numpy as np
import pytest

import fastvi
from fastvi.kernels import layout as lay
from fastvi.kernels.step import extrapolate, varied_weights
from fastvi.studies.convergence import observed_order
from fastvi.studies.reference import chain_cartesian, chain_pendulum_reference

METHODS = ["P1L-Q2G", "P2L-Q3G", "P3L-Q4G", "P4L-Q5G"]


def _polynomial(rng, deg, n, top=None):
    # a dominant slope keeps the extrapolation within the predictor's trust region; ``top``
    # sets the size of the leading coefficient
    C = rng.normal(size=(deg + 1, n)) * 0.2 ** np.arange(deg + 1)[:, None]
    C[1] = 1.0 + 0.1 * C[1]
    if top is not None:
        C[deg] = top
    return (lambda t: sum(C[p] * t ** p for p in range(deg + 1)),
            lambda t: sum(p * C[p] * t ** (p - 1) for p in range(1, deg + 1)))


def _predict_varied(meth, q, dq, steps, two):
    """The guess of ``extrapolate`` with the weights of ``varied_weights`` for the third of
    ``steps`` = (h2, h1, h), from the control points of the first two on the curve q(t)."""
    s, n, tau = meth.s, dq(0.0).shape[0], meth.kernel_tables.tau
    h2, h1, h = steps
    t2 = 0.1
    t1, t0 = t2 + h2, t2 + h2 + h1
    Xpp = np.concatenate([q(t2 + tau[mu] * h2) - q(t2) for mu in range(1, s + 1)])
    Xp = np.concatenate([q(t1 + tau[mu] * h1) - q(t1) for mu in range(1, s + 1)])
    ws = lay.make_workspace(n, 0, s, meth.r, meth.J)
    ws.hist[:] = (h1, h2)
    X = np.zeros(s * n)
    tabs = meth.kernel_tables
    varied_weights(tabs.tau, tabs.Lw, ws.Ew, ws.hist, h, s, two, ws.Ev, ws.E2v)
    extrapolate(ws.Ev, ws.E2v, Xp, Xpp, X, ws.Z, s, n, two, h, dq(t0))
    expected = np.concatenate([q(t0 + tau[nu] * h) - q(t0) for nu in range(1, s + 1)])
    return X, expected


@pytest.mark.parametrize("name", METHODS)
def test_the_predictor_of_a_changing_step_is_exact_on_polynomials_of_its_degree(name):
    """Degree s from the last step alone, s + 2 from the last two and the end slope (the
    polynomials of ``tabs.E`` and ``tabs.E2``), for steps of three different lengths."""
    meth = fastvi.tables.method(name)
    rng = np.random.default_rng(7)
    for deg, two in ((meth.s, False), (meth.s + 2, True)):
        q, dq = _polynomial(rng, deg, 3)
        X, expected = _predict_varied(meth, q, dq, (0.1, 0.08, 0.11), two)
        assert np.max(np.abs(X - expected)) < 1e-11  # round-off of a degree-6 extrapolation
        # one degree more is not reproduced: the test can fail
        q, dq = _polynomial(rng, deg + 1, 3, top=1.0)
        X, expected = _predict_varied(meth, q, dq, (0.1, 0.08, 0.11), two)
        assert np.max(np.abs(X - expected)) > 1e-9


@pytest.mark.parametrize("name", METHODS)
def test_with_equal_steps_the_changing_step_weights_are_the_tables(name):
    """``varied_weights`` builds its weights in another way (barycentric products and the
    α, β correction) than the tables (``fastvi.tables``: Vandermonde solves): equal for
    equal steps, in the columns the extrapolation reads (the new nodes 1…s)."""
    meth = fastvi.tables.method(name)
    tabs, s, h = meth.kernel_tables, meth.s, 0.02
    ws = lay.make_workspace(4, 0, s, meth.r, meth.J)
    ws.hist[:] = (h, h)
    varied_weights(tabs.tau, tabs.Lw, ws.Ew, ws.hist, h, s, True, ws.Ev, ws.E2v)
    assert np.max(np.abs(ws.Ev[:, 1:] - tabs.E[:, 1:])) <= 1e-13 * np.max(np.abs(tabs.E))
    assert np.max(np.abs(ws.E2v[:, 1:] - tabs.E2[:, 1:])) <= 1e-12 * np.max(np.abs(tabs.E2))


@pytest.fixture(scope="module")
def dp():
    return fastvi.scenes.double_pendulum()


@pytest.fixture(scope="module")
def whip(dp):
    """20 s of the double pendulum from π/2, π/2 (it whips over), adaptive and fixed with
    the same number of steps."""
    q0, v0 = dp.initial_state(math.pi / 2, math.pi / 2)
    ad = fastvi.integrate(dp, q0, v0, h=0.05, t_end=20.0, adaptive=3.0)
    k = ad.stats["steps"]
    fx = fastvi.integrate(dp, q0, v0, h=20.0 / k, n_steps=k)
    return ad, fx


def test_adaptive_steps_follow_the_kinetic_energy_and_end_on_t_end(dp, whip):
    ad, _ = whip
    assert ad.success and ad.t[0] == 0.0 and ad.t[-1] == 20.0
    assert ad.stats["adaptive"] == 3.0 and len(ad.t) == ad.stats["steps"] + 1
    assert "P2L-Q3G-NL-CN adaptive (K_r = 3), h = 0.05" in ad.summary()
    hk = np.diff(ad.t)
    assert np.all(hk > 0)
    # h_k ρ(q_k) = ε up to the rule's O(ε) lag (and the shortened last steps)
    ke = ad.energy[0] - 9.81 * (ad.q[:-1, 1] + ad.q[:-1, 3])
    rho = np.sqrt(1.0 + np.maximum(ke, 0.0) / 3.0)
    rel = hk[:-2] * rho[:-2] / 0.05 - 1.0
    assert np.max(np.abs(rel)) < 0.1
    assert hk.max() / hk.min() > 2.5  # it does adapt: the whips take shorter steps


def test_adaptive_steps_hold_constraints_and_beat_the_fixed_step_on_energy(whip):
    ad, fx = whip
    assert ad.constraint_residual.max() < 1e-14
    assert ad.velocity_residual.max() < 1e-13
    e_ad = np.max(np.abs(ad.energy - ad.energy[0]))
    e_fx = np.max(np.abs(fx.energy - fx.energy[0]))
    # measured 3.8e-4 against 2.4e-3 J with the same 897 steps
    assert e_ad < 0.3 * e_fx


def test_saving_every_kth_adaptive_step_keeps_the_same_steps(dp, whip):
    ad, _ = whip
    q0, v0 = dp.initial_state(math.pi / 2, math.pi / 2)
    sub = fastvi.integrate(dp, q0, v0, h=0.05, t_end=20.0, adaptive=3.0, save_every=7)
    k = ad.stats["steps"]
    idx = np.r_[0:k + 1:7, k] if k % 7 else np.r_[0:k + 1:7]
    np.testing.assert_array_equal(sub.t, ad.t[idx])
    np.testing.assert_array_equal(sub.q, ad.q[idx])
    assert sub.constraint_residual[1:].max() <= ad.constraint_residual.max()


def test_an_adaptive_result_saves_and_loads(whip, tmp_path):
    ad, _ = whip
    ad.save(tmp_path / "ad.npz")
    back = fastvi.Result.load(tmp_path / "ad.npz")
    np.testing.assert_array_equal(back.t, ad.t)
    np.testing.assert_array_equal(back.q, ad.q)
    assert back.stats["adaptive"] == 3.0 and back.h == ad.h


def test_energy_of_a_regular_motion_does_not_creep_with_adaptive_steps(dp):
    """A quasi-periodic motion (moderate angles) over 400 s: the reversible rule keeps the
    energy error bounded; its maximum over the last quarter is not above the first's by more
    than the oscillation's own spread."""
    q0, v0 = dp.initial_state(0.9, 0.4)
    res = fastvi.integrate(dp, q0, v0, h=0.05, t_end=400.0, adaptive=1.0, save_every=4)
    dH = np.abs(res.energy - res.energy[0])
    first, last = dH[res.t <= 100.0].max(), dH[res.t >= 300.0].max()
    assert last < 1.5 * first
    assert np.max(np.abs(res.constraint_residual)) < 1e-14


# P3L-Q4G in `make test-slow` only: its first adaptive compile costs `make test` ≈ 10 s, and
# P2L-Q3G checks the same code
@pytest.mark.parametrize("name, order", [("P2L-Q3G", 4),
                                         pytest.param("P3L-Q4G", 6, marks=pytest.mark.slow)])
def test_adaptive_steps_keep_the_methods_order(name, order):
    """Global error in q on the triple pendulum from 45° over 2 s against a SciPy reference
    in angle coordinates, for ε halving: the log–log slope is the method's order."""
    tp = fastvi.scenes.triple_pendulum()
    th0 = np.full(3, math.pi / 4)
    q0, v0 = tp.initial_state(*th0)
    epss = 2.0 / np.array((24, 29, 34, 41, 48) if order == 4 else (32, 38, 45, 54, 64))
    runs = [fastvi.integrate(tp, q0, v0, h=eps, t_end=2.0, method=name, adaptive=2.0)
            for eps in epss]
    # one reference run at every run's times (SciPy evaluates its dense output at t_eval)
    times = np.unique(np.concatenate([res.t for res in runs]))
    th, om = chain_pendulum_reference(th0, np.zeros(3), times, (1.0,) * 3, (1.0,) * 3)
    q_ref, _ = chain_cartesian(th, om, (1.0,) * 3)
    errs = [np.max(np.abs(res.q - q_ref[np.searchsorted(times, res.t)])) for res in runs]
    slope, used = observed_order(epss, np.array(errs), plateau=1e-12, min_points=5)
    assert used.all(), errs
    assert abs(slope - order) <= 0.3, (slope, errs)


@pytest.mark.parametrize("kw, match", [
    (dict(adaptive=0.0), "positive"),
    (dict(adaptive=-1.0), "positive"),
    (dict(adaptive="fast"), "energy scale"),
    (dict(adaptive=1.0, t_end=None, n_steps=10), "t_end"),
    (dict(adaptive=1.0, dense_output=True), "dense_output"),
    (dict(adaptive=1.0, recover=2), "recover"),
    (dict(adaptive=1.0, events=lambda t, q, v, p: q[0]), "events"),
])
def test_what_adaptive_steps_do_not_support_is_refused_by_name(dp, kw, match):
    q0, v0 = dp.initial_state(0.5, 0.5)
    args = dict(h=0.05, t_end=1.0)
    args.update(kw)
    with pytest.raises((ValueError, TypeError), match=match):
        fastvi.integrate(dp, q0, v0, **args)


def test_adaptive_steps_refuse_a_model_with_forces_or_time():
    damped = fastvi.scenes.chain(2, damping=0.1)
    q0, v0 = damped.initial_state([0.5, 0.5])
    with pytest.raises(ValueError, match="energy shell"):
        fastvi.integrate(damped, q0, v0, h=0.05, t_end=1.0, adaptive=1.0)


def test_progress_of_an_adaptive_run_counts_simulated_time(dp, capsys):
    q0, v0 = dp.initial_state(0.5, 0.5)
    fastvi.integrate(dp, q0, v0, h=0.05, t_end=5.0, adaptive=1.0, progress=True)
    err = capsys.readouterr().err
    assert "5/5 s simulated (100%)" in err and "t = 5," in err


def test_adaptive_steps_without_constraints_and_with_a_configuration_dependent_mass():
    """A spring pendulum in polar coordinates (m = 0, M(q)): the density needs only V and
    ∇V, so it adapts there too, with an energy error of the fixed step's order at as many
    steps (measured 4.9e-7 against 2.1e-7 J: the kinetic density is not what this motion's
    error follows)."""
    from tests.models import polar_pendulum

    model = polar_pendulum(spring=50.0)
    q0, v0 = np.array([1.2, 1.0]), np.zeros(2)
    ad = fastvi.integrate(model, q0, v0, h=0.02, t_end=50.0, adaptive=2.0)
    k = ad.stats["steps"]
    fx = fastvi.integrate(model, q0, v0, h=50.0 / k, n_steps=k)
    assert ad.t[-1] == 50.0 and np.diff(ad.t).max() / np.diff(ad.t).min() > 1.8
    assert np.max(np.abs(ad.energy - ad.energy[0])) < 5.0 * np.max(np.abs(fx.energy - fx.energy[0]))


def test_chunks_and_grown_buffers_change_no_bit(dp, whip, monkeypatch):
    """An adaptive run goes through the kernel in chunks of steps, growing its sample
    buffers between them (its number of steps is not known in advance): with chunks of 16
    steps and buffers grown many times it is the same run."""
    integ = importlib.import_module("fastvi.integrate")  # the module: fastvi.integrate is the function

    monkeypatch.setattr(integ, "_ADAPTIVE_CHUNK", 16)
    monkeypatch.setattr(integ, "_ADAPTIVE_BUFFER", 1)
    ad, _ = whip
    q0, v0 = dp.initial_state(math.pi / 2, math.pi / 2)
    small = fastvi.integrate(dp, q0, v0, h=0.05, t_end=20.0, adaptive=3.0)
    assert integ._adaptive_chunk(20.0, 0.05, 1, dp.n, False) == 16
    for f in ("t", "q", "p", "energy", "constraint_residual", "newton_iterations"):
        np.testing.assert_array_equal(getattr(small, f), getattr(ad, f))


def test_results_keep_full_sample_buffers_and_copy_mostly_empty_ones():
    """A result's arrays are its sample buffers when the run filled them (a fixed-step run
    sizes them exactly), views when they are at least half full, and trimmed copies else
    (a short run must not hold a long buffer)."""
    integ = importlib.import_module("fastvi.integrate")
    smp = integ._alloc(10, 3)
    full, half, few = integ._filled(smp, 10), integ._filled(smp, 6), integ._filled(smp, 3)
    assert all(a is b for a, b in zip(full, smp))
    assert all(a.base is b and a.shape[0] == 6 for a, b in zip(half, smp))
    assert all(a.base is None and a.shape[0] == 3 for a in few)
