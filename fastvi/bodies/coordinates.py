r"""Joint coordinates as functions of the director coordinates, with their gradients.

For a joint with frames ``F^A = [a, n₁, n₂]`` in A and ``F^B = [b, b₁, b₂]`` in B (world
vectors ``n₁ = Σ_I F^A_{I1} d^A_I`` and so on, :mod:`fastvi.bodies.joints`):

- the **angle** ``θ = atan2(y, x)``, ``x = b₁·n₁``, ``y = b₁·n₂`` (revolute, driven revolute,
  cylindrical), with ``∇θ = (x ∇y − y ∇x)/(x² + y²)``;
- the **shift** ``s = a·(x_B(X^B) − x_A(X^A))`` (prismatic, driven prismatic, cylindrical).

Both vanish at the reference configuration. :func:`joint_coordinates` returns the values and
the gradients (rows of length ``n``) at one configuration: the outputs read the values, the
initial-data builder holds given coordinates with the gradients.
"""

from __future__ import annotations

import numpy as np

from .rigid import Body, Ground

__all__ = ["joint_coordinates", "HAS_COORDINATES"]

#: the joints whose coordinates are functions of q here
HAS_COORDINATES = ("revolute", "driven_revolute", "cylindrical", "prismatic", "driven_prismatic")


def _vector(asm, body, q, u, point: bool):
    """World vector of body-fixed ``u`` (a direction, or a point if ``point``) and its
    gradient as ``{first column: 3×3 block}``."""
    if isinstance(body, Ground):
        return np.asarray(u, dtype=float), {}
    o = asm.offsets[body]
    blocks = {}
    val = q[o: o + 3].copy() if point else np.zeros(3)
    if point:
        blocks[o] = np.eye(3)
    if isinstance(body, Body):
        for i in range(3):
            val = val + u[i] * q[o + 3 + 3 * i: o + 6 + 3 * i]
            blocks[o + 3 + 3 * i] = u[i] * np.eye(3)
    return val, blocks


def _dot_gradient(n, U, dU, W, dW):
    """``∇(U·W)`` (n,) from the values and their blockwise gradients."""
    g = np.zeros(n)
    for col, B in dU.items():
        g[col: col + 3] += B.T @ W
    for col, B in dW.items():
        g[col: col + 3] += B.T @ U
    return g


def joint_coordinates(asm, joint, q):
    """``(values, gradients)`` of the joint's coordinates at ``q``: shapes (k,) and (k, n);
    ``k = 0`` for a joint without coordinates here (spherical, universal, fixed, distance)."""
    n = q.shape[0]
    vals, grads = [], []
    j = joint
    if j.kind in ("revolute", "driven_revolute", "cylindrical"):
        b1, db1 = _vector(asm, j.b, q, j.frame_b[:, 1], False)
        n1, dn1 = _vector(asm, j.a, q, j.frame_a[:, 1], False)
        n2, dn2 = _vector(asm, j.a, q, j.frame_a[:, 2], False)
        x, y = b1 @ n1, b1 @ n2
        gx, gy = _dot_gradient(n, b1, db1, n1, dn1), _dot_gradient(n, b1, db1, n2, dn2)
        vals.append(np.arctan2(y, x))
        grads.append((x * gy - y * gx) / (x * x + y * y))
    if j.kind in ("prismatic", "driven_prismatic", "cylindrical"):
        a, da = _vector(asm, j.a, q, j.frame_a[:, 0], False)
        xb, dxb = _vector(asm, j.b, q, j.point_b, True)
        xa, dxa = _vector(asm, j.a, q, j.point_a, True)
        r = xb - xa
        dr = dict(dxb)
        for col, B in dxa.items():
            dr[col] = dr.get(col, 0.0) - B
        vals.append(a @ r)
        grads.append(_dot_gradient(n, a, da, r, dr))
    return np.array(vals), np.array(grads).reshape(len(vals), n)
