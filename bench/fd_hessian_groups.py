"""Finite differences of the constraint Hessian by column groups (issue 12, item 3), side by
side with the column-by-column differences and with the exact Hessian.

``chain(N)`` without its ``constraint_hessian`` callback, ``newton="full"`` (the full Newton
matrix, where the Hessian is needed), ``P2L-Q3G``, h = 0.01: the integration loop's µs a
step, medians of interleaved rounds, for (a) grouped differences (the plan's default), (b)
the same plan with the groups switched off (``si[SI_HC_NG] = 0``: one column at a time,
v0.1's way) and (c) the chain's exact Hessian. The trajectories of (a) and (b) are equal bit
for bit.

    .venv/bin/python bench/fd_hessian_groups.py [rounds]
"""

from __future__ import annotations

import sys

import numpy as np

import fastvi
from fastvi import structure
from fastvi.kernels import layout as lay
from fastvi.scenes.chain import _dV, _G, _g, _V, pattern

METHOD = "P2L-Q3G"


def without_hessian(N):
    prm = (*([1.0] * N), *([1.0] * N), 9.81)
    return fastvi.Model(2 * N, N, params=prm, mass=np.ones(2 * N), potential=_V,
                        potential_grad=_dV, potential_hessian=0, constraint=_g,
                        constraint_jacobian=_G, constraint_jacobian_pattern=pattern(N),
                        name=f"chain{N}-no-constraint-hessian")


def main(argv):
    rounds = int(argv[0]) if argv else 3
    meth = fastvi.method(METHOD)
    print(f"{'N':>4} {'groups':>6} {'grouped':>10} {'by column':>10} {'exact':>10} "
          f"{'col/grp':>8} {'grp/exact':>9} {'equal':>6}")
    for N in (16, 32, 64, 128):
        steps = max(10, 4000 // N)
        fd, ex = without_hessian(N), fastvi.scenes.chain(N)
        q0, v0 = ex.initial_state(np.linspace(0.2, 1.0, N))
        grouped = fastvi.Model.__new__(fastvi.Model)  # a second model object: its own plan
        grouped.__dict__.update(fd.__dict__)
        grouped.__dict__.pop(structure._PLANS_ATTR, None)
        plan = structure.plan(fd, meth)
        ng = int(plan.si[lay.SI_HC_NG])
        plan.si[lay.SI_HC_NG] = 0  # `fd`'s memoised plan: column by column
        cases = dict(grouped=grouped, column=fd, exact=ex)
        times = {k: [] for k in cases}
        qs = {}
        for k, mod in cases.items():
            fastvi.integrate(mod, q0, v0, h=0.01, n_steps=2, newton="full", check=False)
        for _ in range(rounds):
            for k, mod in cases.items():
                r = fastvi.integrate(mod, q0, v0, h=0.01, n_steps=steps, newton="full",
                                     check=False, save_every=steps)
                times[k].append(r.stats["integration_time"] / steps)
                qs[k] = r.q
        med = {k: 1e6 * float(np.median(v)) for k, v in times.items()}
        print(f"{N:>4} {ng:>6} {med['grouped']:10.1f} {med['column']:10.1f} {med['exact']:10.1f} "
              f"{med['column'] / med['grouped']:8.2f} {med['grouped'] / med['exact']:9.2f} "
              f"{str(np.array_equal(qs['grouped'], qs['column'])):>6}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
