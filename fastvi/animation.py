r"""Pictures of a moving mechanism: the animation and the path plot of a trajectory.

:meth:`fastvi.Result.animate` and :meth:`fastvi.Result.plot_trajectory` (documented there)
call :func:`render` and :func:`draw_paths` with a figure that :mod:`fastvi.results` makes
(on its own Agg canvas when it is saved, so the process's matplotlib backend never
changes). What to draw comes from a :class:`fastvi.drawing.Drawing`.

Frames are taken at ``fps`` evenly spaced times: from the dense output when the run kept
it (:attr:`fastvi.Result.sol`), else the nearest saved sample (never an interpolation of
the coordinates, which would shorten the rods between two samples). The axis limits hold
every point of every frame and of the saved samples, so the view never moves.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from .drawing import Drawing

__all__ = ["render", "draw_paths", "MAX_DEFAULT_SECONDS"]

#: the default length of an animation: the run in real time, but at most this many seconds
#: (a longer run plays faster; the time label shows by how much)
MAX_DEFAULT_SECONDS = 20.0
#: with dense output, a path plot samples the trajectory this many times per saved sample
_PATH_SAMPLES_PER_SAVED = 8
#: a frame-count from which ``progress=None`` shows a bar on a terminal
_PROGRESS_FROM = 100
#: colours of the three axes of a body frame
_AXIS_COLOURS = ("tab:red", "tab:green", "tab:blue")
#: at most this many saved samples (evenly strided) join the frames to fix the axis limits
#: (≈ 10 µs a sample to evaluate a drawing)
_LIMIT_SAMPLES = 20_000


def drawing_of(result, drawing) -> Drawing:
    """The drawing to use: the argument, else the result's, else an error that says what to do."""
    if drawing is None:
        drawing = getattr(result, "drawing", None)
    if drawing is None:
        raise ValueError(
            f"this result of model {result.model_name!r} has no drawing, so fastvi does not know "
            "how to draw the mechanism: pass `drawing=` (e.g. `drawing=model.drawing`), or give "
            "the model one before integrating, `model.drawing = fastvi.Drawing(2, points=lambda "
            "q: ..., links=[(0, 1)])` (for point masses whose coordinates are q: "
            "`fastvi.drawing.cartesian(n, links, before=[pivot])`). Every scene of fastvi.scenes "
            "has one and fastvi.integrate keeps it in the Result; Result.load and unpickling "
            "rebuild only a scene's, and baseline results and ensemble members carry none")
    if not isinstance(drawing, Drawing):
        raise TypeError(f"`drawing` must be a fastvi.drawing.Drawing, got {type(drawing).__name__}")
    return drawing


def _positive(value, name: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"`{name}` must be a positive number, got {value!r}") from None
    if not (np.isfinite(x) and x > 0):
        raise ValueError(f"`{name}` must be positive and finite, got {value!r}")
    return x


def frame_samples(result, fps: float, duration, every):
    """``(t (F,), q (F, n), speed)``: the frames' times and configurations, and how many
    simulated seconds a second of the animation shows.

    Parameters
    ----------
    result : fastvi.Result or BaselineResult
    fps : float
    duration : float or None
        Seconds of animation; None: the run in real time, at most
        :data:`MAX_DEFAULT_SECONDS`.
    every : int or None
        Instead of ``duration``: every ``every``-th saved sample is a frame.
    """
    fps = _positive(fps, "fps")
    t, q = np.asarray(result.t, dtype=float), np.asarray(result.q)
    if t.size == 0:
        raise ValueError("the result has no samples to draw")
    span = float(t[-1] - t[0])
    if every is not None:
        if duration is not None:
            raise ValueError("pass `duration` (seconds of animation) or `every` (a frame every "
                             "`every` saved samples), not both")
        if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
            raise ValueError(f"`every` must be a positive integer, got {every!r}")
        idx = np.arange(0, t.size, int(every))
        return t[idx], q[idx], _speed(t[idx[-1]] - t[0], (idx.size - 1) / fps)
    if duration is None:
        duration = min(span, MAX_DEFAULT_SECONDS)
        if duration == 0.0:  # one instant: a single frame
            return t[:1], q[:1], 1.0
    duration = _positive(duration, "duration")
    times = np.linspace(t[0], t[-1], max(1, int(round(duration * fps))))
    sol = getattr(result, "sol", None)
    if sol:  # the dense output: the trajectory between the saved samples
        return times, np.atleast_2d(sol(times)[0]), _speed(span, duration)
    right = np.clip(np.searchsorted(t, times), 0, t.size - 1)
    left = np.maximum(right - 1, 0)
    idx = np.where(np.abs(t[right] - times) < np.abs(times - t[left]), right, left)
    return t[idx], q[idx], _speed(span, duration)


def _speed(simulated: float, seconds: float) -> float:
    """Simulated seconds per second of animation (1 when either is zero: nothing moves)."""
    return simulated / seconds if simulated > 0 and seconds > 0 else 1.0


def _frame_tips(drawing: Drawing, t, q, size: float):
    """The ends of the body axes at the frames, (F, 3B, 3) (for the limits), or None."""
    if drawing.frames is None:
        return None
    tips = []
    for tk, qk in zip(t, q):
        origins, R = drawing.body_frames(qk, tk)
        tips.append((origins[:, None, :] + size * np.swapaxes(R, 1, 2)).reshape(-1, 3))
    return np.stack(tips)


def limits(points: np.ndarray, margin: float = 0.08):
    """``(lo, hi)`` per axis holding every point of ``points`` (..., dim), widened by a
    margin of ``margin`` times the largest extent (NaN points are ignored)."""
    flat = points.reshape(-1, points.shape[-1])
    flat = flat[np.all(np.isfinite(flat), axis=1)]
    if flat.size == 0:
        return -np.ones(points.shape[-1]), np.ones(points.shape[-1])
    lo, hi = flat.min(axis=0), flat.max(axis=0)
    pad = margin * float(np.max(hi - lo))
    pad = pad if pad > 0 else 0.5
    return lo - pad, hi + pad


def _saved_points(drawing: Drawing, result) -> np.ndarray:
    """The points at the saved samples (at most :data:`_LIMIT_SAMPLES` of them, evenly
    strided), (·, dim): with the frames' points they fix the axis limits."""
    K = len(result.t)
    idx = np.unique(np.linspace(0, K - 1, min(K, _LIMIT_SAMPLES)).astype(np.int64))
    return drawing.trace(np.asarray(result.q)[idx], np.asarray(result.t)[idx]).reshape(-1, drawing.dim)


def _set_xyz(line, xyz: np.ndarray) -> None:
    if xyz.shape[-1] == 2:
        line.set_data(xyz[:, 0], xyz[:, 1])
    else:
        line.set_data_3d(xyz[:, 0], xyz[:, 1], xyz[:, 2])


class _Picture:
    """The artists of one configuration on an axes (2-D or mplot3d), moved frame by frame."""

    def __init__(self, ax, drawing: Drawing, P: int, *, faded: bool = False, labels: bool = True):
        from matplotlib.collections import LineCollection

        self.ax, self.drawing, self.dim = ax, drawing, drawing.dim
        if self.dim == 3:
            from mpl_toolkits.mplot3d.art3d import Line3DCollection as Collection
        else:
            Collection = LineCollection
        alpha = 0.3 if faded else 1.0
        self.bars = Collection([], colors="0.25", linewidths=2.5, alpha=alpha, zorder=2)
        ax.add_collection(self.bars)
        # one line of markers per (kind, size): a handful of artists, whatever P is
        sizes = drawing.marker_sizes(P)
        groups: dict = {}
        for i in range(P):
            if sizes[i] > 0:
                groups.setdefault((i in drawing.pivots, float(sizes[i])), []).append(i)
        self.markers = []
        for (pivot, size), idx in groups.items():
            line, = ax.plot(*([[]] * self.dim), ls="none", marker="^" if pivot else "o", ms=size,
                            color="k" if pivot else "tab:blue", mec="k", mew=0.6, alpha=alpha,
                            zorder=3)
            self.markers.append((line, np.array(idx)))
        self.axes_lines = []
        if drawing.frames is not None:
            for colour in _AXIS_COLOURS:
                coll = Collection([], colors=colour, linewidths=2.0, alpha=alpha, zorder=4)
                ax.add_collection(coll)
                self.axes_lines.append(coll)
        self.texts = []
        if labels and drawing.labels is not None and not faded:
            for name in drawing.labels:
                self.texts.append(ax.text(*([0.0] * self.dim), f" {name}", fontsize="small",
                                          va="bottom", zorder=5))

    def artists(self) -> list:
        """Every artist that moves."""
        return [self.bars, *(line for line, _ in self.markers), *self.axes_lines, *self.texts]

    def update(self, pts: np.ndarray, frames=None, size: float = 0.0) -> None:
        links = self.drawing.links
        self.bars.set_segments(pts[links] if links.size else [])
        for line, idx in self.markers:
            _set_xyz(line, pts[idx])
        if frames is not None:
            origins, R = frames
            for k, coll in enumerate(self.axes_lines):
                coll.set_segments(np.stack((origins, origins + size * R[:, :, k]), axis=1))
        for text, p in zip(self.texts, pts):
            if self.dim == 3:
                text.set_position_3d(p)
            else:
                text.set_position(p)


def _axes(fig, dim: int, lo, hi):
    """An axes with the fixed limits ``lo, hi`` and equal scales on every axis."""
    if dim == 3:
        ax = fig.add_subplot(projection="3d")
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo)
        ax.set_zlabel("z")
    else:
        ax = fig.add_subplot()
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal", adjustable="box")
        ax.grid(alpha=0.25)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    return ax


def _figure_size(lo, hi, dim: int, side: float = 5.5):
    """Inches: the longer side of a planar view ``side``, the other in proportion."""
    if dim == 3:
        return side, side
    rx, ry = hi[0] - lo[0], hi[1] - lo[1]
    if rx >= ry:
        return side, max(2.5, side * ry / rx) + 0.6
    return max(2.5, side * rx / ry) + 0.6, side


def _writer(path: Path, fps: float):
    """The matplotlib writer for the file's suffix, or an error that says what works."""
    from matplotlib import animation

    suffix = path.suffix.lower()
    if suffix == ".gif":
        return _gif_writer(fps)
    if suffix == ".mp4":
        if not animation.FFMpegWriter.isAvailable():
            raise RuntimeError(
                f"writing {str(path)!r} (an MP4 video) needs ffmpeg, which matplotlib cannot find: "
                "install ffmpeg (e.g. `apt install ffmpeg`, `brew install ffmpeg` or `conda install "
                "ffmpeg`; or set matplotlib's rcParams['animation.ffmpeg_path']), or write a GIF "
                "instead (a path ending in .gif needs only Pillow)")
        return animation.FFMpegWriter(fps=fps)
    raise ValueError(f"`path` must end in .gif (Pillow) or .mp4 (ffmpeg), got {str(path)!r}")


def _gif_writer(fps: float):
    """matplotlib's GIF writer (Pillow), keeping each frame as 256 colours: a third of the
    memory of its RGB frames (a GIF holds 256 colours a frame anyway)."""
    from matplotlib.animation import PillowWriter

    class PalettedGif(PillowWriter):
        def grab_frame(self, **savefig_kwargs):
            super().grab_frame(**savefig_kwargs)
            frames = getattr(self, "_frames", None)  # PillowWriter's list of frames
            if frames and frames[-1].mode == "RGB":
                # method 2: Image.Quantize.FASTOCTREE (4× faster than the default median cut)
                frames[-1] = frames[-1].quantize(256, method=2)

    return PalettedGif(fps=fps)


def _time_text(t: float, speed: float) -> str:
    text = f"t = {t:.3f} s"
    if abs(speed - 1.0) > 0.01:
        text += f"  (×{speed:.3g})" if speed >= 1 else f"  (slowed ×{1 / speed:.3g})"
    return text


def _moving_points(drawing: Drawing, P: int) -> list:
    """The points that move and are drawn (not pivots, not hidden), in order."""
    sizes = drawing.marker_sizes(P)
    return [i for i in range(P) if i not in drawing.pivots and sizes[i] > 0]


def _point_indices(value, P: int, name: str) -> list:
    """``value`` as a list of point indices, checked against the drawing's ``P`` points."""
    idx = [int(i) for i in np.atleast_1d(value)]
    bad = [i for i in idx if not 0 <= i < P]
    if bad:
        raise ValueError(f"`{name}` holds indices outside 0…{P - 1} (the drawing has P = {P} "
                         f"points): {bad}")
    return idx


def render(result, path, fig, *, drawing=None, fps=30, duration=None, every=None, trail=1.0,
           trail_points=None, dpi=80, progress=None) -> Path:
    """Write the animation of :meth:`fastvi.Result.animate` (see there) on ``fig``."""
    drawing = drawing_of(result, drawing)
    path = Path(path)
    writer = _writer(path, _positive(fps, "fps"))
    dpi = _positive(dpi, "dpi")
    trail = 0.0 if trail is None else float(trail)
    if not trail >= 0:
        raise ValueError(f"`trail` must be >= 0 seconds of simulated time (or None), got {trail!r}")
    t, q, speed = frame_samples(result, fps, duration, every)
    P = drawing.check(q[0], t[0])
    pts = drawing.trace(q, t)
    every_point = np.concatenate((pts.reshape(-1, drawing.dim), _saved_points(drawing, result)))
    lo, hi = limits(every_point)
    size = drawing.frame_size or 0.15 * float(np.max(hi - lo))
    tips = _frame_tips(drawing, t, q, size)
    if tips is not None:
        lo, hi = limits(np.concatenate((every_point, tips.reshape(-1, 3))))
    fig.set_size_inches(*_figure_size(lo, hi, drawing.dim))
    ax = _axes(fig, drawing.dim, lo, hi)
    ax.set_title(result.model_name)
    picture = _Picture(ax, drawing, P)
    if trail == 0:
        followed = []
    elif trail_points is None:  # the last moving point: a pendulum's tip
        followed = _moving_points(drawing, P)[-1:]
    else:
        followed = _point_indices(trail_points, P, "trail_points")
    trails = [ax.plot(*([[]] * drawing.dim), lw=1.0, color="tab:orange", alpha=0.8, zorder=1)[0]
              for _ in followed]
    where = (0.02, 0.97)
    clock = (ax.text2D(*where, "", transform=ax.transAxes, va="top") if drawing.dim == 3
             else ax.text(*where, "", transform=ax.transAxes, va="top"))
    fig.tight_layout()
    fig.set_layout_engine(None)  # else every frame is drawn twice (a layout pass first)

    bar = _progress_bar(len(t), progress)
    first = 0
    with writer.saving(fig, str(path), dpi):
        _freeze_background(fig, ax, [*picture.artists(), *trails, clock], dpi)
        for k in range(len(t)):
            picture.update(pts[k], drawing.body_frames(q[k], t[k]), size)
            while t[first] < t[k] - trail:
                first += 1
            for line, i in zip(trails, followed):
                _set_xyz(line, pts[first:k + 1, i])
            clock.set_text(_time_text(t[k], speed))
            writer.grab_frame()
            if bar is not None:
                bar.update(k + 1, final=k + 1 == len(t))
    return path


def _freeze_background(fig, ax, moving, dpi: float) -> None:
    """Draw what does not move once, as an image under the artists that do.

    Each frame then draws that image and the moving artists only: the axes' tick labels
    (text layout) are most of the cost of drawing a frame from scratch.
    """
    fig.set_dpi(dpi)  # the writer's dpi: the image is then the frame's size
    for artist in moving:
        artist.set_visible(False)
    fig.canvas.draw()
    background = np.asarray(fig.canvas.buffer_rgba()).copy()
    for artist in moving:
        artist.set_visible(True)
    ax.set_axis_off()
    ax.patch.set_visible(False)  # mplot3d draws it even with the axis off
    ax.title.set_visible(False)
    fig.figimage(background, origin="upper", zorder=-10)


def _progress_bar(frames: int, progress):
    from .progress import ProgressBar

    if progress is None:
        isatty = getattr(sys.stderr, "isatty", None)
        progress = frames >= _PROGRESS_FROM and callable(isatty) and isatty()
    return ProgressBar(frames, unit="frames", label="fastvi animate") if progress else None


def draw_paths(result, fig, *, points=None, drawing=None):
    """Draw :meth:`fastvi.Result.plot_trajectory` (see there) on ``fig``."""
    drawing = drawing_of(result, drawing)
    t, q = np.asarray(result.t, dtype=float), np.asarray(result.q)
    if t.size == 0:
        raise ValueError("the result has no samples to draw")
    P = drawing.check(q[0], t[0])
    sol = getattr(result, "sol", None)
    if sol and t.size > 1:  # the dense output: smooth paths between the saved samples
        t = np.linspace(t[0], t[-1], min(_PATH_SAMPLES_PER_SAVED * t.size, _LIMIT_SAMPLES))
        q = sol(t)[0]
    points = _moving_points(drawing, P) if points is None else _point_indices(points, P, "points")
    pts = drawing.trace(q, t)
    lo, hi = limits(pts)
    fig.set_size_inches(*_figure_size(lo, hi, drawing.dim, side=6.0))
    ax = _axes(fig, drawing.dim, lo, hi)
    for k, faded in ((0, True), (-1, False)):
        _Picture(ax, drawing, P, faded=faded, labels=False).update(
            pts[k], drawing.body_frames(q[k], t[k]),
            drawing.frame_size or 0.15 * float(np.max(hi - lo)))
    names = drawing.labels or [f"point {i}" for i in range(P)]
    for i in points:
        ax.plot(*pts[:, i].T, lw=0.8, label=names[i])
    if points and len(points) <= 12:
        ax.legend(fontsize="small", loc="upper right")
    ax.set_title(f"{result.model_name}: t = {t[0]:g} (faded) to {t[-1]:g}")
    fig.tight_layout()
    return fig
