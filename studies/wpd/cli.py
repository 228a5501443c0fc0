"""``python -m fastvi wpd`` (or ``python -m studies.wpd``): run the study, write the page.

:func:`run_study` runs the sweeps of :mod:`.runs`, the cost growth of :mod:`.growth` and the
compiled-peer panels (:func:`run_peers`), then writes ``wpd.md`` and the figures; :func:`main`
is the command line.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

import fastvi
from fastvi.studies.cli import default_out, study_parser
from fastvi.studies.reference import REF_TOL

from .. import peers
from .config import FULL, PEERS_FULL, PEERS_QUICK, QUICK, THETA0
from .growth import chain_cost, splice_growth
from .peer_report import peer_figures, peer_markdown
from .peer_runs import peer_pendulum_sweep
from .report import energy_ratio_lines, figures, markdown
from .runs import reference_q, sweep, warm_up
from .stiff import peer_stiff_sweep, stiff_figure, stiff_table


def run_peers(pcfg, log):
    """Run the peer panels; returns (points, elapsed s, missing-reason or None)."""
    if not peers.have_cyrk():
        log(f"compiled peer skipped: {peers.INSTALL_HINT}")
        return [], 0.0, peers.INSTALL_HINT
    t0 = time.perf_counter()
    peers.warm_up_peers()
    points = peer_pendulum_sweep(pcfg, log) + peer_stiff_sweep(pcfg, log)
    return points, time.perf_counter() - t0, None


def growth_rows(cfg, log) -> dict:
    """The cost-growth rows of every chain size of ``cfg``."""
    rows = {}
    for N in cfg["growth"]:
        rows[N] = r = chain_cost(N)
        log(f"chain({N}): {r['rows']} rows, {1e6 * r['cpu_per_step']:.1f} µs/step, "
            f"Schur {r['solvers']['schur']}")
    return rows


def run_study(cfg, outdir: str, log, command: str, figures_on: bool = True,
              growth_on: bool = True, peers_on: bool = True, peers_cfg=None):
    """Run the sweeps, write ``outdir/wpd.md`` and the figures; returns (points, path).

    ``peers_on``: also the compiled-peer panels (:func:`run_peers`, needs CyRK; skipped with
    a note on the page when it is missing), configured by ``peers_cfg`` (default
    :data:`PEERS_QUICK` for the quick configuration, :data:`PEERS_FULL` otherwise)."""
    t_start = time.perf_counter()
    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(*THETA0)
    labels = list(dict.fromkeys(list(cfg["error"]) + list(cfg["long"])))
    warm_up(model, q0, v0, labels, log)
    q_tight = reference_q(cfg["T_error"])
    ref_floor = float(np.max(np.abs(reference_q(cfg["T_error"], tol=10 * REF_TOL) - q_tight)))
    cfg = dict(cfg, ref_floor=ref_floor)
    points = sweep(cfg, model, q0, v0, log)
    growth = growth_rows(cfg, log) if growth_on else {}
    peer_text = []
    os.makedirs(outdir, exist_ok=True)
    if peers_on:
        pcfg = peers_cfg if peers_cfg is not None else (PEERS_QUICK if cfg["repeats"] == 1
                                                        else PEERS_FULL)
        ppoints, p_elapsed, missing = run_peers(pcfg, log)
        pfigs = []
        if figures_on and ppoints:
            pfigs = (peer_figures(ppoints, pcfg, outdir)
                     + stiff_figure(stiff_table(ppoints, pcfg)[0], pcfg, outdir))
        peer_text = peer_markdown(ppoints, pcfg, pfigs, p_elapsed, missing)
    figs = figures(points, cfg, outdir, log) if figures_on else []
    path = os.path.join(outdir, "wpd.md")
    text = markdown(points, cfg, figs, ref_floor, command, time.perf_counter() - t_start, growth)
    if peer_text:
        head, sep, tail = text.partition("## Diagrams\n")
        text = head + "\n".join(peer_text) + "\n" + sep + tail
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
    log(f"wrote {path}" + (f" and {len(figs)} figures" if figs else ""))
    return points, path


def main(argv=None) -> int:
    from . import __doc__ as doc

    parser = study_parser("python -m fastvi wpd", doc)
    parser.add_argument("--quick", action="store_true",
                        help=f"T = {QUICK['T_error']:g} s and {QUICK['T_long']:g} s, few points, single runs")
    parser.add_argument("--out", default=default_out("wpd"), help="directory for wpd.md and figures/ "
                        "(the package's own page: --out docs, from the repository root)")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    parser.add_argument("--no-growth", action="store_true", help="skip the chain(N) cost-growth table")
    parser.add_argument("--no-peers", action="store_true",
                        help="skip the compiled-peer panels (CyRK DOP853 / LSODA / Radau)")
    parser.add_argument("--growth-only", action="store_true",
                        help="regenerate only the chain(N) cost-growth section of the wpd.md in --out")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    args = parser.parse_args(argv)

    def log(msg):
        if not args.quiet:
            print(msg, file=sys.stderr, flush=True)

    cfg = QUICK if args.quick else FULL
    command = "python -m fastvi wpd" + (" --quick" if args.quick else "")
    if args.growth_only:
        path = os.path.join(args.out, "wpd.md")
        splice_growth(path, growth_rows(cfg, log), command + f" --growth-only --out {args.out}")
        print(f"wrote the cost-growth section of {path}")
        return 0
    points, path = run_study(cfg, args.out, log, command, figures_on=not args.no_figures,
                             growth_on=not args.no_growth, peers_on=not args.no_peers)
    print("\n".join(energy_ratio_lines(points, cfg)))
    print(f"wrote {path}")
    return 0
