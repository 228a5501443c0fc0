"""The RK4 baseline on large models: the dense saddle system against ``G M⁻¹ Gᵀ`` over the
pattern of G (banded for a chain, sparse for a tree and a ladder), side by side (issue 12,
item 4). Wall µs a step over 300 steps (h = 0.002), without and with projection, and the
largest differences between the two trajectories.

    .venv/bin/python bench/rk4_structured.py
"""

import time

import numpy as np

import fastvi
from fastvi import structure
from fastvi.baselines import rk4

SCENES = (
    (lambda: fastvi.scenes.chain(40), lambda m: m.initial_state(np.linspace(0.2, 1.0, 40))),
    (lambda: fastvi.scenes.tree(8, 4), lambda m: m.initial_state(0.3 + 0.6 * np.sin(np.arange(33)))),
    (lambda: fastvi.scenes.ladder(16), lambda m: m.initial_state(np.full(16, 0.3))),
)


def main():
    print(f"{'scene':>10} {'proj':>5} {'solver':>7} {'dense us':>9} {'auto us':>9} {'ratio':>6} "
          f"{'max|dq|':>8} {'max|dv|':>8}")
    for make, start in SCENES:
        model = make()
        q0, v0 = start(model)
        auto = structure.plan(model, None).solvers["projection"]
        for project in (False, True):
            us, runs = {}, {}
            for solver in ("dense", "auto"):
                rk4(model, q0, v0, h=0.002, n_steps=2, project=project, solver=solver)
                t0 = time.perf_counter()
                runs[solver] = rk4(model, q0, v0, h=0.002, n_steps=300, project=project,
                                   solver=solver, save_every=30)
                us[solver] = 1e6 * (time.perf_counter() - t0) / 300
            dq = np.abs(runs["dense"].q - runs["auto"].q).max()
            dv = np.abs(runs["dense"].v - runs["auto"].v).max()
            print(f"{model.name:>10} {str(project):>5} {auto:>7} {us['dense']:9.1f} {us['auto']:9.1f} "
                  f"{us['dense'] / us['auto']:6.1f} {dq:8.1e} {dv:8.1e}", flush=True)


if __name__ == "__main__":
    main()
