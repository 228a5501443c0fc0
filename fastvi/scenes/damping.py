r"""Linear viscous damping ``F = −c v`` on every coordinate, shared by the scenes.

The damping coefficient is the **last** entry of the scene's parameter vector, so a scene
appends it to its own parameters and these functions serve every scene. For point masses in
Cartesian coordinates ``−c v`` is a dashpot to the ground on every mass (force ``−c ṙ_i``).
Its derivative by the parameters is ``∂F/∂c = −v`` and zero by every other parameter
(:func:`param_derivatives`).
"""

from __future__ import annotations

import numpy as np


def force(t, q, v, p, out):
    c = p[p.shape[0] - 1]
    for a in range(q.shape[0]):
        out[a] = -c * v[a]


def jacobian_v(t, q, v, p, out):
    """``∂F/∂v = −c I``: the diagonal, its ``force_jacobian_pattern``, alone."""
    c = p[p.shape[0] - 1]
    for a in range(q.shape[0]):
        out[a, a] = -c


def force_by_params(t, q, v, p, out):
    """``out[l] = ∂F/∂θ_l``: ``−v`` for the last parameter ``c``, zero for the others (the
    entries of :func:`param_patterns`, the only ones written)."""
    last = p.shape[0] - 1
    for a in range(q.shape[0]):
        out[last, a] = -v[a]


def param_derivatives(damping) -> dict:
    """The ``param_derivatives`` entries of the force of a scene with ``damping`` (none for
    ``0``): merge them into the scene's own, with :func:`param_patterns`."""
    return {"force": force_by_params} if damping else {}


def param_patterns(damping, k: int, n: int) -> dict:
    """The ``param_patterns`` entry of the force of a scene with ``damping`` and ``k``
    parameters, ``n`` coordinates: the row of ``c`` (none for ``0``)."""
    if not damping:
        return {}
    return {"force": (np.full(n, k - 1), np.arange(n))}


def options(damping, n: int) -> dict:
    """The ``Model`` keyword arguments of a scene with ``damping`` and ``n`` coordinates
    (none for ``0``)."""
    if not damping:
        return {}
    # ∂F/∂q = 0 declared, not a callback: an n × n block of zeros a quadrature point was
    # most of a large chain's exact Newton matrix
    return dict(force=force, force_jacobian_q=0, force_jacobian_v=jacobian_v,
                force_jacobian_pattern=(np.arange(n), np.arange(n)))


def check(damping) -> float:
    """``damping`` as a float: zero (no force at all) or positive and finite."""
    import math

    if isinstance(damping, bool) or not isinstance(damping, (int, float)) and not hasattr(damping, "__float__"):
        raise TypeError(f"`damping` must be a float, got {damping!r}")
    c = float(damping)
    if not (math.isfinite(c) and c >= 0.0):
        raise ValueError(f"`damping` must be >= 0 and finite, got {damping!r}")
    return c
