"""Ensembles: every member is ``integrate`` of that member, bit for bit; failures stay local."""

import warnings

import numba
import numpy as np
import pytest
from scipy.special import ellipk

import fastvi
from fastvi import Status
from fastvi.kernels import drive

from . import models

H = 0.01
STEPS = 150
RESULT_FIELDS = ("t", "q", "v", "p", "energy", "constraint_residual", "velocity_residual",
                 "newton_iterations")


def _states(model, angles):
    states = [model.initial_state(*a) for a in angles]
    return np.array([s[0] for s in states]), np.array([s[1] for s in states])


@pytest.fixture(scope="module")
def dp_members(double_pendulum):
    """Six double-pendulum members from rest to tumbling (θ1, θ2, ω1, ω2)."""
    rng = np.random.default_rng(5)
    angles = np.column_stack((rng.uniform(-3, 3, (6, 2)), rng.uniform(-2, 2, (6, 2))))
    return _states(double_pendulum, angles)


@pytest.fixture(scope="module")
def dp_serial(double_pendulum, dp_members):
    Q0, V0 = dp_members
    return [fastvi.integrate(double_pendulum, q, v, h=H, n_steps=STEPS) for q, v in zip(Q0, V0)]


def test_final_states_equal_integrate_bit_for_bit(double_pendulum, dp_members, dp_serial):
    Q0, V0 = dp_members
    ens = fastvi.integrate_ensemble(double_pendulum, Q0, V0, h=H, n_steps=STEPS, threads=2)
    assert ens.success.all() and ens.q.shape == (6, 4) and ens.t is None
    for i, r in enumerate(dp_serial):
        for name in ("q", "v", "p", "energy"):
            assert np.array_equal(getattr(ens, name)[i], getattr(r, name)[-1]), (i, name)
        assert ens.iterations[i] == r.stats["newton_iterations"]
        assert ens.max_residual[i] == r.stats["max_residual"]
    assert ens.stats["member_steps"] == 6 * STEPS and ens.stats["threads"] == 2


def test_stride_members_equal_integrate_with_save_every_bit_for_bit(double_pendulum, dp_members):
    Q0, V0 = dp_members
    ens = fastvi.integrate_ensemble(double_pendulum, Q0, V0, h=H, n_steps=103, save=10, threads=2)
    assert ens.q.shape == (6, 12, 4)  # steps 0, 10, …, 100 and the last, 103
    for i in range(6):
        r = fastvi.integrate(double_pendulum, Q0[i], V0[i], h=H, n_steps=103, save_every=10)
        m = ens.member(i)
        for name in RESULT_FIELDS:
            assert np.array_equal(getattr(m, name), getattr(r, name)), (i, name)
        assert m.stats["newton_iterations"] == r.stats["newton_iterations"]


def test_diagnostics_equal_the_maxima_of_integrate(double_pendulum, dp_members, dp_serial):
    Q0, V0 = dp_members
    ens = fastvi.integrate_ensemble(double_pendulum, Q0, V0, h=H, n_steps=STEPS, save="diagnostics")
    assert ens.constraint_residual is None and ens.q.shape == (6, 4)
    for i, r in enumerate(dp_serial):
        assert ens.max_energy_error[i] == np.max(np.abs(r.energy_error))
        assert ens.max_constraint_residual[i] == np.max(r.constraint_residual)
        assert ens.max_velocity_residual[i] == np.max(r.velocity_residual)
        assert np.array_equal(ens.q[i], r.q[-1])
    # and they are what a variational integrator should give (not only self-consistent)
    assert ens.max_constraint_residual.max() <= 1e-13  # measured 3e-16
    assert 0 < ens.max_energy_error.max() <= 2e-3  # measured 4e-4 (tumbling members, h = 0.01)
    # the summary names the figures as the single run's does: a conservative model's
    # hidden constraint is G v = 0, its energy figure |ΔH|
    assert "max |ΔH| = " in ens.summary() and "max |Gv| = " in ens.summary()


def test_q_dependent_mass_model_members_equal_integrate():
    model = models.polar_pendulum(exact=False)  # mass callback and finite-difference Hessians
    Q0 = np.array([[1.0, 0.3], [1.0, 1.5], [1.0, -2.5]])
    V0 = np.array([[0.0, 0.0], [0.0, 1.0], [0.0, -0.5]])
    P = np.array([[1.0, 9.81, 1.0, 0.0], [2.0, 9.81, 1.0, 0.0], [1.0, 3.0, 1.0, 0.0]])
    ens = fastvi.integrate_ensemble(model, Q0, V0, h=0.02, n_steps=100, params=P, save=9)
    for i in range(3):
        r = fastvi.integrate(model, Q0[i], V0[i], h=0.02, n_steps=100, params=P[i], save_every=9)
        for name in RESULT_FIELDS:
            assert np.array_equal(getattr(ens.member(i), name), getattr(r, name)), (i, name)


def test_thread_count_changes_no_bit_and_is_restored(double_pendulum, dp_members):
    Q0, V0 = dp_members
    before = numba.get_num_threads()
    one = fastvi.integrate_ensemble(double_pendulum, Q0, V0, h=H, n_steps=50, threads=1, save=1)
    assert numba.get_num_threads() == before and one.stats["threads"] == 1
    two = fastvi.integrate_ensemble(double_pendulum, Q0, V0, h=H, n_steps=50, threads=2, save=1)
    assert numba.get_num_threads() == before and two.stats["threads"] == 2
    assert np.array_equal(one.q, two.q) and np.array_equal(one.p, two.p)


def test_failing_member_does_not_stop_the_others(pendulum):
    """Member 2 has g = 20000: with max_iter = 6 its Newton fails once it swings fast."""
    Q0, V0 = _states(pendulum, [(3.1,), (3.1,), (3.1,), (0.5,)])
    P = np.tile(pendulum.params, (4, 1))
    P[2, 2] = 20000.0
    ens = fastvi.integrate_ensemble(pendulum, Q0, V0, h=H, n_steps=STEPS, params=P, max_iter=6)
    with pytest.raises(fastvi.IntegrationError) as err:
        fastvi.integrate(pendulum, Q0[2], V0[2], h=H, n_steps=STEPS, params=P[2], max_iter=6)
    assert err.value.step > 0  # measured 3: it fails mid-run, not at the start
    assert list(ens.failed) == [2]
    assert ens.status[2] == Status.NEWTON_NOT_CONVERGED == err.value.status
    assert ens.failed_step[2] == err.value.step == ens.steps[2]
    assert np.array_equal(ens.q[2], err.value.result.q[-1])  # the last good state
    (failure,) = ens.failures()
    assert failure["member"] == 2 and failure["step"] == err.value.step
    assert failure["residual"] == err.value.residual
    assert "1 of 4 members failed (1 × NEWTON_NOT_CONVERGED)" in ens.summary()
    for i in (0, 1, 3):
        r = fastvi.integrate(pendulum, Q0[i], V0[i], h=H, n_steps=STEPS, params=P[i], max_iter=6)
        assert ens.status[i] == Status.SUCCESS and ens.steps[i] == STEPS
        assert np.array_equal(ens.q[i], r.q[-1]) and np.array_equal(ens.p[i], r.p[-1])


def test_failed_member_samples_stop_at_the_failure(pendulum):
    Q0, V0 = _states(pendulum, [(3.1,), (3.1,)])
    P = np.tile(pendulum.params, (2, 1))
    P[1, 2] = 20000.0
    ens = fastvi.integrate_ensemble(pendulum, Q0, V0, h=H, n_steps=20, params=P, max_iter=6, save=2)
    k = ens.failed_step[1]  # measured 3: samples at steps 0 and 2
    assert k > 0
    assert ens.n_saved[1] == k // 2 + 1 and ens.n_saved[0] == 11
    assert np.isnan(ens.q[1, ens.n_saved[1]:]).all() and np.isfinite(ens.q[1, :ens.n_saved[1]]).all()
    r = fastvi.integrate(pendulum, Q0[1], V0[1], h=H, n_steps=20, params=P[1], max_iter=6,
                         save_every=2, on_failure="return")
    m = ens.member(1)
    assert m.status == r.status and m.failed_step == r.failed_step
    for name in RESULT_FIELDS:
        assert np.array_equal(getattr(m, name), getattr(r, name)), name


def test_per_member_length_sets_the_pendulum_period(pendulum):
    """T = 4 √(l/g) K(sin(θ0/2)) (exact); ≈ 2π √(l/g) at small amplitude."""
    lengths = np.array([0.25, 0.5, 1.0, 2.0, 4.0])
    theta0, g, h = 0.02, 9.81, 0.005
    Q0 = np.column_stack((lengths * np.sin(theta0), -lengths * np.cos(theta0)))
    V0 = np.zeros_like(Q0)
    P = np.column_stack((np.ones(5), lengths, np.full(5, g)))
    ens = fastvi.integrate_ensemble(pendulum, Q0, V0, h=h, n_steps=2600, params=P, save=1)
    assert ens.success.all()
    for i, l in enumerate(lengths):
        x, t = ens.q[i, :, 0], ens.t
        up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))  # upward zero crossings
        tc = t[up] - x[up] * (t[up + 1] - t[up]) / (x[up + 1] - x[up])
        assert tc.size >= 3
        period = (tc[-1] - tc[0]) / (tc.size - 1)
        exact = 4 * np.sqrt(l / g) * ellipk(np.sin(theta0 / 2) ** 2)
        small = 2 * np.pi * np.sqrt(l / g)
        assert abs(period / exact - 1) <= 1e-7  # measured ≤ 8e-9
        assert abs(period / small - 1) <= 1e-4  # measured 2.5e-5: the amplitude correction θ0²/16


def test_one_shared_params_vector_is_broadcast(pendulum):
    Q0, V0 = _states(pendulum, [(0.3,), (0.6,)])
    a = fastvi.integrate_ensemble(pendulum, Q0, V0, h=H, n_steps=20, params=[1.0, 1.0, 3.0])
    b = fastvi.integrate_ensemble(pendulum, Q0, V0, h=H, n_steps=20, params=[[1.0, 1.0, 3.0]] * 2)
    c = fastvi.integrate_ensemble(pendulum, Q0, V0, h=H, n_steps=20)
    assert np.array_equal(a.q, b.q) and not np.array_equal(a.q, c.q)


def test_t_end_sets_the_step_count_and_results_save_to_npz(pendulum, tmp_path):
    Q0, V0 = _states(pendulum, [(0.3,), (0.6,)])
    ens = fastvi.integrate_ensemble(pendulum, Q0, V0, h=H, t_end=0.2, save=5)
    assert ens.n_steps == 20 and ens.t[-1] == pytest.approx(0.2) and (ens.steps == 20).all()
    ens.save_npz(tmp_path / "ens.npz")
    with np.load(tmp_path / "ens.npz") as data:
        assert np.array_equal(data["q"], ens.q) and int(data["n_steps"]) == 20
        assert str(data["method"]) == ens.method.name


def test_kernels_compile_once_for_all_models(pendulum, double_pendulum):
    for model, a in ((pendulum, [(0.3,)]), (double_pendulum, [(0.3, 0.2)])):
        Q0, V0 = _states(model, a)
        for save in ("final", 3, "diagnostics"):
            fastvi.integrate_ensemble(model, Q0, V0, h=H, n_steps=5, save=save)
    # one signature for every model (size-specialized members compile once per size)
    generic = [sig for sig in drive.run_members.signatures
               if "EnsembleMembers" in str(sig[1]) and "UniTuple(int64 x 5)" in str(sig[1])]
    assert len(generic) == 1, drive.run_members.signatures


def test_members_share_the_compiled_time_loop_of_integrate(double_pendulum, dp_members):
    """A member runs the one time loop with the argument types of ``integrate``'s call, so an
    ensemble compiles no second loop (docs/decisions/0017-one-time-loop.md): with an empty
    cache a second overload of ``run`` would appear here."""
    Q0, V0 = dp_members
    fastvi.integrate(double_pendulum, Q0[0], V0[0], h=H, n_steps=5, events=double_pendulum.flips)
    loops = set(drive.run.overloads)
    ens = fastvi.integrate_ensemble(double_pendulum, Q0, V0, h=H, n_steps=5,
                                    events=double_pendulum.flips)
    assert ens.q.shape == (6, 4)
    assert set(drive.run.overloads) == loops


def test_projection_of_members_is_reported_in_one_warning(pendulum):
    Q0, V0 = _states(pendulum, [(0.3,), (0.4,), (0.5,)])
    Q0[1] *= 1 + 1e-9
    Q0[2] *= 1 + 1e-9
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fastvi.integrate_ensemble(pendulum, Q0, V0, h=H, n_steps=2)
    msgs = [str(w.message) for w in caught if not issubclass(w.category, numba.NumbaExperimentalFeatureWarning)]
    assert len(msgs) == 1 and "2 of 3 members" in msgs[0] and "member 1" in msgs[0]


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        (dict(Q0=np.zeros((2, 3))), ValueError, r"`Q0` must have shape \(N, 2\)"),
        (dict(Q0=np.zeros(2)), ValueError, r"`Q0` must have shape \(N, 2\)"),
        (dict(V0=np.zeros((3, 2))), ValueError, "`Q0` and `V0` must have one row per member"),
        (dict(V0=[[0.0, 0.0], [np.nan, 0.0]]), ValueError, r"`V0\[1\]` must be finite"),
        (dict(params=np.ones((3, 3))), ValueError, r"`params` must be None, shape \(3,\)"),
        (dict(params=[[1, 1, 9.81], [1, 1, np.inf]]), ValueError, r"`params\[1\]` must be finite"),
        (dict(save="trajectory"), ValueError, "`save` must be 'final', 'diagnostics'"),
        (dict(save=0), ValueError, "`save` must be >= 1"),
        (dict(threads=0), ValueError, "`threads` must be >= 1"),
        (dict(threads=numba.config.NUMBA_NUM_THREADS + 1), ValueError, "`threads` must be <="),
        (dict(h=-0.1), ValueError, "`h` must be positive"),
        (dict(method="P2L-Q3X"), ValueError, "P2L-Q3"),
        (dict(solver="superlu"), ValueError, "`solver` must be one of 'auto', 'dense', 'banded'"),
        (dict(specialize="yes"), TypeError, "`specialize` must be None, True or False"),
        (dict(Q0=[[0.0, -1.0], [0.5, -1.0]]), ValueError, r"member 1 \(`Q0\[1\]`, `V0\[1\]`\)"),
    ],
)
def test_bad_arguments_name_the_argument(pendulum, kwargs, error, match):
    Q0, V0 = _states(pendulum, [(0.3,), (0.4,)])
    args = dict(Q0=Q0, V0=V0, h=H, n_steps=5)
    args.update(kwargs)
    with pytest.raises(error, match=match):
        fastvi.integrate_ensemble(pendulum, args.pop("Q0"), args.pop("V0"), **args)


def test_member_trajectory_needs_a_stride(pendulum):
    Q0, V0 = _states(pendulum, [(0.3,)])
    ens = fastvi.integrate_ensemble(pendulum, Q0, V0, h=H, n_steps=5)
    with pytest.raises(ValueError, match="integer stride"):
        ens.member(0)


def test_concatenated_chunks_equal_one_run(double_pendulum, dp_members):
    Q0, V0 = dp_members
    whole = fastvi.integrate_ensemble(double_pendulum, Q0, V0, h=H, n_steps=30, save=4)
    parts = [fastvi.integrate_ensemble(double_pendulum, Q0[a:a + 4], V0[a:a + 4], h=H, n_steps=30, save=4)
             for a in (0, 4)]
    joined = fastvi.EnsembleResult.concatenate(parts)
    for name in ("q", "p", "energy", "constraint_residual", "status", "steps", "iterations"):
        assert np.array_equal(getattr(joined, name), getattr(whole, name)), name


def test_large_mechanism_members_solve_banded_and_equal_integrate_bit_for_bit():
    """chain(16): the ensemble takes the structured plan of integrate (banded Newton, Schur
    and projection), each member with its own band storage, and member i is integrate of
    member i bit for bit; the dense ensemble agrees to round-off."""
    from fastvi import structure

    N = 16
    model = fastvi.scenes.chain(N)
    assert set(structure.plan(model, fastvi.method("P2L-Q3G")).solvers.values()) == {"banded"}
    states = [model.initial_state(np.linspace(a, 2 * a, N)) for a in (0.2, 0.5, 0.9)]
    Q0, V0 = np.array([s[0] for s in states]), np.array([s[1] for s in states])
    ens = fastvi.integrate_ensemble(model, Q0, V0, h=0.01, n_steps=60, save=20, threads=2)
    dense = fastvi.integrate_ensemble(model, Q0, V0, h=0.01, n_steps=60, save=20, solver="dense")
    for i in range(3):
        r = fastvi.integrate(model, Q0[i], V0[i], h=0.01, n_steps=60, save_every=20)
        assert np.array_equal(ens.q[i], r.q) and np.array_equal(ens.p[i], r.p)
        assert np.array_equal(ens.newton_iterations[i], r.newton_iterations)
    assert np.abs(ens.q - dense.q).max() < 1e-12


# the members take the sized stages of integrate (≈ 8 s to compile on an empty cache) through
# the one generic parallel loop; in `make test-slow` for that compile (the sized stages are
# compared with the generic ones bit for bit in `make test` by tests/test_specialize.py)
@pytest.mark.slow
def test_specialized_members_are_the_generic_ones_bit_for_bit(double_pendulum, dp_members):
    Q0, V0 = dp_members
    kw = dict(h=H, n_steps=103, save=10, threads=2)
    gen = fastvi.integrate_ensemble(double_pendulum, Q0, V0, specialize=False, **kw)
    sized = fastvi.integrate_ensemble(double_pendulum, Q0, V0, specialize=True, **kw)
    for name in ("q", "v", "p", "energy", "constraint_residual", "velocity_residual"):
        assert np.array_equal(getattr(gen, name), getattr(sized, name)), name
    assert np.array_equal(gen.iterations, sized.iterations)
    r = fastvi.integrate(double_pendulum, Q0[3], V0[3], h=H, n_steps=103, save_every=10,
                         specialize=True)
    assert np.array_equal(sized.member(3).q, r.q) and np.array_equal(sized.member(3).p, r.p)


def test_progress_reports_member_steps_and_changes_nothing(pendulum, capsys):
    """``progress=True`` used to raise a TypeError; it runs the members in groups, reports
    member-steps on stderr and returns the same ensemble bit for bit."""
    Q0, V0 = _states(pendulum, [(0.1 * (i + 1),) for i in range(30)])
    plain = fastvi.integrate_ensemble(pendulum, Q0, V0, h=H, n_steps=STEPS, save=10)
    capsys.readouterr()
    shown = fastvi.integrate_ensemble(pendulum, Q0, V0, h=H, n_steps=STEPS, save=10, progress=True)
    err = capsys.readouterr().err
    assert f"{30 * STEPS}/{30 * STEPS} member-steps (100%)" in err and "30/30 members" in err
    for name in ("q", "v", "p", "energy", "t", "status", "steps"):
        assert np.array_equal(getattr(plain, name), getattr(shown, name)), name
    with pytest.raises(TypeError, match="`progress` must be True or False"):
        fastvi.integrate_ensemble(pendulum, Q0, V0, h=H, n_steps=STEPS, progress="yes")
