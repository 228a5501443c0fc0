"""Results (repr, load, plots, timing), the progress bar, callback compile cache and messages."""

import io
import os
import pickle
import subprocess
import sys
import textwrap
import time
import warnings

import matplotlib
import numba
import numpy as np
import pytest

import fastvi
from fastvi.baselines import BaselineResult, solve_ivp
from fastvi.ensemble import EnsembleResult
from fastvi.results import ProgressBar, Result, ResultBase, TrajectoryResult

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def run(double_pendulum, dp_start):
    return fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=300)


@pytest.fixture(scope="module")
def ensemble(double_pendulum):
    states = [double_pendulum.initial_state(a, b) for a, b in [(0.5, 1.0), (2.0, -1.0), (3.0, 0.0)]]
    Q0, V0 = np.array([s[0] for s in states]), np.array([s[1] for s in states])
    return fastvi.integrate_ensemble(double_pendulum, Q0, V0, h=0.01, n_steps=200, save=50)


# ------------------------------------------------------------------ one base
def test_results_share_one_base(run, ensemble, pendulum):
    # the SciPy baseline: the RK4 one compiles its kernel for longer than this file takes
    base = solve_ivp(pendulum, *pendulum.initial_state(0.5), t_end=0.1)
    assert isinstance(run, TrajectoryResult) and isinstance(base, TrajectoryResult)
    assert isinstance(ensemble, ResultBase) and isinstance(base, BaselineResult)
    assert fastvi.Result is Result
    from fastvi.integrate import Result as Reexported

    assert Reexported is Result
    assert run.success is True and run.message.startswith("The integration reached")
    assert ensemble.success.shape == (3,) and base.success
    assert "SciPy" in base.summary() and "max |ΔH|" in base.summary()


# ------------------------------------------------------------------ repr, summary, timing
def test_repr_is_one_short_line(run, ensemble):
    text = repr(run)
    assert "\n" not in text and len(text) < 200, text
    assert text.startswith("Result(model='double_pendulum', method='P2L-Q3G-NL-CN', h=0.01, steps=300, "
                           "t=[0, 3], status=SUCCESS, max|ΔH|=")
    etext = repr(ensemble)
    assert "\n" not in etext and len(etext) < 200 and "members=3" in etext and "SUCCESS" in etext


def test_stats_separate_setup_from_integration(run):
    st = run.stats
    for key in ("integration_time", "setup_time", "compile_time", "check_time", "wall_time"):
        assert st[key] >= 0.0, key
    assert st["wall_time"] == pytest.approx(st["integration_time"] + st["setup_time"], rel=1e-9)
    assert st["compile_time"] <= st["setup_time"]
    text = run.summary()
    assert "integration " in text and "setup " in text and "wall time" not in text


def test_ensemble_rate_uses_integration_time(ensemble):
    st = ensemble.stats
    assert st["wall_time"] == pytest.approx(st["integration_time"] + st["setup_time"], rel=1e-9)
    rate = st["member_steps"] / st["integration_time"]
    assert f"{rate:.3g} member-steps/s" in ensemble.summary()


def test_member_summary_does_not_print_nan(ensemble):
    text = ensemble.member(1).summary()
    assert "nan" not in text and "time not measured" in text


# ------------------------------------------------------------------ save / load
def test_load_round_trips_everything(run, tmp_path):
    path = tmp_path / "run.npz"
    run.save(path)
    back = Result.load(path)
    for key in ("t", "q", "v", "p", "energy", "constraint_residual", "velocity_residual",
                "newton_iterations"):
        np.testing.assert_array_equal(getattr(back, key), getattr(run, key))
    assert back.method is run.method and back.h == run.h and back.status == run.status
    assert back.model_name == run.model_name and back.failed_step is None
    assert back.stats == run.stats
    assert repr(back) == repr(run)


def test_load_keeps_recovered_steps_and_failure(double_pendulum, dp_start, tmp_path):
    r = fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=20, max_iter=1, on_failure="return")
    assert not r.success
    r.stats["recovered_steps"] = [(3, 2), (7, 4)]
    r.save(tmp_path / "f.npz")
    back = Result.load(tmp_path / "f.npz")
    assert back.status == r.status and back.failed_step == r.failed_step
    assert back.stats["recovered_steps"] == [(3, 2), (7, 4)]


# ------------------------------------------------------------------ plots
def test_plot_to_path_keeps_the_backend(run, tmp_path):
    before = matplotlib.get_backend()
    fig = run.plot(tmp_path / "run.png")
    assert matplotlib.get_backend() == before
    assert (tmp_path / "run.png").stat().st_size > 1000
    assert len(fig.axes) == 3  # motion, energy error, residuals
    assert fig.axes[0].get_ylabel() == "q(t)"


def test_residual_axis_shows_exact_zeros_at_the_floor(run, tmp_path):
    r = Result(**{**run.__dict__})
    r.constraint_residual = run.constraint_residual.copy()
    r.constraint_residual[1::2] = 0.0  # exactly met at every other sample
    fig = r.plot(tmp_path / "zeros.png")
    ax = fig.axes[2]
    lo, hi = ax.get_ylim()
    nonzero = np.concatenate([r.constraint_residual[1:], r.velocity_residual[1:]])
    nonzero = nonzero[nonzero > 0]
    assert lo > 1e-30 and lo < nonzero.min() and hi > nonzero.max()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "max|g| exact 0" in labels


def test_ensemble_plot_returns_a_figure(ensemble, tmp_path):
    before = matplotlib.get_backend()
    fig = ensemble.plot(tmp_path / "ens.png", coordinates=(2, 3))
    assert matplotlib.get_backend() == before
    assert isinstance(fig, matplotlib.figure.Figure) and len(fig.axes) == 2
    assert fig.axes[0].get_xlabel() == "q[2]" and fig.axes[1].get_xlabel() == "log10 |ΔH| per member"
    assert (tmp_path / "ens.png").stat().st_size > 1000
    q, _ = ensemble.final_state()
    np.testing.assert_array_equal(q, ensemble.q[:, -1])


def test_ensemble_final_mode_knows_its_energy_error(double_pendulum, dp_start):
    ens = fastvi.integrate_ensemble(double_pendulum, [dp_start[0]] * 2, [dp_start[1]] * 2, h=0.01,
                                    n_steps=100)
    r = fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=100)
    np.testing.assert_array_equal(ens.member_energy_error(), [abs(r.energy_error[-1])] * 2)


# ------------------------------------------------------------------ progress
class _Stream(io.StringIO):
    def __init__(self, tty):
        super().__init__()
        self._tty = tty

    def isatty(self):
        return self._tty


def test_progress_bar_updates_one_line_on_a_tty():
    s = _Stream(True)
    bar = ProgressBar(100, stream=s, interval=0.0)
    bar.interval = 0.0
    for k in range(10, 101, 10):
        bar.update(k)
    bar.close(100)
    out = s.getvalue()
    assert out.count("\r") >= 10 and out.count("\n") == 1 and out.endswith("\n")
    assert "100/100 steps (100%)" in out.splitlines()[-1].split("\r")[-1]


def test_progress_bar_writes_plain_lines_otherwise():
    s = _Stream(False)
    bar = ProgressBar(100, stream=s, interval=3600.0)
    for k in range(10, 101, 10):
        bar.update(k)  # throttled: only the first line within the interval
    bar.close(100)
    lines = s.getvalue().splitlines()
    assert "\r" not in s.getvalue() and len(lines) == 2
    assert lines[0].startswith("fastvi: 10/100 steps") and lines[-1].startswith("fastvi: 100/100 steps")


def test_integrate_progress_is_one_bar(double_pendulum, dp_start, capsys):
    r = fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=500, progress=True)
    err = capsys.readouterr().err
    # stderr is captured (not a terminal): a few plain lines, not one per chunk
    assert 1 <= len(err.splitlines()) <= 3 and "500/500 steps (100%)" in err
    plain = fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=500)
    np.testing.assert_array_equal(r.q, plain.q)


# ------------------------------------------------------------------ callback compile cache
def _free_model(V, dV):
    return fastvi.Model(1, params=[2.0], mass=np.eye(1), potential=V, potential_grad=dV)


def test_equal_model_reuses_the_compiled_callbacks():
    def V(q, p):
        return 0.5 * p[0] * q[0] * q[0]

    def dV(q, p, out):
        out[0] = p[0] * q[0]

    t0 = time.perf_counter()
    a = _free_model(V, dV).kernel_arguments()[0]
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    b = _free_model(V, dV).kernel_arguments()[0]
    second = time.perf_counter() - t0
    assert all(x is y for x, y in zip(a, b))
    assert second < 0.2 * first, (first, second)


def test_same_name_other_code_is_compiled_anew():
    def V(q, p):
        return 0.5 * p[0] * q[0] * q[0]

    def dV(q, p, out):
        out[0] = p[0] * q[0]

    one = _free_model(V, dV)

    def V(q, p):  # noqa: F811 - the point: same name, different code
        return 3.0 * p[0] * q[0] * q[0]

    other = _free_model(V, dV)
    q = np.array([1.0])
    assert one.potential_energy(q) == 1.0 and other.potential_energy(q) == 6.0


def _run(code, cwd, env_extra=None):
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{cwd}", **(env_extra or {})}
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=cwd, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout


_USER_MODULE = '''
# {nonce}: a file never seen before, so that the first process really compiles
def V(q, p):
    return {c} * p[0] * q[0] * q[0]

def dV(q, p, out):
    out[0] = 2.0 * {c} * p[0] * q[0]
'''

_PROBE = '''
import time, numpy as np, fastvi, usermod
t0 = time.perf_counter()
m = fastvi.Model(1, params=[1.0], mass=np.eye(1), potential=usermod.V, potential_grad=usermod.dV)
m.kernel_arguments()
print(time.perf_counter() - t0, m.potential_energy(np.array([1.0])))
'''


def test_importable_callbacks_are_cached_on_disk_and_invalidated_by_edits(tmp_path):
    nonce = f"{os.getpid()} {time.time_ns()}"
    (tmp_path / "usermod.py").write_text(_USER_MODULE.format(c="0.5", nonce=nonce))
    # a private cache directory: nothing accumulates in the checkout's __pycache__
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    cold, v1 = map(float, _run(_PROBE, tmp_path, env).split())
    warm, v2 = map(float, _run(_PROBE, tmp_path, env).split())
    assert v1 == v2 == 0.5
    assert warm < 0.3 * cold, (cold, warm)
    # an edit of the user's file must never load the stale compiled code
    (tmp_path / "usermod.py").write_text(_USER_MODULE.format(c="4.0", nonce=nonce))
    _, v3 = map(float, _run(_PROBE, tmp_path, env).split())
    assert list((tmp_path / "cache").rglob("*.nbi"))  # the cache was really used
    assert v3 == 4.0


# ------------------------------------------------------------------ messages
def _plain_helper(x):
    return 2.0 * x


def test_plain_python_helper_names_the_callback():
    def V(q, p):
        return _plain_helper(q[0])

    def dV(q, p, out):
        out[0] = 2.0

    with pytest.raises(TypeError) as info:
        _free_model(V, dV).kernel_arguments()
    msg = str(info.value)
    assert "callback `potential`" in msg and "V`" in msg and "numba.njit" in msg
    assert "fastvi/model.py" not in msg  # the user's code, not fastvi's wrapper
    assert "_plain_helper" in msg  # numba's own first lines are kept


def test_fstring_format_spec_names_the_callback():
    def V(q, p):
        return 0.0

    def dV(q, p, out):
        s = f"{q[0]:.3f}"  # noqa: F841 - numba cannot compile a format spec
        out[0] = 0.0

    with pytest.raises(TypeError, match=r"callback `potential_grad` \(function `[\w.<>]*dV`\)"):
        _free_model(V, dV).kernel_arguments()


def test_njit_helper_compiles():
    @numba.njit
    def helper(x):
        return 2.0 * x

    def V(q, p):
        return helper(q[0])

    def dV(q, p, out):
        out[0] = 2.0

    assert _free_model(V, dV).potential_energy(np.array([3.0])) == 6.0


def test_pickling_a_model_with_main_functions_warns():
    def V(q, p):
        return 0.0

    def dV(q, p, out):
        out[0] = 0.0

    V.__module__ = dV.__module__ = "__main__"  # as if defined in the script being run
    V.__qualname__, dV.__qualname__ = "V", "dV"
    model = _free_model(V, dV)
    with pytest.warns(RuntimeWarning, match=r"`__main__`.*`potential` \(V\).*Dask"):
        try:
            pickle.dumps(model)
        except pickle.PicklingError:
            pass  # this test's V is not really in __main__; the warning comes first


def test_a_script_pickling_its_model_is_warned(tmp_path):
    script = tmp_path / "script.py"
    script.write_text(textwrap.dedent('''
        import pickle, warnings
        import numpy as np, fastvi

        def V(q, p):
            return 0.0

        def dV(q, p, out):
            out[0] = 0.0

        model = fastvi.Model(1, mass=np.eye(1), potential=V, potential_grad=dV, name="script model")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            pickle.dumps(model)
        print([str(w.message) for w in caught])
    '''))
    env = {**os.environ, "PYTHONPATH": ROOT}
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "'script model' is pickled with functions defined in `__main__`" in out.stdout
    assert "`potential` (V), `potential_grad` (dV)" in out.stdout


def test_pickling_a_model_of_module_functions_is_silent(pendulum):
    from tests import models

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pickle.dumps(models.polar_pendulum())
        pickle.dumps(pendulum)


def test_plot_shows_every_coordinate_or_the_groups_given(tmp_path):
    """The issue's slider–crank in 8 coordinates: the default used to stop at q[5] and hid the
    slider; now every coordinate is drawn, or the groups the caller names."""
    from . import models

    r = fastvi.integrate(models.bar_slider_crank(), *models.bar_slider_crank_state(), h=0.01,
                         n_steps=20)
    fig = r.plot(tmp_path / "all.png")
    assert len(fig.axes[0].get_lines()) == 8
    np.testing.assert_array_equal(fig.axes[0].get_lines()[6].get_ydata(), r.q[:, 6])  # slider x
    names = ["x1", "y1", "θ1", "x2", "y2", "θ2", "x3", "y3"]
    fig = r.plot(tmp_path / "groups.png", labels=names,
                 coordinates={"crank": [0, 1, 2], "rod": [3, 4, 5], "slider": [6, 7]})
    assert [ax.get_ylabel() for ax in fig.axes[:3]] == ["crank", "rod", "slider"]
    assert [t.get_text() for t in fig.axes[2].get_legend().get_texts()] == ["x3", "y3"]
    with pytest.raises(ValueError, match=r"outside 0…7"):
        r.plot(tmp_path / "bad.png", coordinates=[8])
    with pytest.raises(ValueError, match="`labels` must name each of the n = 8"):
        r.plot(tmp_path / "bad.png", labels=["x"])


def test_a_driven_run_reports_its_energy_balance_and_names_the_velocity_residual():
    model = fastvi.scenes.slider_crank(drive=5.0)
    r = fastvi.integrate(model, *model.initial_state(0.0), h=0.01, t_end=2.0)
    text, rep = r.summary(), repr(r)
    # H changes by what the motor does (about 1 J here): the balance is what is small
    assert abs(r.energy_error[-1]) > 0.1 and np.max(np.abs(r.energy_balance)) < 1e-6
    assert "max |ΔH − W|" in text and "max |Gv + g_t|" in text and "max |Gv| " not in text
    assert "max|ΔH−W|=" in rep and "max|ΔH|=" not in rep
