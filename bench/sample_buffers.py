"""What handing the sample buffers to the result saves, against copying them out.

    .venv/bin/python bench/sample_buffers.py [--rounds=9]

``fastvi.integrate`` writes its samples into buffers allocated before the run. Until
2026-11-26 the result held trimmed copies of them; now it holds the buffers themselves when
the run filled them (a fixed-step run sizes them exactly), views when they are at least half
full (``integrate._filled``). Copying is not cheap on this machine: memory written for the
first time costs ≈ 2.5 µs a 4 KiB page (page faults), ≈ 0.1 µs a sample of the double
pendulum (18 numbers). This times the public call both ways, interleaved in one process
(process CPU, median of ``--rounds``), at the speed study's settings: energies saved every
0.1 s (the adaptive runs every 0.1 s on average), T = 1000 s, ``specialize=True``.
"""

import importlib
import sys
import time

import numpy as np

import fastvi
from fastvi.kernels.layout import Samples
from fastvi.studies import wpd

integ = importlib.import_module("fastvi.integrate")  # the module: fastvi.integrate is the function
CASES = (("P2L-Q3G", 0.04, None), ("P2L-Q3G", 0.02, None), ("P3L-Q4G", 0.025, None),
         ("P2L-Q3G", 0.08, wpd.PEER_ADAPTIVE_KR), ("P3L-Q4G", 0.0625, wpd.PEER_ADAPTIVE_KR))


def _copied(smp, J):
    """The result's arrays as before: trimmed copies of every buffer."""
    return Samples(*(a[:J].copy() for a in smp))


def main(rounds=9, T=1000.0):
    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(*wpd.THETA0)
    kept = integ._filled
    print(f"double pendulum, T = {T:g} s, process CPU of the public call, median of {rounds}")
    print(f"{'method':<9} {'h or ε':>7} {'adaptive':>8} {'every':>5} {'samples':>7} "
          f"{'copied ms':>9} {'kept ms':>8} {'kept/copied':>11}")
    for method, h, kr in CASES:
        label = method if kr is None else method + wpd.ADAPTIVE
        every = wpd.peer_save_every(model, q0, v0, label, h, T, specialize=True)
        kw = dict(h=h, t_end=T, method=method, adaptive=kr, specialize=True, save_every=every)
        fastvi.integrate(model, q0, v0, **{**kw, "t_end": 1.0})  # compile / load
        cpu = {"copied": [], "kept": []}
        for _ in range(rounds):
            for how, fn in (("copied", _copied), ("kept", kept)):
                integ._filled = fn
                try:
                    c0 = time.process_time()
                    res = fastvi.integrate(model, q0, v0, **kw)
                    cpu[how].append(time.process_time() - c0)
                finally:
                    integ._filled = kept
        a, b = np.median(cpu["copied"]), np.median(cpu["kept"])
        print(f"{method:<9} {h:>7g} {'' if kr is None else kr:>8} {every:>5} {len(res.t):>7} "
              f"{1e3 * a:>9.2f} {1e3 * b:>8.2f} {b / a:>11.3f}")


if __name__ == "__main__":
    opts = dict(a[2:].split("=") for a in sys.argv[1:] if a.startswith("--"))
    main(rounds=int(opts.get("rounds", 9)))
