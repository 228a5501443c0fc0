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

# params = (m1, m2, m3, l1, l2, l3, g)
_NB = 3  # bodies


def _V(q, p):
    return p[6] * (p[0] * q[1] + p[1] * q[3] + p[2] * q[5])


def _dV(q, p, out):
    for i in range(_NB):
        out[2 * i] = 0.0
        out[2 * i + 1] = p[6] * p[i]


def _ddV(q, p, out):
    out[:, :] = 0.0


def _g(q, p, out):
    px = 0.0
    py = 0.0
    for i in range(_NB):
        dx = q[2 * i] - px
        dy = q[2 * i + 1] - py
        out[i] = 0.5 * (dx * dx + dy * dy - p[3 + i] * p[3 + i])
        px = q[2 * i]
        py = q[2 * i + 1]


def _G(q, p, out):
    out[:, :] = 0.0
    px = 0.0
    py = 0.0
    for i in range(_NB):
        dx = q[2 * i] - px
        dy = q[2 * i + 1] - py
        out[i, 2 * i] = dx
        out[i, 2 * i + 1] = dy
        if i > 0:
            out[i, 2 * i - 2] = -dx
            out[i, 2 * i - 1] = -dy
        px = q[2 * i]
        py = q[2 * i + 1]


def _ddg(q, eta, p, out):
    out[:, :] = 0.0
    for i in range(_NB):
        d = eta[i] + (eta[i + 1] if i + 1 < _NB else 0.0)
        out[2 * i, 2 * i] = d
        out[2 * i + 1, 2 * i + 1] = d
        if i + 1 < _NB:
            e = -eta[i + 1]
            out[2 * i, 2 * i + 2] = e
            out[2 * i + 2, 2 * i] = e
            out[2 * i + 1, 2 * i + 3] = e
            out[2 * i + 3, 2 * i + 1] = e


def state_from_angles(theta1, theta2, theta3, omega1=0.0, omega2=0.0, omega3=0.0,
                      l1=1.0, l2=1.0, l3=1.0):
    """Cartesian ``(q, v)`` from angles measured from the downward vertical.

    ``r_i = r_{i−1} + l_i (sin θ_i, −cos θ_i)`` and ``ṙ_i = ṙ_{i−1} + l_i ω_i (cos θ_i, sin θ_i)``.
    """
    q = np.zeros(6)
    v = np.zeros(6)
    x = y = vx = vy = 0.0
    for i, (th, om, li) in enumerate(((theta1, omega1, l1), (theta2, omega2, l2),
                                      (theta3, omega3, l3))):
        s, c = np.sin(th), np.cos(th)
        x, y = x + li * s, y - li * c
        vx, vy = vx + li * c * om, vy + li * s * om
        q[2 * i], q[2 * i + 1] = x, y
        v[2 * i], v[2 * i + 1] = vx, vy
    return q, v


def angles(q):
    """``(theta1, theta2, theta3)`` of configurations ``q`` (..., 6)."""
    q = np.asarray(q)
    t1 = np.arctan2(q[..., 0], -q[..., 1])
    t2 = np.arctan2(q[..., 2] - q[..., 0], -(q[..., 3] - q[..., 1]))
    t3 = np.arctan2(q[..., 4] - q[..., 2], -(q[..., 5] - q[..., 3]))
    return t1, t2, t3


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
    -> (q0, v0)`` (angles from the downward vertical) and ``angles(q) -> (θ1, θ2, θ3)``.
    ``params = (m1, m2, m3, l1, l2, l3, g)``.
    """
    m = _triple("m", m)
    l = _triple("l", l)
    check_positive(g=g)
    model = Model(
        6, 3, params=(*m, *l, g), mass=np.diag([m[0], m[0], m[1], m[1], m[2], m[2]]),
        potential=_V, potential_grad=_dV, potential_hessian=_ddV, constraint=_g,
        constraint_jacobian=_G, constraint_hessian=_ddg, name="triple_pendulum",
    )

    def initial_state(theta1, theta2, theta3, omega1=0.0, omega2=0.0, omega3=0.0):
        return state_from_angles(theta1, theta2, theta3, omega1, omega2, omega3, *l)

    return attach(model, "triple_pendulum", dict(m=m, l=l, g=g),
                  initial_state=initial_state, angles=angles)
