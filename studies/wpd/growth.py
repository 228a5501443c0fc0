"""How the cost of a step grows with the number of bodies: ``fastvi.scenes.chain(N)``.

The study's section "Cost growth with the number of bodies": the integration loop's time per
step on chains of N links, the linear solvers :func:`fastvi.structure.plan` chose, and the
exponent of a power law fitted to the cost (``--growth-only`` regenerates this section alone).
"""

from __future__ import annotations

import numpy as np

import fastvi
from fastvi import structure

from ..machine import environment
from .runs import compile_kernels


GROWTH_METHOD = "P2L-Q3G"
GROWTH_H = 0.01
GROWTH_STEP_BUDGET = 20_000  # steps(N) ≈ budget / N: the structured step costs O(N)
GROWTH_MIN_STEPS = 20


def chain_angles(N: int) -> np.ndarray:
    """The start of the cost-growth runs: a smooth arc of link angles, at most 0.6 rad."""
    return 0.6 * np.sin(np.linspace(0.3, 2.8, N))


def growth_steps(N: int) -> int:
    """Steps timed for ``chain(N)``: fewer for large N, so each run takes ~10–50 ms."""
    return int(max(GROWTH_MIN_STEPS, min(10_000, GROWTH_STEP_BUDGET // N)))


def fit_exponent(rows: dict, key: str = "cpu_per_step") -> dict:
    """Least-squares slope of log(cost per step) against log N, and the local slopes."""
    Ns = np.array(sorted(rows))
    c = np.array([rows[N][key] for N in Ns])
    slope = float(np.polyfit(np.log(Ns), np.log(c), 1)[0])
    local = {f"{a}-{b}": float(np.log(c[i + 1] / c[i]) / np.log(b / a))
             for i, (a, b) in enumerate(zip(Ns[:-1], Ns[1:]))}
    return dict(exponent=slope, local=local, sizes=[int(N) for N in Ns])


def chain_cost(N: int, method: str = GROWTH_METHOD, h: float = GROWTH_H) -> dict:
    r"""Cost per step of ``method`` on ``fastvi.scenes.chain(N)`` and how its systems are solved.

    The integration loop's time per step (``stats["integration_time"]``: set-up — pattern,
    ordering, initial projection — excluded; best of two runs of :func:`growth_steps`
    steps), Newton iterations per step, the solvers and Schur bandwidth of the plan
    (:func:`fastvi.structure.plan`) and the constraint residual.
    """
    model = fastvi.scenes.chain(N)
    q0, v0 = model.initial_state(chain_angles(N))
    steps = growth_steps(N)
    meth = fastvi.method(method)
    compile_kernels(model, q0, v0, method, h)
    per = []
    for _ in range(2):
        res = fastvi.integrate(model, q0, v0, h=h, n_steps=steps, method=method, save_every=steps)
        per.append(res.stats["integration_time"] / steps)
    plan = structure.plan(model, meth)
    its = res.stats["newton_iterations"] / res.stats["steps"]
    return dict(N=N, rows=meth.s * model.n + meth.J * model.m, steps=steps,
                cpu_per_step=min(per), iterations=its, solvers=plan.solvers,
                band=plan.bandwidths.get("schur"), g=float(np.max(res.constraint_residual)))


def growth_lines(rows: dict) -> list[str]:
    """The cost-growth section: table, fitted exponent and local slopes."""
    if len(rows) < 2:
        return []
    f = fit_exponent(rows)
    P = ["## Cost growth with the number of bodies\n",
         f"`fastvi.scenes.chain(N)` (n = 2N, m = N constraints), `{GROWTH_METHOD}`, "
         f"h = {GROWTH_H:g}, at rest from a smooth arc of angles; time per step of the "
         "integration loop (`stats[\"integration_time\"]`, best of two runs; fewer steps for "
         "large N), with the linear solves `solver=\"auto\"` chose for the Schur complement of "
         "the mechanics iteration and the end projection (`fastvi.structure`: banded after a "
         "reverse Cuthill–McKee ordering for a chain) and the Schur complement's bandwidth. "
         "The same measurement under pytest-benchmark, with the dense path beside it: "
         "`bench/test_bench_chain.py`; the crossover dense / banded / sparse on chains, "
         "ladders and trees: `docs/benchmarks.md`.\n",
         "| N | Newton rows | steps | µs/step | Newton its/step | Schur / projection | Schur band (kl, ku) | max\\|g\\| |",
         "|---|---|---|---|---|---|---|---|"]
    for N in sorted(rows):
        r = rows[N]
        sv = r["solvers"]
        band = "–" if r["band"] is None or sv["schur"] == "dense" else f"({r['band'][0]}, {r['band'][1]})"
        P.append(f"| {N} | {r['rows']} | {r['steps']} | {1e6 * r['cpu_per_step']:.1f} | "
                 f"{r['iterations']:.2f} | {sv['schur']} / {sv['projection']} | {band} | {r['g']:.1e} |")
    Ns = f["sizes"]
    P.append("")
    P.append(f"Fitted exponent of the cost per step over N = {Ns[0]}…{Ns[-1]}: **{f['exponent']:.2f}**; "
             "local slopes " + ", ".join(f"{k}: {v:.2f}" for k, v in f["local"].items()) + ".")
    P.append("")
    return P


def splice_growth(path: str, rows: dict, command: str) -> None:
    """Replace the cost-growth section of an existing page ``path`` (``--growth-only``)."""
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    head, sep, rest = text.partition("## Cost growth with the number of bodies\n")
    if not sep:
        raise ValueError(f"{path} has no section '## Cost growth with the number of bodies'")
    _, sep2, tail = rest.partition("\n## ")
    lines = growth_lines(rows)
    lines.insert(1, f"*This section regenerated alone by `{command}` ({environment()}).*\n")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(head + "\n".join(lines) + (sep2 + tail if sep2 else ""))
