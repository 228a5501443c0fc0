r"""Slider–crank mechanism, free or driven at a constant crank speed.

Three bodies as point masses in the plane: the crank pin ``A = (x_A, y_A)`` on a crank of
length ``r`` about the origin, the connecting rod's centre ``C`` (the rod ``AB`` of length
``L`` as a point mass at its middle) and the slider ``B`` on the x-axis:
``q = (x_A, y_A, x_C, y_C, x_B, y_B)``, ``M = diag(m_A, m_A, m_C, m_C, m_B, m_B)``, gravity
``−g ŷ``. Five constraints hold the geometry:

    ½ (|A|² − r²),  ½ (|B − A|² − L²),  C − (A + B)/2 (two rows),  y_B

With ``drive=Ω`` a sixth, rheonomic constraint prescribes the crank angle ``φ(t) = Ω t``:

    g_6 = x_A sin(Ω t) − y_A cos(Ω t) = r sin(Ω t − θ_A) = 0

The mechanism then has no degree of freedom left, and the multiplier of ``g_6`` is the
motor's torque over ``r``: the power of the drive is ``λ_6 g_{6,t} = λ_6 r Ω``, so the
torque is ``τ = (dW/dt)/Ω`` with ``W`` the work in :attr:`fastvi.Result.work`.

``params = (r, L, m_A, m_C, m_B, g, Ω)`` (``Ω`` unused when free).
"""

from __future__ import annotations

import numpy as np

from ..model import Model
from ..drawing import cartesian
from ._common import attach, check_positive

# Two sets of callbacks with the same five rows. The free mechanism's take no time: it is a
# time-independent model, which is what lets it give exact derivatives by θ (``Model``
# refuses them for a time-dependent model with constraints). The driven set (``_*_driven``)
# takes ``t`` first, as ``time_dependent=True`` requires of the potential and constraint
# callbacks, for the drive's sixth row. numba cannot call a plain Python function from a
# compiled callback, so the driven set repeats the rows instead of calling the free one.


def _V(q, p):
    return p[5] * (p[2] * q[1] + p[3] * q[3] + p[4] * q[5])


def _dV(q, p, out):
    out[:] = 0.0
    for i in range(3):  # the weights m_A g, m_C g, m_B g at y_A, y_C, y_B
        out[2 * i + 1] = p[5] * p[2 + i]


def _g(q, p, out):
    dx, dy = q[4] - q[0], q[5] - q[1]
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] - p[0] * p[0])
    out[1] = 0.5 * (dx * dx + dy * dy - p[1] * p[1])
    out[2] = q[2] - 0.5 * (q[0] + q[4])
    out[3] = q[3] - 0.5 * (q[1] + q[5])
    out[4] = q[5]


#: the rows of G that do not move: C − (A + B)/2 and y_B
_G_FIXED = np.array([[-0.5, 0.0, 1.0, 0.0, -0.5, 0.0],
                     [0.0, -0.5, 0.0, 1.0, 0.0, -0.5],
                     [0.0, 0.0, 0.0, 0.0, 0.0, 1.0]])


def _G(q, p, out):
    out[:, :] = 0.0
    out[2:5, :] = _G_FIXED
    for a in (0, 1):  # the x (a = 0) and y (a = 1) columns of A and B
        out[0, a] = q[a]
        out[1, a] = q[a] - q[a + 4]
        out[1, a + 4] = q[a + 4] - q[a]


def _ddg(q, eta, p, out):
    out[:, :] = 0.0
    for a in (0, 1):
        out[a, a] = eta[0] + eta[1]
        out[a + 4, a + 4] = eta[1]
        out[a, a + 4] = -eta[1]
        out[a + 4, a] = -eta[1]


# the free mechanism's derivatives by θ = (r, L, m_A, m_C, m_B, g, Ω); G is declared 0
def _dV_by_params(q, p, out):
    """``∂(∇V)/∂θ``: ``g`` by each mass at its ``y``, each mass by ``g``."""
    out[:, :] = 0.0
    for i in range(3):
        out[2 + i, 2 * i + 1] = p[5]
        out[5, 2 * i + 1] = p[2 + i]


def _g_by_params(q, p, out):
    """``∂g/∂θ``: ``∂g_1/∂r = −r``, ``∂g_2/∂L = −L``."""
    out[:, :] = 0.0
    out[0, 0] = -p[0]
    out[1, 1] = -p[1]


# the driven mechanism's, time first: the free rows, and the drive's sixth
def _V_driven(t, q, p):
    return p[5] * (p[2] * q[1] + p[3] * q[3] + p[4] * q[5])


def _dV_driven(t, q, p, out):
    out[:] = 0.0
    for i in range(3):
        out[2 * i + 1] = p[5] * p[2 + i]


def _g_driven(t, q, p, out):
    dx, dy, phi = q[4] - q[0], q[5] - q[1], p[6] * t
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] - p[0] * p[0])
    out[1] = 0.5 * (dx * dx + dy * dy - p[1] * p[1])
    out[2] = q[2] - 0.5 * (q[0] + q[4])
    out[3] = q[3] - 0.5 * (q[1] + q[5])
    out[4] = q[5]
    out[5] = q[0] * np.sin(phi) - q[1] * np.cos(phi)


def _G_driven(t, q, p, out):
    out[:, :] = 0.0
    out[2:5, :] = _G_FIXED
    for a in (0, 1):
        out[0, a] = q[a]
        out[1, a] = q[a] - q[a + 4]
        out[1, a + 4] = q[a + 4] - q[a]
    out[5, 0] = np.sin(p[6] * t)
    out[5, 1] = -np.cos(p[6] * t)


def _ddg_driven(t, q, eta, p, out):
    out[:, :] = 0.0  # the drive row is linear in q
    for a in (0, 1):
        out[a, a] = eta[0] + eta[1]
        out[a + 4, a + 4] = eta[1]
        out[a, a + 4] = -eta[1]
        out[a + 4, a] = -eta[1]


def _gt(t, q, p, out):
    phi = p[6] * t
    out[:5] = 0.0
    out[5] = p[6] * (q[0] * np.cos(phi) + q[1] * np.sin(phi))


def state(phi, omega, r=0.3, L=1.0):
    """The exact ``(q, v)`` for crank angle ``phi`` and crank speed ``omega`` (slider to
    the right of the crank)."""
    xa, ya = r * np.cos(phi), r * np.sin(phi)
    vxa, vya = -r * np.sin(phi) * omega, r * np.cos(phi) * omega
    s = np.sqrt(L * L - ya * ya)
    xb, vxb = xa + s, vxa - ya * vya / s
    q = np.array([xa, ya, 0.5 * (xa + xb), 0.5 * ya, xb, 0.0])
    v = np.array([vxa, vya, 0.5 * (vxa + vxb), 0.5 * vya, vxb, 0.0])
    return q, v


def slider_crank(r: float = 0.3, L: float = 1.0, m_a: float = 0.5, m_c: float = 1.0,
                 m_b: float = 2.0, g: float = 9.81, drive: float | None = None) -> Model:
    r"""Planar slider–crank (n = 6), free (m = 5) or driven at crank speed ``drive`` (m = 6).

    Parameters
    ----------
    r, L : float
        Crank and connecting-rod lengths (``r < L``).
    m_a, m_c, m_b : float
        Point masses of the crank pin, the rod (at its centre) and the slider.
    g : float
        Gravity along ``−y``.
    drive : float, optional
        Crank speed ``Ω`` (rad/s) imposed by the rheonomic constraint ``φ(t) = Ω t``. None:
        the free mechanism (one degree of freedom).

    Returns
    -------
    Model
        Exact second derivatives. Free: a time-independent model (callbacks without ``t``)
        with exact derivatives by the parameters (``param_derivatives``): ``∇V`` by each
        mass (``g`` at its ``y``) and by ``g`` (each mass at its ``y``), ``g_1`` by ``r``
        and ``g_2`` by ``L``, ``G`` declared 0 (it holds no parameter); the rest are zero.
        Driven: ``time_dependent=True`` (the callbacks take ``t`` first) with an exact
        ``∂g/∂t`` and no derivatives by θ (a time-dependent model with constraints cannot
        give them: the step is differenced in θ). Helpers ``initial_state(phi,
        omega=drive)`` (exact, consistent at ``t0 = phi/Ω`` when driven), ``crank_angle(q)``
        and a ``drawing`` (O, A, C, B).
    """
    check_positive(r=r, L=L, m_a=m_a, m_c=m_c, m_b=m_b, g=g)
    if not r < L:
        raise ValueError(f"the crank must be shorter than the rod: `r` = {r} >= `L` = {L}")
    driven = drive is not None
    if driven and not np.isfinite(drive):
        raise ValueError(f"`drive` must be a finite crank speed or None, got {drive!r}")
    if driven:
        callbacks = dict(potential=_V_driven, potential_grad=_dV_driven, constraint=_g_driven,
                         constraint_jacobian=_G_driven, constraint_hessian=_ddg_driven,
                         time_dependent=True, constraint_time_derivative=_gt)
    else:
        callbacks = dict(potential=_V, potential_grad=_dV, constraint=_g, constraint_jacobian=_G,
                         constraint_hessian=_ddg,
                         param_derivatives=dict(potential_grad=_dV_by_params,
                                                constraint=_g_by_params, constraint_jacobian=0))
    model = Model(
        6, 6 if driven else 5, params=(r, L, m_a, m_c, m_b, g, float(drive or 0.0)),
        mass=np.diag([m_a, m_a, m_c, m_c, m_b, m_b]), potential_hessian=0, **callbacks,
        mass_params=(2, 3, 4), name="slider_crank" + ("-driven" if driven else ""),
    )

    def initial_state(phi: float, omega: float | None = None):
        w = drive if omega is None else omega
        if w is None:
            w = 0.0
        return state(phi, w, r, L)

    def crank_angle(q):
        q = np.asarray(q)
        return np.arctan2(q[..., 1], q[..., 0])

    # points O (the crank's pivot), A, C, B: C, the rod's mass, sits on the bar A–B
    drawing = cartesian(6, [(0, 1), (1, 3)], before=[(0.0, 0.0)], labels=("O", "A", "C", "B"))
    return attach(model, "slider_crank", dict(r=r, L=L, m_a=m_a, m_c=m_c, m_b=m_b, g=g, drive=drive),
                  drawing=drawing, initial_state=initial_state, crank_angle=crank_angle)
