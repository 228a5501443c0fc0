"""Ensembles beyond one machine: members split into chunks, each run on a Dask worker.

Needs the optional extra ``dask`` (``pip install "fastvi[dask]"``); Dask is imported only
when :func:`integrate_ensemble` is called. Each chunk runs with the ``prange`` driver of
:func:`fastvi.integrate_ensemble` on a worker, so the gathered :class:`EnsembleResult`
equals the local one bit for bit. The model travels to the workers as a recipe (a scene's
name and arguments, or a user model's importable module-level functions; see
``Model.__reduce__``) and is recompiled there once per worker; the integration kernels come
from numba's on-disk cache. How to point it at a real cluster: ``docs/ensembles.md``.
"""

from __future__ import annotations

import math
import pickle
import threading
import time

from . import ensemble as _ens
from .ensemble import EnsembleResult
from .model import Model
from .tables import Method

__all__ = ["integrate_ensemble"]

#: default chunks per Dask worker thread: enough to balance uneven members and workers
#: without paying the per-task overhead (tens of milliseconds) too often.
CHUNKS_PER_WORKER_THREAD = 4
#: compiled models a worker process keeps (by pickled recipe) for later calls
_MODELS_KEPT = 8
_MODELS: dict = {}
_MODELS_LOCK = threading.Lock()


def integrate_ensemble(
    model: Model,
    Q0,
    V0,
    *,
    client,
    h: float,
    t_end: float | None = None,
    n_steps: int | None = None,
    t0: float = 0.0,
    method: str | Method = "P2L-Q3G",
    params=None,
    save="final",
    threads: int | None = None,
    tol: float = _ens.check.DEFAULT_TOL,
    max_iter: int = _ens.check.DEFAULT_MAX_ITER,
    newton: str = "auto",
    check: bool = True,
    chunk_size: int | None = None,
    events=None,
    keep_events: int = 1,
    solver: str = "auto",
    specialize: bool | None = None,
) -> EnsembleResult:
    """:func:`fastvi.integrate_ensemble` with the members spread over a Dask cluster.

    Parameters
    ----------
    model, Q0, V0, h, t_end, n_steps, t0, method, params, save, tol, max_iter, newton, check, solver,
    specialize :
        As in :func:`fastvi.integrate_ensemble`.
    events, keep_events :
        As in :func:`fastvi.integrate_ensemble`. The event functions travel with each task
        (Dask pickles them: module-level functions by reference, so a worker must be able to
        import their module) and are compiled once per worker process.
    client : distributed.Client
        A connected Dask client (``Client("tcp://scheduler:8786")``, a ``LocalCluster``,
        a dask-jobqueue cluster, ...). Every worker must be able to import fastvi (and the
        module defining a user model's functions).
    threads : int, optional
        Numba threads per chunk on a worker. Default: the Dask threads of that worker
        (start workers with ``--nthreads`` equal to their cores and one process each, so
        numba, not Dask, uses the cores).
    chunk_size : int, optional
        Members per task. Default: ``N / (4 · total worker threads)``, rounded up.

    Returns
    -------
    EnsembleResult
        Members in the order of ``Q0``; ``stats["wall_time"]`` is the elapsed time on the
        client, ``stats["chunks"]`` the number of tasks, ``stats["worker_time"]`` the sum of
        the chunks' compiled-loop times.

    Raises
    ------
    ImportError
        Without ``dask.distributed``.
    ValueError, TypeError
        Bad arguments (checked on the client before anything is sent), or an inconsistent
        initial state (found on a worker, naming the member by its index in ``Q0``).
    """
    try:
        import distributed  # noqa: F401
    except ImportError as exc:  # pragma: no cover - the extra is installed for the tests
        raise ImportError('fastvi.distributed needs Dask: pip install "fastvi[dask]"') from exc
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    opts = _ens._options(h, t_end, n_steps, method, save, tol, max_iter, newton, t0, keep_events,
                         solver, specialize)
    _ens.events_.check_list(events)
    if threads is not None:  # the upper bound is the worker's NUMBA_NUM_THREADS: checked there
        threads = _ens.check.count(threads, "threads", 1)
    Q0, V0, P = _ens._members(model, Q0, V0, params)
    N = Q0.shape[0]
    if chunk_size is None:
        workers = sum(client.nthreads().values())
        if workers < 1:
            raise ValueError("the Dask cluster of `client` has no workers")
        chunk_size = math.ceil(N / (CHUNKS_PER_WORKER_THREAD * workers))
    chunk_size = _ens.check.count(chunk_size, "chunk_size", 1)
    if check and not getattr(model, "checked", True):  # on the client, once, not once per chunk
        model.check(Q0[0], V0[0], params=P[0], n_random=1, t=opts["t0"])

    t_start = time.perf_counter()
    # The model travels as its pickled recipe (bytes, small); each worker process unpickles
    # and compiles it once and keeps it for later tasks and later calls (_worker_model).
    blob = pickle.dumps(model)
    futures = [
        client.submit(_run_chunk, blob, Q0[a:a + chunk_size], V0[a:a + chunk_size],
                      P[a:a + chunk_size], opts, threads, a, events, pure=False)
        for a in range(0, N, chunk_size)
    ]
    parts = client.gather(futures)
    wall = time.perf_counter() - t_start
    result = EnsembleResult.concatenate(parts)
    result.method = opts["method"]  # the client's (memoised) Method, not a worker's copy
    result.stats.update(wall_time=wall, worker_time=sum(p.stats["integration_time"] for p in parts),
                        chunks=len(parts))
    return result


def _run_chunk(blob, Q0, V0, P, opts, threads, first_member, events=None) -> EnsembleResult:
    """One task: members ``first_member …`` of the ensemble, with the local prange driver."""
    model = _worker_model(blob)
    if threads is None:
        threads = _worker_threads()
    threads = _ens._validate_threads(threads)
    return _ens._ensemble(model, Q0, V0, P, opts, threads, run_check=False,
                          first_member=first_member, events=events)


def _worker_model(blob: bytes) -> Model:
    """The model pickled as ``blob``, unpickled (and compiled) once per worker process."""
    with _MODELS_LOCK:
        model = _MODELS.pop(blob, None)
        if model is None:
            model = pickle.loads(blob)
        _MODELS[blob] = model  # most recently used last
        while len(_MODELS) > _MODELS_KEPT:
            del _MODELS[next(iter(_MODELS))]
        return model


def _worker_threads() -> int:
    """The Dask threads of this worker, capped by numba's pool."""
    import numba
    from distributed import get_worker

    try:
        n = get_worker().state.nthreads
    except (ValueError, AttributeError):  # not on a worker (e.g. a synchronous scheduler)
        n = numba.config.NUMBA_NUM_THREADS
    return max(1, min(int(n), numba.config.NUMBA_NUM_THREADS))
