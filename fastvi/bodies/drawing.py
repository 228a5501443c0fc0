"""How a built mechanism is drawn (``model.drawing``, for :meth:`fastvi.Result.animate`).

Every body and point mass is a point at its centre of mass; every joint is a point at its
location on its first body (on the ground: a pivot), joined by bars to the centres of the two
bodies it connects. Rigid bodies also show their body frames, the directors ``d₁, d₂, d₃``
(principal axes).
"""

from __future__ import annotations

import numpy as np

from ..drawing import Drawing
from .outputs import _directors, _world_point
from .rigid import Body, Ground


def mechanism_drawing(asm) -> Drawing:
    """The :class:`fastvi.drawing.Drawing` of the built mechanism ``asm`` (an
    :class:`~fastvi.bodies.mechanism.Assembly`)."""
    movers = [b for b in asm.bodies if not isinstance(b, Ground)]
    rigid = [b for b in movers if isinstance(b, Body)]
    centre = {b: i for i, b in enumerate(movers)}
    links, pivots = [], []
    for k, j in enumerate(asm.joints):
        at = len(movers) + k
        for body in (j.a, j.b):
            if not isinstance(body, Ground):
                links.append((centre[body], at))
        if isinstance(j.a, Ground) or isinstance(j.b, Ground):
            pivots.append(at)

    def points(q):
        q2 = np.asarray(q, dtype=float).reshape(1, -1)
        out = [q2[0, asm.offsets[b]: asm.offsets[b] + 3] for b in movers]
        for j in asm.joints:
            body, X = (j.b, j.point_b) if isinstance(j.a, Ground) else (j.a, j.point_a)
            out.append(_world_point(q2, body, asm, X)[0])
        return np.array(out)

    def frames(q):
        q2 = np.asarray(q, dtype=float).reshape(1, -1)
        origins = np.array([q2[0, asm.offsets[b]: asm.offsets[b] + 3] for b in rigid]).reshape(-1, 3)
        R = np.array([_directors(q2, asm.offsets[b])[0] for b in rigid]).reshape(-1, 3, 3)
        return origins, R

    labels = [b.name for b in movers] + [j.name for j in asm.joints]
    return Drawing(3, points, links=links or (), frames=frames if rigid else None,
                   labels=labels, pivots=tuple(pivots))
