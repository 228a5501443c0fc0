"""Time ``fastvi.integrate`` on the double pendulum for whatever fastvi is on ``sys.path``.

Run as a child process by ``bench/test_bench_release.py`` — once with this tree, once with a
worktree of the previous release — so that two versions of the package can be timed in one
benchmark session. Reads commands ``<method> <n_steps> <newton> [sized|generic] [model=chainN]``
from stdin, one per line (``sized``: ``specialize=True``, the size-specialized kernels, where the
tree has them; ``generic``: ``specialize=False``; neither: the default; ``model=chainN``: ``fastvi.scenes.chain(N)`` from the cost-growth study's start
instead of the double pendulum; ``model=sliderK``: the stiff panel's rod–slider with spring
stiffness K, e.g. ``slider1e8``);
answers each with one line of JSON: the thread CPU seconds of the integration (no
compile: every method is warmed up first), the Newton iterations per step and the final
state. ``newton`` is ignored by a release that has no such option.
"""

import importlib
import inspect
import json
import sys
import time

import numpy as np

import fastvi

H = 0.01


def _study(module: str, released: str):
    """A module of the speed study: ``module`` of a tree that has the ``studies/`` folder,
    ``released`` of a release that shipped the studies in the package."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError:
        return importlib.import_module(released)


def _scene(name):
    if name.startswith("slider"):  # the stiff panel's rod–slider, e.g. slider1e8 (k = 1e8)
        peers = _study("studies.peers", "fastvi.studies.peers")

        k = float(name[6:])
        model = fastvi.scenes.rotary_rod_slider(k=k)
        return (model, *model.initial_state(0.0, peers.SLIDER_R0 + peers.slider_stretch(k)))
    if name.startswith("chain"):
        N = int(name[5:])
        growth = _study("studies.wpd.growth", "fastvi.studies.wpd")
        model = fastvi.scenes.chain(N)
        return (model, *model.initial_state(growth.chain_angles(N)))
    model = fastvi.scenes.double_pendulum()
    return (model, *model.initial_state(np.pi / 2, np.pi / 2))


def main() -> None:
    scenes = {}
    params = inspect.signature(fastvi.integrate).parameters
    has_newton = "newton" in params
    has_sized = "specialize" in params
    warm = set()
    print(json.dumps(dict(ready=fastvi.__file__)), flush=True)
    for line in sys.stdin:
        method, n_steps, newton, *rest = line.split()
        name = next((t[6:] for t in rest if t.startswith("model=")), "double_pendulum")
        sized = "sized" in rest
        generic = "generic" in rest
        if name not in scenes:
            scenes[name] = _scene(name)
        model, q0, v0 = scenes[name]
        n_steps = int(n_steps)
        kw = dict(h=H, n_steps=n_steps, method=method, save_every=n_steps)
        if has_newton:
            kw["newton"] = newton
        if (sized or generic) and has_sized:
            kw["specialize"] = bool(sized)
        key = (method, newton, bool(sized), generic, name)
        if key not in warm:
            fastvi.integrate(model, q0, v0, **{**kw, "n_steps": 10, "save_every": 10})
            warm.add(key)
        t0 = time.thread_time()
        res = fastvi.integrate(model, q0, v0, **kw)
        cpu = time.thread_time() - t0
        print(json.dumps(dict(cpu=cpu, iterations=res.stats["newton_iterations"] / n_steps,
                              q=res.q[-1].tolist(), energy=float(res.energy[-1]))), flush=True)


if __name__ == "__main__":
    main()
