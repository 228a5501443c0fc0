"""The Dask path: chunks on worker processes give the local ensemble, bit for bit."""

import subprocess
import sys

import numpy as np
import pytest

import fastvi

distributed = pytest.importorskip("distributed")
import fastvi.distributed as fdist  # noqa: E402

FIELDS = ("t", "q", "v", "p", "energy", "constraint_residual", "velocity_residual",
          "newton_iterations", "iterations", "max_residual", "residual", "status", "failed_step",
          "steps", "n_saved")


@pytest.fixture(scope="module")
def client():
    # two worker processes: the models really travel (pickled recipe) and are recompiled there
    cluster = distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                       dashboard_address=None)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


def _same(a, b):
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None and y is None) or np.array_equal(x, y, equal_nan=True), name


def test_local_cluster_equals_local_ensemble_bit_for_bit(client, double_pendulum):
    rng = np.random.default_rng(11)
    states = [double_pendulum.initial_state(*a) for a in rng.uniform(-2.5, 2.5, (7, 2))]
    Q0, V0 = np.array([s[0] for s in states]), np.array([s[1] for s in states])
    kw = dict(h=0.01, n_steps=60, save=7)
    local = fastvi.integrate_ensemble(double_pendulum, Q0, V0, **kw)
    dist = fdist.integrate_ensemble(double_pendulum, Q0, V0, client=client, chunk_size=3, **kw)
    assert dist.stats["chunks"] == 3 and len(dist) == 7
    assert dist.method is local.method
    _same(dist, local)
    workers = {w["id"] for w in client.scheduler_info()["workers"].values()}
    assert len(workers) == 2


def test_failures_and_params_come_back_from_the_workers(client, pendulum):
    Q0 = np.array([pendulum.initial_state(3.1)[0]] * 4)
    V0 = np.zeros((4, 2))
    P = np.tile(pendulum.params, (4, 1))
    P[1, 2] = 20000.0  # fails at step 3 with max_iter = 6 (see test_ensemble)
    P[3, 1] = 2.0
    Q0[3] *= 2.0
    kw = dict(h=0.01, n_steps=40, params=P, max_iter=6, save="diagnostics")
    local = fastvi.integrate_ensemble(pendulum, Q0, V0, **kw)
    dist = fdist.integrate_ensemble(pendulum, Q0, V0, client=client, chunk_size=1, **kw)
    assert list(dist.failed) == [1] and dist.failed_step[1] > 0
    _same(dist, local)
    for name in ("max_energy_error", "max_constraint_residual", "max_velocity_residual"):
        assert np.array_equal(getattr(dist, name), getattr(local, name)), name


def test_inconsistent_member_is_named_by_its_global_index(client, pendulum):
    Q0 = np.array([pendulum.initial_state(0.3)[0]] * 5)
    Q0[4] = [0.5, -1.0]  # off the circle
    with pytest.raises(ValueError, match=r"member 4 \(`Q0\[4\]`"):
        fdist.integrate_ensemble(pendulum, Q0, np.zeros((5, 2)), client=client, h=0.01, n_steps=5,
                                 chunk_size=2)


def test_bad_arguments_fail_on_the_client_before_any_task(pendulum):
    Q0 = np.array([pendulum.initial_state(0.3)[0]])
    with pytest.raises(ValueError, match="`h` must be positive"):
        fdist.integrate_ensemble(pendulum, Q0, np.zeros((1, 2)), client=None, h=0.0, n_steps=5)
    with pytest.raises(ValueError, match="`save` must be"):
        fdist.integrate_ensemble(pendulum, Q0, np.zeros((1, 2)), client=None, h=0.1, n_steps=5,
                                 save="all")


def test_importing_fastvi_does_not_import_dask():
    code = "import sys, fastvi; print(any(m.split('.')[0] in ('dask', 'distributed') for m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_events_travel_to_the_workers(client, double_pendulum):
    rng = np.random.default_rng(4)
    states = [double_pendulum.initial_state(*a) for a in rng.uniform(-3.0, 3.0, (6, 2))]
    Q0, V0 = np.array([s[0] for s in states]), np.array([s[1] for s in states])
    kw = dict(h=0.01, n_steps=300, events=double_pendulum.flips, keep_events=2)
    local = fastvi.integrate_ensemble(double_pendulum, Q0, V0, **kw)
    dist = fdist.integrate_ensemble(double_pendulum, Q0, V0, client=client, chunk_size=2, **kw)
    assert local.terminated.size > 0
    _same(dist, local)
    for name in ("t_events", "q_events", "v_events", "n_events"):
        assert np.array_equal(getattr(dist, name), getattr(local, name), equal_nan=True), name
