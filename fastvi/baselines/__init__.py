"""Baselines on the same :class:`~fastvi.Model` callbacks: what the variational integrator is
compared with.

:func:`rk4`
    Classical RK4 (numba) on the index-1 formulation, with or without projection onto the
    constraints after each step (paper B's "traditional Runge–Kutta method").
:func:`solve_ivp`
    SciPy's ``solve_ivp`` on the same index-1 right-hand side.

Both return a :class:`BaselineResult` with the fields of :class:`fastvi.Result` that make
sense for them (``t, q, v, energy, constraint_residual, velocity_residual, stats``).
"""

from .rk4 import BaselineResult, rk4
from .scipy_ivp import solve_ivp

__all__ = ["rk4", "solve_ivp", "BaselineResult"]
