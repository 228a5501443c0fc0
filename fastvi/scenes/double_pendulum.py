r"""Planar double pendulum in Cartesian coordinates (paper B's first example).

``q = (x1, y1, x2, y2)``; masses ``m1, m2`` on massless rods ``l1`` (origin to 1) and ``l2``
(1 to 2); gravity ``−g ŷ``. ``M = diag(m1, m1, m2, m2)`` is constant, ``V = g (m1 y1 + m2 y2)``
is linear, and the two constraints are

    g1 = ½ (x1² + y1² − l1²),   g2 = ½ ((x2 − x1)² + (y2 − y1)² − l2²).
"""

from __future__ import annotations

import numpy as np

from ..model import Model
from . import damping as damping_
from ..drawing import cartesian
from ._common import attach, check_positive
from .chain import param_derivatives as _chain_param_derivatives
from .chain import param_patterns as _chain_param_patterns

# params = (m1, m2, l1, l2, g): the layout of a 2-link `chain`, whose derivatives by the
# parameters (∇V by m1, m2, g; g by l1, l2; G by none) this scene shares


def potential(q, p):
    """``V = g (m1 y1 + m2 y2)`` (``params = (m1, m2, l1, l2, g)``)."""
    return p[4] * (p[0] * q[1] + p[1] * q[3])


def potential_grad(q, p, out):
    """``∇V = (0, g m1, 0, g m2)``."""
    out[0] = 0.0
    out[1] = p[4] * p[0]
    out[2] = 0.0
    out[3] = p[4] * p[1]


def _g(q, p, out):
    dx = q[2] - q[0]
    dy = q[3] - q[1]
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] - p[2] * p[2])
    out[1] = 0.5 * (dx * dx + dy * dy - p[3] * p[3])


def _G(q, p, out):
    dx = q[2] - q[0]
    dy = q[3] - q[1]
    out[0, 0] = q[0]
    out[0, 1] = q[1]
    out[0, 2] = 0.0
    out[0, 3] = 0.0
    out[1, 0] = -dx
    out[1, 1] = -dy
    out[1, 2] = dx
    out[1, 3] = dy


def _ddg(q, eta, p, out):
    a = eta[0] + eta[1]
    b = eta[1]
    out[:, :] = 0.0
    out[0, 0] = a
    out[1, 1] = a
    out[2, 2] = b
    out[3, 3] = b
    out[0, 2] = -b
    out[2, 0] = -b
    out[1, 3] = -b
    out[3, 1] = -b


def state_from_angles(theta1, theta2, omega1=0.0, omega2=0.0, l1=1.0, l2=1.0):
    """Cartesian ``(q, v)`` from angles measured from the downward vertical."""
    s1, c1, s2, c2 = np.sin(theta1), np.cos(theta1), np.sin(theta2), np.cos(theta2)
    q = np.array([l1 * s1, -l1 * c1, l1 * s1 + l2 * s2, -l1 * c1 - l2 * c2])
    v = np.array([l1 * c1 * omega1, l1 * s1 * omega1,
                  l1 * c1 * omega1 + l2 * c2 * omega2, l1 * s1 * omega1 + l2 * s2 * omega2])
    return q, v


def angles(q):
    """``(theta1, theta2)`` of configurations ``q`` (..., 4)."""
    q = np.asarray(q)
    t1 = np.arctan2(q[..., 0], -q[..., 1])
    t2 = np.arctan2(q[..., 2] - q[..., 0], -(q[..., 3] - q[..., 1]))
    return t1, t2


def inner_flip(t, q, v, params):
    """Event: the inner rod passes over the top (``x1`` changes sign while ``y1 > 0``).

    NaN while the rod points downwards (undefined there: the crossing of the bottom is not
    a flip). Terminal: the run, or an ensemble member, ends at the first flip.
    """
    return q[0] if q[1] > 0.0 else np.nan


def outer_flip(t, q, v, params):
    """Event: the outer rod passes over the top (``x2 − x1`` changes sign while
    ``y2 > y1``); NaN while it points downwards. Terminal."""
    return q[2] - q[0] if q[3] > q[1] else np.nan


inner_flip.terminal = True
outer_flip.terminal = True


def double_pendulum(m1: float = 1.0, m2: float = 1.0, l1: float = 1.0, l2: float = 1.0,
                    g: float = 9.81, damping: float = 0.0) -> Model:
    """Planar double pendulum (n = 4, m = 2) with exact second derivatives.

    Defaults are paper B's parameters. The model has
    ``initial_state(theta1, theta2, omega1=0, omega2=0) -> (q0, v0)`` and
    ``angles(q) -> (theta1, theta2)``, and ``flips = (inner_flip, outer_flip)``: terminal
    events for a rod passing over the top (``integrate(..., events=model.flips)``), and a
    ``drawing`` (pivot, m1, m2). ``damping = c > 0`` adds the force ``−c ṙ_i`` on
    both masses (:mod:`fastvi.scenes.damping`; ``params`` then end with ``c``): with unit
    masses the angle equations simply gain ``−c θ̇``.
    """
    check_positive(m1=m1, m2=m2, l1=l1, l2=l2, g=g)
    c = damping_.check(damping)
    model = Model(
        4, 2, params=(m1, m2, l1, l2, g) + ((c,) if c else ()), mass=np.diag([m1, m1, m2, m2]),
        potential=potential, potential_grad=potential_grad, potential_hessian=0, constraint=_g,
        constraint_jacobian=_G, constraint_hessian=_ddg, param_derivatives=_chain_param_derivatives(c),
        param_patterns=_chain_param_patterns(2, c),
        mass_params=(0, 1), name="double_pendulum" + ("-damped" if c else ""), **damping_.options(c, 4),
    )

    def initial_state(theta1, theta2, omega1=0.0, omega2=0.0):
        return state_from_angles(theta1, theta2, omega1, omega2, l1, l2)

    drawing = cartesian(4, [(0, 1), (1, 2)], before=[(0.0, 0.0)], labels=("pivot", "m1", "m2"))
    return attach(model, "double_pendulum", dict(m1=m1, m2=m2, l1=l1, l2=l2, g=g, damping=c),
                  drawing=drawing, initial_state=initial_state, angles=angles,
                  flips=(inner_flip, outer_flip))
