r"""Planar four-bar linkage, parallelogram form, in redundant Cartesian coordinates.

Ground pivots ``A = (0, 0)`` and ``D = (L, 0)``; crank ``AB`` and rocker ``DC`` of length
``a``, coupler ``BC`` of length ``L`` (equal to the ground link: a parallelogram). Point masses
``mB`` at B and ``mC`` at C, gravity ``−g ŷ``. ``q = (xB, yB, xC, yC)``, three constraints

    g1 = ½ (|B|² − a²),   g2 = ½ (|C − B|² − L²),   g3 = ½ (|C − D|² − a²),

one degree of freedom. When the bars are aligned (crank angle 0 or π) the constraint
Jacobian loses rank: the parallelogram and anti-parallelogram branches cross there, and a
crank with enough energy passes through that singular position twice per turn.

The model has exact derivatives by its parameters ``params = (mB, mC, a, L, g)``
(``Model(param_derivatives=...)``): ``∇V`` by the masses and ``g``, the constraints by
``a`` and ``L``, and ``G`` by ``L`` (the rocker's pivot ``D`` sits at ``(L, 0)``).
"""

from __future__ import annotations

import numpy as np

from ..model import Model
from ..drawing import cartesian
from ._common import attach, check_positive
# the same masses-then-g layout: V = g (mB yB + mC yC), and so the same ∂(∇V)/∂θ as a
# 2-link chain's (g by mB at yB, by mC at yC; mB and mC by g), written on its pattern only
from .double_pendulum import potential as _V, potential_grad as _dV
from .chain import param_patterns as _chain_param_patterns
from .chain import potential_grad_by_params as _dV_by_params

# params = (mB, mC, a, L, g)


def _g(q, p, out):
    dx = q[2] - q[0]
    dy = q[3] - q[1]
    ex = q[2] - p[3]
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] - p[2] * p[2])
    out[1] = 0.5 * (dx * dx + dy * dy - p[3] * p[3])
    out[2] = 0.5 * (ex * ex + q[3] * q[3] - p[2] * p[2])


def _G(q, p, out):
    dx = q[2] - q[0]
    dy = q[3] - q[1]
    out[:, :] = 0.0
    out[0, 0] = q[0]
    out[0, 1] = q[1]
    out[1, 0] = -dx
    out[1, 1] = -dy
    out[1, 2] = dx
    out[1, 3] = dy
    out[2, 2] = q[2] - p[3]
    out[2, 3] = q[3]


def _ddg(q, eta, p, out):
    a = eta[0] + eta[1]
    b = eta[1]
    c = eta[1] + eta[2]
    out[:, :] = 0.0
    out[0, 0] = a
    out[1, 1] = a
    out[2, 2] = c
    out[3, 3] = c
    out[0, 2] = -b
    out[2, 0] = -b
    out[1, 3] = -b
    out[3, 1] = -b


# the derivatives by θ = (mB, mC, a, L, g) write only the entries of `param_patterns`
# (the kernels hand them `out` zeroed there); the constant mass matrix is data
def _g_by_params(q, p, out):
    """``∂g/∂θ``: ``∂g1/∂a = ∂g3/∂a = −a``, ``∂g2/∂L = −L`` and ``∂g3/∂L = −(xC − L)``
    (D = (L, 0) moves with L); zero by the masses and ``g``."""
    out[2, 0] = -p[2]
    out[2, 2] = -p[2]
    out[3, 1] = -p[3]
    out[3, 2] = p[3] - q[2]


def _G_by_params(q, p, out):
    """``∂G/∂θ`` (k, m, n): only ``G[2, 2] = xC − L`` moves, ``∂/∂L = −1``."""
    out[:, :, :] = 0.0
    out[3, 2, 2] = -1.0


def _param_patterns():
    """``(l, entry)`` of the non-zeros of the derivatives by θ: ``∂(∇V)/∂θ`` as a 2-link
    chain's, ``∂g/∂θ`` at ``(a: g1, g3)`` and ``(L: g2, g3)``."""
    return dict(potential_grad=_chain_param_patterns(2)["potential_grad"],
                constraint=(np.array([2, 2, 3, 3]), np.array([0, 2, 1, 2])))


def four_bar(mB: float = 1.0, mC: float = 1.0, a: float = 1.0, L: float = 2.0, g: float = 9.81) -> Model:
    """Parallelogram four-bar linkage (n = 4, m = 3) with exact second derivatives and
    exact derivatives by its parameters.

    The model has ``initial_state(theta, omega=0.0) -> (q0, v0)`` on the parallelogram
    branch (crank angle ``theta`` from the ground line, coupler parallel to the ground),
    ``crank_angle(q)`` and ``coupler_tilt(q)`` (the coupler's angle to the ground: 0 on the
    parallelogram branch), and a ``drawing`` (A, B, C, D).
    """
    check_positive(mB=mB, mC=mC, a=a, L=L, g=g)
    model = Model(
        4, 3, params=(mB, mC, a, L, g), mass=np.diag([mB, mB, mC, mC]), potential=_V,
        potential_grad=_dV, potential_hessian=0, constraint=_g, constraint_jacobian=_G,
        constraint_hessian=_ddg, mass_params=(0, 1), name="four_bar",
        param_derivatives=dict(potential_grad=_dV_by_params, constraint=_g_by_params,
                               constraint_jacobian=_G_by_params),
        param_patterns=_param_patterns(),
    )

    def initial_state(theta: float, omega: float = 0.0):
        B = a * np.array([np.cos(theta), np.sin(theta)])
        vB = a * omega * np.array([-np.sin(theta), np.cos(theta)])
        return np.r_[B, B + [L, 0.0]], np.r_[vB, vB]

    def crank_angle(q):
        q = np.asarray(q)
        return np.arctan2(q[..., 1], q[..., 0])

    def coupler_tilt(q):
        q = np.asarray(q)
        return np.arctan2(q[..., 3] - q[..., 1], q[..., 2] - q[..., 0])

    drawing = cartesian(4, [(0, 1), (1, 2), (2, 3)], before=[(0.0, 0.0)], after=[(L, 0.0)],
                        labels=("A", "B", "C", "D"))
    return attach(model, "four_bar", dict(mB=mB, mC=mC, a=a, L=L, g=g), drawing=drawing,
                  initial_state=initial_state, crank_angle=crank_angle, coupler_tilt=coupler_tilt)
