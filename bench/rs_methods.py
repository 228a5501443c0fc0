"""The r = s methods against the defaults (r = s + 1) on the peer panel's double pendulum.

    .venv/bin/python bench/rs_methods.py [REPEATS]

Each pair (``P2L-Q2G`` / ``P2L-Q3G`` at h = 0.02, ``P3L-Q3G`` / ``P3L-Q4G`` and ``P4L-Q4G`` /
``P4L-Q5G`` at h = 0.025 and 0.05) is run as ``python -m fastvi wpd`` runs fastvi against
DOP853 (``fastvi.studies.wpd.fastvi_peer_run``: the public ``integrate`` with
``specialize=True``, T = 1000 s, energies saved every 0.1 s), round-robin in one process,
REPEATS times (default 3); printed: the median CPU time per step, max|ΔH| and max|g|. An
r = s method integrates the quadratic kinetic energy exactly with one Gauss point fewer
and has the same order and error constant in q (``docs/orders.md``); whether it is the
cheaper at equal *energy* error is what this measures. Compiling the six sized kernels
takes ≈ 7 minutes on the 2-core machine (once; then cached).
"""

import sys
import time

import numpy as np

import fastvi
from fastvi.studies.wpd import THETA0, fastvi_peer_run

PAIRS = (("P2L-Q2G", "P2L-Q3G", 0.02), ("P3L-Q3G", "P3L-Q4G", 0.025),
         ("P4L-Q4G", "P4L-Q5G", 0.025), ("P3L-Q3G", "P3L-Q4G", 0.05),
         ("P4L-Q4G", "P4L-Q5G", 0.05))


def main(repeats=3, T=1000.0):
    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(*THETA0)
    specs = [(m, h) for rs, default, h in PAIRS for m in (default, rs)]
    t0 = time.perf_counter()
    for method in dict.fromkeys(m for m, _ in specs):
        fastvi.integrate(model, q0, v0, h=0.01, n_steps=2, method=method, specialize=True)
    print(f"compiled / loaded in {time.perf_counter() - t0:.0f} s", flush=True)
    runs = {spec: [] for spec in specs}
    for _ in range(repeats):
        for method, h in specs:
            runs[(method, h)].append(fastvi_peer_run(model, q0, v0, method, h, T,
                                                      specialize=True))
    per_step = {}
    for (method, h), rs in runs.items():
        cpu = float(np.median([c for c, _ in rs]))
        info = rs[-1][1]
        per_step[(method, h)] = (cpu / info["steps"] * 1e6, info["dH"])
        print(f"{method} h = {h:<6g} {cpu:.4f} s  {per_step[(method, h)][0]:.3f} µs/step  "
              f"max|ΔH| {info['dH']:.2e}  max|g| {info['g']:.1e}")
    print("r = s / default:")
    for rs, default, h in PAIRS:
        (ta, ea), (tb, eb) = per_step[(rs, h)], per_step[(default, h)]
        print(f"  {rs} / {default}, h = {h:g}: step {ta / tb:.3f}, max|ΔH| {ea / eb:.2f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
