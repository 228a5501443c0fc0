"""Dense output and events (issue 14), against exact answers and SciPy.

The pendulum released at rest from θ0 crosses the vertical at ``T/4 + k T/2`` with
``T = 4 √(l/g) K(sin²(θ0/2))`` (complete elliptic integral of the first kind, SciPy's
``ellipk`` with parameter m = sin²(θ0/2)); the state between grid points is compared with
SciPy's DOP853 at tight tolerance on ``θ'' = −(g/l) sin θ``.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.special import ellipk

import fastvi
from fastvi.status import Status

TH0, G = 1.0, 9.81
PERIOD = 4 * np.sqrt(1 / G) * ellipk(np.sin(TH0 / 2) ** 2)
METHODS = [("P1L-Q2G", 1), ("P2L-Q3G", 2), ("P3L-Q4G", 3)]


def cross(t, q, v, p):
    return q[0]  # the bob passes under the pivot


def up(t, q, v, p):
    return q[0]


up.direction = 1.0


def stop(t, q, v, p):
    return q[0]


stop.terminal = True
stop.direction = -1


def low(t, q, v, p):
    return q[1] + 0.95  # the bob within 5 cm of its lowest point


def at_half(t, q, v, p):
    return t - 0.5


@pytest.fixture(scope="module")
def pend():
    return fastvi.scenes.pendulum()


def _exact_crossings(count):
    return PERIOD / 4 + np.arange(count) * PERIOD / 2


def _reference(t):
    ref = solve_ivp(lambda s, y: [y[1], -G * np.sin(y[0])], (0, t.max() + 1e-9), [TH0, 0.0],
                    t_eval=t, rtol=1e-13, atol=1e-13, method="DOP853")
    th, w = ref.y
    return (np.stack([np.sin(th), -np.cos(th)], 1), np.stack([np.cos(th) * w, np.sin(th) * w], 1))


@pytest.mark.parametrize("name,s", METHODS)
def test_event_times_and_dense_output_converge_at_their_orders(pend, name, s):
    hs = np.array([0.04, 0.02, 0.01, 0.005])
    T_END = 2.0
    q0, v0 = pend.initial_state(TH0)
    e_t, e_q, e_v = [], [], []
    for h in hs:
        n = int(round(T_END / h))
        r = fastvi.integrate(pend, q0, v0, h=h, n_steps=n, method=name, events=cross, dense_output=True)
        te = r.t_events[0]
        assert te.size == 2  # T/4 + k T/2 < 2 s for k = 0, 1 (T = 2.14 s)
        e_t.append(np.abs(te - _exact_crossings(te.size)).max())
        tm = np.arange(n) * h + 0.37 * h  # inside every step
        qr, vr = _reference(tm)
        q, v = r.sol(tm)
        e_q.append(np.abs(q - qr).max())
        e_v.append(np.abs(v - vr).max())
        assert np.array_equal(r.sol(r.t)[0], r.q)  # the grid points are the integrator's q_k
        assert np.abs(r.q_events[0][:, 0]).max() < 1e-13  # the located state is on the event

    def slope(e):
        return np.log(e[0] / e[-1]) / np.log(hs[0] / hs[-1])

    assert slope(e_q) > s + 1 - 0.2, e_q  # interior q: order s + 1
    assert slope(e_v) > s - 0.2, e_v  # interior v: order s
    assert slope(e_t) > s + 1 - 0.3, e_t  # event times: at least s + 1


def test_direction_filters_crossings(pend):
    q0, v0 = pend.initial_state(TH0)
    r = fastvi.integrate(pend, q0, v0, h=0.01, n_steps=300, events=[cross, up])
    both, rising = r.t_events
    assert both.size == 3 and np.array_equal(rising, both[1::2])  # it starts swinging left
    assert np.all(r.v_events[1][:, 0] > 0)


def test_terminal_event_ends_the_run_at_the_event(pend):
    q0, v0 = pend.initial_state(TH0)
    r = fastvi.integrate(pend, q0, v0, h=0.01, n_steps=1000, events=stop, dense_output=True)
    assert r.status == Status.TERMINATED and r.success and "termination event" in r.message
    (te,) = r.t_events
    assert te.size == 1 and abs(te[0] - PERIOD / 4) < 1e-6
    assert r.t[-1] == te[0]  # the last sample is the state at the event (as SciPy's)
    assert r.t[-2] < te[0] and r.stats["steps"] == int(np.ceil(te[0] / 0.01))  # within that step
    q, v = r.sol(te[0])
    assert np.array_equal(q, r.q[-1]) and np.array_equal(v, r.v[-1])
    assert np.allclose(q, r.q_events[0][0], atol=1e-15) and np.allclose(v, r.v_events[0][0], atol=1e-15)


def test_several_events_and_records_that_grow(pend):
    q0, v0 = pend.initial_state(TH0)
    r = fastvi.integrate(pend, q0, v0, h=0.01, n_steps=8000, events=[cross, low], save_every=100)
    n_cross = int((80 - PERIOD / 4) // (PERIOD / 2)) + 1
    assert r.t_events[0].size == n_cross > 64  # beyond the initial record capacity
    assert np.abs(r.t_events[0] - _exact_crossings(n_cross)).max() < 1e-5
    assert r.t_events[1].size == 2 * n_cross  # entering and leaving the low band each swing
    assert np.allclose(r.q_events[1][:, 1], -0.95, atol=1e-13)


def test_event_exactly_at_a_grid_point_is_found_once(pend):
    q0, v0 = pend.initial_state(TH0)
    r = fastvi.integrate(pend, q0, v0, h=0.125, n_steps=8, events=at_half)
    assert r.t_events[0].tolist() == [0.5]
    assert np.array_equal(r.q_events[0][0], r.q[4])


def test_events_on_a_time_dependent_model():
    kapitza = fastvi.scenes.kapitza_pendulum()

    def pivot_top(t, q, v, p):
        return np.sin(p[4] * t)  # the pivot passes its top at ω t = k π

    r = fastvi.integrate(kapitza, *kapitza.initial_state(3.0), h=1e-3, n_steps=200, events=pivot_top)
    w = kapitza.params[4]
    k = np.arange(1, r.t_events[0].size + 1)
    assert r.t_events[0].size == int(0.2 * w / np.pi) and np.abs(r.t_events[0] - k * np.pi / w).max() < 1e-12


def test_bad_events_are_refused_naming_them(pend):
    q0, v0 = pend.initial_state(TH0)
    with pytest.raises(TypeError, match=r"events\[1\]"):
        fastvi.integrate(pend, q0, v0, h=0.01, n_steps=3, events=[cross, 3.0])

    def bad(t, q, v, p):
        return f"{q[0]:.3f}"

    with pytest.raises(TypeError, match="could not be compiled"):
        fastvi.integrate(pend, q0, v0, h=0.01, n_steps=3, events=bad)
    with pytest.raises(ValueError, match="recover"):
        fastvi.integrate(pend, q0, v0, h=0.01, n_steps=3, events=cross, recover=1)
    r = fastvi.integrate(pend, q0, v0, h=0.01, n_steps=3, dense_output=True)
    with pytest.raises(ValueError, match="integrated interval"):
        r.sol(1.0)


# ----------------------------------------------------------------------------- ensembles
def inner_under(t, q, v, p):
    return q[0]  # the inner rod passes under the pivot (both directions, never terminal)


def _flip_members(dp, count, seed):
    rng = np.random.default_rng(seed)
    angles = np.vstack([[[0.5, 0.5]], rng.uniform(-3.0, 3.0, (count - 1, 2))])  # member 0 cannot flip
    states = [dp.initial_state(a, b) for a, b in angles]
    return np.array([s[0] for s in states]), np.array([s[1] for s in states])


_RUN_FIELDS = ("t", "q", "v", "p", "energy", "constraint_residual", "velocity_residual",
               "newton_iterations", "work")


def _same_run(m, r, i):
    """``m`` (an ensemble's member) is ``r`` (integrate of it) array for array."""
    assert m.status == r.status, i
    for name in _RUN_FIELDS:
        a, b = getattr(m, name), getattr(r, name)
        assert (a is None and b is None) or np.array_equal(a, b), (i, name)
    for name in ("t_events", "q_events", "v_events"):
        assert len(getattr(m, name)) == len(getattr(r, name)), (i, name)
        for a, b in zip(getattr(m, name), getattr(r, name)):
            assert np.array_equal(a, b), (i, name)


def test_ensemble_members_record_the_events_of_integrate_bit_for_bit(double_pendulum):
    dp = double_pendulum
    Q0, V0 = _flip_members(dp, 10, 3)
    events = list(dp.flips) + [inner_under]
    kw = dict(h=0.01, n_steps=400)
    ens = fastvi.integrate_ensemble(dp, Q0, V0, save=7, events=events, keep_events=40, **kw)
    assert ens.t_events.shape == (10, 3, 40) and ens.q_events.shape == (10, 3, 40, 4)
    ended = ens.terminated
    assert 0 < ended.size < 10 and ens.success.all()
    assert np.all(ens.steps[ended] < 400) and np.all(ens.n_events[ended, :2].sum(axis=1) == 1)
    # NaN below the pivot: member 0 swings under it again and again and never flips
    assert ens.n_events[0, 2] >= 3 and ens.n_events[0, :2].sum() == 0
    for i in range(10):
        r = fastvi.integrate(dp, Q0[i], V0[i], save_every=7, events=events, **kw)
        _same_run(ens.member(i), r, i)
        if i in ended:  # integrate, and the member, end at the event
            e = int(np.flatnonzero(ens.n_events[i, :2])[0])
            assert r.t[-1] == ens.t_events[i, e, 0] == ens.t_final[i]
            assert np.array_equal(r.q[-1], ens.q_events[i, e, 0])
    # a flip is located on the top: the rod is vertical there, pointing up
    for i in ended:
        e = int(np.flatnonzero(ens.n_events[i, :2])[0])
        q = ens.q_events[i, e, 0]
        dx, dy = (q[0], q[1]) if e == 0 else (q[2] - q[0], q[3] - q[1])
        assert abs(dx) < 1e-12 and dy > 0.999
        assert ens.t0 + (ens.steps[i] - 1) * ens.h < ens.t_final[i] <= ens.t0 + ens.steps[i] * ens.h


def test_ensemble_keeps_the_first_crossings_and_counts_them_all(double_pendulum):
    dp = double_pendulum
    Q0, V0 = _flip_members(dp, 4, 5)
    full = fastvi.integrate_ensemble(dp, Q0, V0, h=0.01, n_steps=300, events=inner_under, keep_events=64)
    one = fastvi.integrate_ensemble(dp, Q0, V0, h=0.01, n_steps=300, events=inner_under)
    assert one.t_events.shape == (4, 1, 1) and np.array_equal(one.n_events, full.n_events)
    assert np.array_equal(one.t_events[:, :, 0], full.t_events[:, :, 0], equal_nan=True)
    assert np.array_equal(one.q, full.q)  # events never change the trajectory
    assert one.n_events.max() > 1
    with pytest.raises(ValueError, match="keep_events"):
        fastvi.integrate_ensemble(dp, Q0, V0, h=0.01, n_steps=300, events=inner_under, save=10).member(0)
    with pytest.raises(ValueError, match="`keep_events` must be >= 1"):
        fastvi.integrate_ensemble(dp, Q0, V0, h=0.01, n_steps=3, events=inner_under, keep_events=0)


# ----------------------------------------------------------- ensemble members end at their event
def ends_at(t, q, v, p):
    return t - 0.505  # inside the step from 0.50 to 0.51


ends_at.terminal = True


def just_before(t, q, v, p):
    return t - 0.503  # in that last step, before the terminal event


def just_after(t, q, v, p):
    return t - 0.507  # in that last step, after the terminal event: it never happens


def twice_under(t, q, v, p):
    return q[0]


twice_under.terminal = 2  # the second pass under the pivot


@pytest.fixture(scope="module")
def damped():
    return fastvi.scenes.double_pendulum(damping=0.3)  # a force: the results carry the work


def _spinning_members(dp, count, seed):
    """Member 0 at rest, the others spun (θ1, θ2, ω1, ω2): most flip within a second or two."""
    rng = np.random.default_rng(seed)
    spun = np.column_stack((rng.uniform(-3.0, 3.0, (count - 1, 2)), rng.uniform(-8.0, 8.0, (count - 1, 2))))
    states = [dp.initial_state(*a) for a in np.vstack([[[0.5, 0.5, 0.0, 0.0]], spun])]
    return np.array([s[0] for s in states]), np.array([s[1] for s in states])


def test_terminated_members_of_a_forced_model_are_integrate_work_included(damped):
    Q0, V0 = _spinning_members(damped, 8, 3)
    events = list(damped.flips) + [inner_under]
    kw = dict(h=0.01, n_steps=300)
    ens = fastvi.integrate_ensemble(damped, Q0, V0, save=7, events=events, keep_events=50, **kw)
    ended = ens.terminated
    assert 0 < ended.size < 8 and ens.work is not None
    for i in range(8):
        r = fastvi.integrate(damped, Q0[i], V0[i], save_every=7, events=events, on_failure="return", **kw)
        _same_run(ens.member(i), r, i)
        assert ens.t_final[i] == r.t[-1]
    # the trajectory up to the event is the run's without events; the other members are
    # that run's bit for bit
    plain = fastvi.integrate_ensemble(damped, Q0, V0, save=7, **kw)
    going = ens.status == Status.SUCCESS
    assert going.sum() == 8 - ended.size and np.array_equal(ens.t_final[going], plain.t_final[going])
    for name in ("q", "v", "p", "energy", "constraint_residual", "velocity_residual",
                 "newton_iterations", "work"):
        a, b = getattr(ens, name), getattr(plain, name)
        assert np.array_equal(a[going], b[going], equal_nan=True), name
        for i in ended:
            J = ens.n_saved[i]
            assert np.array_equal(a[i, :J - 1], b[i, :J - 1]), (i, name)
            assert np.isnan(a[i, J:]).all() and ens.t[J - 2] < ens.t_final[i] < ens.t[J - 1]


def test_final_state_of_a_terminated_member_is_the_last_sample_of_integrate(double_pendulum):
    dp = double_pendulum
    Q0, V0 = _flip_members(dp, 5, 5)
    events = [ends_at, just_before, just_after]
    kw = dict(h=0.01, n_steps=200, events=events)
    fin = fastvi.integrate_ensemble(dp, Q0, V0, **kw)
    diag = fastvi.integrate_ensemble(dp, Q0, V0, save="diagnostics", **kw)
    stride = fastvi.integrate_ensemble(dp, Q0, V0, save=10, **kw)
    assert (fin.status == Status.TERMINATED).all() and np.array_equal(fin.steps, [51] * 5)
    q, v = fin.final_state()
    for i in range(5):
        r = fastvi.integrate(dp, Q0[i], V0[i], **kw)
        assert r.status == Status.TERMINATED and abs(r.t[-1] - 0.505) < 1e-12
        assert fin.t_final[i] == diag.t_final[i] == fin.t_terminal[i] == r.t[-1]
        assert np.array_equal(q[i], r.q[-1]) and np.array_equal(v[i], r.v[-1])
        _same_run(stride.member(i), fastvi.integrate(dp, Q0[i], V0[i], save_every=10, **kw), i)
        for ens in (fin, diag, stride):
            last = (i,) if ens.t is None else (i, ens.n_saved[i] - 1)
            for name in ("q", "v", "p", "energy"):
                assert np.array_equal(getattr(ens, name)[last], getattr(r, name)[-1]), (i, name)
            # the crossing after the terminal one, in the same step, did not happen
            assert ens.n_events[i].tolist() == [a.size for a in r.t_events] == [1, 1, 0]
            assert np.isnan(ens.t_events[i, 2]).all() and np.isnan(ens.q_events[i, 2]).all()
            assert ens.t_events[i, :2, 0].tolist() == [r.t_events[0][0], r.t_events[1][0]]
        # diagnostics: the maxima over every step taken (to 0.51) and the state at the event
        steps = fastvi.integrate(dp, Q0[i], V0[i], h=0.01, n_steps=51)
        assert diag.max_energy_error[i] == max(np.max(np.abs(steps.energy_error)), abs(r.energy_error[-1]))
        assert diag.max_constraint_residual[i] == max(np.max(steps.constraint_residual),
                                                      r.constraint_residual[-1])
        assert diag.max_velocity_residual[i] == max(np.max(steps.velocity_residual),
                                                    r.velocity_residual[-1])


def test_a_terminal_count_beyond_keep_events_ends_the_member_at_its_event(double_pendulum):
    dp = double_pendulum
    Q0, V0 = _flip_members(dp, 4, 5)
    kw = dict(h=0.01, n_steps=300, events=twice_under)
    one = fastvi.integrate_ensemble(dp, Q0, V0, **kw)  # keep_events=1 < terminal = 2
    assert one.t_events.shape == (4, 1, 1) and one.terminated.size > 0
    for i in range(4):
        r = fastvi.integrate(dp, Q0[i], V0[i], **kw)
        assert one.status[i] == r.status and one.t_final[i] == r.t[-1]
        assert np.array_equal(one.q[i], r.q[-1]) and np.array_equal(one.energy[i], r.energy[-1])
        assert one.n_events[i, 0] == r.t_events[0].size and one.t_events[i, 0, 0] == r.t_events[0][0]
