r"""Rotary rod–slider (paper B's second example): a configuration-dependent mass matrix.

A uniform rod OA (mass ``mA``, length ``l``) turns about the fixed point O in the vertical
plane OXY; a slider B (mass ``mB``) rides on the rod, held by a spring of stiffness ``k`` and
natural length ``r0`` attached at O; gravity acts along ``−Y``. Coordinates
``q = (θ, r, φ)``: the rod angle ``θ`` from ``+X``, and the slider's polar radius ``r`` and
polar angle ``φ``. The slider stays on the rod through the holonomic constraint

    g(q) = φ − θ = 0,

and the Lagrangian ``L = T − V`` has

    T = ½ (mA l²/3) θ̇² + ½ mB (ṙ² + r² φ̇²),      M(q) = diag(mA l²/3, mB, mB r²),
    V = mA g (l/2) sin θ + mB g r sin φ + ½ k (r − r0)².

``M`` depends on ``r``, so this scene exercises the kernels' ``∂T/∂q`` and ``∂(Mv)/∂q``
path (with exact second derivatives). Paper B gives ``l = 2 m``, ``mA = 2 kg``,
``mB = 5 kg``, ``k = 1000 N/m``; the spring's natural length and the initial state did not
survive, so ``r0 = 1 m`` and the default start (θ = φ = 0, r = r0, at rest: the rod released
horizontally) are fastvi's choices.

The model has exact derivatives of its callbacks by its parameters (``M``, ``∂T/∂q`` and
``∇V`` by ``(l, mA, mB, k, r0, g)``; the constraint does not depend on them), so
:func:`fastvi.sensitivity` and :func:`fastvi.adjoint` need no differences in ``params``.
"""

from __future__ import annotations

import numpy as np

from ..model import Model
from ..drawing import Drawing
from ._common import attach, check_positive

# params = (l, mA, mB, k, r0, g)


def _mass(q, p, out):
    out[:, :] = 0.0
    out[0, 0] = p[1] * p[0] * p[0] / 3.0
    out[1, 1] = p[2]
    out[2, 2] = p[2] * q[1] * q[1]


def _dT(q, v, p, out):
    # ∂T/∂q: only r enters M
    out[0] = 0.0
    out[1] = p[2] * q[1] * v[2] * v[2]
    out[2] = 0.0


def _ddT(q, v, p, out):
    out[:, :] = 0.0
    out[1, 1] = p[2] * v[2] * v[2]


def _dMv(q, v, p, out):
    # ∂(M v)_a / ∂q_b: (M v)_2 = mB r² φ̇
    out[:, :] = 0.0
    out[2, 1] = 2.0 * p[2] * q[1] * v[2]


def _V(q, p):
    stretch = q[1] - p[4]
    return (p[1] * p[5] * 0.5 * p[0] * np.sin(q[0]) + p[2] * p[5] * q[1] * np.sin(q[2])
            + 0.5 * p[3] * stretch * stretch)


def _dV(q, p, out):
    out[0] = p[1] * p[5] * 0.5 * p[0] * np.cos(q[0])
    out[1] = p[2] * p[5] * np.sin(q[2]) + p[3] * (q[1] - p[4])
    out[2] = p[2] * p[5] * q[1] * np.cos(q[2])


def _ddV(q, p, out):
    out[:, :] = 0.0
    out[0, 0] = -p[1] * p[5] * 0.5 * p[0] * np.sin(q[0])
    out[1, 1] = p[3]
    c = p[2] * p[5] * np.cos(q[2])
    out[1, 2] = c
    out[2, 1] = c
    out[2, 2] = -p[2] * p[5] * q[1] * np.sin(q[2])


def _g(q, p, out):
    out[0] = q[2] - q[0]


def _G(q, p, out):
    out[0, 0] = -1.0
    out[0, 1] = 0.0
    out[0, 2] = 1.0


def _ddg(q, eta, p, out):
    out[:, :] = 0.0  # the constraint is linear


# derivatives by params = (l, mA, mB, k, r0, g) (``Model``'s ``param_derivatives``): each
# ``out[i]`` is the callback's derivative by ``params[i]``; the constraint and G do not
# depend on them


def _mass_by_params(q, p, out):
    """``∂M/∂θ``: ``M₀₀ = mA l²/3`` by ``l`` (``2 mA l/3``) and ``mA`` (``l²/3``);
    ``M₁₁ = mB`` and ``M₂₂ = mB r²`` by ``mB`` (``1``, ``r²``)."""
    out[:, :, :] = 0.0
    out[0, 0, 0] = 2.0 * p[1] * p[0] / 3.0
    out[1, 0, 0] = p[0] * p[0] / 3.0
    out[2, 1, 1] = 1.0
    out[2, 2, 2] = q[1] * q[1]


def _dT_by_params(q, v, p, out):
    """``∂(∂T/∂q)/∂θ``: ``∂T/∂r = mB r φ̇²`` by ``mB`` (``r φ̇²``), zero otherwise."""
    out[:, :] = 0.0
    out[2, 1] = q[1] * v[2] * v[2]


def _dV_by_params(q, p, out):
    """``∂(∇V)/∂θ``: ``∂V/∂θ = mA g (l/2) cos θ`` by ``l``, ``mA``, ``g``;
    ``∂V/∂r = mB g sin φ + k (r − r0)`` by ``mB``, ``k`` (``r − r0``), ``r0`` (``−k``), ``g``;
    ``∂V/∂φ = mB g r cos φ`` by ``mB``, ``g``."""
    out[:, :] = 0.0
    c0 = np.cos(q[0])
    s2 = np.sin(q[2])
    c2 = np.cos(q[2])
    out[0, 0] = 0.5 * p[1] * p[5] * c0              # by l
    out[1, 0] = 0.5 * p[5] * p[0] * c0              # by mA
    out[5, 0] = 0.5 * p[1] * p[0] * c0              # by g
    out[2, 1] = p[5] * s2                           # by mB
    out[3, 1] = q[1] - p[4]                         # by k
    out[4, 1] = -p[3]                               # by r0
    out[5, 1] = p[2] * s2                           # by g
    out[2, 2] = p[5] * q[1] * c2                    # by mB
    out[5, 2] = p[2] * q[1] * c2                    # by g


#: ``Model``'s ``param_derivatives``: every callback θ enters (``G`` and ``g`` declared 0)
param_derivatives = dict(mass=_mass_by_params, kinetic_grad=_dT_by_params,
                         potential_grad=_dV_by_params, constraint=0, constraint_jacobian=0)


def energy_parts(q, v, l=2.0, mA=2.0, mB=5.0, k=1000.0, r0=1.0, g=9.81):
    """Energy components at configurations ``q`` and velocities ``v`` (..., 3).

    Returns
    -------
    dict of ndarray
        ``rod_kinetic = ½ (mA l²/3) θ̇²``, ``slider_kinetic = ½ mB (ṙ² + r² φ̇²)``,
        ``gravity = mA g (l/2) sin θ + mB g r sin φ``, ``spring = ½ k (r − r0)²``; their sum
        is the total energy ``H``.
    """
    q = np.asarray(q, float)
    v = np.asarray(v, float)
    th, r, ph = q[..., 0], q[..., 1], q[..., 2]
    return dict(
        rod_kinetic=0.5 * mA * l * l / 3.0 * v[..., 0] ** 2,
        slider_kinetic=0.5 * mB * (v[..., 1] ** 2 + r * r * v[..., 2] ** 2),
        gravity=mA * g * 0.5 * l * np.sin(th) + mB * g * r * np.sin(ph),
        spring=0.5 * k * (r - r0) ** 2,
    )


def rotary_rod_slider(l: float = 2.0, mA: float = 2.0, mB: float = 5.0, k: float = 1000.0,
                      r0: float = 1.0, g: float = 9.81) -> Model:
    """Rotary rod–slider (n = 3, m = 1), mass matrix ``diag(mA l²/3, mB, mB r²)``.

    Parameters
    ----------
    l, mA : float
        Rod length (m) and mass (kg); paper B: 2 m, 2 kg.
    mB : float
        Slider mass (kg); paper B: 5 kg.
    k, r0 : float
        Spring stiffness (N/m; paper B: 1000) and natural length (m; fastvi's choice).
    g : float
        Gravitational acceleration (m/s²).

    Returns
    -------
    Model
        With ``initial_state(theta=0, r=r0, omega=0, r_dot=0) -> (q0, v0)`` (consistent:
        ``φ = θ``, ``φ̇ = θ̇``), ``energy_parts(q, v)`` (see :func:`energy_parts`) and
        ``slider_position(q) -> (x, y)``, and a ``drawing`` (O, the rod O–A, the slider B);
        its callbacks have exact derivatives by ``params`` (:data:`param_derivatives`).
    """
    check_positive(l=l, mA=mA, mB=mB, k=k, r0=r0, g=g)
    model = Model(
        3, 1, params=(l, mA, mB, k, r0, g), mass=_mass, kinetic_grad=_dT, kinetic_hessian=_ddT,
        momentum_jacobian=_dMv, potential=_V, potential_grad=_dV, potential_hessian=_ddV,
        constraint=_g, constraint_jacobian=_G, constraint_hessian=_ddg,
        param_derivatives=param_derivatives, name="rotary_rod_slider",
    )
    kw = dict(l=l, mA=mA, mB=mB, k=k, r0=r0, g=g)

    def initial_state(theta=0.0, r=None, omega=0.0, r_dot=0.0):
        r = r0 if r is None else r
        return np.array([theta, r, theta], float), np.array([omega, r_dot, omega], float)

    def parts(q, v):
        return energy_parts(q, v, **kw)

    def slider_position(q):
        q = np.asarray(q, float)
        return q[..., 1] * np.cos(q[..., 2]), q[..., 1] * np.sin(q[..., 2])

    def points(q):  # O, the rod's tip A (no mass: not marked), the slider B
        return np.array([[0.0, 0.0], [l * np.cos(q[0]), l * np.sin(q[0])],
                         [q[1] * np.cos(q[2]), q[1] * np.sin(q[2])]])

    drawing = Drawing(2, points, [(0, 1)], pivots=(0,), labels=("O", "A", "B"), sizes=(7.0, 0.0, 12.0))
    return attach(model, "rotary_rod_slider", kw, drawing=drawing, initial_state=initial_state,
                  energy_parts=parts, slider_position=slider_position)
