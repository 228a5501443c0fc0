"""Which adaptive method is cheapest at an energy level (docs/benchmarks.md, "an order-10
adaptive contender"): the public call as the speed study times it.

    .venv/bin/python bench/adaptive_methods.py [STARTS] METHOD=eps,eps,... [METHOD=...]
    .venv/bin/python bench/adaptive_methods.py 4 P3L-Q4G=0.1,0.08,0.0625 P5L-Q5G=0.125,0.1,0.08

For each method and ε: ``wpd.fastvi_peer_run`` (``adaptive=PEER_ADAPTIVE_KR``,
``specialize=True``, T = 1000 s, energies every 0.1 s on average), the median process CPU
of 5 runs from the study's nominal start, and max|ΔH| and max|g| over ``STARTS`` of the
study's starts (``wpd.peer_starts``; default 4). Compiles the sized kernels of each method
first (minutes each on an empty cache; see bench/compile_memory.py).
"""
import sys

import numpy as np

import fastvi
from fastvi.studies import wpd

T = 1000.0
REPEATS = 5


def main(argv) -> None:
    count = int(argv[0]) if argv and argv[0].isdigit() else 4
    specs = [(name, float(e)) for a in argv if "=" in a
             for name, eps in [a.split("=", 1)] for e in eps.split(",")]
    if not specs:
        raise SystemExit(__doc__)
    model = fastvi.scenes.double_pendulum()
    starts = wpd.peer_starts(count)
    q0, v0 = model.initial_state(*starts[0])
    for name, eps in specs:
        label = name + wpd.ADAPTIVE
        fastvi.integrate(model, q0, v0, h=0.01, n_steps=2, method=name, specialize=True)
        cpus = [wpd.fastvi_peer_run(model, q0, v0, label, eps, T, specialize=True)
                for _ in range(REPEATS)]
        info = cpus[-1][1]
        dHs, gs = [info["dH"]], [info["g"]]
        for th in starts[1:]:
            other = wpd.fastvi_peer_run(model, *model.initial_state(*th), label, eps, T,
                                        specialize=True)[1]
            dHs.append(other["dH"])
            gs.append(other["g"])
        cpu = float(np.median([c for c, _ in cpus]))
        print(f"{label:<18} ε {eps:<7g} CPU {1e3 * cpu:7.1f} ms  steps {info['steps']:6d}  "
              f"{1e6 * cpu / info['steps']:.3f} µs/step  max|ΔH| {np.median(dHs):.2e} "
              f"({min(dHs):.1e}…{max(dHs):.1e})  max|g| {max(gs):.1e}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
