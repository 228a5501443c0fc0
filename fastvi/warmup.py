"""The first calls a new user makes, timed: what compiling the kernels costs.

``python -m fastvi compile`` runs them once so that numba's on-disk cache holds every
kernel (later processes load them in a fraction of a second);
``python -m fastvi compile --report`` runs them in a fresh process with an empty,
temporary numba cache and prints, for each first call, its wall and CPU time and the
process's peak resident memory so far — the cost a user pays on a new machine.

The four first calls are the four kinds of kernel a session uses:

1. ``integrate`` of the double pendulum (the conservative kernel);
2. ``integrate`` of the damped double pendulum (forces and time);
3. ``integrate`` with terminal events and dense output;
4. ``integrate_ensemble`` of 8 members (the parallel driver).

``--only specialize`` times a fifth kind: ``integrate(..., specialize=True)`` of the
double pendulum, the step's stages compiled for its sizes (which the default,
``specialize=None``, then uses for every run of a model of those sizes). ``--only
sensitivity,adjoint,sensitivity-ensemble`` compiles (or times) the derivatives of the flow:
``sensitivity`` of the damped double pendulum by its initial state and parameters,
``adjoint`` of it, and ``sensitivity_ensemble`` of 4 members (the full Newton included,
which the first two compile only when a step needs it, as ``integrate`` does);
``sensitivity-state`` the default ``sensitivity``, by the initial state alone (no part by
the parameters compiled);
``sensitivity-sized`` and ``adjoint-sized`` the same two with ``specialize=True``, the
linearised step compiled for the model's sizes. ``--only large`` times ``integrate`` of a
chain of 16 links (the banded and sparse solves of a large mechanism), ``--only bodies``
that of the Bricard mechanism of rigid bodies (which also takes the full Newton).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

__all__ = ["FIRST_CALLS", "first_calls", "main"]


def _peak_mb() -> float:
    """Peak resident memory of this process so far (MB), from ``/proc`` (Linux) or
    ``getrusage``."""
    try:
        with open(f"/proc/{os.getpid()}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _conservative():
    import fastvi

    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    return fastvi.integrate(model, q0, v0, h=0.01, n_steps=100)


def _forces():
    import fastvi

    model = fastvi.scenes.double_pendulum(damping=0.1)
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    return fastvi.integrate(model, q0, v0, h=0.01, n_steps=100)


def _events():
    import fastvi

    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2, 0.0, 6.0)
    return fastvi.integrate(model, q0, v0, h=0.01, n_steps=200, events=model.flips,
                            dense_output=True)


def _ensemble():
    import fastvi

    model = fastvi.scenes.double_pendulum()
    states = [model.initial_state(np.pi / 2, a) for a in np.linspace(1.0, 2.0, 8)]
    Q0 = np.array([q for q, _ in states])
    V0 = np.array([v for _, v in states])
    return fastvi.integrate_ensemble(model, Q0, V0, h=0.01, n_steps=100)


def _specialized():
    import fastvi

    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    return fastvi.integrate(model, q0, v0, h=0.01, n_steps=100, specialize=True)


def _large():
    import fastvi

    model = fastvi.scenes.chain(16)
    q0, v0 = model.initial_state(np.linspace(0.2, 0.9, 16))
    return fastvi.integrate(model, q0, v0, h=0.01, n_steps=50)


def _bodies():
    import fastvi
    from fastvi.bodies import scenes

    model = scenes.bricard()
    q0, v0 = model.initial_state()
    return fastvi.integrate(model, q0, v0, h=0.02, t_end=1.0)


def _damped():
    import fastvi

    model = fastvi.scenes.double_pendulum(damping=0.3)
    return (model, *model.initial_state(1.0, 0.5))


def _sensitivity(specialize=None):
    import fastvi

    model, q0, v0 = _damped()
    return fastvi.sensitivity(model, q0, v0, h=0.01, n_steps=10, wrt=("q0", "v0", "params"),
                              specialize=specialize)


def _sensitivity_by_the_state():
    import fastvi

    model, q0, v0 = _damped()
    return fastvi.sensitivity(model, q0, v0, h=0.01, n_steps=10)


def _adjoint(specialize=None):
    import fastvi

    model, q0, v0 = _damped()
    return fastvi.adjoint(model, q0, v0, lambda r: (np.ones((len(r.t), model.n)), None),
                          h=0.01, n_steps=10, specialize=specialize)


def _sensitivity_ensemble():
    import fastvi

    model, q0, v0 = _damped()
    return fastvi.sensitivity_ensemble(model, np.tile(q0, (4, 1)), np.tile(v0, (4, 1)), h=0.01,
                                       n_steps=10)


#: name -> the first call of one kind of kernel (the first four: a new session's)
FIRST_CALLS = {
    "integrate": _conservative,
    "forces": _forces,
    "events+dense": _events,
    "ensemble": _ensemble,
    "specialize": _specialized,
    "large": _large,
    "bodies": _bodies,
    "sensitivity-state": _sensitivity_by_the_state,
    "sensitivity": _sensitivity,
    "adjoint": _adjoint,
    "sensitivity-ensemble": _sensitivity_ensemble,
    "sensitivity-sized": lambda: _sensitivity(specialize=True),
    "adjoint-sized": lambda: _adjoint(specialize=True),
}
_SESSION = ("integrate", "forces", "events+dense", "ensemble")


def first_calls(names=None) -> list[dict]:
    """Run the first calls ``names`` (default: a new session's four) in this process.

    Returns one record per call: ``name``, ``wall`` and ``cpu`` seconds (process CPU time,
    all threads) and ``peak_mb``, the process's peak resident memory after the call."""
    out = []
    for name in names or _SESSION:
        w, c = time.perf_counter(), time.process_time()
        FIRST_CALLS[name]()
        out.append(dict(name=name, wall=time.perf_counter() - w, cpu=time.process_time() - c,
                        peak_mb=_peak_mb()))
    return out


def _child(names) -> list[dict]:
    """:func:`first_calls` in a fresh interpreter with an empty, temporary numba cache."""
    with tempfile.TemporaryDirectory(prefix="fastvi-cold-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        code = ("import json, sys; from fastvi.warmup import first_calls; "
                f"print(json.dumps(first_calls({list(names)!r})))")
        w = time.perf_counter()
        run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                             text=True, check=False)
        if run.returncode != 0:
            raise RuntimeError(f"the cold first calls failed:\n{run.stderr}")
        records = json.loads(run.stdout.strip().splitlines()[-1])
        records.append(dict(name="process", wall=time.perf_counter() - w, cpu=float("nan"),
                            peak_mb=records[-1]["peak_mb"]))
        return records


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m fastvi compile",
        description="Compile fastvi's kernels into numba's on-disk cache, or (--report) time "
                    "the first calls of a new session in a fresh process with an empty cache.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--report", action="store_true",
                        help="time each first call cold (fresh process, empty temporary cache)")
    parser.add_argument("--only", default=",".join(_SESSION),
                        help="comma-separated first calls: " + ", ".join(FIRST_CALLS))
    parser.add_argument("--json", metavar="FILE", help="with --report: also write the records here")
    args = parser.parse_args(argv)
    names = [x for x in args.only.split(",") if x]
    unknown = sorted(set(names) - set(FIRST_CALLS))
    if unknown:
        parser.error(f"--only: unknown first call(s) {unknown}; choose from {list(FIRST_CALLS)}")
    records = _child(names) if args.report else first_calls(names)
    print(f"{'first call':20s} {'wall s':>8s} {'CPU s':>8s} {'peak MB':>8s}")
    for r in records:
        print(f"{r['name']:20s} {r['wall']:8.2f} {r['cpu']:8.2f} {r['peak_mb']:8.0f}")
    if args.report:
        calls = [r for r in records if r["name"] != "process"]
        print(f"{'all calls':20s} {sum(r['wall'] for r in calls):8.2f} "
              f"{sum(r['cpu'] for r in calls):8.2f} {max(r['peak_mb'] for r in calls):8.0f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(records, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
