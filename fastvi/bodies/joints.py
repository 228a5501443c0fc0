r"""The joint library: each joint as constraint rows in the form of :mod:`fastvi.bodies.packing`.

A joint connects body A and body B at a point (``X^A`` in A, ``X^B`` in B) and carries a
*joint frame* in each body: orthonormal columns ``F^A = [a, n₁, n₂]`` (``a`` the joint's axis)
and ``F^B = [b, b₁, b₂]``, equal in the world at the reference (assembly) configuration —
the bodies' initial poses. With ``r = x_A(X^A) − x_B(X^B)`` the rows are

==================  =============================================================  ======
joint               equations                                                      rows
==================  =============================================================  ======
spherical           ``r = 0``                                                      3
revolute            ``r = 0``, ``a·b₁ = a·b₂ = 0``                                 5
universal           ``r = 0``, ``a·b' = 0`` (``b'`` B's axis, ⟂ ``a`` initially)   4
cylindrical         ``a·b₁ = a·b₂ = 0``, ``n₁·r = n₂·r = 0``                       4
prismatic           cylindrical and ``n₁·b₂ = 0`` (no rotation about ``a``)        5
fixed               ``r = 0``, ``n₀·b₁ = n₀·b₂ = n₁·b₂ = 0`` (frames aligned)       6
driven revolute     revolute and ``(b₁·n₂) cos θ(t) − (b₁·n₁) sin θ(t) = 0``       6
driven prismatic    prismatic and ``a·(x_B − x_A) − s(t) = 0``                     6
distance            ``½ (|r|² − L²) = 0``                                          1
==================  =============================================================  ======

(vectors of A and B are body-fixed: ``a = a_I d^A_I``.) Every equation is at most bilinear
in ``q``, so its Hessian is constant (times ``cos θ(t)``, ``sin θ(t)`` for a drive). A body's
own six rows, ``½ (d_I·d_I − 1) = 0`` and ``d_I·d_J = 0``, are :func:`internal_rows`.

The joint's angle (revolute, cylindrical) is measured from the reference configuration
about ``a``, positive by the right-hand rule; the displacement (prismatic, cylindrical) along
``a``; a driven joint's ``θ(t)`` the same way.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import packing as pk
from .profile import Profile
from .rigid import Body, Ground, PointMass, reference_directors as _directors, reference_point

__all__ = ["Joint", "JOINT_KINDS", "make_joint", "joint_rows", "internal_rows"]

#: joint kinds and their joint coordinates (what :mod:`fastvi.bodies.kinematics` takes)
JOINT_KINDS = {
    "spherical": ("rx", "ry", "rz"), "revolute": ("angle",), "universal": ("angle1", "angle2"),
    "cylindrical": ("angle", "shift"), "prismatic": ("shift",), "fixed": (),
    "driven_revolute": (), "driven_prismatic": (), "distance": (),
}
#: joints that only use the points (allowed on point masses)
_POINT_ONLY = ("spherical", "distance")


@dataclass(eq=False)
class Joint:
    """A joint between bodies ``a`` and ``b`` with its geometry in principal body coordinates.

    Attributes
    ----------
    kind : str
        One of :data:`JOINT_KINDS`.
    name : str
    a, b : Body, PointMass or Ground
    point_a, point_b : ndarray (3,)
        ``X^A``, ``X^B`` (principal coordinates; world on the ground).
    frame_a, frame_b : ndarray (3, 3)
        ``F^A``, ``F^B`` (columns: the axis, then two normals).
    drive : Profile or None
        ``θ(t)`` or ``s(t)`` of a driven joint.
    length : float
        Of a distance joint.
    offset : ndarray (3,)
        A distance joint's ``x_B − x_A`` at the reference configuration, in the frame ``F^A``
        (what the kinematics keeps).
    index : int
        Its place in the mechanism.
    """

    kind: str
    name: str
    a: object
    b: object
    point_a: np.ndarray
    point_b: np.ndarray
    frame_a: np.ndarray
    frame_b: np.ndarray
    drive: Profile | None = None
    length: float = 0.0
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    index: int = -1
    rows: list = field(default_factory=list)

    @property
    def coordinates(self) -> tuple:
        """Names of the joint's coordinates (its degrees of freedom)."""
        return JOINT_KINDS[self.kind]

    def __repr__(self) -> str:
        return f"Joint({self.kind}, {self.name!r}, {self.a.name!r} → {self.b.name!r})"


# ------------------------------------------------------------------------------- geometry
def _frame(axis) -> np.ndarray:
    """An orthonormal frame whose first column is ``axis`` (unit): ``[a, n₁, n₂]``."""
    a = np.asarray(axis, dtype=float)
    trial = np.eye(3)[int(np.argmin(np.abs(a)))]
    n1 = np.cross(a, trial)
    n1 /= np.linalg.norm(n1)
    return np.column_stack([a, n1, np.cross(a, n1)])


def _unit(x, name: str, owner: str) -> np.ndarray:
    x = np.array(x, dtype=float).reshape(-1)
    if x.shape != (3,) or not np.all(np.isfinite(x)):
        raise ValueError(f"{owner}: `{name}` must be a finite 3-vector, got {x!r}")
    norm = float(np.linalg.norm(x))
    if norm == 0.0:
        raise ValueError(f"{owner}: `{name}` has zero length; give the joint's axis as a non-zero vector")
    return x / norm


def _turn(u, w) -> np.ndarray:
    """The smallest rotation taking the unit vector ``u`` to the unit vector ``w``."""
    c = float(u @ w)
    axis = np.cross(u, w)
    s = float(np.linalg.norm(axis))
    if s < 1e-15:
        if c > 0:
            return np.eye(3)
        return 2.0 * np.outer(_frame(u)[:, 1], _frame(u)[:, 1]) - np.eye(3)
    k = axis / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * K @ K


def make_joint(kind: str, name: str, a, b, *, point=None, point_a=None, point_b=None, axis=None,
               axis_a=None, axis_b=None, drive=None, length=None) -> Joint:
    """A :class:`Joint` from the user's geometry.

    Points: ``point`` (world, at the reference configuration) or ``point_a`` (A's body
    frame; world on the ground) and optionally ``point_b`` (B's frame; default: where
    ``point_a`` is at the reference configuration). Axes: ``axis`` (world) or ``axis_a``
    (A's frame) and optionally ``axis_b`` (B's frame; the universal joint's second axis,
    required there). Body frames are the user's; principal coordinates are computed here.
    """
    owner = f"{kind.replace('_', ' ')} joint {name!r}"
    if a is b:
        raise ValueError(f"{owner}: `a` and `b` are the same body {a.name!r}; a joint connects two bodies")
    if isinstance(a, Ground) and isinstance(b, Ground):
        raise ValueError(f"{owner}: both `a` and `b` are the ground")
    if kind not in _POINT_ONLY:
        for side, body in (("a", a), ("b", b)):
            if isinstance(body, PointMass):
                raise ValueError(f"{owner}: `{side}` = point mass {body.name!r} has no axes; a point mass "
                                 "takes spherical and distance joints only")
    Da, Db = _directors(a), _directors(b)
    # --- points (principal coordinates)
    if point is not None:
        if point_a is not None or point_b is not None:
            raise ValueError(f"{owner}: give `point` (world) or `point_a`/`point_b` (body frames), not both")
        world = _vec(point, "point", owner)
        Xa = Da.T @ (world - reference_point(a, np.zeros(3)))
        Xb = Db.T @ (world - reference_point(b, np.zeros(3)))
    else:
        Xa = _user_to_principal(a, _vec(point_a, "point_a", owner) if point_a is not None else np.zeros(3))
        world = reference_point(a, Xa)
        if point_b is not None:
            Xb = _user_to_principal(b, _vec(point_b, "point_b", owner))
        elif kind == "distance":  # a rod between two points: b's defaults to its origin
            Xb = np.zeros(3)
        else:
            Xb = Db.T @ (world - reference_point(b, np.zeros(3)))
    for side, body, X in (("a", a, Xa), ("b", b, Xb)):
        if isinstance(body, PointMass) and np.abs(X).max() > 1e-12 * max(1.0, np.abs(body.position).max()):
            raise ValueError(f"{owner}: the joint point is not at point mass {body.name!r} (offset {X}); a "
                             f"point mass has no extent: put the joint at its position")
    if isinstance(a, PointMass):
        Xa = np.zeros(3)
    if isinstance(b, PointMass):
        Xb = np.zeros(3)
    # --- frames: a spherical or fixed joint's frame is A's own (user) body frame
    Fa = a.axes.T if isinstance(a, Body) else np.eye(3)
    Fb = Db.T @ Da @ Fa
    if kind not in ("spherical", "fixed", "distance"):
        if axis is not None:
            if axis_a is not None:
                raise ValueError(f"{owner}: give `axis` (world) or `axis_a` (body frame of `a`), not both")
            ua = Da.T @ _unit(axis, "axis", owner)
        elif axis_a is not None:
            ua = _user_to_principal(a, _unit(axis_a, "axis_a", owner))
        else:
            raise ValueError(f"{owner}: the joint needs an axis: pass `axis` (world) or `axis_a`")
        Fa = _frame(ua)
        Fb = Db.T @ Da @ Fa
        if kind == "universal":
            if axis_b is None:
                raise ValueError(f"{owner}: a universal joint needs its second axis `axis_b` (body frame "
                                 "of `b`), perpendicular to the first at the reference configuration")
            ub = _user_to_principal(b, _unit(axis_b, "axis_b", owner))
            ub_in_a = Da.T @ Db @ ub
            if abs(float(ub_in_a @ ua)) > 1e-9:
                raise ValueError(f"{owner}: `axis_b` must be perpendicular to the first axis at the "
                                 f"reference configuration (cos of their angle = {float(ub_in_a @ ua):.3g})")
            Fa = np.column_stack([ua, ub_in_a, np.cross(ua, ub_in_a)])
            Fb = Db.T @ Da @ Fa
        elif axis_b is not None:  # B's axis as given: turn B's frame onto it
            ub = _user_to_principal(b, _unit(axis_b, "axis_b", owner))
            Fb = _turn(Fb[:, 0], ub) @ Fb
    elif axis is not None or axis_a is not None or axis_b is not None:
        raise ValueError(f"{owner}: a {kind} joint takes no axis")
    dist = 0.0
    if kind == "distance":
        dist = (float(np.linalg.norm(reference_point(a, Xa) - reference_point(b, Xb))) if length is None
                else float(length))
        if not np.isfinite(dist) or dist <= 0.0:
            raise ValueError(f"{owner}: `length` must be positive, got {length!r}")
    offset = Fa.T @ Da.T @ (reference_point(b, Xb) - reference_point(a, Xa))
    return Joint(kind, name, a, b, Xa, Xb, Fa, Fb, drive, dist, offset if kind == "distance" else np.zeros(3))


def _vec(x, name, owner) -> np.ndarray:
    x = np.array(x, dtype=float).reshape(-1)
    if x.shape != (3,) or not np.all(np.isfinite(x)):
        raise ValueError(f"{owner}: `{name}` must be a finite 3-vector, got {x!r}")
    return x


def _user_to_principal(body, x) -> np.ndarray:
    return body.to_principal(x) if not isinstance(body, Ground) else np.asarray(x, dtype=float)


# ------------------------------------------------------------------------------- rows
def _rows_builder(j: Joint, offsets: dict):
    a, b = j.a, j.b
    oa, na = offsets.get(a, -1), pk.slots_of(a)
    ob, nb = offsets.get(b, -1), pk.slots_of(b)
    out = []

    def row(label, terms, kind=pk.STATIC, c0=0.0, law=None):
        out.append((f"{j.name}: {label}", pk.row_record(kind, max(oa, 0), na, max(ob, 0), nb, terms,
                                                       c0, law)))

    return row, out


def joint_rows(j: Joint, offsets: dict) -> list:
    """``[(label, record), …]``: the rows of a joint, given each body's first coordinate."""
    row, out = _rows_builder(j, offsets)
    a, b = j.a, j.b
    pa, pb = pk.point(0, a, j.point_a), pk.point(1, b, j.point_b)
    sep = pa - pb  # r = x_A − x_B

    def dir_a(k):
        return pk.direction(0, a, j.frame_a[:, k])

    def dir_b(k):
        return pk.direction(1, b, j.frame_b[:, k])

    if j.kind == "distance":
        row("distance", [(sep, 0.5 * sep)], c0=-0.5 * j.length ** 2)
        return out
    if j.kind not in ("cylindrical", "prismatic", "driven_prismatic"):
        for k, axis in enumerate("xyz"):
            row(f"r_{axis} = 0", [(pk.constant(np.eye(3)[k]), sep)])
    if j.kind == "fixed":
        row("n0·b1 = 0", [(dir_a(0), dir_b(1))])
        row("n0·b2 = 0", [(dir_a(0), dir_b(2))])
        row("n1·b2 = 0", [(dir_a(1), dir_b(2))])
    if j.kind == "universal":
        row("a·b' = 0", [(dir_a(0), dir_b(1))])
    if j.kind in ("revolute", "driven_revolute", "cylindrical", "prismatic", "driven_prismatic"):
        row("a·b1 = 0", [(dir_a(0), dir_b(1))])
        row("a·b2 = 0", [(dir_a(0), dir_b(2))])
    if j.kind in ("cylindrical", "prismatic", "driven_prismatic"):
        row("n1·r = 0", [(dir_a(1), sep)])
        row("n2·r = 0", [(dir_a(2), sep)])
    if j.kind in ("prismatic", "driven_prismatic"):
        row("n1·b2 = 0", [(dir_a(1), dir_b(2))])
    if j.kind == "driven_revolute":
        row("angle = θ(t)", [(dir_b(1), dir_a(2)), (dir_b(1), dir_a(1))], kind=pk.DRIVE_ANGLE,
            law=j.drive.pack())
    if j.kind == "driven_prismatic":
        row("shift = s(t)", [(dir_a(0), -sep)], kind=pk.DRIVE_SHIFT, law=j.drive.pack())
    return out


def internal_rows(body, offset: int) -> list:
    """The six rows of a rigid body: ``½ (d_I·d_I − 1) = 0`` and ``d_I·d_J = 0`` (I < J)."""
    out = []
    e = np.eye(3)
    for i in range(3):
        d = pk.direction(0, body, e[i])
        out.append((f"{body.name}: |d{i + 1}| = 1",
                    pk.row_record(pk.STATIC, offset, 4, 0, 0, [(d, 0.5 * d)], -0.5)))
    for i, k in ((0, 1), (0, 2), (1, 2)):
        out.append((f"{body.name}: d{i + 1}·d{k + 1} = 0",
                    pk.row_record(pk.STATIC, offset, 4, 0, 0,
                                  [(pk.direction(0, body, e[i]), pk.direction(0, body, e[k]))])))
    return out
