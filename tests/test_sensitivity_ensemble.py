"""Ensemble sensitivities: member ``i`` is ``fastvi.sensitivity`` of that member, bit for bit
(which ``test_sensitivity.py`` checks against differences of whole runs and theory).

The first ensemble of sensitivities compiles its member (some 11 s of CPU; more inside the
test suite's two processes), which ``make test``'s 4-minute budget cannot take: the tests
that run one are marked ``slow`` (``make test-slow``)."""

import numpy as np
import pytest

import fastvi

STEPS = 40


def _members(model, angles):
    starts = [model.initial_state(*a) for a in angles]
    return np.array([q for q, _ in starts]), np.array([v for _, v in starts])


@pytest.mark.slow
def test_members_equal_single_sensitivities_bit_for_bit():
    """Different starts and parameters per member, derivatives by q0, v0 and a parameter
    moving the constraints (a rod length)."""
    dp = fastvi.scenes.double_pendulum(damping=0.3)
    Q0, V0 = _members(dp, [(0.9, -0.4, 0.3, 1.1), (2.0, 1.0, 0.0, 0.0), (0.1, 0.2, 0.0, 0.0)])
    P = np.tile(dp.params, (3, 1))
    P[1, 5] *= 1.5  # params (m1, m2, l1, l2, g, c): member 1 damped harder
    P[2, 4] *= 0.5  # member 2 under weaker gravity
    wrt, index = ("q0", "v0", "params"), [5, 3]  # by the damping and the outer rod's length
    ens = fastvi.sensitivity_ensemble(dp, Q0, V0, h=0.02, n_steps=STEPS, params=P, wrt=wrt,
                                      param_index=index, save_every=10, threads=2)
    assert len(ens) == 3 and ens.dq.shape == (3, 5, dp.n, 2 * dp.n + 2)
    for i in range(3):
        one = fastvi.sensitivity(dp, Q0[i], V0[i], h=0.02, n_steps=STEPS, params=P[i], wrt=wrt,
                                 param_index=index, save_every=10)
        assert np.array_equal(one.result.q, ens.q[i]) and np.array_equal(one.result.p, ens.p[i])
        for name in ("dq", "dv", "dp"):
            assert np.array_equal(getattr(one, name), getattr(ens, name)[i]), (i, name)
        assert ens.labels == one.labels
        assert np.array_equal(ens.jacobian()[i], np.vstack([one.dq[-1], one.dv[-1]]))
    # the members differ: the test would not pass with one member's derivatives copied
    assert np.abs(ens.dq[0, -1] - ens.dq[1, -1]).max() > 0.1


@pytest.mark.slow
def test_progress_runs_groups_of_members_and_changes_no_bit(capsys):
    dp = fastvi.scenes.double_pendulum(damping=0.3)
    Q0, V0 = _members(dp, [(0.9, -0.4), (2.0, 1.0), (0.1, 0.2)])
    P = np.tile(dp.params, (3, 1))
    P[2, 5] *= 2.0
    kw = dict(h=0.02, n_steps=STEPS, params=P, save_every=10, threads=2)
    quiet_run = fastvi.sensitivity_ensemble(dp, Q0, V0, **kw)
    shown = fastvi.sensitivity_ensemble(dp, Q0, V0, progress=True, **kw)  # groups of 2 and 1
    err = capsys.readouterr().err
    assert f"{3 * STEPS}/{3 * STEPS} member-steps (100%)" in err and "3/3 members" in err, err
    for name in ("q", "p", "dq", "dv", "dp"):
        assert np.array_equal(getattr(quiet_run, name), getattr(shown, name)), name
    with pytest.raises(TypeError, match="`progress` must be True or False"):
        fastvi.sensitivity_ensemble(dp, Q0, V0, progress=1, **kw)


@pytest.mark.slow
def test_a_failed_member_is_named_never_returned_as_nan(double_pendulum):
    # member 1 falls under g = 20000: six Newton iterations cannot follow it
    Q0, V0 = _members(double_pendulum, [(1.5, 1.5), (1.5, 1.5)])
    P = np.tile(double_pendulum.params, (2, 1))
    P[1, 4] = 20000.0
    with pytest.raises(fastvi.IntegrationError,
                       match=r"member 1 is not .*members that failed: 1 of 2") as err:
        fastvi.sensitivity_ensemble(double_pendulum, Q0, V0, h=0.02, n_steps=STEPS, params=P,
                                    max_iter=6)
    with pytest.raises(fastvi.IntegrationError) as single:
        fastvi.sensitivity(double_pendulum, Q0[1], V0[1], h=0.02, n_steps=STEPS, params=P[1],
                           max_iter=6)
    assert err.value.step == single.value.step and err.value.status == single.value.status
    assert np.array_equal(err.value.result.q, single.value.result.q)


def test_arguments_are_checked(double_pendulum):
    Q0, V0 = _members(double_pendulum, [(0.3, 0.2)])
    with pytest.raises(ValueError, match="one row per member"):
        fastvi.sensitivity_ensemble(double_pendulum, Q0, np.vstack([V0, V0]), h=0.02, n_steps=2)
    with pytest.raises(TypeError, match="fastvi.Model"):
        fastvi.sensitivity_ensemble("pendulum", Q0, V0, h=0.02, n_steps=2)
