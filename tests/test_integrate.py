"""The public driver: what it returns, what it refuses, and how it fails."""

import pickle
import warnings
from pathlib import Path

import numpy as np
import pytest

import fastvi
from fastvi import IntegrationError, Status
from fastvi._launch import _key
from fastvi.kernels import drive, step

from . import models


def test_double_pendulum_acceptance_run(double_pendulum, dp_start):
    """Issue 2 acceptance: 10^4 steps at h = 0.01 with P2L-Q3G."""
    q0, v0 = dp_start
    r = fastvi.integrate(double_pendulum, q0, v0, h=0.01, n_steps=10_000, method="P2L-Q3G")
    assert r.success and r.stats["steps"] == 10_000 and r.t[-1] == pytest.approx(100.0)
    assert r.q.shape == (10_001, 4) and r.energy.shape == (10_001,)
    assert np.max(r.constraint_residual) <= 1e-10  # measured 4e-16
    assert np.max(r.velocity_residual) <= 1e-10  # measured 2e-15
    assert np.max(np.abs(r.energy_error)) <= 1e-3  # measured 6e-5
    # measured 4.0 with the default mechanics matrix (linear convergence, cheaper iterations;
    # docs/decisions/0001-mechanics-newton.md), 2.7 with newton="full"
    assert 1.0 <= r.stats["newton_iterations"] / 10_000 <= 4.5


def test_constraints_hold_at_round_off_at_every_step(double_pendulum):
    q0, v0 = double_pendulum.initial_state(2.0, -1.0, 3.0, -4.0)
    for name in ["P1L-Q2G", "P3L-Q4G", "P2L-Q3G-NE-CE", "P4L-Q5G"]:
        r = fastvi.integrate(double_pendulum, q0, v0, h=0.02, n_steps=2000, method=name)
        g = np.array([double_pendulum.constraint_value(q) for q in r.q])
        Gv = np.array([double_pendulum.constraint_jacobian_value(q) @ v for q, v in zip(r.q, r.v)])
        assert np.abs(g).max() <= 1e-14  # measured 4e-16
        assert np.abs(Gv).max() <= 1e-12  # measured 5e-15
        np.testing.assert_allclose(r.constraint_residual[1:], np.abs(g[1:]).max(axis=1), atol=1e-16)


def test_save_every_keeps_every_kth_step_and_the_last(double_pendulum, dp_start):
    full = fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=103)
    sub = fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=103, save_every=10)
    np.testing.assert_array_equal(sub.t, np.r_[full.t[::10], full.t[-1]])
    np.testing.assert_array_equal(sub.q, np.vstack([full.q[::10], full.q[-1:]]))
    assert sub.newton_iterations[1:].sum() == full.newton_iterations[1:].sum()
    assert sub.constraint_residual[1] == full.constraint_residual[1:11].max()


def test_progress_chunks_change_no_bit(double_pendulum, dp_start, capsys):
    a = fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=500)
    b = fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=500, progress=True)
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.p, b.p)
    assert "500/500 steps (100%)" in capsys.readouterr().err


def test_t_end_and_params_override(pendulum):
    q0, v0 = pendulum.initial_state(0.1)
    r = fastvi.integrate(pendulum, q0, v0, h=0.01, t_end=1.0)
    assert r.stats["steps"] == 100
    # a longer pendulum (params = m, l, g) swings more slowly: params reach the callbacks
    q0l = 2.0 * q0
    slow = fastvi.integrate(pendulum, q0l, 2.0 * v0, h=0.01, t_end=1.0, params=[1.0, 2.0, 9.81])
    assert pendulum.angle(slow.q[-1]) > pendulum.angle(r.q[-1])


def test_result_can_be_saved_and_plotted(double_pendulum, dp_start, tmp_path):
    r = fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=50)
    r.save(tmp_path / "run.npz")
    back = np.load(tmp_path / "run.npz")
    np.testing.assert_array_equal(back["q"], r.q)
    assert str(back["method"]) == "P2L-Q3G-NL-CN"
    r.plot(tmp_path / "run.png")
    assert (tmp_path / "run.png").stat().st_size > 1000
    assert "max |g|" in r.summary()


def test_unconstrained_and_q_dependent_mass_models_run():
    r = fastvi.integrate(models.quartic(), [0.8, -0.3], [0.2, 0.5], h=0.05, n_steps=400, method="P3L-Q4G")
    assert r.success and np.abs(r.energy_error).max() < 1e-9  # measured 1e-12
    s = fastvi.integrate(models.polar_pendulum(spring=50.0), [1.1, 0.7], [0.4, 1.3], h=0.01, n_steps=400)
    assert s.success and np.abs(s.energy_error).max() < 1e-6  # measured 2e-8


def test_kernels_compile_once_for_every_model(double_pendulum, dp_start):
    """Every model's cfuncs share one type, so no model triggers a recompile: one generic
    step and one time loop for conservative models and models with forces or time alike."""
    fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=5)
    fastvi.integrate(models.polar_pendulum(), [1.0, 0.5], [0.0, 0.0], h=0.01, n_steps=5)
    fastvi.integrate(models.quartic(), [1.0, 0.5], [0.0, 0.0], h=0.01, n_steps=5, method="P3L-Q3L")
    damped = fastvi.scenes.double_pendulum(damping=0.1)
    fastvi.integrate(damped, *dp_start, h=0.01, n_steps=5)
    kapitza = fastvi.scenes.kapitza_pendulum()
    fastvi.integrate(kapitza, *kapitza.initial_state(3.0), h=1e-3, n_steps=5)
    def generic(sigs):  # the size-specialized kernels compile once per size, by design
        return [sig for sig in sigs if "UniTuple(int64 x 5)" in str(sig[5])]

    # one workspace type in the time loops (a structured plan's loop view is a dense one's:
    # layout.loop_view); one time loop, and a second one with the event code once a run had
    # events; one more per per-step hook of the linearised flow when those ran in this process
    kinds = [(str(sig[5]), str(sig[15]), str(sig[16])) for sig in generic(drive.run.signatures)]
    assert len(kinds) == len(set(kinds)), drive.run.signatures
    assert len({ws for ws, _, _ in kinds}) == 1, drive.run.signatures
    assert sum(hook == "none" for _, _, hook in kinds) <= 2, drive.run.signatures
    # one compiled step for every model (run-time sizes, dense or structured plan)
    generic_steps = [k for k in step._STEPS  # (model, options, sizes) -> entry point
                     if k[2] == _key((0, 0, 0, 0, 0))]
    assert len(generic_steps) == 1, list(step._STEPS)


def test_every_scene_callback_has_the_one_signature():
    # scenes whose size has no default; Brüls' heavy top is a lamina (singular M) by default
    required = {"chain": dict(N=3), "heavy_top": dict(inertia=(0.234375, 0.4, 0.234375))}
    for name, make in fastvi.scenes.SCENES.items():
        cfs, flags, _ = make(**required.get(name, {})).kernel_arguments()
        for cf in cfs:
            assert cf._sig == fastvi.CALLBACK_SIGNATURE, name


def test_scene_models_pickle_as_recipes(double_pendulum, dp_start):
    clone = pickle.loads(pickle.dumps(fastvi.scenes.double_pendulum(l2=0.5)))
    assert clone.params[3] == 0.5
    user = pickle.loads(pickle.dumps(models.polar_pendulum()))
    a = fastvi.integrate(user, [1.0, 0.5], [0.0, 0.0], h=0.01, n_steps=20)
    b = fastvi.integrate(models.polar_pendulum(), [1.0, 0.5], [0.0, 0.0], h=0.01, n_steps=20)
    np.testing.assert_array_equal(a.q, b.q)


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "kwargs,exc,match",
    [
        (dict(q0=[0.0, -1.0, 0.0]), ValueError, r"`q0` must have shape \(4,\)"),
        (dict(q0=["a", "b", "c", "d"]), TypeError, "`q0` must be an array of real numbers"),
        (dict(v0=[0.0, np.nan, 0.0, 0.0]), ValueError, "`v0` must be finite"),
        (dict(h=-0.1), ValueError, "`h` must be positive and finite, got -0.1"),
        (dict(h=np.inf), ValueError, "`h` must be positive and finite"),
        (dict(n_steps=None), ValueError, "exactly one of `t_end` and `n_steps`"),
        (dict(t_end=1.0), ValueError, "exactly one of `t_end` and `n_steps`"),
        (dict(n_steps=2.5), TypeError, "`n_steps` must be an integer"),
        (dict(n_steps=-3), ValueError, "`n_steps` must be >= 1"),
        # (t_end = 0.105 with h = 0.01 is accepted now: a shorter last step, test_scipy_habits.py)
        (dict(n_steps=None, t_end=-1.0), ValueError, "`t_end` must be finite and positive"),
        (dict(method="P2L-Q3X"), ValueError, "Did you mean:.*P2L-Q3G"),
        (dict(save_every=0), ValueError, "`save_every` must be >= 1"),
        (dict(tol=0.5), ValueError, "`tol` must be in"),
        (dict(params=[1.0, 2.0]), ValueError, r"`params` must have shape \(5,\)"),
        (dict(on_failure="ignore"), ValueError, "`on_failure`"),
        (dict(q0=[1.0, 0.0, 2.0, 0.5]), ValueError, "`q0` violates the constraints"),
    ],
)
def test_rejects_bad_arguments_naming_them(double_pendulum, dp_start, kwargs, exc, match):
    args = dict(q0=dp_start[0], v0=dp_start[1], h=0.01, n_steps=10)
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        fastvi.integrate(double_pendulum, args.pop("q0"), args.pop("v0"), **args)


def test_rejects_a_model_that_is_not_a_model(dp_start):
    with pytest.raises(TypeError, match="`model` must be a fastvi.Model"):
        fastvi.integrate("double pendulum", *dp_start, h=0.01, n_steps=1)


def test_slightly_inconsistent_data_are_projected_with_a_warning(double_pendulum, dp_start):
    q0, v0 = dp_start
    with pytest.warns(UserWarning, match=r"`q0` was projected .*max\|g\| was 1\.0"):
        r = fastvi.integrate(double_pendulum, q0 + 1e-8, v0, h=0.01, n_steps=2)
    assert np.abs(double_pendulum.constraint_value(r.q[0])).max() < 1e-15
    with pytest.warns(UserWarning, match="`v0` was projected"):
        fastvi.integrate(double_pendulum, q0, v0 + 1e-8, h=0.01, n_steps=2)
    with warnings.catch_warnings():  # round-off is projected silently
        warnings.simplefilter("error")
        fastvi.integrate(double_pendulum, q0 + 1e-16, v0, h=0.01, n_steps=2)


def test_rank_deficient_constraint_jacobian_at_q0_is_rejected(pendulum):
    # with l = 0 the origin satisfies g = 0 but G(0) = 0
    with pytest.raises(ValueError, match="full row rank"):
        fastvi.integrate(pendulum, [0.0, 0.0], [0.0, 0.0], h=0.01, n_steps=1, params=[1.0, 0.0, 9.81])


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(mass=np.eye(3)), r"`mass` must be an \(2, 2\) array"),
        (dict(mass=np.array([[1.0, 2.0], [0.0, 1.0]])), "`mass` must be symmetric"),
        (dict(mass=-np.eye(2)), "`mass` must be positive definite"),
        (dict(m=1), "`constraint` is required"),
        (dict(n=0), "`n` must be >= 1"),
        (dict(mass=models.mass), "`kinetic_grad`"),
    ],
)
def test_model_constructor_rejects_inconsistent_definitions(kwargs, match):
    args = dict(n=2, m=0, mass=np.eye(2), potential=models.quartic_V, potential_grad=models.quartic_dV,
                params=(1.0,))
    args.update(kwargs)
    with pytest.raises((ValueError, TypeError), match=match):
        fastvi.Model(args.pop("n"), args.pop("m"), **args)


def test_newton_failure_raises_with_the_partial_result(double_pendulum):
    q0, v0 = double_pendulum.initial_state(2.0, 2.0, 15.0, -15.0)
    with pytest.raises(IntegrationError) as info:
        fastvi.integrate(double_pendulum, q0, v0, h=0.5, n_steps=100, max_iter=3)
    err = info.value
    assert isinstance(err, RuntimeError)
    assert err.status in (Status.NEWTON_NOT_CONVERGED, Status.SINGULAR_JACOBIAN, Status.NONFINITE)
    assert f"at step {err.step}" in str(err) and err.time == pytest.approx(0.5 * err.step)
    assert err.result.stats["steps"] == err.step and len(err.result.t) == err.step + 1
    assert np.all(np.isfinite(err.result.q))
    partial = fastvi.integrate(double_pendulum, q0, v0, h=0.5, n_steps=100, max_iter=3, on_failure="return")
    assert not partial.success and partial.failed_step == err.step


def test_a_fresh_process_loads_the_kernels_from_the_cache(double_pendulum, dp_start):
    """The second process must not recompile (make demo twice)."""
    import subprocess
    import sys

    fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=2)  # this process fills the cache
    code = ("import fastvi, numpy as np; from fastvi.kernels import drive; m = fastvi.scenes.double_pendulum();"
            "q, v = m.initial_state(1.0, 0.5); fastvi.integrate(m, q, v, h=0.01, n_steps=2);"
            "print(sum(drive.run.stats.cache_hits.values()), sum(drive.run.stats.cache_misses.values()))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["1", "0"]


def test_kernel_cache_is_stamped_with_every_compiled_source():
    """numba only watches the defining file; `run` inlines `step` from another file."""
    from fastvi import _numba

    stamp = _numba._package_stamp()
    assert len(stamp) == 64
    loc = _numba._InTree.from_function(drive.run.py_func, drive.__file__)
    assert loc is not None and loc.get_source_stamp() == stamp
    assert _numba._InTree.from_function(test_kernel_cache_is_stamped_with_every_compiled_source, __file__) is None
    # a module outside the package that compiles fastvi's kernels into its own opts in
    # (tests/yardstick.py): the package's stamp and its own file's, so that either edit counts
    scope = {_numba.STAMP_OPT_IN: True}
    exec("def kernel(x):\n    return x", scope)
    loc = _numba._InTree.from_function(scope["kernel"], __file__)
    assert loc is not None
    plain = _numba._numba_class("InTreeCacheLocator").from_function(scope["kernel"], __file__)
    assert loc.get_source_stamp() == (stamp, plain.get_source_stamp())


def test_the_step_profile_carries_the_kernels_stamp_and_its_own(monkeypatch):
    """The step profile's compiled loops (``bench/step_profile.py``, outside the package) inline
    the kernels: they opt in, so their stamp is the kernels' and their own file's; an edit of
    the package's own studies helpers (no compiled code) leaves the kernels' stamp alone."""
    from bench import step_profile
    from fastvi import _numba

    kernels = _numba._package_stamp()
    loc = _numba._InTree.from_function(step_profile.loop_residual.py_func, step_profile.__file__)
    assert loc is not None and loc.get_source_stamp()[0] == kernels
    real = Path.read_bytes
    def edited(path):
        text = real(path)
        return text + b"\n# edited\n" if path.name == "reference.py" else text
    monkeypatch.setattr(_numba, "_STAMP", [])
    monkeypatch.setattr(Path, "read_bytes", edited)
    assert _numba._package_stamp() == kernels
    # and an edited kernel moves the kernels' stamp
    def kernel_edited(path):
        text = real(path)
        return text + b"\n# edited\n" if path.name == "step.py" else text
    monkeypatch.setattr(_numba, "_STAMP", [])
    monkeypatch.setattr(Path, "read_bytes", kernel_edited)
    assert _numba._package_stamp() != kernels
