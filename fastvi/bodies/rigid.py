r"""Bodies of a mechanism: rigid bodies in director coordinates, point masses and the ground.

A rigid body is ``q_b = (φ, d₁, d₂, d₃) ∈ ℝ¹²``: ``φ`` its centre of mass and ``d_I`` the
columns of its rotation matrix, taken along the **principal axes** of its inertia tensor.
A material point with coordinates ``X`` in that frame is at ``x = φ + X_I d_I``, and the
kinetic energy is

.. math::

    T = \tfrac12 m |\dot φ|^2 + \tfrac12 \sum_I E_I |\dot d_I|^2, \qquad
    E_I = \tfrac12 \operatorname{tr} J - J_I = \int X_I^2 \, dm,

so the mass matrix ``diag(m 1₃, E₁ 1₃, E₂ 1₃, E₃ 1₃)`` is constant and diagonal. The user
gives the inertia tensor ``J`` about the centre of mass in any body frame; :func:`principal`
diagonalises it once, and every point and axis the user gives in that frame is turned into
principal coordinates (``X_principal = Pᵀ X_user``). Outputs turn back: the user's rotation
matrix is ``R_user = [d₁ d₂ d₃] Pᵀ``.

A point mass is ``q = x ∈ ℝ³`` with mass matrix ``m 1₃``; the ground has no coordinates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Body", "PointMass", "Ground", "GROUND", "principal", "rotation_matrix",
           "skew", "expm_so3", "reference_directors", "reference_point"]

#: relative tolerance of the inertia checks (triangle inequality, symmetry, rotation matrices)
_RTOL = 1e-12


def skew(w) -> np.ndarray:
    """The matrix ``ŵ`` with ``ŵ x = w × x``."""
    x, y, z = (float(c) for c in w)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def expm_so3(w) -> np.ndarray:
    r"""``exp(ŵ)``, the rotation by the angle ``|w|`` about ``w`` (Rodrigues' formula)."""
    w = np.asarray(w, dtype=float)
    a = float(np.linalg.norm(w))
    K = skew(w)
    if a < 1e-8:  # series: keeps the formula exact to round-off near zero
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + math.sin(a) / a * K + (1.0 - math.cos(a)) / (a * a) * K @ K


def rotation_matrix(R, name: str) -> np.ndarray:
    """``R`` as a proper rotation matrix (3, 3), or a ValueError naming the argument."""
    R = np.array(R, dtype=float)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"`{name}` must be a finite 3×3 rotation matrix, got shape {R.shape}")
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > 1e-10 or np.linalg.det(R) < 0:
        raise ValueError(f"`{name}` must be a rotation matrix (RᵀR = 1, det R = +1): |RᵀR − 1| = "
                         f"{err:.1e}, det R = {np.linalg.det(R):.3g}")
    # round-off in a user's matrix would otherwise enter the internal constraints as |g| ~ 1e-16·…
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def _mass(value, owner: str) -> float:
    if not (isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
            and math.isfinite(value) and value > 0):
        raise ValueError(f"{owner}: `mass` must be positive and finite, got {value!r}")
    return float(value)


def _vector(x, name: str, owner: str) -> np.ndarray:
    x = np.array(x, dtype=float).reshape(-1) if x is not None else np.zeros(3)
    if x.shape != (3,) or not np.all(np.isfinite(x)):
        raise ValueError(f"{owner}: `{name}` must be a finite 3-vector, got {x!r}")
    return x


def principal(inertia, owner: str = "body"):
    r"""Principal moments ``J_I`` and axes ``P`` of an inertia tensor about the centre of mass.

    Parameters
    ----------
    inertia : array_like (3, 3) or (3,)
        The symmetric inertia tensor in the user's body frame, or its diagonal.
    owner : str
        Named in error messages (``"body 'top'"``).

    Returns
    -------
    J : ndarray (3,)
        Principal moments, in the order of the columns of ``P``.
    P : ndarray (3, 3)
        A rotation whose columns are the principal axes in the user's frame. A diagonal
        tensor keeps the user's axes (``P = 1``).

    Raises
    ------
    ValueError
        A tensor that is not symmetric, a negative moment, or moments that break the
        triangle inequality ``J₁ + J₂ ≥ J₃`` (and its permutations): no mass distribution has
        them. A moment ``J_I = J_J + J_K`` (a lamina, ``E_I = 0``) is allowed here.
    """
    J = np.array(inertia, dtype=float)
    if J.shape == (3,):
        J = np.diag(J)
    if J.shape != (3, 3) or not np.all(np.isfinite(J)):
        raise ValueError(f"{owner}: `inertia` must be a finite 3×3 tensor or its diagonal (3,), "
                         f"got shape {J.shape}")
    scale = max(float(np.abs(J).max()), 1e-300)
    if np.abs(J - J.T).max() > _RTOL * scale:
        raise ValueError(f"{owner}: `inertia` must be symmetric, got {J.tolist()}")
    off = J - np.diag(np.diag(J))
    if not off.any():
        moments, P = np.diag(J).copy(), np.eye(3)
    else:
        moments, P = np.linalg.eigh(0.5 * (J + J.T))
        if np.linalg.det(P) < 0:
            P[:, 2] = -P[:, 2]
    if np.any(moments <= 0.0):
        raise ValueError(f"{owner}: `inertia` has a principal moment <= 0 ({moments.tolist()}); a "
                         "rigid body's principal moments about its centre of mass are positive")
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        if moments[j] + moments[k] < moments[i] * (1.0 - _RTOL):
            raise ValueError(
                f"{owner}: `inertia` breaks the triangle inequality J{j + 1} + J{k + 1} >= J{i + 1} of "
                f"its principal moments {moments.tolist()}: no mass distribution has it (E{i + 1} = "
                f"½ tr J − J{i + 1} = {0.5 * moments.sum() - moments[i]:.3g} < 0)")
    return moments, P


@dataclass(frozen=True, eq=False)
class Ground:
    """The fixed frame: points and axes given on it are in world coordinates."""

    name: str = "ground"

    def __repr__(self) -> str:
        return "GROUND"


#: the ground, for joints and springs to the fixed frame (``"ground"`` is accepted as well)
GROUND = Ground()


@dataclass(eq=False)
class PointMass:
    """A point mass: three coordinates ``x``, no orientation (a spherical joint with it is a
    rigid attachment).

    Parameters
    ----------
    name : str
    mass : float
    position, velocity : array_like (3,)
    """

    name: str
    mass: float
    position: np.ndarray
    velocity: np.ndarray
    index: int = -1
    size = 3

    def __post_init__(self):
        owner = f"point mass {self.name!r}"
        self.mass = _mass(self.mass, owner)
        self.position = _vector(self.position, "position", owner)
        self.velocity = _vector(self.velocity, "velocity", owner)

    @property
    def rotation(self) -> np.ndarray:
        return np.eye(3)

    @property
    def omega(self) -> np.ndarray:
        return np.zeros(3)

    def to_principal(self, X) -> np.ndarray:
        return np.asarray(X, dtype=float)

    def coordinates(self):
        """``(q, v)`` of the point mass (3,)."""
        return self.position.copy(), self.velocity.copy()

    def mass_diagonal(self) -> np.ndarray:
        return np.full(3, self.mass)

    def __repr__(self) -> str:
        return f"PointMass({self.name!r}, m={self.mass:g})"


@dataclass(eq=False)
class Body:
    r"""A rigid body.

    Parameters
    ----------
    name : str
    mass : float
        Positive.
    inertia : array_like (3, 3) or (3,)
        Inertia tensor about the centre of mass in the body frame (or its diagonal).
    position : array_like (3,)
        Centre of mass in the world at the reference (assembly) configuration.
    rotation : array_like (3, 3)
        Body frame → world at the reference configuration (columns: the body axes).
    velocity : array_like (3,)
        Velocity of the centre of mass.
    omega : array_like (3,)
        Angular velocity in the world frame; or ``omega_body`` in the body frame.

    Attributes
    ----------
    moments : ndarray (3,)
        Principal moments ``J_I`` (the directors' order).
    axes : ndarray (3, 3)
        ``P``: the principal axes (columns) in the user's body frame.
    second_moments : ndarray (3,)
        ``E_I = ½ tr J − J_I``, the directors' inertias.
    """

    name: str
    mass: float
    inertia: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray
    index: int = -1
    moments: np.ndarray = field(init=False)
    axes: np.ndarray = field(init=False)
    second_moments: np.ndarray = field(init=False)
    size = 12

    def __post_init__(self):
        owner = f"body {self.name!r}"
        self.mass = _mass(self.mass, owner)
        self.moments, self.axes = principal(self.inertia, owner)
        self.inertia = self.axes @ np.diag(self.moments) @ self.axes.T
        self.second_moments = 0.5 * self.moments.sum() - self.moments
        # a moment at the triangle's edge is a lamina: E_I is round-off, make it exact
        self.second_moments[np.abs(self.second_moments) <= _RTOL * self.moments.sum()] = 0.0
        self.position = _vector(self.position, "position", owner)
        self.velocity = _vector(self.velocity, "velocity", owner)
        self.omega = _vector(self.omega, "omega", owner)
        self.rotation = rotation_matrix(self.rotation, f"{owner}: rotation")

    def to_principal(self, X) -> np.ndarray:
        """Body-frame coordinates of a point or axis in the principal (director) frame."""
        return self.axes.T @ np.asarray(X, dtype=float)

    def directors(self) -> np.ndarray:
        """The reference directors ``[d₁ d₂ d₃] = R P`` (columns)."""
        return self.rotation @ self.axes

    def coordinates(self):
        """``(q, v)`` of the body (12,): ``(φ, d₁, d₂, d₃)`` and ``ḋ_I = ω × d_I``."""
        D = self.directors()
        q = np.concatenate([self.position, D[:, 0], D[:, 1], D[:, 2]])
        Dd = np.cross(self.omega, D.T)
        v = np.concatenate([self.velocity, Dd[0], Dd[1], Dd[2]])
        return q, v

    def mass_diagonal(self) -> np.ndarray:
        return np.concatenate([np.full(3, self.mass), np.repeat(self.second_moments, 3)])

    def __repr__(self) -> str:
        return f"Body({self.name!r}, m={self.mass:g}, J={self.moments.tolist()})"


def reference_directors(body) -> np.ndarray:
    """World directions of a body's principal axes at the reference configuration (columns);
    the identity for the ground and a point mass."""
    return body.directors() if isinstance(body, Body) else np.eye(3)


def reference_point(body, X) -> np.ndarray:
    """World position of the point ``X`` (principal coordinates; world on the ground) at the
    reference configuration."""
    origin = np.zeros(3) if isinstance(body, Ground) else body.position
    return origin + reference_directors(body) @ np.asarray(X, dtype=float)
