"""The derivative results are saved and read back bit for bit, and summarised in one line.

``SensitivityResult``, ``AdjointResult`` and ``EnsembleSensitivityResult`` each write one
``.npz`` (no pickle) holding their nested trajectory ``Result``; the model is not written
and ``load(path, model=…)`` gives it back. The runs are tiny (ten steps of the damped
double pendulum); the sensitivity kernels compile once per process.
"""

import dataclasses

import numpy as np
import pytest

import fastvi
from fastvi import AdjointResult, EnsembleSensitivityResult, Result, SensitivityResult

H, STEPS, EVERY = 0.02, 10, 5
WRT, INDEX = ("q0", "v0", "params"), [5, 3]  # by the damping and the outer rod's length


@pytest.fixture(scope="module")
def damped():
    return fastvi.scenes.double_pendulum(damping=0.3)


@pytest.fixture(scope="module")
def start(damped):
    return damped.initial_state(0.9, -0.4, 0.3, 1.1)


@pytest.fixture(scope="module")
def sens(damped, start):
    return fastvi.sensitivity(damped, *start, h=H, n_steps=STEPS, save_every=EVERY, wrt=WRT,
                              param_index=INDEX)


@pytest.fixture(scope="module")
def adj(damped, start):
    rng = np.random.default_rng(3)
    K = STEPS // EVERY + 1
    Lq, Lv = rng.normal(size=(K, 4)), rng.normal(size=(K, 4))
    return fastvi.adjoint(damped, *start, lambda r: (Lq, Lv), h=H, n_steps=STEPS,
                          save_every=EVERY, param_index=INDEX)


def _same_array(a, b, what):
    assert isinstance(b, np.ndarray), what
    assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b), what


def _same_stats(a: dict, b: dict, what):
    """Equal dicts of scalars, NaN equal to NaN (a monitor that measured nothing)."""
    assert set(a) == set(b), what
    for k, x in a.items():
        y = b[k]
        same = type(x) is type(y) and (x == y or (x != x and y != y))
        assert same, f"{what}[{k!r}]: {x!r} != {y!r}"


def _same_result(a: Result, b: Result):
    """Every field of two trajectories equal, arrays bit for bit."""
    for f in dataclasses.fields(Result):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name == "sol":  # no dense output in these runs: nothing to save
            assert not x and not y
        elif f.name == "drawing":  # a scene's drawing is rebuilt from its recipe
            assert (x is None) == (y is None) and (x is None or x.scene == y.scene)
        elif isinstance(x, np.ndarray):
            _same_array(x, y, f"result.{f.name}")
        elif f.name == "stats":
            _same_stats(x, y, "result.stats")
        else:
            assert x == y and type(x) is type(y), f"result.{f.name}: {x!r} != {y!r}"


def _same_sensitivity(a: SensitivityResult, b: SensitivityResult):
    _same_result(a.result, b.result)
    for name in ("t", "dq", "dv", "dp", "params", "_dth"):
        _same_array(getattr(a, name), getattr(b, name), name)
    assert b.labels == a.labels and all(type(x) is str for x in b.labels)
    assert b._pidx == a._pidx and all(type(x) is int for x in b._pidx)
    assert b.t is b.result.t


# ------------------------------------------------------------------ SensitivityResult
def test_sensitivity_round_trips_bit_for_bit(sens, damped, tmp_path):
    assert sens._pidx == [3, 5] and sens._dth.shape == (10, 2)  # the saved private fields
    sens.save(tmp_path / "sens.npz")
    back = SensitivityResult.load(tmp_path / "sens.npz", model=damped)
    _same_sensitivity(sens, back)
    assert back._model is damped
    g0, gv0 = sens.tangent_residual()
    g1, gv1 = back.tangent_residual()
    assert np.array_equal(g0, g1) and np.array_equal(gv0, gv1)
    assert repr(back) == repr(sens) and back.summary() == sens.summary()


def test_tangent_residual_without_the_model_says_to_pass_it(sens, tmp_path):
    sens.save(tmp_path / "sens.npz")
    back = SensitivityResult.load(tmp_path / "sens.npz")
    _same_sensitivity(sens, back)  # all but the model is there
    with pytest.raises(ValueError,
                       match=r"needs the model.*SensitivityResult.load\(path, model=model\)"):
        back.tangent_residual()


def test_load_checks_the_model_against_the_run(sens, tmp_path):
    sens.save(tmp_path / "sens.npz")
    with pytest.raises(ValueError, match=r"`model` .*'double_pendulum' .*'double_pendulum-damped'"):
        SensitivityResult.load(tmp_path / "sens.npz", model=fastvi.scenes.double_pendulum())
    with pytest.raises(TypeError, match=r"`model` .*fastvi.Model.*got str"):
        SensitivityResult.load(tmp_path / "sens.npz", model="double_pendulum-damped")


def test_sensitivity_repr_and_summary_are_one_line(sens):
    text = repr(sens)
    assert "\n" not in text and len(text) < 200, text
    assert text == ("SensitivityResult(model='double_pendulum-damped', method='P2L-Q3G-NL-CN', "
                    "h=0.02, steps=10, samples=3, directions=10, status=SUCCESS)")
    line = sens.summary()
    assert "\n" not in line
    assert "3 samples × 10 directions (4 q0, 4 v0, 2 params)" in line and "status SUCCESS" in line
    assert f"max |∂q(t_end)| = {np.abs(sens.dq[-1]).max():.3e}" in line
    assert sens.success is True and sens.message == sens.result.message


# ------------------------------------------------------------------ AdjointResult
def test_adjoint_round_trips_bit_for_bit(adj, damped, tmp_path):
    adj.save(tmp_path / "adj.npz")
    back = AdjointResult.load(tmp_path / "adj.npz", model=damped)
    _same_result(adj.result, back.result)
    for name in ("grad_q0", "grad_v0", "grad_params", "lam_q", "lam_p"):
        _same_array(getattr(adj, name), getattr(back, name), name)
    assert back.param_index == adj.param_index == INDEX
    assert set(adj.stats) == {"checkpoints", "segment", "backward_time"}
    _same_stats(adj.stats, back.stats, "stats")
    assert repr(back) == repr(adj) and back.summary() == adj.summary()
    with pytest.raises(ValueError, match="`model`"):
        AdjointResult.load(tmp_path / "adj.npz", model=fastvi.scenes.pendulum())


def test_adjoint_summary_gives_the_gradients_norm(adj):
    norm = np.sqrt(sum(np.sum(g ** 2) for g in (adj.grad_q0, adj.grad_v0, adj.grad_params)))
    assert norm > 0
    line = adj.summary()
    assert "\n" not in line and f"|∇J| = {norm:.3e}" in line, line
    assert "3 samples, 2 parameters" in line and "status SUCCESS" in line
    text = repr(adj)
    assert "\n" not in text and len(text) < 200 and f"|grad|={norm:.3g}" in text, text


# ------------------------------------------------------------------ EnsembleSensitivityResult
def _ensemble_of(members, stats):
    """An ensemble result put together from single runs, as sensitivity_ensemble stacks them
    (its own loop compiles for the slow tests only)."""
    runs = [s.result for s in members]
    stack = lambda objs, name: np.stack([getattr(o, name) for o in objs])  # noqa: E731
    return EnsembleSensitivityResult(
        members[0].t, stack(runs, "q"), stack(runs, "v"), stack(runs, "p"), stack(members, "dq"),
        stack(members, "dv"), stack(members, "dp"), members[0].labels,
        np.stack([s.params for s in members]), members, stats)


def _same_ensemble(a, b):
    assert len(b) == len(a) and b.labels == a.labels
    _same_stats(a.stats, b.stats, "stats")
    for name in ("t", "q", "v", "p", "dq", "dv", "dp", "params"):
        _same_array(getattr(a, name), getattr(b, name), name)
    for x, y in zip(a.members, b.members):
        _same_sensitivity(x, y)


def test_ensemble_round_trips_bit_for_bit(sens, damped, tmp_path):
    q0, v0 = damped.initial_state(2.0, 1.0)
    prm = damped.params.copy()
    prm[5] *= 1.5
    other = fastvi.sensitivity(damped, q0, v0, h=H, n_steps=STEPS, save_every=EVERY, wrt=WRT,
                               param_index=INDEX, params=prm)
    ens = _ensemble_of([sens, other], dict(members=2, threads=1, integration_time=0.25,
                                           compile_time=0.0, setup_time=0.5, wall_time=0.75))
    ens.save(tmp_path / "ens.npz")
    back = EnsembleSensitivityResult.load(tmp_path / "ens.npz", model=damped)
    _same_ensemble(ens, back)
    assert np.abs(back.dq[0, -1] - back.dq[1, -1]).max() > 1e-3  # two members, not one twice
    assert np.array_equal(back.members[1].tangent_residual()[1], other.tangent_residual()[1])
    assert repr(back) == repr(ens) and back.summary() == ens.summary()
    assert repr(ens) == ("EnsembleSensitivityResult(model='double_pendulum-damped', members=2, "
                         "method='P2L-Q3G-NL-CN', h=0.02, steps=10, samples=3, directions=10, "
                         "status=SUCCESS)")
    line = ens.summary()
    assert "ensemble of 2 members" in line and "SUCCESS, 1 threads, integration 0.25 s" in line
    assert ens.success.tolist() == [True, True]
    with pytest.raises(ValueError, match="model="):
        EnsembleSensitivityResult.load(tmp_path / "ens.npz").members[0].tangent_residual()


@pytest.mark.slow
def test_a_computed_ensemble_round_trips_bit_for_bit(damped, tmp_path):
    starts = [damped.initial_state(0.9, -0.4, 0.3, 1.1), damped.initial_state(2.0, 1.0)]
    Q0, V0 = np.array([q for q, _ in starts]), np.array([v for _, v in starts])
    ens = fastvi.sensitivity_ensemble(damped, Q0, V0, h=H, n_steps=STEPS, save_every=EVERY,
                                      wrt=WRT, param_index=INDEX, threads=2)
    ens.save(tmp_path / "ens.npz")
    back = EnsembleSensitivityResult.load(tmp_path / "ens.npz", model=damped)
    _same_ensemble(ens, back)
    assert repr(back) == repr(ens) and back.summary() == ens.summary()


# ------------------------------------------------------------------ files of another kind
def test_a_file_of_another_kind_names_the_class_that_wrote_it(sens, adj, tmp_path):
    sens.result.save(tmp_path / "run.npz")
    sens.save(tmp_path / "sens.npz")
    adj.save(tmp_path / "adj.npz")
    with pytest.raises(ValueError, match=r"was written by Result.save, not by SensitivityResult"
                                         r".save: read it with fastvi.Result.load"):
        SensitivityResult.load(tmp_path / "run.npz")
    with pytest.raises(ValueError, match=r"by SensitivityResult.save, not by Result.save"):
        Result.load(tmp_path / "sens.npz")
    with pytest.raises(ValueError, match=r"by AdjointResult.save.*fastvi.AdjointResult.load"):
        EnsembleSensitivityResult.load(tmp_path / "adj.npz")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(ValueError, match="no fastvi result wrote"):
        AdjointResult.load(tmp_path / "other.npz")
    np.save(tmp_path / "bare.npy", np.zeros(3))
    with pytest.raises(ValueError, match=r"one bare array"):
        Result.load(tmp_path / "bare.npy")


def test_a_result_file_without_its_class_name_is_a_result(sens, tmp_path):
    """Files that Result.save wrote before it named the class: the same arrays, no tag."""
    sens.result.save(tmp_path / "run.npz")
    with np.load(tmp_path / "run.npz") as data:
        old = {k: data[k] for k in data.files if k != "fastvi_kind"}
    assert "fastvi_kind" not in old and len(old) > 10
    np.savez_compressed(tmp_path / "old.npz", **old)
    _same_result(sens.result, Result.load(tmp_path / "old.npz"))
    with pytest.raises(ValueError, match=r"written by Result.save.*fastvi.Result.load"):
        SensitivityResult.load(tmp_path / "old.npz")
