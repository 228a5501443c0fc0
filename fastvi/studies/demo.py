"""``python -m fastvi demo``: the double pendulum, 10^4 steps, and a one-line summary."""

from __future__ import annotations

import numpy as np

from .cli import study_parser


def main(argv=None) -> int:
    parser = study_parser("python -m fastvi demo", __doc__)
    parser.add_argument("--method", default="P2L-Q3G", help="integrator (see fastvi.tables)")
    parser.add_argument("--h", type=float, default=0.01, help="step size")
    parser.add_argument("--steps", type=int, default=10_000, help="number of steps")
    parser.add_argument("--plot", metavar="PNG", help="also save the motion, energy and residual plots here")
    parser.add_argument("--orders", action="store_true",
                        help="also measure the convergence orders of P1L-Q2G, P2L-Q3G, P3L-Q4G (README table)")
    args = parser.parse_args(argv)

    import fastvi

    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    # the first call compiles the model's callbacks (and, once per machine, the kernels):
    # res.stats["setup_time"] holds it, "integration_time" the compiled loop alone
    res = fastvi.integrate(model, q0, v0, h=args.h, n_steps=args.steps, method=args.method)
    print(f"fastvi demo: double pendulum, θ1 = θ2 = π/2 at rest (set-up and compile "
          f"{res.stats['setup_time']:.2f} s)")
    print(f"  method           {res.method.name}")
    print(f"  h                {res.h:g}")
    print(f"  steps            {res.stats['steps']}  (t_end = {res.t[-1]:g})")
    print(f"  integration      {res.stats['integration_time']:.3f} s")
    print(f"  max |H - H0|     {np.max(np.abs(res.energy_error)):.3e}")
    print(f"  max |g(q)|       {np.max(res.constraint_residual):.3e}")
    print(f"  max |G(q) v|     {np.max(res.velocity_residual):.3e}")
    print(f"  Newton its/step  {res.stats['newton_iterations'] / res.stats['steps']:.2f}")
    if args.plot:
        res.plot(args.plot)
        print(f"  plot             {args.plot}")
    if args.orders:
        print_orders(model, q0, v0)
    return 0


def print_orders(model, q0, v0, T: float = 1.0) -> None:
    """Observed order at t = 1 against SciPy DOP853 (rtol = atol = 1e-13, angle coordinates)."""
    import fastvi
    from fastvi.studies.convergence import observed_order
    from fastvi.studies.reference import chain_pendulum_reference

    ref, _ = chain_pendulum_reference(model.angles(q0), [0.0, 0.0], [T], [1.0, 1.0], [1.0, 1.0])
    print("\n| method | N = T/h | max angle error at t = 1 | observed order |")
    print("|---|---|---|---|")
    for name, steps in [("P1L-Q2G", [20, 40, 80, 160, 320]), ("P2L-Q3G", [10, 20, 40, 80, 160]),
                        ("P3L-Q4G", [20, 28, 40, 56, 80])]:
        hs, errs = [], []
        for N in steps:
            r = fastvi.integrate(model, q0, v0, h=T / N, n_steps=N, method=name)
            hs.append(T / N)
            errs.append(float(np.max(np.abs(np.array(model.angles(r.q[-1])) - ref[0]))))
        order, _ = observed_order(hs, errs)
        print(f"| {name} | {steps[0]}–{steps[-1]} | {errs[0]:.1e} … {errs[-1]:.1e} | {order:.2f} |")
