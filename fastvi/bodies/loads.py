r"""Loads on a mechanism: springs and dampers, applied forces and torques.

Gravity is not here: it is the linear potential ``V = −Σ_b m_b g·φ_b`` of the mechanism.

=======================  =====================================================================
load                     contribution
=======================  =====================================================================
linear spring–damper     between ``x_A(X^A)`` and ``x_B(X^B)``, ``r = x_A − x_B``, ``l = |r|``:
                         ``V = ½ k (l − L)²``; force ``−c (r·ṙ/l²) r`` along the line. With
                         ``L = 0``: ``V = ½ k |r|²`` and ``−c ṙ`` (a smooth zero-length spring)
rotary spring–damper     about a revolute or cylindrical joint's axis, with its angle
                         ``θ = atan2(b₁·n₂, b₁·n₁)``: ``V = ½ k (θ − θ₀)²`` (``θ − θ₀`` taken in
                         (−π, π]) and torque ``−c θ̇``
force                    ``f(t) = f·s(t)`` (world) at ``X`` of a body: generalized force
                         ``(f, X₁ f, X₂ f, X₃ f)``
torque                   ``τ(t) = τ·s(t)`` (world) on a rigid body: ``½ τ × d_I`` on each director
=======================  =====================================================================

``s(t)`` is a :class:`~fastvi.bodies.profile.Profile` (default 1). Springs enter the
potential (so the energy includes them), dampers and applied loads the force callback (so
:attr:`fastvi.Result.work_forces` is their work).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import packing as pk
from .profile import Profile
from .rigid import Ground, PointMass, reference_point

__all__ = ["Load", "load_record"]


@dataclass(eq=False)
class Load:
    """One load: ``kind`` (``"spring"``, ``"rotary_spring"``, ``"force"``, ``"torque"``), its
    bodies, expressions (principal coordinates), constants and profile."""

    kind: str
    name: str
    a: object
    b: object
    vectors: tuple  # expressions (EXPR,) each
    stiffness: float = 0.0
    damping: float = 0.0
    rest: float = 0.0
    profile: Profile = Profile(value=1.0)
    index: int = -1

    def __repr__(self) -> str:
        return f"Load({self.kind}, {self.name!r})"


def _nonnegative(x, name: str, owner: str) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)) or not \
            math.isfinite(x) or x < 0:
        raise ValueError(f"{owner}: `{name}` must be a finite number >= 0, got {x!r}")
    return float(x)


def spring(name, a, b, Xa, Xb, stiffness, damping, length) -> Load:
    """A linear spring–damper between ``Xa`` on ``a`` and ``Xb`` on ``b`` (principal
    coordinates); ``length=None`` is the distance at the reference configuration."""
    owner = f"spring {name!r}"
    k = _nonnegative(stiffness, "stiffness", owner)
    c = _nonnegative(damping, "damping", owner)
    if a is b:
        raise ValueError(f"{owner}: `a` and `b` are the same body {a.name!r}")
    sep = pk.point(0, a, Xa) - pk.point(1, b, Xb)
    if length is None:
        length = float(np.linalg.norm(reference_point(a, Xa) - reference_point(b, Xb)))
    L = _nonnegative(length, "length", owner)
    return Load("spring", name, a, b, (sep,), k, c, L)


def rotary_spring(name, joint, stiffness, damping, angle) -> Load:
    """A rotary spring–damper about the axis of a revolute (or cylindrical) ``joint``; its rest
    angle ``angle`` is measured like the joint's angle (0 at the reference configuration)."""
    owner = f"rotary spring {name!r}"
    if joint.kind not in ("revolute", "cylindrical", "driven_revolute"):
        raise ValueError(f"{owner}: `joint` must be a revolute or cylindrical joint, got the "
                         f"{joint.kind} joint {joint.name!r}")
    k = _nonnegative(stiffness, "stiffness", owner)
    c = _nonnegative(damping, "damping", owner)
    if isinstance(angle, bool) or not isinstance(angle, (int, float, np.integer, np.floating)) \
            or not math.isfinite(angle):
        raise ValueError(f"{owner}: `angle` must be a finite number (rad), got {angle!r}")
    a, b = joint.a, joint.b
    vectors = (pk.direction(0, a, joint.frame_a[:, 1]), pk.direction(0, a, joint.frame_a[:, 2]),
               pk.direction(1, b, joint.frame_b[:, 1]))
    return Load("rotary_spring", name, a, b, vectors, k, c, float(angle))


def applied(kind, name, body, vector, X, profile) -> Load:
    """A force ``vector`` at ``X`` (principal coordinates) or a torque ``vector`` on ``body``."""
    owner = f"{kind} {name!r}"
    if isinstance(body, Ground):
        raise ValueError(f"{owner}: a {kind} on the ground does nothing; name a body")
    if kind == "torque" and isinstance(body, PointMass):
        raise ValueError(f"{owner}: point mass {body.name!r} has no orientation to take a torque")
    f = np.array(vector, dtype=float).reshape(-1)
    if f.shape != (3,) or not np.all(np.isfinite(f)):
        raise ValueError(f"{owner}: the {kind} must be a finite 3-vector, got {vector!r}")
    e = pk.point(0, body, X) if kind == "force" else np.zeros(pk.EXPR)
    e[pk.SLOTS:] = f
    return Load(kind, name, body, None, (e,), profile=profile)


_KIND_CODE = {"force": pk.FORCE, "torque": pk.TORQUE, "rotary_spring": pk.ROTARY_SPRING}


def load_record(load: Load, offsets: dict) -> np.ndarray:
    """The load's record for the parameter vector."""
    rec = np.zeros(pk.LOAD_W)
    code = _KIND_CODE.get(load.kind)
    if code is None:
        code = pk.SPRING if load.rest > 0 else pk.VECTOR_SPRING
    rec[pk.L_KIND] = code
    for off, body in ((pk.L_OFFA, load.a), (pk.L_OFFB, load.b)):
        if body is not None:
            rec[off] = max(offsets.get(body, 0), 0)
            rec[off + 1] = pk.slots_of(body)
    for base, vec in zip((pk.L_V1, pk.L_V2, pk.L_V3), load.vectors):
        rec[base: base + pk.EXPR] = vec
    rec[pk.L_K], rec[pk.L_C], rec[pk.L_REST] = load.stiffness, load.damping, load.rest
    rec[pk.L_LAW: pk.L_LAW + 6] = load.profile.pack()
    return rec
