r"""Kapitza's pendulum: a planar pendulum whose pivot is driven vertically.

``q = (x, y)``, the bob of mass ``m`` on a massless rod of length ``l`` about the pivot
``(0, y_p(t))`` with ``y_p = a cos(ω t)``, gravity ``−g ŷ``. A rheonomic constraint:

    g(t, q) = ½ (x² + (y − y_p(t))² − l²),   G = (x, y − y_p),   g_t = (y − y_p) a ω sin(ω t)

In the angle ``θ`` from the downward vertical the motion obeys
``θ̈ = −(g + ÿ_p(t)) sin θ / l`` with ``ÿ_p = −a ω² cos(ω t)`` (an independent reference).
The inverted position ``θ = π`` is stable when ``a² ω² > 2 g l`` (Kapitza 1951).

``params = (m, l, g, a, ω)``.
"""

from __future__ import annotations

import numpy as np

from ..model import Model
from ..drawing import Drawing
from ._common import attach, check_positive


def _V(t, q, p):
    return p[0] * p[2] * q[1]


def _dV(t, q, p, out):
    out[0] = 0.0
    out[1] = p[0] * p[2]


def _g(t, q, p, out):
    dy = q[1] - p[3] * np.cos(p[4] * t)
    out[0] = 0.5 * (q[0] * q[0] + dy * dy - p[1] * p[1])


def _G(t, q, p, out):
    out[0, 0] = q[0]
    out[0, 1] = q[1] - p[3] * np.cos(p[4] * t)


def _ddg(t, q, eta, p, out):
    out[:, :] = 0.0
    out[0, 0] = eta[0]
    out[1, 1] = eta[0]


def _gt(t, q, p, out):
    dy = q[1] - p[3] * np.cos(p[4] * t)
    out[0] = dy * p[3] * p[4] * np.sin(p[4] * t)


def kapitza_pendulum(m: float = 1.0, l: float = 1.0, g: float = 9.81, a: float = 0.05,
                     omega: float = 150.0) -> Model:
    r"""Pendulum on a vertically oscillating pivot (n = 2, m = 1), time-dependent.

    Parameters
    ----------
    m, l, g : float
        Bob mass, rod length, gravity.
    a, omega : float
        Amplitude and angular frequency of the pivot, ``y_p = a cos(ω t)``. The defaults
        (``a ω = 7.5 m/s``, ``a² ω² = 56 > 2 g l = 19.6``) make the inverted position stable;
        resolve the drive with ``ω h ≲ 0.2``.

    Returns
    -------
    Model
        ``time_dependent=True`` with exact ``∂g/∂t``; helpers
        ``initial_state(theta, theta_dot=0.0, t0=0.0) -> (q0, v0)`` (consistent at ``t0``:
        the pivot's velocity included), ``angle(q, t) -> theta``, ``pivot(t) -> y_p`` and a
        ``drawing`` (the moving pivot, the bob).
    """
    check_positive(m=m, l=l, g=g, a=a, omega=omega)
    model = Model(
        2, 1, params=(m, l, g, a, omega), mass=m * np.eye(2), potential=_V, potential_grad=_dV,
        potential_hessian=0, constraint=_g, constraint_jacobian=_G, constraint_hessian=_ddg,
        time_dependent=True, constraint_time_derivative=_gt, mass_params=(0,),
        name="kapitza_pendulum",
    )

    def pivot(t):
        return a * np.cos(omega * np.asarray(t))

    def initial_state(theta: float, theta_dot: float = 0.0, t0: float = 0.0):
        yp, vp = a * np.cos(omega * t0), -a * omega * np.sin(omega * t0)
        q0 = np.array([l * np.sin(theta), yp - l * np.cos(theta)])
        v0 = np.array([l * np.cos(theta) * theta_dot, vp + l * np.sin(theta) * theta_dot])
        return q0, v0

    def angle(q, t):
        q = np.asarray(q)
        return np.arctan2(q[..., 0], pivot(t) - q[..., 1])

    def points(t, q):  # the pivot moves: the drawing reads the time
        return np.array([[0.0, pivot(t)], [q[0], q[1]]])

    drawing = Drawing(2, points, [(0, 1)], pivots=(0,), labels=("pivot", "bob"), time_dependent=True)
    return attach(model, "kapitza_pendulum", dict(m=m, l=l, g=g, a=a, omega=omega),
                  drawing=drawing, initial_state=initial_state, angle=angle, pivot=pivot)
