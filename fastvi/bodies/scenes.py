r"""Ready-made rigid-body mechanisms (registered in :data:`fastvi.scenes.SCENES`).

================================  ===========================================================
scene                             mechanism
================================  ===========================================================
:func:`heavy_top`                 Brüls, Cardona & Arnold's heavy top (a lamina by default)
:func:`lagrange_top`              a symmetric top in steady precession, with its exact motion
:func:`fast_top`                  Simo & Wong's fast symmetric top
:func:`spatial_slider_crank`      IFToMM's spatial slider–crank (R–S–U–P joints)
:func:`bricard`                   IFToMM A04, Bricard's overconstrained 6R linkage
:func:`flyball_governor`          IFToMM A05, the stiff flyball governor
:func:`body_chain`                N rigid rods on spherical joints (cost scaling)
================================  ===========================================================

Every scene returns the ``fastvi.Model`` of :meth:`fastvi.bodies.Mechanism.build` (with
``model.assembly``) whose ``initial_state()`` gives the scene's documented start, consistent
to round-off.
"""

from __future__ import annotations

import math

import numpy as np

from ..scenes._common import attach, check_positive
from . import kinematics
from .mechanism import Mechanism
from .rigid import GROUND, expm_so3

__all__ = ["heavy_top", "lagrange_top", "fast_top", "spatial_slider_crank", "bricard",
           "flyball_governor", "body_chain", "BRULS_INERTIA"]

#: the heavy top of Brüls, Cardona & Arnold: a lamina (J₂ = J₁ + J₃, so E₂ = 0)
BRULS_INERTIA = (0.234375, 0.46875, 0.234375)


def _top(name, mass, inertia, com, rotation, omega_body, g):
    """A rigid body on a ball joint at the origin, its centre of mass at ``R com``."""
    com = np.asarray(com, dtype=float)
    R = np.asarray(rotation, dtype=float)
    w = R @ np.asarray(omega_body, dtype=float)
    mech = Mechanism(gravity=(0.0, 0.0, -g), name=name)
    body = mech.body("top", mass=mass, inertia=inertia, position=R @ com, rotation=R,
                     velocity=np.cross(w, R @ com), omega=w)
    mech.spherical(GROUND, body, point=(0.0, 0.0, 0.0), name="pivot")
    return mech.build()


def heavy_top(mass: float = 15.0, inertia=BRULS_INERTIA, com=(0.0, 1.0, 0.0),
              omega_body=(0.0, 150.0, -4.61538), g: float = 9.81):
    r"""The heavy top of Brüls, Cardona & Arnold (2012): a body on a ball joint at the origin.

    Parameters
    ----------
    mass : float, default 15
    inertia : array_like (3,) or (3, 3), default ``(0.234375, 0.46875, 0.234375)``
        About the centre of mass, body frame. The default is a lamina (``J₂ = J₁ + J₃``),
        whose director inertia ``E₂`` vanishes: its mass matrix is singular, which this
        fastvi refuses; pass a thicker body (e.g. ``J₂ = 0.4``) meanwhile.
    com : array_like (3,), default (0, 1, 0)
        The centre of mass from the fixed point, body frame.
    omega_body : array_like (3,), default (0, 150, −4.61538)
        Initial angular velocity, body frame (rad/s).
    g : float, default 9.81
        Gravity along −z.

    Returns
    -------
    fastvi.Model
        ``R(0) = 1``; ``initial_state()`` is the start.
    """
    check_positive(mass=mass, g=g)
    model = _top("heavy_top", mass, inertia, com, np.eye(3), omega_body, g)
    return attach(model, "heavy_top", dict(mass=mass, inertia=tuple(np.ravel(inertia).tolist()),
                                           com=tuple(com), omega_body=tuple(omega_body), g=g))


def lagrange_top(mass: float = 1.0, J1: float = 0.1, J3: float = 0.15, length: float = 0.5,
                 g: float = 9.81, tilt: float = 0.5, precession: float = 3.0):
    r"""A symmetric (Lagrange) top in steady precession, with its exact motion.

    The body has ``J = diag(J₁, J₁, J₃)`` about its centre of mass, which sits at ``l e₃``
    (body frame) from the fixed point at the origin; gravity ``−g e_z``. Tilted by ``α₀`` from
    the upward vertical and precessing at ``ω_p`` about ``e_z``, it precesses steadily when it
    spins about its axis at

    .. math:: ω_s = \frac{m g l}{J_3 ω_p} + \frac{J_1 + m l^2 - J_3}{J_3}\, ω_p \cos α_0,

    and then ``R(t) = Rot(e_z, ω_p t) R₀ Rot(e₃, ω_s t)`` with ``R₀ = Rot(e_x, −α₀)``, angular
    velocity ``ω = ω_p e_z + ω_s d₃``.

    Returns
    -------
    fastvi.Model
        With ``spin`` (``ω_s``), ``exact(t) -> (q, v)`` (arrays (K, 12) on times (K,)) and
        ``initial_state()``.
    """
    check_positive(mass=mass, J1=J1, J3=J3, length=length, g=g)
    if not math.isfinite(precession) or precession == 0.0:
        raise ValueError(f"`precession` must be a non-zero finite rate, got {precession!r}")
    spin = mass * g * length / (J3 * precession) + (J1 + mass * length ** 2 - J3) / J3 * precession \
        * math.cos(tilt)
    R0 = expm_so3((-tilt, 0.0, 0.0))
    omega_world = np.array([0.0, 0.0, precession]) + spin * R0[:, 2]
    model = _top("lagrange_top", mass, (J1, J1, J3), (0.0, 0.0, length), R0,
                 R0.T @ omega_world, g)

    def exact(t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        q = np.empty((t.size, 12))
        v = np.empty((t.size, 12))
        for k, tk in enumerate(t):
            R = expm_so3((0.0, 0.0, precession * tk)) @ R0 @ expm_so3((0.0, 0.0, spin * tk))
            w = np.array([0.0, 0.0, precession]) + spin * R[:, 2]
            phi = length * R[:, 2]
            q[k] = np.concatenate([phi, R[:, 0], R[:, 1], R[:, 2]])
            v[k] = np.concatenate([np.cross(w, phi)] + [np.cross(w, R[:, i]) for i in range(3)])
        return q, v

    kw = dict(mass=mass, J1=J1, J3=J3, length=length, g=g, tilt=tilt, precession=precession)
    return attach(model, "lagrange_top", kw, exact=exact, spin=spin)


def fast_top(mass: float = 20.0, inertia=(5.0, 5.0, 1.0), length: float = 1.0, g: float = 1.0,
             tilt=(0.05, 0.0, 0.0), omega_body=(0.0, 0.0, 50.0)):
    r"""Simo & Wong's fast symmetric top: ``J = diag(5, 5, 1)`` about the centre of mass at
    ``l e₃`` from the fixed point, ``m = 20``, ``g = 1``, ``Λ₀ = exp(skew(0.05, 0, 0))`` and
    ``W₀ = (0, 0, 50)`` in the body frame."""
    check_positive(mass=mass, length=length, g=g)
    model = _top("fast_top", mass, inertia, (0.0, 0.0, length), expm_so3(tilt), omega_body, g)
    kw = dict(mass=mass, inertia=tuple(np.ravel(inertia).tolist()), length=length, g=g,
              tilt=tuple(tilt), omega_body=tuple(omega_body))
    return attach(model, "fast_top", kw)


def _rod_inertia(mass, length, side):
    """A prism ``length × side × side`` along its x axis, about its centre."""
    return (mass * 2 * side ** 2 / 12.0, mass * (length ** 2 + side ** 2) / 12.0,
            mass * (length ** 2 + side ** 2) / 12.0)


def _frame_along(x, hint=(0.0, 0.0, 1.0)):
    """A rotation whose first column is the unit vector ``x``."""
    x = np.asarray(x, dtype=float) / np.linalg.norm(x)
    h = np.asarray(hint, dtype=float)
    if abs(x @ h) > 0.9:
        h = np.array([0.0, 1.0, 0.0]) if abs(x[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(h, x)
    y /= np.linalg.norm(y)
    return np.column_stack([x, y, np.cross(x, y)])


def spatial_slider_crank(speed: float = 6.0, g: float = 9.81):
    r"""IFToMM's spatial slider–crank: crank (R), connecting rod (S at the crank, U at the
    slider) and a slider (P) on the x axis.

    The crank (0.12 kg, ``J = diag(10⁻⁴, 10⁻⁵, 10⁻⁴)``, centre of mass on its axis) turns
    about ``e_x`` through ``A = (0, 0.1, 0.12)``, its pin ``B`` 0.08 m from ``A`` (initially
    straight up); the rod (0.5 kg, 0.3 m, ``J = diag(4·10⁻⁴, 4·10⁻³, 4·10⁻³)`` along its own x
    axis) joins ``B`` by a ball joint and the slider (2 kg) at ``C = (0.2, 0, 0)`` by a
    universal joint (axes: the slide direction in the slider, ``e_x × (C − B)`` in the rod);
    gravity ``−g e_z``. One degree of freedom; ``initial_state(angle=0, speed=6)`` sets the
    crank's angle and angular velocity.
    """
    check_positive(g=g)
    A = np.array([0.0, 0.1, 0.12])
    B = A + np.array([0.0, 0.0, 0.08])
    C = np.array([math.sqrt(0.3 ** 2 - 0.1 ** 2 - 0.2 ** 2), 0.0, 0.0])
    rod_frame = _frame_along(C - B, hint=(1.0, 0.0, 0.0))
    mech = Mechanism(gravity=(0.0, 0.0, -g), name="spatial_slider_crank")
    crank = mech.body("crank", mass=0.12, inertia=(1e-4, 1e-5, 1e-4), position=A)
    rod = mech.body("rod", mass=0.5, inertia=(4e-4, 4e-3, 4e-3), position=0.5 * (B + C),
                    rotation=rod_frame)
    slider = mech.body("slider", mass=2.0, inertia=(1e-4, 1e-4, 1e-4), position=C)
    mech.revolute(GROUND, crank, point=A, axis=(1.0, 0.0, 0.0), name="crank")
    mech.spherical(crank, rod, point=B, name="B")
    mech.universal(slider, rod, point=C, axis_a=(1.0, 0.0, 0.0), axis_b=(0.0, 1.0, 0.0), name="C")
    mech.prismatic(GROUND, slider, point=C, axis=(1.0, 0.0, 0.0), name="slide")
    model = mech.build()

    def initial_state(angle: float = 0.0, speed: float = speed):
        return kinematics.initial_state(model, {"crank": angle}, {"crank": speed})

    return attach(model, "spatial_slider_crank", dict(speed=speed, g=g), initial_state=initial_state)


#: Bricard's linkage: the corners of the loop (m) and the rods between them
BRICARD_POINTS = np.array([[0, 0, 0], [1, 0, 0], [1, -1, 0], [1, -1, 1], [0, -1, 1], [0, 0, 1]], float)


def bricard(mass: float = 1.0, side: float = 0.1, g: float = 9.81, redundant: str = "drop"):
    r"""IFToMM A04: Bricard's linkage, five rods and the ground closed by six revolute joints.

    The rods (1 m, ``mass``, square section ``side``) run along edges of the unit cube from
    ``P₀ = 0`` through ``P₁ … P₄`` to ``P₅ = (0, 0, 1)``, the ground closing the loop from
    ``P₅`` to ``P₀``; each joint's axis is perpendicular to the two links it joins. Gravity
    ``−g e_y``, released from rest. Grübler's count gives no mobility, but the 60 equations on
    60 coordinates have rank 59: one degree of freedom and one redundant row, which
    :meth:`~fastvi.bodies.Mechanism.build` drops (``redundant="keep"`` keeps it).
    """
    check_positive(mass=mass, side=side, g=g)
    P = BRICARD_POINTS
    mech = Mechanism(gravity=(0.0, -g, 0.0), name="bricard")
    rods = []
    for k in range(5):
        d = P[k + 1] - P[k]
        rods.append(mech.body(f"rod{k + 1}", mass=mass, inertia=_rod_inertia(mass, 1.0, side),
                              position=0.5 * (P[k] + P[k + 1]), rotation=_frame_along(d)))
    links = [P[0] - P[5]] + [P[k + 1] - P[k] for k in range(5)] + [P[0] - P[5]]
    chain = [GROUND] + rods + [GROUND]
    for k in range(6):
        axis = np.cross(links[k], links[k + 1])
        mech.revolute(chain[k], chain[k + 1], point=P[k], axis=axis / np.linalg.norm(axis),
                      name=f"J{k}")
    model = mech.build(redundant=redundant)
    return attach(model, "bricard", dict(mass=mass, side=side, g=g, redundant=redundant))


def flyball_governor(stiffness: float = 8e5, damping: float = 4e4, omega: float = 2 * math.pi,
                     g: float = 9.81, density: float = 3000.0):
    r"""IFToMM A05: the stiff flyball governor.

    A shaft (``1 × 0.01 × 0.01`` m, density 3000) turns freely about ``e_z`` on the ground; a
    slider (a 0.1 m cube) slides along it and turns with it, its centre at ``s = 0.5`` m. Two
    rods (``1 × 0.01 × 0.01`` m) hang on hinges at ``(±0.05, 0, 1)`` (axes ``e_y`` of the
    shaft), 30° below the horizontal, with a 5 kg point mass at each far end (a ball joint to
    a point mass holds it rigidly). A spring–damper (``stiffness`` N/m, ``damping`` N s/m,
    rest length 0.5 m, at rest initially) joins each side of the slider to the middle of a
    rod. Gravity ``−g e_z``; everything starts turning rigidly at ``omega`` about ``e_z``
    (``initial_state(omega)``).
    """
    check_positive(stiffness=stiffness, g=g, density=density)
    side, L, cube, s0, half = 0.01, 1.0, 0.1, 0.5, 0.05
    alpha = math.radians(30.0)
    m_rod = density * L * side * side
    mech = Mechanism(gravity=(0.0, 0.0, -g), name="flyball_governor")
    shaft = mech.body("shaft", mass=m_rod, inertia=_rod_inertia(m_rod, L, side),
                      position=(0.0, 0.0, 0.5 * L), rotation=_frame_along((0.0, 0.0, 1.0)))
    m_cube = density * cube ** 3
    slider = mech.body("slider", mass=m_cube, inertia=(m_cube * cube ** 2 / 6.0,) * 3,
                       position=(0.0, 0.0, s0))
    mech.revolute(GROUND, shaft, point=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0), name="shaft")
    mech.prismatic(shaft, slider, point=(0.0, 0.0, s0), axis=(0.0, 0.0, 1.0), name="slide")
    for sign, tag in ((1.0, "AC"), (-1.0, "BD")):
        hinge = np.array([sign * half, 0.0, L])
        d = np.array([sign * math.cos(alpha), 0.0, -math.sin(alpha)])
        rod = mech.body(f"rod{tag}", mass=m_rod, inertia=_rod_inertia(m_rod, L, side),
                        position=hinge + 0.5 * L * d, rotation=_frame_along(d))
        ball = mech.point_mass(f"ball{tag}", mass=5.0, position=hinge + L * d)
        mech.revolute(shaft, rod, point=hinge, axis=(0.0, 1.0, 0.0), name=f"hinge{tag}")
        mech.spherical(rod, ball, point=hinge + L * d, name=f"ball{tag}")
        mech.spring(slider, rod, point_a=(sign * half, 0.0, 0.0), point_b=(0.0, 0.0, 0.0),
                    stiffness=stiffness, damping=damping, length=0.5, name=f"spring{tag}")
    model = mech.build()

    def initial_state(omega: float = omega):
        return kinematics.initial_state(model, rates={"shaft": omega})

    kw = dict(stiffness=stiffness, damping=damping, omega=omega, g=g, density=density)
    return attach(model, "flyball_governor", kw, initial_state=initial_state)


def body_chain(N: int = 8, mass: float = 1.0, length: float = 1.0, side: float = 0.05, g: float = 9.81):
    r"""``N`` rigid rods (``length``, square section ``side``) hanging from the origin on
    spherical joints, released at rest from a smooth arc in the x–z plane: ``n = 12 N``
    coordinates and ``m = 9 N`` rows, the cost-scaling mechanism of the rigid-body benchmarks
    (its ``G`` has a fixed number of entries per row, declared to the kernels)."""
    if isinstance(N, bool) or not isinstance(N, (int, np.integer)) or N < 1:
        raise ValueError(f"`N` must be a positive integer, got {N!r}")
    check_positive(mass=mass, length=length, side=side, g=g)
    mech = Mechanism(gravity=(0.0, 0.0, -g), name=f"body_chain{N}")
    angles = 0.6 * np.sin(np.linspace(0.3, 2.8, int(N)))
    top = np.zeros(3)
    prev = GROUND
    for k, a in enumerate(angles):
        d = np.array([math.sin(a), 0.0, -math.cos(a)])
        rod = mech.body(f"rod{k}", mass=mass, inertia=_rod_inertia(mass, length, side),
                        position=top + 0.5 * length * d, rotation=_frame_along(d, hint=(0.0, 1.0, 0.0)))
        mech.spherical(prev, rod, point=top, name=f"S{k}")
        top = top + length * d
        prev = rod
    model = mech.build()
    kw = dict(N=int(N), mass=mass, length=length, side=side, g=g)
    return attach(model, "body_chain", kw)
