r"""Rigid bodies in director coordinates, a joint library and redundant constraints.

A mechanism of rigid bodies, point masses and joints becomes an ordinary
:class:`fastvi.Model`: each rigid body is ``(φ, d₁, d₂, d₃) ∈ ℝ¹²`` (centre of mass and
principal directors) with a constant diagonal mass matrix and six quadratic constraints of
its own; every joint equation is at most bilinear, so every Hessian is exact and constant.
The callbacks are written once (:mod:`fastvi.bodies.callbacks`) and read the mechanism from
the parameter vector, so they compile once per size ``(n, m)``. See ``docs/rigid-bodies.md``.

Build with :class:`Mechanism`; read the results with the functions of
:mod:`fastvi.bodies.outputs`; ready-made mechanisms are in :mod:`fastvi.bodies.scenes`.
"""

from .mechanism import Assembly, Mechanism
from .profile import Profile
from .redundancy import DegreesOfFreedom, RankCheck, recheck
from .rigid import GROUND, Body, PointMass
from .kinematics import initial_state
from . import outputs

__all__ = ["Mechanism", "Assembly", "Profile", "GROUND", "Body", "PointMass", "DegreesOfFreedom",
           "RankCheck", "recheck", "initial_state", "outputs"]
