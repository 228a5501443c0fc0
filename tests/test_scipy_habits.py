"""What solve_ivp users type works, or says what to type: ``t_span``, ``t_eval``, a span that
is not a whole number of steps, terminal events that end at the event, ``res.sol``.

The reference is SciPy's own ``solve_ivp`` (DOP853 at rtol = atol = 1e-13) on the same
pendulum in its angle, ``θ'' = −(g/l) sin θ``, called with the same arguments.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fastvi
from fastvi.status import Status

TH0, G = 1.0, 9.81
T0, T1 = 0.0477, 10.0  # the start, and an end that is not a whole number of steps


@pytest.fixture(scope="module")
def pend():
    return fastvi.scenes.pendulum()


def _scipy(t_span, **kw):
    sol = solve_ivp(lambda t, y: [y[1], -G * np.sin(y[0])], t_span, [TH0, 0.0], method="DOP853",
                    rtol=1e-13, atol=1e-13, **kw)
    assert sol.success
    return sol


def test_t_span_with_a_shorter_last_step_lands_on_t_end_like_solve_ivp(pend):
    ref = _scipy((T0, T1))
    r = fastvi.integrate(pend, *pend.initial_state(TH0), h=0.01, t_span=(T0, T1))
    assert r.status == Status.SUCCESS
    assert r.t[0] == ref.t[0] == T0 and r.t[-1] == ref.t[-1] == T1  # both end exactly on t1
    steps = int((T1 - T0) / 0.01)
    assert r.stats["steps"] == steps + 1 and len(r.t) == steps + 2
    assert r.stats["last_step"] == pytest.approx((T1 - T0) - steps * 0.01, rel=1e-9)
    assert 0 < r.t[-1] - r.t[-2] < 0.01
    np.testing.assert_allclose(np.diff(r.t[:-1]), 0.01, rtol=1e-9)
    # the shorter step is a step of the same motion: the end agrees with SciPy to the
    # method's accuracy, and the energy error stays that of the steps of h
    assert abs(pend.angle(r.q[-1]) - ref.y[0, -1]) < 1e-6
    assert np.max(np.abs(r.energy_error)) < 1e-6
    assert r.constraint_residual.max() < 1e-13


def test_t_end_with_t0_is_no_longer_refused(pend):
    r = fastvi.integrate(pend, *pend.initial_state(TH0), h=0.01, t0=T0, t_end=T1)
    r2 = fastvi.integrate(pend, *pend.initial_state(TH0), h=0.01, t_span=(T0, T1))
    np.testing.assert_array_equal(r.q, r2.q)
    assert r.t[-1] == T1


def test_a_span_shorter_than_h_is_one_step_of_the_span(pend):
    r = fastvi.integrate(pend, *pend.initial_state(TH0), h=0.1, t_span=(0.0, 0.03))
    assert r.stats["steps"] == 1 and r.t[-1] == pytest.approx(0.03) and r.h == pytest.approx(0.03)


def test_t_eval_samples_the_step_polynomials_like_solve_ivp(pend):
    t_eval = np.linspace(T0, T1, 41)
    ref = _scipy((T0, T1), t_eval=t_eval)
    r = fastvi.integrate(pend, *pend.initial_state(TH0), h=0.005, t_span=(T0, T1), t_eval=t_eval)
    np.testing.assert_array_equal(r.t, ref.t)
    np.testing.assert_array_equal(r.t, t_eval)
    # between grid points the polynomial is of order s + 1 = 3 in q (docs/events.md)
    assert np.max(np.abs(pend.angle(r.q) - ref.y[0])) < 1e-5
    omega = (r.q[:, 0] * r.v[:, 1] - r.q[:, 1] * r.v[:, 0]) * -1.0  # θ' = (x ẏ − y ẋ)/l², y = −cos θ
    assert np.max(np.abs(-omega - ref.y[1])) < 1e-3
    assert r.q.shape == (41, 2) and np.all(r.constraint_residual < 1e-6)
    with pytest.raises(ValueError, match="dense_output=True"):
        r.sol(1.0)  # as in SciPy, `sol` comes with dense_output=True only


def test_res_sol_without_dense_output_says_what_to_pass(pend):
    r = fastvi.integrate(pend, *pend.initial_state(TH0), h=0.01, n_steps=10)
    assert not r.sol
    with pytest.raises(ValueError, match=r"pass `dense_output=True`"):
        r.sol(0.05)
    with pytest.raises(ValueError, match=r"pass `dense_output=True`"):
        r.sol.t_max


@pytest.mark.parametrize("kwargs, match", [
    (dict(t_span=(0.0, 1.0), t_end=1.0), "not both"),
    (dict(t_span=(0.0, 1.0), n_steps=10), "not both"),
    (dict(t_span=(1.0, 0.0)), "run forward"),
    (dict(t_span=1.0), "pair"),
    (dict(t_span=(0.0, 1.0), t_eval=[0.5, 0.2]), "sorted"),
    (dict(t_span=(0.0, 1.0), t_eval=[0.5, 1.5]), r"within the integrated interval \[0, 1\]"),
    (dict(t_span=(0.0, 1.0), t_eval=[0.5], recover=2), "`recover` cannot be combined"),
])
def test_bad_scipy_style_arguments_say_what_to_use(pend, kwargs, match):
    with pytest.raises((ValueError, TypeError), match=match):
        fastvi.integrate(pend, *pend.initial_state(TH0), h=0.01, **kwargs)


def _down(t, q, v, p):
    return q[0]


_down.terminal = True
_down.direction = -1


def _down_y(t, y):  # the same event, SciPy's way
    return np.sin(y[0])


_down_y.terminal = True
_down_y.direction = -1


@pytest.mark.parametrize("dense", [True, False])
def test_a_terminal_event_ends_at_the_event_like_solve_ivp(pend, dense):
    r = fastvi.integrate(pend, *pend.initial_state(TH0), h=0.01, t_end=10.0, events=_down,
                         dense_output=dense)
    ref = _scipy((0.0, 10.0), events=_down_y)
    te = r.t_events[0][-1]
    assert r.status == Status.TERMINATED and len(r.t_events[0]) == 1
    assert abs(r.t[-1] - te) <= 4 * np.finfo(float).eps * te  # at the event, not the step's end
    # SciPy ends at its event too; the times agree to the method's accuracy (order 4, h = 0.01)
    assert abs(te - ref.t_events[0][0]) < 1e-7 and abs(ref.t[-1] - ref.t_events[0][0]) < 1e-15
    if dense:
        qe, ve = r.sol(te)
        np.testing.assert_array_equal(r.q[-1], qe)
        np.testing.assert_array_equal(r.v[-1], ve)
    else:
        np.testing.assert_array_equal(r.q[-1], r.q_events[0][-1])
    assert abs(r.q[-1, 0]) < 1e-12  # the bob is under the pivot
    assert abs(pend.angle(r.q[-1]) - ref.y_events[0][0][0]) < 1e-7
    # the velocity is the polynomial's, of order s = 2 inside a step (docs/events.md): the
    # angular velocity there agrees with SciPy's to that order, and so does the energy
    q, v = r.q[-1], r.v[-1]
    omega = q[0] * v[1] - q[1] * v[0]
    assert abs(omega - ref.y_events[0][0][1]) < 1e-3
    assert abs(r.energy[-1] - r.energy[0]) < 1e-3


def test_t_eval_stops_at_a_terminal_event_like_solve_ivp(pend):
    t_eval = np.linspace(0.0, 2.0, 21)
    ref = _scipy((0.0, 2.0), events=_down_y, t_eval=t_eval)
    r = fastvi.integrate(pend, *pend.initial_state(TH0), h=0.01, t_span=(0.0, 2.0), t_eval=t_eval,
                         events=_down)
    np.testing.assert_array_equal(r.t, ref.t)


def test_runs_with_events_print_no_numba_warnings_with_warnings_on():
    """With warnings on (``-W default``, and again after import as a user would), a run with
    events, a terminal event and an ensemble with events print no NumbaExperimentalFeatureWarning
    (numba's note on first-class functions, fastvi's own business). The event is defined in
    ``-c`` code, so it is compiled afresh in the subprocess."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    code = (
        "import warnings, numpy as np, fastvi\n"
        "warnings.simplefilter('default')\n"
        "m = fastvi.scenes.pendulum()\n"
        "def ev(t, q, v, p):\n    return q[0]\n"
        "ev.terminal = True\n"
        "q0, v0 = m.initial_state(1.0)\n"
        "r = fastvi.integrate(m, q0, v0, h=0.01, t_end=2.0, events=ev, dense_output=True)\n"
        "e = fastvi.integrate_ensemble(m, np.array([q0, q0]), np.array([v0, v0]), h=0.01, "
        "n_steps=100, events=[ev])\n"
        "print('ok', int(r.status), len(r.t_events[0]))\n")
    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-W", "default", "-c", code], cwd=root, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0 and "ok 1 1" in proc.stdout, proc.stderr[-2000:]
    assert "NumbaExperimentalFeatureWarning" not in proc.stderr, proc.stderr[-2000:]
    assert "Warning" not in proc.stderr, proc.stderr[-2000:]
