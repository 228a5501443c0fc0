"""fastvi against the compiled peer (issue 11, item 5), under pytest-benchmark.

The speed study's comparison at two of its levels, in a minute: at each level, the contender
the study found best there (``P2L-Q3G`` adaptive at ≈ 1e-2 J, ``P3L-Q4G`` adaptive at
≈ 1e-4 J: the public ``fastvi.integrate`` with ``specialize=True``, samples every 0.1 s on
average, as :func:`fastvi.studies.wpd.fastvi_peer_run` runs it) against CyRK's C++ DOP853 on
the hand-written Cartesian index-1 right-hand side of the same double pendulum
(:mod:`fastvi.studies.peers`, variant (a)), over the goal's T = 1000 s from θ1 = θ2 = π/2 at
rest.

**Equal error.** On this chaotic motion one start's max|ΔH| is a 1.3–4× lottery, so, as in
the study, each setting's error is the median over :data:`STARTS` starts 1e-12 rad apart
(:func:`fastvi.studies.wpd.peer_starts`). DOP853's tolerance runs over a quarter-decade
grid; its cost at fastvi's error is interpolated log–log between the two grid tolerances
that bracket that error, both timed.

**Timing** as the study's: process CPU of the ``fastvi.integrate`` call and of CyRK's solver
call (``peers.run_peer``: energies evaluated afterwards, untimed), contenders interleaved
round by round from the nominal start, medians. pytest-benchmark records the whole
interleaved measurement of a level as one round. The ratio is printed at the end
(``make bench``); the full sweep over levels and T is ``python -m fastvi wpd``
(``docs/wpd.md``).

Skipped when CyRK (the ``bench`` extra: ``pip install -e .[bench]``) is missing.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("CyRK")

import fastvi  # noqa: E402
from fastvi.studies import peers, wpd  # noqa: E402

T = 1000.0
#: (study level, contender, ε): the speed study's best fastvi at ≈ 1e-2 and ≈ 1e-4 J
#: (docs/wpd.md); both methods' sized kernels are those `make bench` compiles anyway
LEVELS = ((1e-2, "P2L-Q3G" + wpd.ADAPTIVE, 0.08), (1e-4, "P3L-Q4G" + wpd.ADAPTIVE, 0.0625))
TOLS = tuple(10.0 ** (-k / 4) for k in range(24, 49))  # DOP853 rtol = atol, 1e-6 … 1e-12
STARTS = 4
ROUNDS = 7

_report: dict[float, dict] = {}


@pytest.fixture(scope="module")
def setup():
    model = fastvi.scenes.double_pendulum()
    starts = wpd.peer_starts(STARTS)
    peers.warm_up_peers(methods=("DOP853",))
    ys = [peers.cartesian_start(th) for th in starts]
    # the median error over the starts of every grid tolerance, once (untimed)
    dop_dH = {tol: float(np.median([_dop(y, tol)[1]["dH"] for y in ys])) for tol in TOLS}
    return dict(model=model, starts=starts, ys=ys, dop_dH=dop_dH)


def _dop(y0, tol):
    r = peers.run_peer("cartesian", y0, peers.DP_PARAMS, T=T, tol=tol)
    return r["cpu"], dict(dH=r["dH"] if r["ok"] else np.inf, steps=r["steps"])


def _fastvi(model, theta, label, eps):
    q0, v0 = model.initial_state(*theta)
    return wpd.fastvi_peer_run(model, q0, v0, label, eps, T, specialize=True)


def _bracket(dop_dH: dict, target: float):
    """The grid tolerances (looser, tighter) whose median errors bracket ``target``."""
    tols = sorted(dop_dH, reverse=True)  # loosest first: errors fall along the list
    for loose, tight in zip(tols, tols[1:]):
        if dop_dH[tight] <= target < dop_dH[loose]:
            return loose, tight
    raise AssertionError(f"no DOP853 tolerance in {tols[0]:g} … {tols[-1]:g} brackets "
                         f"max|ΔH| = {target:.2e} J: widen TOLS")


@pytest.mark.parametrize("level,label,eps", LEVELS, ids=[f"{lv:g}J" for lv, _, _ in LEVELS])
def test_fastvi_vs_dop853(benchmark, setup, level, label, eps):
    model, starts = setup["model"], setup["starts"]
    _fastvi(model, starts[0], label, eps)  # compiles (or loads) the sized kernels
    infos = [_fastvi(model, th, label, eps)[1] for th in starts]
    assert all(i["ok"] for i in infos) and max(i["g"] for i in infos) < 1e-13
    dH = float(np.median([i["dH"] for i in infos]))
    loose, tight = _bracket(setup["dop_dH"], dH)
    y0 = setup["ys"][0]
    jobs = {"fastvi": lambda: _fastvi(model, starts[0], label, eps),
            "loose": lambda: _dop(y0, loose), "tight": lambda: _dop(y0, tight)}
    cpus = {name: [] for name in jobs}

    def interleaved():
        for _ in range(ROUNDS):
            for name, job in jobs.items():
                cpus[name].append(job()[0])

    benchmark.pedantic(interleaved, rounds=1, iterations=1)
    med = {name: float(np.median(c)) for name, c in cpus.items()}
    e = setup["dop_dH"]
    # log–log interpolation of DOP853's cost at fastvi's error
    x = (np.log(dH) - np.log(e[loose])) / (np.log(e[tight]) - np.log(e[loose]))
    dop = float(np.exp(np.log(med["loose"]) + x * (np.log(med["tight"]) - np.log(med["loose"]))))
    _report[level] = dict(label=label, eps=eps, dH=dH, fastvi=med["fastvi"], dop=dop,
                          loose=loose, tight=tight, dH_loose=e[loose], dH_tight=e[tight])
    benchmark.extra_info.update(_report[level], T=T, starts=STARTS)
    assert 0.0 < x <= 1.0 and dop > 0.0


@pytest.fixture(scope="module", autouse=True)
def report(print_uncaptured):
    yield
    if _report:
        print_uncaptured(_print_report)


def _print_report(write):
    write.sep(f"fastvi vs compiled DOP853 (CyRK), double pendulum, T = {T:g} s, equal max|dH|")
    write(f"(max|dH|: median over {STARTS} starts; CPU: medians of {ROUNDS} interleaved rounds "
          f"from the nominal start; DOP853 (a) interpolated between the bracketing tolerances)")
    for level, r in sorted(_report.items(), reverse=True):
        ratio = r["fastvi"] / r["dop"]
        write(f"~{level:g} J: {r['label']} eps = {r['eps']:g}: max|dH| {r['dH']:.2e} J, "
              f"{1e3 * r['fastvi']:.1f} ms | DOP853 (a) at rtol = atol {r['loose']:.2g} … "
              f"{r['tight']:.2g} (max|dH| {r['dH_loose']:.1e} … {r['dH_tight']:.1e}): "
              f"{1e3 * r['dop']:.1f} ms | fastvi / DOP853 = {ratio:.2f} "
              f"(issue 11 goal <= {wpd.PEER_GOAL:g}: {'met' if ratio <= wpd.PEER_GOAL else 'MISSED'})")
