r"""Planar pendulum in Cartesian coordinates.

``q = (x, y)``, point mass ``m`` on a massless rod of length ``l`` about the origin, gravity
``−g ŷ``: ``M = m I``, ``V = m g y``, one constraint ``g(q) = ½ (x² + y² − l²)``.
"""

from __future__ import annotations

import numpy as np

from ..model import Model
from ..drawing import cartesian
from ._common import attach, check_positive

# params = (m, l, g)


def _V(q, p):
    return p[0] * p[2] * q[1]


def _dV(q, p, out):
    out[0] = 0.0
    out[1] = p[0] * p[2]


def _g(q, p, out):
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] - p[1] * p[1])


def _G(q, p, out):
    out[0, 0] = q[0]
    out[0, 1] = q[1]


def _dV_by_params(q, p, out):
    """``∂(∇V)/∂(m, l, g)``: ``g`` by ``m`` and ``m`` by ``g`` at ``y``."""
    out[:, :] = 0.0
    out[0, 1] = p[2]
    out[2, 1] = p[0]


def _g_by_params(q, p, out):
    """``∂g/∂l = −l``."""
    out[0, 0] = 0.0
    out[1, 0] = -p[1]
    out[2, 0] = 0.0


def _ddg(q, eta, p, out):
    out[:, :] = 0.0
    out[0, 0] = eta[0]
    out[1, 1] = eta[0]


def pendulum(m: float = 1.0, l: float = 1.0, g: float = 9.81) -> Model:
    """Planar pendulum (n = 2, m = 1) with exact second derivatives.

    The model has ``initial_state(theta, omega=0.0) -> (q0, v0)`` with ``theta`` measured
    from the downward vertical, ``angle(q) -> theta``, and a ``drawing`` (pivot, bob).
    """
    check_positive(m=m, l=l, g=g)
    model = Model(
        2, 1, params=(m, l, g), mass=m * np.eye(2), potential=_V, potential_grad=_dV,
        potential_hessian=0, constraint=_g, constraint_jacobian=_G, constraint_hessian=_ddg,
        param_derivatives=dict(potential_grad=_dV_by_params, constraint=_g_by_params,
                               constraint_jacobian=0),
        mass_params=(0,), name="pendulum",
    )

    def initial_state(theta: float, omega: float = 0.0):
        q0 = np.array([l * np.sin(theta), -l * np.cos(theta)])
        v0 = np.array([l * np.cos(theta) * omega, l * np.sin(theta) * omega])
        return q0, v0

    def angle(q):
        q = np.asarray(q)
        return np.arctan2(q[..., 0], -q[..., 1])

    drawing = cartesian(2, [(0, 1)], before=[(0.0, 0.0)], labels=("pivot", "bob"))
    return attach(model, "pendulum", dict(m=m, l=l, g=g), drawing=drawing,
                  initial_state=initial_state, angle=angle)
