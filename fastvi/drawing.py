r"""How to draw a model's configuration: the :class:`Drawing` record.

A drawing turns a configuration ``q`` into what a picture of the mechanism shows: the
positions of its points (joints, masses, the ground pivots), the bars between them and,
for rigid bodies in space, their body frames. :meth:`fastvi.Result.animate` and
:meth:`fastvi.Result.plot_trajectory` read it from ``model.drawing``; every scene of
:mod:`fastvi.scenes` has one, and :func:`cartesian` builds one for point masses whose
coordinates are ``q`` itself.

A drawing holds functions, which do not travel: pickled (or written by
:meth:`fastvi.Result.save`), a scene's drawing travels as the scene's name and arguments
and is rebuilt on arrival, and any other drawing arrives as None.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

__all__ = ["Drawing", "cartesian"]


@dataclass(frozen=True, eq=False)
class Drawing:
    r"""How to draw a model's configuration (a record; set it as ``model.drawing``).

    Parameters
    ----------
    dim : {2, 3}
        The space the mechanism moves in: the plane ``(x, y)`` or space ``(x, y, z)``.
    points : callable
        ``points(q) -> (P, dim)`` array: the positions of the drawn points at the
        configuration ``q`` (n,) — joints, point masses and the fixed ground points alike,
        always the same ``P`` of them in the same order. With ``time_dependent=True`` it is
        ``points(t, q)`` (time first, as the model's callbacks).
    links : array_like of int, shape (L, 2)
        Pairs of point indices drawn as bars (``[]``: none).
    frames : callable, optional
        Only for ``dim = 3``: ``frames(q) -> (origins, R)`` with ``origins`` (B, 3) and
        ``R`` (B, 3, 3), the body frames of ``B`` rigid bodies, drawn as three short axes
        from each origin along the columns ``R[b][:, 0]`` (red), ``R[b][:, 1]`` (green) and
        ``R[b][:, 2]`` (blue). For a body with director coordinates
        ``q_b = (φ, d1, d2, d3)``: ``origins[b] = φ`` and ``R[b] = [d1 d2 d3]``.
        ``frames(t, q)`` with ``time_dependent=True``.
    labels : sequence of str, optional
        A name per point (``P`` of them): written next to the points of an animation and
        used in the legend of :meth:`fastvi.Result.plot_trajectory`.
    sizes : array_like (P,), optional
        Marker diameter of each point in typographic points (0 hides a point); default 9
        for a moving point and 7 for a pivot.
    pivots : sequence of int, optional
        Indices of the points that are supports (fixed or driven), drawn as black
        triangles; the default trail of an animation follows the last point that is not
        one of them.
    frame_size : float, optional
        Length of the drawn body axes; default 15 % of the largest extent of the motion.
    time_dependent : bool, default False
        ``points`` and ``frames`` take the time first (a moving support, a driven crank).
    scene : tuple, optional
        ``(name, kwargs)`` of the :data:`fastvi.scenes.SCENES` constructor whose model
        carries this drawing: how a pickled or saved one is rebuilt (the scenes set it).

    Examples
    --------
    A planar pendulum in Cartesian coordinates ``q = (x, y)`` hung from the origin:

    >>> import numpy as np
    >>> from fastvi.drawing import Drawing
    >>> drawing = Drawing(2, points=lambda q: np.array([[0.0, 0.0], [q[0], q[1]]]),
    ...                   links=[(0, 1)], pivots=(0,), labels=("pivot", "bob"))
    >>> drawing.positions(np.array([0.6, -0.8]))
    array([[ 0. ,  0. ],
           [ 0.6, -0.8]])
    """

    dim: int
    points: Callable
    links: np.ndarray = ()
    frames: Callable | None = None
    labels: tuple | None = None
    sizes: np.ndarray | None = None
    pivots: tuple = ()
    frame_size: float | None = None
    time_dependent: bool = False
    scene: tuple | None = None

    def __post_init__(self):
        if isinstance(self.dim, bool) or self.dim not in (2, 3):
            raise ValueError(f"`dim` must be 2 (the plane) or 3 (space), got {self.dim!r}")
        if not callable(self.points):
            raise TypeError(f"`points` must be a function q -> (P, {self.dim}) array, got {self.points!r}")
        links = np.asarray(self.links if len(self.links) else np.zeros((0, 2)))
        if links.ndim != 2 or links.shape[1] != 2 or (links.size and not np.all(links == np.round(links))):
            raise ValueError(f"`links` must be pairs of point indices, shape (L, 2), got {self.links!r}")
        if links.size and links.min() < 0:
            raise ValueError(f"`links` holds a negative point index: {links.min()}")
        object.__setattr__(self, "links", links.astype(np.int64))
        if self.frames is not None:
            if self.dim != 3:
                raise ValueError("`frames` (body frames) are drawn in space only: pass dim=3")
            if not callable(self.frames):
                raise TypeError(f"`frames` must be a function q -> (origins, R) or None, got {self.frames!r}")
        if self.labels is not None:
            object.__setattr__(self, "labels", tuple(str(x) for x in self.labels))
        if self.sizes is not None:
            sizes = np.asarray(self.sizes, dtype=float)
            if sizes.ndim != 1 or not np.all(np.isfinite(sizes)) or np.any(sizes < 0):
                raise ValueError(f"`sizes` must be a vector of marker sizes >= 0, got {self.sizes!r}")
            object.__setattr__(self, "sizes", sizes)
        try:
            pivots = tuple(int(i) for i in self.pivots)
        except (TypeError, ValueError):
            raise TypeError(f"`pivots` must be a sequence of point indices, got {self.pivots!r}") from None
        if any(i < 0 for i in pivots):
            raise ValueError(f"`pivots` holds a negative point index: {pivots}")
        object.__setattr__(self, "pivots", pivots)
        if self.frame_size is not None and not (np.isfinite(self.frame_size) and self.frame_size > 0):
            raise ValueError(f"`frame_size` must be a positive length or None, got {self.frame_size!r}")
        if not isinstance(self.time_dependent, (bool, np.bool_)):
            raise TypeError(f"`time_dependent` must be True or False, got {self.time_dependent!r}")

    # ------------------------------------------------------------------ evaluation
    def _call(self, fn, q, t):
        q = np.asarray(q, dtype=float)
        return fn(t, q) if self.time_dependent else fn(q)

    def positions(self, q, t: float = 0.0) -> np.ndarray:
        """The points at configuration ``q`` (n,) and time ``t``: an array (P, dim)."""
        pts = np.asarray(self._call(self.points, q, t), dtype=float)
        if pts.ndim != 2 or pts.shape[1] != self.dim:
            raise ValueError(f"`drawing.points(q)` must return a (P, {self.dim}) array, got shape "
                             f"{pts.shape}")
        return pts

    def body_frames(self, q, t: float = 0.0):
        """``(origins (B, 3), R (B, 3, 3))`` at ``q`` and ``t``, or None without ``frames``."""
        if self.frames is None:
            return None
        origins, R = (np.asarray(x, dtype=float) for x in self._call(self.frames, q, t))
        if origins.ndim != 2 or origins.shape[1] != 3 or R.shape != (origins.shape[0], 3, 3):
            raise ValueError(f"`drawing.frames(q)` must return origins (B, 3) and R (B, 3, 3), got "
                             f"shapes {origins.shape} and {R.shape}")
        return origins, R

    def check(self, q, t: float = 0.0) -> int:
        """Evaluate the drawing once and check it against itself; returns ``P``.

        Raises
        ------
        ValueError
            Naming the field that does not fit the number of points ``P``.
        """
        P = self.positions(q, t).shape[0]
        if self.links.size and self.links.max() >= P:
            raise ValueError(f"`drawing.links` names point {self.links.max()} but `points` gives {P}")
        if self.pivots and max(self.pivots) >= P:
            raise ValueError(f"`drawing.pivots` names point {max(self.pivots)} but `points` gives {P}")
        for name in ("labels", "sizes"):
            value = getattr(self, name)
            if value is not None and len(value) != P:
                raise ValueError(f"`drawing.{name}` must have one entry per point (P = {P}), got {len(value)}")
        self.body_frames(q, t)
        return P

    def trace(self, q, t) -> np.ndarray:
        """The points along a trajectory: ``q`` (K, n) at times ``t`` (K,) -> array (K, P, dim)."""
        return np.stack([self.positions(qk, tk) for qk, tk in zip(q, np.asarray(t, dtype=float))])

    def marker_sizes(self, P: int) -> np.ndarray:
        """The marker diameters of the ``P`` points (``sizes``, or the defaults)."""
        if self.sizes is not None:
            return self.sizes
        sizes = np.full(P, 9.0)
        sizes[list(self.pivots)] = 7.0
        return sizes

    # ------------------------------------------------------------------ travel
    def __copy__(self):
        return self  # a frozen record: a copy may share it (and its functions)

    def __deepcopy__(self, memo):
        return self

    def __reduce__(self):
        # the functions stay home: a scene's drawing is rebuilt from the scene, any other is lost
        if self.scene is not None:
            return (_from_scene, tuple(self.scene))
        return (_lost, ())


def _from_scene(name, kwargs):
    from .scenes import SCENES

    return SCENES[name](**kwargs).drawing


def _lost():
    return None


def for_scene(drawing: Drawing, name: str, kwargs: dict) -> Drawing:
    """``drawing`` marked as the one of scene ``name`` built with ``kwargs`` (so that it
    travels as that recipe)."""
    return replace(drawing, scene=(name, dict(kwargs)))


def saved(drawing) -> dict:
    """The arrays :meth:`fastvi.Result.save` writes for ``drawing``: its scene's recipe as
    JSON, or nothing (a drawing not from a scene, or with arguments JSON cannot hold)."""
    if drawing is None or drawing.scene is None:
        return {}
    try:
        text = json.dumps(list(drawing.scene), default=_plain)
    except (TypeError, ValueError):
        return {}
    return {"drawing_scene": np.array(text)}


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON")


def loaded(data):
    """The drawing of a file written by :meth:`fastvi.Result.save` (None if it has none)."""
    if "drawing_scene" not in data.files:
        return None
    name, kwargs = json.loads(str(data["drawing_scene"]))
    return _from_scene(name, kwargs)


def cartesian(n: int, links, *, dim: int = 2, before=(), after=(), pivots=None, **options) -> Drawing:
    r"""A drawing of point masses whose coordinates are ``q`` itself.

    ``q = (x1, y1, x2, y2, …)`` (``dim = 2``) or ``(x1, y1, z1, …)`` (``dim = 3``): the
    points are the fixed points ``before``, the ``n / dim`` masses in their order in ``q``,
    then the fixed points ``after``.

    Parameters
    ----------
    n : int
        The model's number of coordinates (a multiple of ``dim``).
    links : array_like of int, shape (L, 2)
        Bars between points, indexed in that combined order.
    dim : {2, 3}
    before, after : array_like, shape (·, dim)
        Fixed points (ground pivots) listed before and after the masses.
    pivots : sequence of int, optional
        Default: the fixed points.
    **options
        The other fields of :class:`Drawing` (``labels``, ``sizes``, …).

    Returns
    -------
    Drawing

    Examples
    --------
    A double pendulum ``q = (x1, y1, x2, y2)`` hung from the origin:

    >>> import numpy as np
    >>> from fastvi.drawing import cartesian
    >>> drawing = cartesian(4, [(0, 1), (1, 2)], before=[(0.0, 0.0)])
    >>> drawing.positions(np.array([1.0, 0.0, 1.0, -1.0]))
    array([[ 0.,  0.],
           [ 1.,  0.],
           [ 1., -1.]])
    """
    if n % dim:
        raise ValueError(f"`n` = {n} coordinates are not whole points of dimension {dim}")
    head = np.asarray(before, dtype=float).reshape(-1, dim)
    tail = np.asarray(after, dtype=float).reshape(-1, dim)
    masses = n // dim

    def points(q):
        return np.concatenate((head, np.reshape(q, (masses, dim)), tail))

    if pivots is None:
        first_tail = len(head) + masses
        pivots = (*range(len(head)), *range(first_tail, first_tail + len(tail)))
    return Drawing(dim, points, links, pivots=tuple(pivots), **options)
