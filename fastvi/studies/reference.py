"""Independent reference solutions: SciPy DOP853 at tight tolerance in minimal coordinates.

These never touch fastvi's kernels, so agreement with them is evidence, not tautology.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

REF_TOL = 1e-13


def chain_pendulum_rhs(masses, lengths, g):
    """Right-hand side of a planar N-link pendulum in angles from the downward vertical.

    Point masses ``masses[i]`` at the end of massless rods ``lengths[i]``. With
    ``μ_ij = Σ_{k ≥ max(i,j)} m_k``: ``Σ_j μ_ij l_i l_j cos(θ_i − θ_j) θ̈_j
    = −Σ_j μ_ij l_i l_j sin(θ_i − θ_j) θ̇_j² − μ_ii g l_i sin θ_i``.
    """
    m = np.asarray(masses, dtype=float)
    l = np.asarray(lengths, dtype=float)
    N = len(m)
    tail = np.cumsum(m[::-1])[::-1]
    mu = tail[np.maximum.outer(np.arange(N), np.arange(N))]
    ll = np.outer(l, l)

    def rhs(t, y):
        th, om = y[:N], y[N:]
        d = th[:, None] - th[None, :]
        A = mu * ll * np.cos(d)
        b = -(mu * ll * np.sin(d)) @ (om * om) - tail * g * l * np.sin(th)
        return np.concatenate((om, np.linalg.solve(A, b)))

    return rhs


def chain_pendulum_reference(theta0, omega0, t_eval, masses, lengths, g=9.81, tol=REF_TOL):
    """Angles and angular velocities at ``t_eval`` (DOP853, rtol = atol = ``tol``)."""
    rhs = chain_pendulum_rhs(masses, lengths, g)
    y0 = np.concatenate((np.asarray(theta0, float), np.asarray(omega0, float)))
    t_eval = np.atleast_1d(np.asarray(t_eval, float))
    sol = solve_ivp(rhs, (0.0, float(t_eval[-1])), y0, method="DOP853", rtol=tol, atol=tol,
                    t_eval=t_eval, dense_output=False)
    if not sol.success:  # pragma: no cover
        raise RuntimeError(sol.message)
    N = len(masses)
    return sol.y[:N].T, sol.y[N:].T


def chain_cartesian(theta, omega, lengths):
    """Cartesian positions and velocities (x1, y1, x2, y2, ...) of an N-link pendulum."""
    theta = np.atleast_2d(theta)
    omega = np.atleast_2d(omega)
    l = np.asarray(lengths, float)
    x = np.cumsum(l * np.sin(theta), axis=-1)
    y = np.cumsum(-l * np.cos(theta), axis=-1)
    vx = np.cumsum(l * np.cos(theta) * omega, axis=-1)
    vy = np.cumsum(l * np.sin(theta) * omega, axis=-1)
    q = np.stack((x, y), axis=-1).reshape(theta.shape[0], -1)
    v = np.stack((vx, vy), axis=-1).reshape(theta.shape[0], -1)
    return q, v
