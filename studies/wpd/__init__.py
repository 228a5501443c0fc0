r"""``python -m fastvi wpd``: work–precision diagrams, fastvi against RK4, SciPy and compiled peers.

Single source of ``docs/wpd.md`` and ``docs/figures/wpd-*.png``. On the planar double
pendulum (Cartesian, ``n = 4``, ``m = 2``, paper B's parameters, released at rest from
θ1 = θ2 = π/2) it runs, on the *same* :class:`fastvi.Model` callbacks (:mod:`.runs`),

* fastvi ``P1L-Q2G`` … ``P4L-Q5G`` (defaults: Lobatto control nodes, constraints at every
  node) and paper B's own scheme ``P2L-Q3G-NE-CE``, sweeping the step ``h``;
* classical RK4 on the index-1 form, with and without projection onto the constraints
  (:func:`fastvi.baselines.rk4`), sweeping ``h``;
* SciPy ``solve_ivp`` (RK45, DOP853, Radau) on the same compiled index-1 right-hand side
  (:func:`fastvi.baselines.solve_ivp`), sweeping ``rtol = atol``,

and plots wall time against

(a) the error of ``q`` at ``T = 10`` s against a tight, independent reference (SciPy DOP853
    at ``rtol = atol = 1e-13`` in angle coordinates,
    :func:`fastvi.studies.reference.chain_pendulum_reference`);
(b) the maximum energy error ``max |H − H(0)|`` over ``T = 1000`` s;
(c) the maximum constraint residual ``max |g(q)|`` over the same runs as (b).

It reads off (:mod:`.fronts`), at equal error, each rival's wall time over that of fastvi's
cheapest method and where the curves cross (:mod:`.report`), and tabulates the cost per step
on ``fastvi.scenes.chain(N)`` with the fitted exponent (:mod:`.growth`).

**Compiled peers** (:mod:`.peer_runs`, :mod:`.peer_report`; needs CyRK, the ``bench``
extra): CyRK's C++ DOP853 on hand-written ``@njit`` right-hand sides (:mod:`studies.peers`) of
the same pendulum, (a) Cartesian index-1 and (b) angle coordinates, against fastvi with
default settings through :func:`fastvi.integrate`: CPU time against ``max |H − H(0)|`` at
``T = 1000`` s and ``T = 10^4`` s, the ratio "fastvi best / DOP853" at
``max|ΔH| = 1e-2, 1e-4, 1e-6, 1e-8`` J, the growth of the energy error and of the constraint
drift with ``T``; and the **stiff panel** (:mod:`.stiff`): the rod–slider with spring
stiffness ``k = 10^3 … 10^8`` over ``T = 10`` s, fastvi against CyRK DOP853, LSODA and
Radau, the CPU time of each to reach a fixed energy error, and the crossover stiffness.
Without CyRK these sections say how to install it; ``--no-peers`` skips them.

Every setting is in :mod:`.config`. Timing: everything is compiled (or loaded from numba's
cache) before timing; each point is the median of several runs (long runs are timed once).
All ratios come from one process, one run of this command. The page names the fastvi
version, the machine and the packages of the run (:mod:`studies.machine`).

Usage::

    python -m fastvi wpd                 # full study (≈ 10–20 min on 2 cores), writes ./fastvi-study-wpd/
    python -m fastvi wpd --quick         # T = 1 s and 10 s, few points (tests, a first look)
    python -m fastvi wpd --out DIR       # write DIR/wpd.md and DIR/figures/wpd-*.png
    python -m fastvi wpd --no-peers      # without the compiled-peer (CyRK) panels
"""

from .cli import main, run_peers, run_study

__all__ = ["main", "run_study", "run_peers"]
