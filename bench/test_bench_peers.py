"""fastvi with default settings against the compiled peer, under pytest-benchmark.

``fastvi.integrate`` as a user calls it — the default method ``P2L-Q3G``, the default
kernels (with the stages compiled for the model's sizes in the cache, which the default
uses; ``specialize=False``, a first session's generic kernels, is timed beside it), a fixed
step ``h`` chosen for each level of energy error — against CyRK's C++
DOP853 on the hand-written Cartesian index-1 right-hand side of the same double pendulum
(:mod:`studies.peers`, variant (a)), over T = 1000 s and T = 10⁴ s from
θ1 = θ2 = π/2 at rest, at two levels of max|ΔH| (≈ 1e-2 and ≈ 1e-4 J). Over the longer
span a variational step's energy error stays bounded while DOP853's drifts, so DOP853 needs
a tighter tolerance for the same max|ΔH|.

**Equal error.** On this chaotic motion one start's max|ΔH| is a 1.3–4× lottery, so each
setting's error is the median over :data:`STARTS` starts 1e-12 rad apart
(:func:`studies.wpd.peer_runs.peer_starts`). DOP853's tolerance runs over a quarter-decade
grid; its cost at fastvi's error is interpolated log–log between the two grid tolerances
that bracket that error, both timed.

**Timing**: process CPU of the ``fastvi.integrate`` call (energies saved every 0.1 s) and of
CyRK's solver call (``peers.run_peer``: energies evaluated afterwards, untimed), contenders
interleaved round by round from the nominal start, medians. pytest-benchmark records the
whole interleaved measurement of a level as one round. The ratios are printed at the end
(``make bench``); the full sweep over methods, levels and T is ``python -m fastvi wpd``
(``docs/wpd.md``).

Skipped when CyRK (the ``bench`` extra: ``pip install -e .[bench]``) is missing.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("CyRK")

import fastvi  # noqa: E402
from studies import peers  # noqa: E402
from studies.wpd import peer_runs  # noqa: E402

#: (T, level, method, h): the default method at a fixed step giving ≈ the level's max|ΔH|
#: (its error ∝ h⁴: docs/wpd.md's P2L-Q3G rows scaled)
LEVELS = ((1000.0, 1e-2, "P2L-Q3G", 0.025), (1000.0, 1e-4, "P2L-Q3G", 0.011),
          (1e4, 1e-2, "P2L-Q3G", 0.025), (1e4, 1e-4, "P2L-Q3G", 0.011))
TOLS = tuple(10.0 ** (-k / 4) for k in range(24, 57))  # DOP853 rtol = atol, 1e-6 … 1e-14
STARTS = 4
ROUNDS = 5

_report: dict[tuple, dict] = {}
_dop_dH: dict[float, dict] = {}


@pytest.fixture(scope="module")
def setup():
    model = fastvi.scenes.double_pendulum()
    starts = peer_runs.peer_starts(STARTS)
    peers.warm_up_peers(methods=("DOP853",))
    ys = [peers.cartesian_start(th) for th in starts]
    return dict(model=model, starts=starts, ys=ys)


def _dop_errors(ys, T):
    """The median error over the starts of every grid tolerance at span ``T``, once (untimed)."""
    if T not in _dop_dH:
        _dop_dH[T] = {tol: float(np.median([_dop(y, tol, T)[1]["dH"] for y in ys])) for tol in TOLS}
    return _dop_dH[T]


def _dop(y0, tol, T):
    r = peers.run_peer("cartesian", y0, peers.DP_PARAMS, T=T, tol=tol)
    return r["cpu"], dict(dH=r["dH"] if r["ok"] else np.inf, steps=r["steps"])


def _fastvi(model, theta, method, h, T, **options):
    q0, v0 = model.initial_state(*theta)
    return peer_runs.fastvi_peer_run(model, q0, v0, method, h, T, **options)


def _bracket(dop_dH: dict, target: float):
    """The grid tolerances (looser, tighter) whose median errors bracket ``target``."""
    tols = sorted(dop_dH, reverse=True)  # loosest first: errors fall along the list
    for loose, tight in zip(tols, tols[1:]):
        if dop_dH[tight] <= target < dop_dH[loose]:
            return loose, tight
    raise AssertionError(f"no DOP853 tolerance in {tols[0]:g} … {tols[-1]:g} brackets "
                         f"max|ΔH| = {target:.2e} J: widen TOLS")


@pytest.mark.parametrize("T,level,method,h", LEVELS,
                         ids=[f"T{T:g}-{lv:g}J" for T, lv, _, _ in LEVELS])
def test_fastvi_vs_dop853(benchmark, setup, T, level, method, h):
    model, starts = setup["model"], setup["starts"]
    # compiles (or loads) the kernels, the stages sized for the model included, which the
    # default (specialize=None) then takes, as after one long run or `python -m fastvi compile`
    _fastvi(model, starts[0], method, h, 1.0, specialize=True)
    _fastvi(model, starts[0], method, h, 1.0, specialize=False)
    infos = [_fastvi(model, th, method, h, T)[1] for th in starts]
    assert all(i["ok"] for i in infos) and max(i["g"] for i in infos) < 1e-13
    dH = float(np.median([i["dH"] for i in infos]))
    e = _dop_errors(setup["ys"], T)
    loose, tight = _bracket(e, dH)
    y0 = setup["ys"][0]
    jobs = {"fastvi": lambda: _fastvi(model, starts[0], method, h, T),
            "generic": lambda: _fastvi(model, starts[0], method, h, T, specialize=False),
            "loose": lambda: _dop(y0, loose, T), "tight": lambda: _dop(y0, tight, T)}
    cpus = {name: [] for name in jobs}

    def interleaved():
        for _ in range(ROUNDS):
            for name, job in jobs.items():
                cpus[name].append(job()[0])

    benchmark.pedantic(interleaved, rounds=1, iterations=1)
    med = {name: float(np.median(c)) for name, c in cpus.items()}
    # log–log interpolation of DOP853's cost at fastvi's error
    x = (np.log(dH) - np.log(e[loose])) / (np.log(e[tight]) - np.log(e[loose]))
    dop = float(np.exp(np.log(med["loose"]) + x * (np.log(med["tight"]) - np.log(med["loose"]))))
    _report[(T, level)] = dict(method=method, h=h, dH=dH, fastvi=med["fastvi"], dop=dop,
                               generic=med["generic"],
                               loose=loose, tight=tight, dH_loose=e[loose], dH_tight=e[tight])
    benchmark.extra_info.update(_report[(T, level)], T=T, starts=STARTS)
    assert 0.0 < x <= 1.0 and dop > 0.0


@pytest.fixture(scope="module", autouse=True)
def report(print_uncaptured):
    yield
    if _report:
        print_uncaptured(_print_report)


def _print_report(write):
    write.sep("fastvi (default settings) vs compiled DOP853 (CyRK), double pendulum, equal max|dH|")
    write(f"(max|dH|: median over {STARTS} starts; CPU: medians of {ROUNDS} interleaved rounds "
          f"from the nominal start; DOP853 (a) interpolated between the bracketing tolerances)")
    for (T, level), r in sorted(_report.items()):
        write(f"T = {T:g} s, ~{level:g} J: {r['method']} h = {r['h']:g}: max|dH| {r['dH']:.2e} J, "
              f"{1e3 * r['fastvi']:.1f} ms | DOP853 (a) at rtol = atol {r['loose']:.2g} … "
              f"{r['tight']:.2g} (max|dH| {r['dH_loose']:.1e} … {r['dH_tight']:.1e}): "
              f"{1e3 * r['dop']:.1f} ms | fastvi / DOP853 = {r['fastvi'] / r['dop']:.2f} "
              f"(specialize=False: {r['generic'] / r['dop']:.2f})")
