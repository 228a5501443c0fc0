r"""Build a multibody mechanism and turn it into a ``fastvi.Model``: :class:`Mechanism`.

.. code-block:: python

    from fastvi import bodies

    mech = bodies.Mechanism(gravity=(0, 0, -9.81))
    top = mech.body("top", mass=15.0, inertia=(0.234375, 0.46875, 0.234375),
                    omega_body=(0, 150, -4.61538))
    mech.spherical(bodies.GROUND, top, point_b=(0, -1, 0))   # the fixed point, in the body frame
    model = mech.build()
    q0, v0 = model.initial_state()
    res = fastvi.integrate(model, q0, v0, h=1e-3, t_end=2.0)

Bodies are added at their **reference configuration** (position, rotation, velocity, angular
velocity); joints are defined by points and axes in the body frames, or in the world at the
reference configuration, and measure their angles from it. :meth:`Mechanism.build` numbers
the coordinates, writes the rows and loads into the parameter vector
(:mod:`fastvi.bodies.packing`), finds the degrees of freedom and the redundant rows
(:mod:`fastvi.bodies.redundancy`), drops those, and returns an ordinary ``fastvi.Model`` whose
callbacks are the generic ones of :mod:`fastvi.bodies.callbacks`, with the description of the
mechanism attached as ``model.assembly`` (:class:`Assembly`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import Model
from . import callbacks as cb
from . import packing as pk
from .joints import Joint, internal_rows, joint_rows, make_joint
from .loads import Load, applied, load_record, rotary_spring, spring
from .profile import as_profile
from .redundancy import RANK_RTOL, DegreesOfFreedom, analyse, twist_basis
from .rigid import GROUND, Body, Ground, PointMass

__all__ = ["Mechanism", "Assembly"]


@dataclass(frozen=True, eq=False)
class Assembly:
    """A built mechanism: what the outputs and initial-data helpers read (``model.assembly``).

    Attributes
    ----------
    name : str
    bodies : tuple
        Bodies and point masses in coordinate order.
    offsets : dict
        Body → index of its first coordinate.
    joints : tuple of Joint
    loads : tuple of Load
    gravity : ndarray (3,)
    row_labels : tuple of str
        A label per row of the model's ``g``.
    row_joint : ndarray of int
        The joint of each row (−1 for a body's own rows).
    joint_row_indices : ndarray of int
        The model's rows that belong to joints.
    dof : DegreesOfFreedom
        Found at the reference configuration before the redundant rows were dropped.
    q_ref, v_ref : ndarray (n,)
        The bodies' reference configuration and velocities as given.
    """

    name: str
    bodies: tuple
    offsets: dict
    joints: tuple
    loads: tuple
    gravity: np.ndarray
    row_labels: tuple
    row_joint: np.ndarray
    joint_row_indices: np.ndarray
    dof: DegreesOfFreedom
    q_ref: np.ndarray
    v_ref: np.ndarray

    def body(self, key):
        """A body by name, index or object."""
        return _find(self.bodies, key, "body")

    def joint(self, key) -> Joint:
        """A joint by name, index or object."""
        return _find(self.joints, key, "joint")

    def rows_of(self, joint) -> np.ndarray:
        """The model's rows of ``joint``."""
        return np.flatnonzero(self.row_joint == self.joint(joint).index)

    def slice(self, body) -> slice:
        """The coordinates of ``body``."""
        b = self.body(body)
        return slice(self.offsets[b], self.offsets[b] + b.size)


def _find(items, key, what):
    for item in items:
        if item is key or (isinstance(key, str) and item.name == key):
            return item
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool) and 0 <= key < len(items):
        return items[int(key)]
    names = ", ".join(repr(i.name) for i in items)
    raise KeyError(f"no {what} {key!r}; the {what}s are {names}")


def _name_of(x) -> str:
    return repr(getattr(x, "name", x))


class Mechanism:
    r"""A multibody mechanism: rigid bodies, point masses, joints and loads.

    Parameters
    ----------
    gravity : array_like (3,), default (0, 0, −9.81)
        The acceleration of gravity (world frame).
    name : str, default "mechanism"

    Notes
    -----
    Every ``a``/``b``/``body`` argument takes a body object returned by :meth:`body` or
    :meth:`point_mass`, its name, its index (in the order of addition), or the ground
    (:data:`fastvi.bodies.GROUND` or ``"ground"``). Joint geometry: ``point`` and ``axis`` in
    the world at the reference configuration, or ``point_a``/``axis_a`` in the body frame of
    ``a`` (world on the ground) with ``point_b``/``axis_b`` optional in the frame of ``b``
    (default: where ``a``'s are at the reference configuration).
    """

    def __init__(self, gravity=(0.0, 0.0, -9.81), name: str = "mechanism"):
        g = np.array(gravity, dtype=float).reshape(-1)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f"`gravity` must be a finite 3-vector, got {gravity!r}")
        self.gravity = g
        self.name = str(name)
        self.bodies: list = []
        self.joints: list[Joint] = []
        self.loads: list[Load] = []

    ground = GROUND

    # ------------------------------------------------------------------ bodies
    def _new_name(self, name, prefix: str, items) -> str:
        name = f"{prefix}{len(items)}" if name is None else str(name)
        if any(x.name == name for x in items) or name == "ground":
            raise ValueError(f"the name {name!r} is taken; give each {prefix.rstrip('_')} its own name")
        return name

    def body(self, name: str, *, mass: float, inertia, position=(0.0, 0.0, 0.0), rotation=None,
             velocity=(0.0, 0.0, 0.0), omega=None, omega_body=None) -> Body:
        r"""Add a rigid body at its reference configuration.

        Parameters
        ----------
        name : str
        mass : float
        inertia : array_like (3, 3) or (3,)
            Inertia tensor about the centre of mass in the body frame (or its diagonal); it
            is diagonalised here (:func:`fastvi.bodies.rigid.principal`), and its principal
            moments must satisfy the triangle inequality.
        position : array_like (3,)
            Centre of mass (world).
        rotation : array_like (3, 3), default identity
            Body frame → world.
        velocity : array_like (3,)
            Velocity of the centre of mass.
        omega, omega_body : array_like (3,), optional
            Angular velocity in the world or the body frame (at most one).

        Returns
        -------
        Body
        """
        name = self._new_name(name, "body_", self.bodies)
        if omega is not None and omega_body is not None:
            raise ValueError(f"body {name!r}: give `omega` (world) or `omega_body` (body frame), not both")
        R = np.eye(3) if rotation is None else rotation
        b = Body(name, mass, inertia, position, R, velocity, np.zeros(3))
        if omega_body is not None:
            b.omega = b.rotation @ np.asarray(omega_body, dtype=float).reshape(3)
        elif omega is not None:
            b.omega = np.asarray(omega, dtype=float).reshape(3)
        if not np.all(np.isfinite(b.omega)):
            raise ValueError(f"body {name!r}: the angular velocity must be finite")
        b.index = len(self.bodies)
        self.bodies.append(b)
        return b

    def point_mass(self, name: str, *, mass: float, position, velocity=(0.0, 0.0, 0.0)) -> PointMass:
        """Add a point mass (three coordinates, no orientation).

        Returns
        -------
        PointMass
        """
        name = self._new_name(name, "point_", self.bodies)
        pm = PointMass(name, mass, position, velocity)
        pm.index = len(self.bodies)
        self.bodies.append(pm)
        return pm

    def _resolve(self, x, arg: str, owner: str):
        if x is GROUND or (isinstance(x, str) and x == "ground") or isinstance(x, Ground):
            return GROUND
        for b in self.bodies:
            if b is x or (isinstance(x, str) and b.name == x):
                return b
        if isinstance(x, (int, np.integer)) and not isinstance(x, bool) and 0 <= x < len(self.bodies):
            return self.bodies[int(x)]
        names = ", ".join(f"{i}: {b.name!r}" for i, b in enumerate(self.bodies)) or "none yet"
        raise ValueError(f"{owner}: argument `{arg}` = {x!r} is not a body of mechanism {self.name!r} "
                         f"(bodies {names}; the ground is fastvi.bodies.GROUND or 'ground')")

    # ------------------------------------------------------------------ joints
    def _joint(self, kind, a, b, name, **geometry) -> Joint:
        name = self._new_name(name, f"{kind}_", self.joints)
        owner = f"{kind.replace('_', ' ')} joint {name!r}"
        A, B = self._resolve(a, "a", owner), self._resolve(b, "b", owner)
        j = make_joint(kind, name, A, B, **geometry)
        j.index = len(self.joints)
        self.joints.append(j)
        return j

    def spherical(self, a, b, *, point=None, point_a=None, point_b=None, name=None) -> Joint:
        """A ball joint: the points coincide (3 rows)."""
        return self._joint("spherical", a, b, name, point=point, point_a=point_a, point_b=point_b)

    def revolute(self, a, b, *, point=None, point_a=None, point_b=None, axis=None, axis_a=None,
                 axis_b=None, name=None) -> Joint:
        """A hinge about ``axis`` through ``point`` (5 rows)."""
        return self._joint("revolute", a, b, name, point=point, point_a=point_a, point_b=point_b,
                           axis=axis, axis_a=axis_a, axis_b=axis_b)

    def universal(self, a, b, *, axis_a, axis_b, point=None, point_a=None, point_b=None,
                  name=None) -> Joint:
        """A Cardan joint: the points coincide and ``axis_a`` (in ``a``) stays perpendicular to
        ``axis_b`` (in ``b``) (4 rows). The axes must be perpendicular at the reference
        configuration."""
        return self._joint("universal", a, b, name, point=point, point_a=point_a, point_b=point_b,
                           axis_a=axis_a, axis_b=axis_b)

    def cylindrical(self, a, b, *, point=None, point_a=None, point_b=None, axis=None, axis_a=None,
                    axis_b=None, name=None) -> Joint:
        """Rotation about and sliding along ``axis`` (4 rows)."""
        return self._joint("cylindrical", a, b, name, point=point, point_a=point_a, point_b=point_b,
                           axis=axis, axis_a=axis_a, axis_b=axis_b)

    def prismatic(self, a, b, *, point=None, point_a=None, point_b=None, axis=None, axis_a=None,
                  axis_b=None, name=None) -> Joint:
        """Sliding along ``axis`` without rotation (5 rows)."""
        return self._joint("prismatic", a, b, name, point=point, point_a=point_a, point_b=point_b,
                           axis=axis, axis_a=axis_a, axis_b=axis_b)

    def fixed(self, a, b, *, point=None, point_a=None, point_b=None, name=None) -> Joint:
        """A rigid connection (6 rows)."""
        return self._joint("fixed", a, b, name, point=point, point_a=point_a, point_b=point_b)

    def distance(self, a, b, *, point_a=None, point_b=None, length=None, name=None) -> Joint:
        """A massless rod between ``point_a`` and ``point_b`` (body frames, default the centres of
        mass): ``|x_A − x_B| = length`` (1 row; default: the reference distance)."""
        return self._joint("distance", a, b, name, point_a=point_a, point_b=point_b, length=length)

    def driven_revolute(self, a, b, angle, *, point=None, point_a=None, point_b=None, axis=None,
                        axis_a=None, axis_b=None, name=None) -> Joint:
        r"""A revolute joint whose angle is prescribed, ``θ(t)`` (6 rows; time-dependent).

        ``angle`` is a :class:`~fastvi.bodies.Profile` (or a constant), measured from the
        reference configuration; its multiplier is the motor torque."""
        drive = as_profile(angle, "angle", f"driven revolute joint {name!r}")
        return self._joint("driven_revolute", a, b, name, point=point, point_a=point_a,
                           point_b=point_b, axis=axis, axis_a=axis_a, axis_b=axis_b, drive=drive)

    def driven_prismatic(self, a, b, shift, *, point=None, point_a=None, point_b=None, axis=None,
                         axis_a=None, axis_b=None, name=None) -> Joint:
        """A prismatic joint whose displacement ``s(t)`` along ``axis`` is prescribed (6 rows)."""
        drive = as_profile(shift, "shift", f"driven prismatic joint {name!r}")
        return self._joint("driven_prismatic", a, b, name, point=point, point_a=point_a,
                           point_b=point_b, axis=axis, axis_a=axis_a, axis_b=axis_b, drive=drive)

    # ------------------------------------------------------------------ loads
    def _point(self, body, X, arg, owner):
        if X is None:
            return np.zeros(3)
        X = np.array(X, dtype=float).reshape(-1)
        if X.shape != (3,) or not np.all(np.isfinite(X)):
            raise ValueError(f"{owner}: `{arg}` must be a finite 3-vector, got {X!r}")
        if isinstance(body, PointMass) and np.any(X != 0):
            raise ValueError(f"{owner}: `{arg}` must be (0, 0, 0) on point mass {body.name!r}")
        return body.to_principal(X) if isinstance(body, Body) else X

    def spring(self, a, b, *, stiffness: float, damping: float = 0.0, length=None, point_a=None,
               point_b=None, name=None) -> Load:
        """A linear spring–damper between ``point_a`` on ``a`` and ``point_b`` on ``b`` (body
        frames; world on the ground); ``length`` the rest length (default: the reference
        distance; 0: a zero-length spring ``½ k |r|²`` with a vector damper)."""
        name = self._new_name(name, "spring_", self.loads)
        owner = f"spring {name!r}"
        A, B = self._resolve(a, "a", owner), self._resolve(b, "b", owner)
        ld = spring(name, A, B, self._point(A, point_a, "point_a", owner),
                    self._point(B, point_b, "point_b", owner), stiffness, damping, length)
        return self._add_load(ld)

    def rotary_spring(self, joint, *, stiffness: float, damping: float = 0.0, angle: float = 0.0,
                      name=None) -> Load:
        """A torsion spring–damper about a revolute or cylindrical joint's axis, at rest at
        ``angle`` (the joint's angle, 0 at the reference configuration)."""
        name = self._new_name(name, "rotary_spring_", self.loads)
        j = _find(self.joints, joint, "joint") if not isinstance(joint, Joint) else joint
        return self._add_load(rotary_spring(name, j, stiffness, damping, angle))

    def force(self, body, force, *, point=None, profile=1.0, name=None) -> Load:
        """A force ``force · s(t)`` (world) at ``point`` (body frame; default the centre of
        mass) of ``body``; ``profile`` is ``s`` (a Profile or a constant)."""
        name = self._new_name(name, "force_", self.loads)
        owner = f"force {name!r}"
        B = self._resolve(body, "body", owner)
        ld = applied("force", name, B, force, self._point(B, point, "point", owner),
                     as_profile(profile, "profile", owner))
        return self._add_load(ld)

    def torque(self, body, torque, *, profile=1.0, name=None) -> Load:
        """A torque ``torque · s(t)`` (world) on a rigid body."""
        name = self._new_name(name, "torque_", self.loads)
        owner = f"torque {name!r}"
        B = self._resolve(body, "body", owner)
        return self._add_load(applied("torque", name, B, torque, np.zeros(3),
                                      as_profile(profile, "profile", owner)))

    def _add_load(self, load: Load) -> Load:
        load.index = len(self.loads)
        self.loads.append(load)
        return load

    # ------------------------------------------------------------------ build
    def coordinates(self):
        """``(offsets, q_ref, v_ref, mass diagonal)`` in the order the bodies were added."""
        offsets, qs, vs, ms = {}, [], [], []
        o = 0
        for b in self.bodies:
            offsets[b] = o
            q, v = b.coordinates()
            qs.append(q)
            vs.append(v)
            ms.append(b.mass_diagonal())
            o += b.size
        return offsets, np.concatenate(qs), np.concatenate(vs), np.concatenate(ms)

    def rows(self, offsets):
        """``(labels, records, joint of each row)``: the bodies' own rows, then the joints'."""
        labels, records, owner = [], [], []
        for b in self.bodies:
            if isinstance(b, Body):
                for label, rec in internal_rows(b, offsets[b]):
                    labels.append(label)
                    records.append(rec)
                    owner.append(-1)
        for j in self.joints:
            for label, rec in joint_rows(j, offsets):
                labels.append(label)
                records.append(rec)
                owner.append(j.index)
        return labels, np.array(records).reshape(-1, pk.ROW_W), np.array(owner, dtype=int)

    def build(self, *, redundant: str = "drop", rank_rtol: float = RANK_RTOL, t0: float = 0.0,
              name: str | None = None) -> Model:
        """The ``fastvi.Model`` of the mechanism.

        Parameters
        ----------
        redundant : {"drop", "keep", "raise"}, default "drop"
            What to do with redundant joint rows found at the reference configuration
            (:func:`fastvi.bodies.redundancy.analyse`): drop them (the factorisation's choice),
            keep every row (the step's Newton matrix is then singular), or raise.
        rank_rtol : float
            Relative pivot size below which a row counts as redundant.
        t0 : float, default 0
            The time of the reference configuration (for driven joints).
        name : str, optional
            The model's name (default: the mechanism's).

        Returns
        -------
        fastvi.Model
            With ``model.assembly`` (:class:`Assembly`), ``model.dof`` (the
            :class:`~fastvi.bodies.redundancy.DegreesOfFreedom` found) and
            ``model.initial_state(values=None, rates=None, t=t0)``. It counts as checked:
            ``fastvi.integrate`` does not compare its derivatives with finite differences
            (the library's callbacks are tested on every joint and load kind, and the
            comparison costs ``O(m n²)``); ``model.check(q, v)`` runs it on demand.
        """
        if redundant not in ("drop", "keep", "raise"):
            raise ValueError(f"`redundant` must be 'drop', 'keep' or 'raise', got {redundant!r}")
        if not self.bodies:
            raise ValueError(f"mechanism {self.name!r} has no bodies; add some with `body()` or "
                             "`point_mass()`")
        offsets, q_ref, v_ref, mdiag = self.coordinates()
        n = q_ref.shape[0]
        labels, records, owner = self.rows(offsets)
        linear = np.zeros(n)
        for b in self.bodies:
            linear[offsets[b]: offsets[b] + 3] = -b.mass * self.gravity
        loads = np.array([load_record(ld, offsets) for ld in self.loads]).reshape(-1, pk.LOAD_W)
        timed = any(j.drive is not None for j in self.joints)
        springs = any(ld.stiffness > 0 for ld in self.loads)
        forced = any(ld.kind in ("force", "torque") or ld.damping > 0 for ld in self.loads)
        make = dict(n=n, linear=linear, loads=loads, mdiag=mdiag, timed=timed, springs=springs,
                    forced=forced, name=name or self.name)
        model = self._model(records, **make)
        # the rank at the reference configuration, from the compiled Jacobian of every row
        G = model.constraint_jacobian_value(q_ref, t=float(t0)) if records.shape[0] else np.zeros((0, n))
        dof = analyse(G, twist_basis(self.bodies, offsets, q_ref), np.flatnonzero(owner >= 0), labels,
                      rank_rtol)
        if dof.redundant and redundant == "raise":
            raise ValueError(f"mechanism {self.name!r}: {dof}")
        if dof.redundant and redundant == "drop":
            keep = np.array(dof.kept_rows, dtype=int)
            records, owner = records[keep], owner[keep]
            labels = [labels[i] for i in keep]
            model = self._model(records, **make)
        model_name = make["name"]
        model.assembly = Assembly(
            name=model_name, bodies=tuple(self.bodies), offsets=dict(offsets), joints=tuple(self.joints),
            loads=tuple(self.loads), gravity=self.gravity.copy(), row_labels=tuple(labels), row_joint=owner,
            joint_row_indices=np.flatnonzero(owner >= 0), dof=dof, q_ref=q_ref, v_ref=v_ref)
        model.dof = dof
        from .drawing import mechanism_drawing

        model.drawing = mechanism_drawing(model.assembly)
        # The callbacks are the library's, checked against finite differences on every row and
        # load kind (tests/test_bodies.py); the automatic check of the first integration costs
        # O(m n²) (116 s for 64 bodies), so a built model counts as checked. Model.check(q, v)
        # still runs it on demand.
        model.checked = True
        from .kinematics import initial_state

        def _initial_state(values=None, rates=None, t=t0):
            return initial_state(model, values, rates, t=t)

        _initial_state.__doc__ = initial_state.__doc__
        model.initial_state = _initial_state
        return model

    def _model(self, records, *, n, linear, loads, mdiag, timed, springs, forced, name) -> Model:
        """The ``fastvi.Model`` of the given rows. A lamina's or a rod's zero director inertia
        makes the mass matrix singular, which the Model accepts where it is definite on the
        tangent space of the constraints (checked by the first integration)."""
        m = records.shape[0]
        cols = [pk.row_columns(records[a]) for a in range(m)]
        rows = np.array([a for a in range(m) for _ in cols[a]], dtype=np.int64)
        pattern = (rows, np.array([c for cs in cols for c in cs], dtype=np.int64)) if m else None
        params = pk.pack(n, linear, records, loads)
        return Model(n, m, params=params, mass=mdiag, name=name, time_dependent=timed,
                     constraint_jacobian_pattern=pattern, fixed_params=pk.structural(params),
                     **cb.model_callbacks(timed, springs, forced))

    def __repr__(self) -> str:
        return (f"Mechanism({self.name!r}: {len(self.bodies)} bodies, {len(self.joints)} joints, "
                f"{len(self.loads)} loads)")
