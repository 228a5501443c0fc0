"""``python -m fastvi demo``: the double pendulum, 10^4 steps, and a one-line summary."""

from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m fastvi demo", description=__doc__)
    parser.add_argument("--method", default="P2L-Q3G")
    parser.add_argument("--h", type=float, default=0.01)
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--plot", metavar="PNG", help="also save energy/constraint plots here")
    args = parser.parse_args(argv)

    t0 = time.perf_counter()
    import fastvi

    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    # the first call compiles the model's callbacks (and, once per machine, the kernels)
    fastvi.integrate(model, q0, v0, h=args.h, n_steps=1, method=args.method)
    t1 = time.perf_counter()
    res = fastvi.integrate(model, q0, v0, h=args.h, n_steps=args.steps, method=args.method)
    print(f"fastvi demo: double pendulum, θ1 = θ2 = π/2 at rest (set-up and compile {t1 - t0:.2f} s)")
    print(f"  method           {res.method.name}")
    print(f"  h                {res.h:g}")
    print(f"  steps            {res.stats['steps']}  (t_end = {res.t[-1]:g})")
    print(f"  wall time        {res.stats['wall_time']:.3f} s")
    print(f"  max |H - H0|     {np.max(np.abs(res.energy_error)):.3e}")
    print(f"  max |g(q)|       {np.max(res.constraint_residual):.3e}")
    print(f"  max |G(q) v|     {np.max(res.velocity_residual):.3e}")
    print(f"  Newton its/step  {res.stats['newton_iterations'] / res.stats['steps']:.2f}")
    if args.plot:
        res.plot(args.plot)
        print(f"  plot             {args.plot}")
    return 0
