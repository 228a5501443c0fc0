r"""Spherical pendulum in Cartesian coordinates (a point mass on a rigid rod in 3-D).

``q = (x, y, z)``, point mass ``m`` on a massless rod of length ``l`` about a fixed point at
the origin, gravity ``−g ẑ``: ``M = m I``, ``V = m g z``, one constraint

    g(q) = ½ (x² + y² + z² − l²).

The Lagrangian and the constraint are invariant under rotations about the z axis, so the
angular momentum ``L_z = x p_y − y p_x`` is conserved by the exact flow and, by the discrete
Noether theorem, by every variational integrator whose discrete Lagrangian inherits the
symmetry (fastvi's Galerkin integrators do: the interpolation and the quadrature commute
with rotations, and the momentum projection adds a multiple of ``∇g ∥ q``, which has no
torque about the origin).

The model has exact derivatives of its callbacks by its parameters (``∇V`` by ``m`` and
``g``, ``g(q)`` by ``l``; the constant ``M`` is data), so :func:`fastvi.sensitivity` and
:func:`fastvi.adjoint` need no differences in ``params``.
"""

from __future__ import annotations

import numpy as np

from ..model import Model
from ..drawing import cartesian
from ._common import attach, check_positive

# params = (m, l, g)


def _V(q, p):
    return p[0] * p[2] * q[2]


def _dV(q, p, out):
    out[0] = 0.0
    out[1] = 0.0
    out[2] = p[0] * p[2]


def _g(q, p, out):
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] - p[1] * p[1])


def _G(q, p, out):
    out[0, 0] = q[0]
    out[0, 1] = q[1]
    out[0, 2] = q[2]


def _ddg(q, eta, p, out):
    out[:, :] = 0.0
    out[0, 0] = eta[0]
    out[1, 1] = eta[0]
    out[2, 2] = eta[0]


# derivatives by params = (m, l, g) (``Model``'s ``param_derivatives``): ``out[i]`` is the
# callback's derivative by ``params[i]``; the constant M = m I is data, G does not depend on θ


def _dV_by_params(q, p, out):
    """``∂(∇V)/∂θ``: ``∂V/∂z = m g`` by ``m`` (``g``) and ``g`` (``m``), zero by ``l``."""
    out[:, :] = 0.0
    out[0, 2] = p[2]
    out[2, 2] = p[0]


def _g_by_params(q, p, out):
    """``∂g/∂θ``: ``∂g/∂l = −l``, zero by ``m`` and ``g``."""
    out[:, :] = 0.0
    out[1, 0] = -p[1]


#: ``Model``'s ``param_derivatives``: every callback θ enters (``G`` declared 0)
param_derivatives = dict(potential_grad=_dV_by_params, constraint=_g_by_params,
                         constraint_jacobian=0)


def state_from_angles(theta, phi, theta_dot=0.0, phi_dot=0.0, l=1.0):
    r"""Cartesian ``(q, v)`` from spherical angles.

    Parameters
    ----------
    theta : float
        Polar angle from the downward vertical (``theta = 0``: hanging straight down).
    phi : float
        Azimuth about the z axis, from the x axis.
    theta_dot, phi_dot : float, default 0
        Their rates.
    l : float, default 1
        Rod length.

    Returns
    -------
    q, v : ndarray (3,)
        ``q = l (sin θ cos φ, sin θ sin φ, −cos θ)`` and ``v = ∂q/∂θ θ̇ + ∂q/∂φ φ̇``.
    """
    st, ct, sp, cp = np.sin(theta), np.cos(theta), np.sin(phi), np.cos(phi)
    q = l * np.array([st * cp, st * sp, -ct])
    v = l * (np.array([ct * cp, ct * sp, st]) * theta_dot + np.array([-st * sp, st * cp, 0.0]) * phi_dot)
    return q, v


def angles(q):
    """``(theta, phi)`` of configurations ``q`` (..., 3): polar angle from the downward vertical
    and azimuth from the x axis."""
    q = np.asarray(q)
    theta = np.arctan2(np.hypot(q[..., 0], q[..., 1]), -q[..., 2])
    phi = np.arctan2(q[..., 1], q[..., 0])
    return theta, phi


def angular_momentum(q, p):
    """Angular momentum ``L = q × p`` about the pivot, shape (..., 3); ``L[..., 2]`` is conserved."""
    return np.cross(np.asarray(q), np.asarray(p))


def spherical_pendulum(m: float = 1.0, l: float = 1.0, g: float = 9.81) -> Model:
    """Spherical pendulum (n = 3, m = 1) with exact second derivatives.

    Parameters
    ----------
    m : float, default 1
        Mass of the bob.
    l : float, default 1
        Rod length.
    g : float, default 9.81
        Gravitational acceleration (along −z).

    Returns
    -------
    Model
        With ``initial_state(theta, phi, theta_dot=0, phi_dot=0) -> (q0, v0)`` (``theta``
        the polar angle from the downward vertical), ``angles(q) -> (theta, phi)``,
        ``angular_momentum(q, p) -> q × p`` and a 3-D ``drawing`` (pivot, bob); its
        callbacks have exact derivatives by ``params`` (:data:`param_derivatives`).

    Examples
    --------
    >>> import fastvi
    >>> model = fastvi.scenes.spherical_pendulum()
    >>> q0, v0 = model.initial_state(1.0, 0.0, 0.0, 2.0)
    >>> res = fastvi.integrate(model, q0, v0, h=0.01, n_steps=100)
    >>> Lz = model.angular_momentum(res.q, res.p)[:, 2]
    >>> bool(abs(Lz[-1] - Lz[0]) < 1e-12)
    True
    """
    check_positive(m=m, l=l, g=g)
    model = Model(
        3, 1, params=(m, l, g), mass=m * np.eye(3), potential=_V, potential_grad=_dV,
        potential_hessian=0, constraint=_g, constraint_jacobian=_G, constraint_hessian=_ddg,
        param_derivatives=param_derivatives, mass_params=(0,), name="spherical_pendulum",
    )

    def initial_state(theta: float, phi: float, theta_dot: float = 0.0, phi_dot: float = 0.0):
        return state_from_angles(theta, phi, theta_dot, phi_dot, l)

    drawing = cartesian(3, [(0, 1)], dim=3, before=[(0.0, 0.0, 0.0)], labels=("pivot", "bob"))
    return attach(model, "spherical_pendulum", dict(m=m, l=l, g=g), drawing=drawing,
                  initial_state=initial_state, angles=angles, angular_momentum=angular_momentum)
