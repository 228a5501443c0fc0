"""Every setting of the speed study: what runs, over which span, how often.

Panels (a)–(c) (:data:`FULL`, :data:`QUICK`): fastvi, RK4 and SciPy on the double pendulum.
The compiled-peer panels (:data:`PEERS_FULL`, :data:`PEERS_QUICK`): fastvi with default
settings against CyRK's DOP853 on the pendulum, and the stiff rod–slider against CyRK's
DOP853, LSODA and Radau.
"""

from __future__ import annotations

import numpy as np

#: fastvi's defaults P1…P4 and paper B's own scheme
FASTVI_METHODS = ("P1L-Q2G", "P2L-Q3G", "P3L-Q4G", "P4L-Q5G", "P2L-Q3G-NE-CE")
THETA0 = (np.pi / 2, np.pi / 2)  # paper B's start, at rest
T_ERROR = 10.0  # panel (a)
T_LONG = 1000.0  # panels (b), (c)
#: SciPy's energies and residuals over T = 1000 s are read from its dense output every
#: SAMPLE_DT seconds (denser output costs SciPy extra evaluations, and sparser sampling can
#: only lower its maxima); fastvi and RK4 keep every step, so their maxima are over more
#: samples (never in their favour). Panel (a) asks SciPy for q(T) only.
SAMPLE_DT = 1.0
REPEATS = 3
LONG_RUN = 6.0  # s: a run longer than this is timed once (budget of the whole study)

# Sweeps: step sizes (fixed-step) or rtol = atol (adaptive), chosen to span ~1e-1 … 1e-10 in
# error at a total cost of a few minutes. T must be a whole number of steps.
FULL = dict(
    T_error=T_ERROR,
    T_long=T_LONG,
    repeats=REPEATS,
    error={
        "P1L-Q2G": (0.02, 0.01, 0.005, 0.0025, 0.00125),
        "P2L-Q3G": (0.08, 0.04, 0.02, 0.01, 0.005, 0.0025),
        "P3L-Q4G": (0.1, 0.05, 0.025, 0.0125, 0.00625),
        "P4L-Q5G": (0.1, 0.05, 0.025, 0.0125),
        "P2L-Q3G-NE-CE": (0.02, 0.01, 0.005, 0.0025, 0.00125),
        "RK4": (0.01, 0.005, 0.0025, 0.00125, 0.000625),
        "RK4+proj": (0.01, 0.005, 0.0025, 0.00125, 0.000625),
        "SciPy RK45": (1e-4, 1e-6, 1e-8, 1e-10, 1e-12),
        "SciPy DOP853": (1e-4, 1e-6, 1e-8, 1e-10, 1e-12),
        "SciPy Radau": (1e-4, 1e-6, 1e-8),
    },
    long={
        "P1L-Q2G": (0.02, 0.01),
        "P2L-Q3G": (0.04, 0.02, 0.01, 0.005),
        "P3L-Q4G": (0.1, 0.05, 0.025, 0.0125, 0.00625),
        "P4L-Q5G": (0.1, 0.05, 0.025, 0.0125),
        "P2L-Q3G-NE-CE": (0.02, 0.01),
        "RK4": (0.005, 0.0025, 0.00125),
        "RK4+proj": (0.01, 0.005, 0.0025, 0.00125),
        "SciPy RK45": (1e-8, 1e-9),
        "SciPy DOP853": (1e-9, 1e-11, 1e-13),
        "SciPy Radau": (1e-5, 1e-7),
    },
    #: SciPy contenders run over a shorter horizon in panels (b), (c) (cost); label says so
    long_horizon={"SciPy Radau": 100.0},
    #: chain(N) sizes of the cost-growth table
    growth=(2, 4, 8, 16, 32, 64, 128, 256),
)
QUICK = dict(
    T_error=1.0,
    T_long=10.0,
    repeats=1,
    error={
        "P1L-Q2G": (0.02, 0.01),
        "P2L-Q3G": (0.05, 0.02),
        "P3L-Q4G": (0.05, 0.025),
        "P4L-Q5G": (0.05, 0.025),
        "P2L-Q3G-NE-CE": (0.02, 0.01),
        "RK4": (0.01, 0.005),
        "RK4+proj": (0.01, 0.005),
        "SciPy RK45": (1e-5, 1e-8),
        "SciPy DOP853": (1e-5, 1e-8),
        "SciPy Radau": (1e-4,),
    },
    long={
        "P2L-Q3G": (0.04, 0.02),
        "P3L-Q4G": (0.05, 0.025),
        "P4L-Q5G": (0.05, 0.025),
        "RK4": (0.005,),
        "RK4+proj": (0.01, 0.005),
        "SciPy DOP853": (1e-6, 1e-9),
    },
    long_horizon={},
    growth=(2, 4),
)


# ----------------------------------------------------------------------------- compiled peers
# fastvi against a compiled DOP853 (CyRK's C++ solver on hand-written @njit right-hand sides,
# :mod:`studies.peers`), and a stiff panel on the rod–slider.
#: a peer-panel run longer than this (CPU s) is timed once: long enough to average out the
#: timer (the T = 10^4 s fastvi runs), and the study stays within minutes
PEER_LONG_RUN = 2.0
#: … and in the stiff panel (its slowest settings are the finest steps at k = 10^8)
STIFF_LONG_RUN = 0.5
#: energy levels (J) at which the fastvi / DOP853 ratio is read off
PEER_LEVELS = (1e-2, 1e-4, 1e-6, 1e-8)
#: the double pendulum from π/2 is chaotic: starts 1e-12 rad apart follow different paths
#: after a few tens of seconds, and max|ΔH| over T = 1000 s, an extreme of the path, then
#: differs by up to 4× for the same method and h (docs/benchmarks.md, "Against a compiled DOP853").
#: Each setting's max|ΔH| is the median over the nominal start and ``starts − 1`` starts of
#: the panel's configuration perturbed by PEER_START_SPREAD (rad, the same for every
#: contender: peer_starts); the CPU time is the nominal start's (it does not depend on the
#: path beyond noise).
PEER_START_SPREAD = 1e-12
PEER_START_SEED = 2026
#: fastvi's energies are sampled every PEER_SAMPLE_DT seconds (save_every = PEER_SAMPLE_DT/h):
#: saving every step would cost fastvi more than the peer pays for storing its steps
PEER_SAMPLE_DT = 0.1
#: … and in the stiff panel every STIFF_SAMPLE_DT seconds (≥ 10⁴ samples over T = 10 s: the
#: energy error of a step beyond the fast period oscillates from step to step)
STIFF_SAMPLE_DT = 1e-3
#: tolerance of the stiff panel's reference end state (CyRK DOP853, untimed)
STIFF_REF_TOL = 1e-11
#: the stiff panel's target: max|ΔH| ≤ STIFF_TARGET_REL × the spring energy at the start
STIFF_TARGET_REL = 1e-4
#: the stiff panel's fastvi steps: h = T/⌈T ω / c⌉ for each c (ωh ≈ c), at most the stiff
#: configuration's ``h_max`` (this, unless a configuration says otherwise)
STIFF_H_MAX = 0.01
#: the pendulum panels' adaptive contenders (label "<method> adaptive", knob ε):
#: ``integrate(..., adaptive=PEER_ADAPTIVE_KR)``, the energy scale of the step density
#: (docs/benchmarks.md: 3 J fits this pendulum, whose kinetic energy reaches ≈ 30 J)
PEER_ADAPTIVE_KR = 3.0
#: the length (s) of the untimed pilot run that gives an adaptive contender's mean step
PEER_PILOT_T = 100.0
NO_SAMPLES = 1 << 40  # save_every of a run whose samples are not read: the first and last
ADAPTIVE = " adaptive"

PEERS_FULL = dict(
    #: the host's load slows single runs by up to 40 %: a median of 5 interleaved runs
    #: keeps one slow stretch from moving a contender's point (3 did not)
    repeats=5,
    starts=8,
    T=(1000.0, 10000.0),
    fastvi={
        # (h = 0.1 is beyond P4L-Q5G's stability limit here: its energy error explodes).
        # P4L-Q4G (r = s: one quadrature point fewer, the same order 8; docs/orders.md) costs
        # 0.89–0.96 of a P4L-Q5G step here, with 0.35–1.04× its energy error; P2L-Q2G and
        # P3L-Q3G cost 0.93–0.96 of their defaults' step but leave 1.4–2.1× their energy
        # error at h = 0.02, 0.025, so they are left out (docs/benchmarks.md)
        # The adaptive contenders (time-reversible, not symplectic) run ε where their
        # energy errors meet the fixed steps' levels. P5L-Q5G (order 10, r = s) adaptive
        # reaches 1e-6 J at 0.94–1.0 of P4L-Q4G adaptive's cost and 1e-8 J at the same
        # cost; at 1e-4 J it costs ≈ 1.15× P3L-Q4G adaptive (docs/benchmarks.md)
        1000.0: {"P1L-Q2G": (0.01,), "P2L-Q3G": (0.04, 0.02, 0.01),
                 "P3L-Q4G": (0.05, 0.025, 0.0125), "P4L-Q5G": (0.05, 0.025, 0.0125),
                 "P4L-Q4G": (0.05, 0.025, 0.0125),
                 "P2L-Q3G" + ADAPTIVE: (0.08, 0.0625, 0.05, 0.04),
                 "P3L-Q4G" + ADAPTIVE: (0.1, 0.08, 0.0625, 0.05, 0.04),
                 "P4L-Q4G" + ADAPTIVE: (0.0625, 0.05, 0.04, 0.03),
                 "P5L-Q5G" + ADAPTIVE: (0.1, 0.08, 0.0625, 0.05)},
        # fewer points at T = 10^4 s (cost; the finest, 8·10^5 steps, is timed once)
        10000.0: {"P3L-Q4G": (0.05, 0.025), "P4L-Q5G": (0.05, 0.025, 0.0125),
                  "P4L-Q4G": (0.05, 0.025, 0.0125),
                  "P3L-Q4G" + ADAPTIVE: (0.08, 0.0625, 0.05),
                  "P4L-Q4G" + ADAPTIVE: (0.0625, 0.05, 0.04),
                  "P5L-Q5G" + ADAPTIVE: (0.08, 0.0625)},
    },
    dop={1000.0: (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14),
         10000.0: (1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14)},
    #: energy-error growth with T at one setting per contender
    growth=dict(T=(100.0, 1000.0, 10000.0), fastvi=("P3L-Q4G", 0.025), tol=1e-10,
                adaptive=("P3L-Q4G" + ADAPTIVE, 0.0625)),
    # r = s methods (P2L-Q2G, P3L-Q3G) are stable at any ωh; the defaults (r = s + 1) are not
    stiff=dict(T=10.0, ks=(1e3, 1e4, 1e5, 1e6, 1e7, 1e8),
               methods=("P2L-Q2G", "P3L-Q3G", "P2L-Q3G", "P3L-Q4G"),
               c=(64.0, 16.0, 4.0, 1.0, 0.5),
               peers={"DOP853": (1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10),
                      "LSODA": (1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10),
                      "Radau": (1e-5, 1e-6, 1e-7, 1e-8, 1e-9)}),
)
PEERS_QUICK = dict(
    repeats=1,
    starts=2,
    T=(100.0,),
    fastvi={100.0: {"P3L-Q4G": (0.05, 0.025), "P4L-Q5G": (0.05,),
                    "P3L-Q4G" + ADAPTIVE: (0.0625,)}},
    dop={100.0: (1e-8, 1e-10, 1e-12)},
    growth=dict(T=(10.0, 100.0), fastvi=("P3L-Q4G", 0.025), tol=1e-10),
    stiff=dict(T=1.0, ks=(1e3, 1e6), methods=("P2L-Q2G", "P3L-Q4G"), c=(4.0, 0.5),
               peers={"DOP853": (1e-6, 1e-9), "LSODA": (1e-6, 1e-9), "Radau": (1e-6,)}),
)
#: the methods "fastvi's best" is chosen from in panels (a)–(c): the defaults (paper B's -NE-CE
#: variant is on the diagrams, but on the double pendulum it is the same map as P1L-Q2G, RATTLE)
BEST_OF = FASTVI_METHODS[:4]

#: contender labels of the peer panels
DOP_A, DOP_B = "DOP853 (a) Cartesian", "DOP853 (b) angles"

