"""The stiff panel of ``python -m fastvi wpd`` alone, at the stiffnesses you name.

The rod–slider of ``docs/wpd.md`` ("Stiff rod–slider") with the study's full settings
(``wpd.PEERS_FULL["stiff"]``: fastvi's four methods over ωh ≈ 64 … 0.5 with
``specialize=True``, CyRK DOP853 / LSODA / Radau over their tolerances, every contender
round-robin in one process, median of 3), at the given k only, and its table: CPU time of
each contender to reach max|ΔH| ≤ 1e-4 J and the ratio best peer / best fastvi (goal of
issue 11: ≥ 10 at k = 1e8). Minutes, not the hour of the whole study.

    .venv/bin/python bench/stiff_panel.py [k ...]        (default: 1e7 1e8)

Needs the ``bench`` extra (CyRK).
"""

from __future__ import annotations

import sys

from fastvi.studies import wpd


def main(argv: list[str]) -> None:
    ks = tuple(float(a) for a in argv) or (1e7, 1e8)
    pcfg = dict(wpd.PEERS_FULL)
    pcfg["stiff"] = dict(pcfg["stiff"], ks=ks)
    points = wpd.peer_stiff_sweep(pcfg, lambda s: print(s, file=sys.stderr))
    table, target = wpd.stiff_table(points, pcfg)
    _, _, ratios = wpd.stiff_summary(table, pcfg)
    print(f"CPU seconds to reach max|ΔH| <= {target:g} J (≤: every run met it, the cheapest)")
    for k, row in table.items():
        cells = "  ".join(f"{lab} {'≤ ' if how == '≤' else ''}{c:.4g}" for lab, (c, how) in row.items())
        print(f"k = {k:g}: {cells}")
        print(f"    best peer / best fastvi = {ratios[k]:.2f}")


if __name__ == "__main__":
    main(sys.argv[1:])
