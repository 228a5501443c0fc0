r"""Planar triple pendulum in Cartesian coordinates (paper A's third example).

``q = (x1, y1, x2, y2, x3, y3)``; point masses ``m1, m2, m3`` on massless rods ``l1``
(origin to 1), ``l2`` (1 to 2) and ``l3`` (2 to 3); gravity ``−g ŷ``. The mass matrix
``M = diag(m1, m1, m2, m2, m3, m3)`` is constant, the potential ``V = g (m1 y1 + m2 y2 + m3 y3)``
is linear, and the three constraints are, with ``r_0 = 0`` and ``r_i = (x_i, y_i)``,

    g_i = ½ (|r_i − r_{i−1}|² − l_i²),   i = 1, 2, 3.

Their Jacobian rows are ``∂g_i/∂r_i = r_i − r_{i−1} = −∂g_i/∂r_{i−1}``, and the contracted
Hessian ``Σ_i η_i ∇²g_i`` is block tridiagonal with 2×2 identity blocks:
diagonal ``η_i + η_{i+1}`` (``η_4 = 0``) and off-diagonal ``−η_{i+1}`` between bodies ``i``
and ``i + 1``.
"""

from __future__ import annotations

import numpy as np

from ..model import Model
from ._common import attach, check_positive
from .chain import (constraint as _g, constraint_hessian as _ddg,
                    constraint_jacobian as _G, potential as _V, potential_grad as _dV)
from .chain import pattern as _chain_pattern
from .chain import param_derivatives as _chain_param_derivatives
from .chain import param_patterns as _chain_param_patterns
from .chain import angles as _chain_angles
from .chain import drawing as _chain_drawing
from .chain import state_from_angles as _chain_state

# params = (m1, m2, m3, l1, l2, l3, g): the layout of a 3-link `chain`, whose callbacks
# (written for any number of links) this scene reuses.
def state_from_angles(theta1, theta2, theta3, omega1=0.0, omega2=0.0, omega3=0.0,
                      l1=1.0, l2=1.0, l3=1.0):
    """Cartesian ``(q, v)`` from angles measured from the downward vertical.

    ``r_i = r_{i−1} + l_i (sin θ_i, −cos θ_i)`` and ``ṙ_i = ṙ_{i−1} + l_i ω_i (cos θ_i, sin θ_i)``.
    """
    return _chain_state((theta1, theta2, theta3), (omega1, omega2, omega3), (l1, l2, l3))


def angles(q):
    """``(theta1, theta2, theta3)`` of configurations ``q`` (..., 6)."""
    th = _chain_angles(q)
    return th[..., 0], th[..., 1], th[..., 2]


def _triple(name: str, value) -> tuple[float, float, float]:
    try:
        vals = tuple(value)
    except TypeError:
        raise TypeError(f"`{name}` must be a sequence of three numbers, got {value!r}") from None
    if len(vals) != 3:
        raise ValueError(f"`{name}` must have three entries (one per body), got {len(vals)}")
    for i, x in enumerate(vals):
        check_positive(**{f"{name}[{i}]": x})
    return tuple(float(x) for x in vals)


def triple_pendulum(m=(1.0, 1.0, 1.0), l=(1.0, 1.0, 1.0), g: float = 9.81) -> Model:
    """Planar triple pendulum (n = 6, m = 3) with exact second derivatives.

    Parameters
    ----------
    m : sequence of 3 floats
        Point masses of the three bodies.
    l : sequence of 3 floats
        Rod lengths, origin to body 1, body 1 to 2, body 2 to 3.
    g : float
        Gravitational acceleration (along ``−y``).

    The model has ``initial_state(theta1, theta2, theta3, omega1=0, omega2=0, omega3=0)
    -> (q0, v0)`` (angles from the downward vertical), ``angles(q) -> (θ1, θ2, θ3)`` and a
    ``drawing`` (the pivot, then the three bodies).
    ``params = (m1, m2, m3, l1, l2, l3, g)``.
    """
    m = _triple("m", m)
    l = _triple("l", l)
    check_positive(g=g)
    model = Model(
        6, 3, params=(*m, *l, g), mass=np.diag([m[0], m[0], m[1], m[1], m[2], m[2]]),
        potential=_V, potential_grad=_dV, potential_hessian=0, constraint=_g,
        constraint_jacobian=_G, constraint_hessian=_ddg, constraint_jacobian_pattern=_chain_pattern(3),
        param_derivatives=_chain_param_derivatives(), param_patterns=_chain_param_patterns(3),
        mass_params=(0, 1, 2), name="triple_pendulum",
    )

    def initial_state(theta1, theta2, theta3, omega1=0.0, omega2=0.0, omega3=0.0):
        return state_from_angles(theta1, theta2, theta3, omega1, omega2, omega3, *l)

    return attach(model, "triple_pendulum", dict(m=m, l=l, g=g), drawing=_chain_drawing(3),
                  initial_state=initial_state, angles=angles)
