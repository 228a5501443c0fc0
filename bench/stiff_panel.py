"""The stiff panel of ``python -m fastvi wpd`` alone, at the stiffnesses you name.

The rod–slider of ``docs/wpd.md`` ("Stiff rod–slider") with the study's full settings
(``wpd.PEERS_FULL["stiff"]``: fastvi's four methods over ωh ≈ 64 … 0.5 with
``specialize=True``, CyRK DOP853 / LSODA / Radau over their tolerances, every contender
round-robin in one process, median of ``repeats``), at the given k only, and its table:
CPU time of each contender to reach max|ΔH| ≤ 1e-4 J and the ratio best peer / best fastvi
(goal of issue 11: ≥ 10 at k = 1e8). Minutes, not the hour of the whole study.

    .venv/bin/python bench/stiff_panel.py [k ...] [--h-max=H]   (default: 1e7 1e8)

``--h-max`` sets the stiff configuration's ``h_max``, the cap of fastvi's step (the study's:
``wpd.STIFF_H_MAX``, 0.01): at large k the cap, not the grid ωh ≈ c, sets fastvi's cheapest
run (``docs/benchmarks.md``). Each run's rod-angle error against the tight reference is
printed with it.

Needs the ``bench`` extra (CyRK).
"""

from __future__ import annotations

import sys

from fastvi.studies import wpd


def main(argv: list[str]) -> None:
    opts = [a for a in argv if a.startswith("--")]
    ks = tuple(float(a) for a in argv if not a.startswith("--")) or (1e7, 1e8)
    h_max = wpd.STIFF_H_MAX
    for o in opts:
        if o.startswith("--h-max="):
            h_max = float(o.split("=", 1)[1])
        else:
            raise SystemExit(f"unknown option {o!r}: the options are --h-max=H")
    pcfg = dict(wpd.PEERS_FULL)
    pcfg["stiff"] = dict(pcfg["stiff"], ks=ks, h_max=h_max)
    points = wpd.peer_stiff_sweep(pcfg, lambda s: print(s, file=sys.stderr))
    for p in points:
        print(f"  {p.label:12s} k {p.k:g} knob {p.knob:.3g}  CPU {1e3 * p.cpu:.3f} ms  "
              f"max|ΔH| {p.dH:.2e}  |Δθ| {p.err_theta:.1e} rad  |Δr| {p.err_r:.1e} m")
    table, target = wpd.stiff_table(points, pcfg)
    _, _, ratios = wpd.stiff_summary(table, pcfg)
    print(f"CPU seconds to reach max|ΔH| <= {target:g} J (≤: every run met it, the cheapest)")
    for k, row in table.items():
        cells = "  ".join(f"{lab} {'≤ ' if how == '≤' else ''}{c:.4g}" for lab, (c, how) in row.items())
        print(f"k = {k:g}: {cells}")
        print(f"    best peer / best fastvi = {ratios[k]:.2f}")


if __name__ == "__main__":
    main(sys.argv[1:])
