"""What the integrators return: :class:`Result` and the base shared with the other results.

:class:`ResultBase` holds what :class:`Result`, :class:`fastvi.EnsembleResult` and
:class:`fastvi.baselines.BaselineResult` have in common (success, message, timing text, a
short ``repr``); :class:`TrajectoryResult` adds what the two single-trajectory results share
(energy error, residual summary, plot). The progress bar of :func:`fastvi.integrate` lives
here too, since it formats what a result later reports.

The storage of results is here as well: :func:`save_npz` and :func:`open_npz` write and
read a compressed ``.npz`` tagged with the class that wrote it, and :func:`result_arrays` /
:func:`result_from` turn a :class:`Result` into arrays under a key prefix and back, so that
the derivative results (:class:`fastvi.SensitivityResult`, :class:`fastvi.AdjointResult`,
:class:`fastvi.EnsembleSensitivityResult`) store their trajectory in their own file the way
:meth:`Result.save` does.
"""

from __future__ import annotations

import bisect
import math
import os
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from . import drawing as _drawing
from .progress import ProgressBar  # noqa: F401 - part of this module's API
from .status import MESSAGES, Status
from .tables import Method, method as _method

__all__ = ["ResultBase", "TrajectoryResult", "Result", "ProgressBar", "NoDenseOutput"]


def _seconds(x) -> str:
    """``0.0712 s`` / ``24.4 s``: three significant digits, whatever the magnitude."""
    return f"{x:.3g} s" if x == x else "n/a"


def timing(stats: dict) -> str:
    """``integration 0.07 s, setup 0.8 s (compile 0.7 s)``, from what ``stats`` holds.

    Results built before the split (or by the baselines) only have ``wall_time``.
    """
    if "integration_time" not in stats:
        wall = stats.get("wall_time", float("nan"))
        return f"wall time {_seconds(wall)}" if wall == wall else "time not measured"
    text = f"integration {_seconds(stats['integration_time'])}"
    setup = stats.get("setup_time", float("nan"))
    if setup == setup:
        compile_ = stats.get("compile_time", 0.0)
        text += f", setup {_seconds(setup)}"
        if compile_ == compile_ and compile_ > 0.01:  # below: a cache hit, not news
            text += f" (compile {_seconds(compile_)})"
    return text


def run_text(result) -> str:
    """``method P2L-Q3G-NL-CN, h = 0.01, steps = 300``: the run of a result that holds one
    trajectory, for a one-line summary."""
    return f"method {result._label()}, h = {result.h:g}, steps = {result.stats.get('steps', '?')}"


def run_items(result) -> list[str]:
    """``model='…', method='…', h=…, steps=…``: the start of the ``repr`` of a result that
    holds one trajectory (its own or nested)."""
    return [f"model={result.model_name!r}", f"method={result._label()!r}", f"h={result.h:g}",
            f"steps={result.stats.get('steps', '?')}"]


class ResultBase:
    """Shared behaviour of every fastvi result (a mixin for dataclasses).

    Subclasses have a ``status`` (a field or a property) and define :meth:`_repr_items`;
    :meth:`_timing` reads their ``stats``. The trajectories also have ``h`` and
    ``model_name`` and define :meth:`_label` (the method's name).
    """

    @property
    def success(self):
        """``status >= 0`` (a bool, or an (N,) bool array for an ensemble)."""
        return self.status >= 0

    @property
    def message(self) -> str:
        """The words for :attr:`status`."""
        status = np.asarray(self.status)
        if status.ndim:  # an ensemble: the message of its worst member
            failed = status[status < 0]
            code = int(failed[0]) if failed.size else int(Status.SUCCESS)
            return MESSAGES[Status(code)]
        return MESSAGES[Status(int(status))]

    def _label(self) -> str:  # pragma: no cover - every subclass overrides it
        raise NotImplementedError

    def _timing(self) -> str:
        """:func:`timing` of :attr:`stats`."""
        return timing(self.stats)

    def _status_text(self) -> str:
        status = np.asarray(self.status)
        if status.ndim:
            bad = int(np.count_nonzero(status < 0))
            return "SUCCESS" if bad == 0 else f"{bad} of {status.size} FAILED"
        return Status(int(status)).name

    def _repr_items(self) -> list[str]:  # pragma: no cover - every subclass overrides it
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(self._repr_items())})"


class TrajectoryResult(ResultBase):
    """A single trajectory sampled at ``t``: :class:`Result` and ``BaselineResult``."""

    @property
    def energy_error(self) -> np.ndarray:
        """``H(t) − H(0)``."""
        return self.energy - self.energy[0]

    @property
    def energy_balance(self) -> np.ndarray:
        r"""``H(t) − H(t0) − W(t)``: the energy error once the work ``W`` done on the system
        by forces, time-dependent potentials and driving constraints is accounted for
        (``W = 0`` and this is :attr:`energy_error` for a conservative model). It stays at
        the size of a conservative run's energy error, without drift, while ``H`` itself
        may decay (damping) or be pumped (a drive)."""
        work = getattr(self, "work", None)
        return self.energy_error if work is None else self.energy_error - work

    def _balance_text(self) -> str:
        if getattr(self, "work", None) is None:
            return f"max |ΔH| = {np.max(np.abs(self.energy_error)):.3e}"
        return (f"ΔH = {self.energy_error[-1]:.3e}, work = {self.work[-1]:.3e}, "
                f"max |ΔH − W| = {np.max(np.abs(self.energy_balance)):.3e}")

    def _velocity_label(self) -> str:
        """``|Gv|``, or ``|Gv + g_t|`` for a model with forces or time (what the residual
        is: the hidden constraint of a driven constraint has the term ``g_t``)."""
        return "|Gv|" if getattr(self, "work", None) is None else "|Gv + g_t|"

    def _repr_items(self) -> list[str]:
        t = self.t
        span = f"[{t[0]:g}, {t[-1]:g}]" if t.size else "[]"
        # a forced or driven model: the energy balance, not the change of H its forces make
        err = (np.abs(self.energy_balance) if getattr(self, "work", None) is not None
               else np.abs(self.energy_error)) if self.energy.size else np.zeros(1)
        name = "max|ΔH|" if getattr(self, "work", None) is None else "max|ΔH−W|"
        return [*run_items(self), f"t={span}", f"status={self._status_text()}",
                f"{name}={np.max(err):.2g}"]

    def summary(self) -> str:
        """One line with the figures a user checks first."""
        text = (
            f"{self.model_name}: {self._label()}, h = {self.h:g}, steps = {self.stats['steps']}, "
            f"{self._timing()}, "
            f"{self._balance_text()}, "
            f"max |g| = {np.max(self.constraint_residual):.3e}, "
            f"max {self._velocity_label()} = {np.max(self.velocity_residual):.3e}"
        )
        if "newton_iterations" in self.stats:
            text += (f", Newton iterations/step = "
                     f"{self.stats['newton_iterations'] / max(1, self.stats['steps']):.2f}")
        return text

    def plot(self, path=None, *, coordinates=None, labels=None):
        """Motion, energy error and constraint residuals against time (needs matplotlib).

        Parameters
        ----------
        path : str or path-like, optional
            Save the figure there (PNG, PDF, … by extension). Drawn on its own canvas:
            the process's matplotlib backend is never changed.
        coordinates : sequence of int, or mapping of str to sequences of int, optional
            Which components of ``q`` to draw (default: every one, so that none is hidden).
            A mapping groups them, one panel per group, titled by its key, e.g.
            ``{"crank": [0, 1, 2], "rod": [3, 4, 5], "slider": [6, 7]}``.
        labels : sequence of str, optional
            A name per coordinate (``n`` of them) for the legends, e.g.
            ``["x1", "y1", "θ1", …]`` (default ``q[i]``).

        Returns
        -------
        matplotlib.figure.Figure

        Notes
        -----
        Residuals are drawn on a log axis whose range comes from the nonzero values;
        samples that are exactly zero (a constraint met to the last bit) are drawn on the
        bottom edge as open markers labelled "exact 0", instead of at a fake 1e-300.
        """
        n = self.q.shape[1] if self.q.ndim == 2 else 0
        groups = _coordinate_groups(coordinates, n)
        if labels is not None:
            labels = [str(x) for x in labels]
            if len(labels) != n:
                raise ValueError(f"`labels` must name each of the n = {n} coordinates, got {len(labels)}")
        fig = new_figure(path, figsize=(7, 5.0 + 2.5 * len(groups)))
        axes = fig.subplots(len(groups) + 2, 1, sharex=True)
        a1, a2 = axes[-2], axes[-1]
        for ax, (title, idx) in zip(axes, groups):
            for i in idx:
                ax.plot(self.t, self.q[:, i], lw=0.8, label=labels[i] if labels else f"q[{i}]")
            ax.set_ylabel("q(t)" if title is None else title)
            if idx and len(idx) <= 12:
                ax.legend(fontsize="small", ncol=min(len(idx), 4), loc="upper right")
        a0 = axes[0]
        if getattr(self, "work", None) is None:
            a1.plot(self.t, self.energy_error, lw=0.8)
            a1.set_ylabel("H(t) − H(0)")
        else:
            a1.plot(self.t, self.energy_error, lw=0.8, label="H − H(t0)")
            a1.plot(self.t, self.work, lw=0.8, ls="--", label="work W")
            a1.set_ylabel("energy")
            a1.legend(fontsize="small", loc="upper right")
            ab = a1.twinx()
            ab.plot(self.t, self.energy_balance, lw=0.6, color="tab:red")
            ab.set_ylabel("balance H − H(t0) − W", color="tab:red")
        residual_panel(a2, self.t[1:], {"max|g|": self.constraint_residual[1:],
                                         f"max{self._velocity_label()}": self.velocity_residual[1:]})
        a2.set_xlabel("t")
        a0.set_title(f"{self.model_name}, {self._label()}, h = {self.h:g}")
        fig.tight_layout()
        return finish_figure(fig, path)

    def animate(self, path, *, drawing=None, fps=30, duration=None, every=None, trail=1.0,
                trail_points=None, dpi=80, progress=None):
        """Write an animation of the mechanism: a GIF (Pillow) or an MP4 video (ffmpeg).

        Drawn from the model's :class:`fastvi.drawing.Drawing` (``model.drawing``; every
        scene has one), with the axis limits fixed from the whole run and the time written
        in a corner. Frames are evenly spaced in time: from the dense output when the run
        kept it (``dense_output=True``), else the nearest saved sample (the coordinates are
        never interpolated: that would shorten the rods). Needs matplotlib; the figure has
        its own canvas, so the process's backend is never changed.

        Parameters
        ----------
        path : str or path-like
            The file: ``.gif`` or ``.mp4`` (needs the ``ffmpeg`` program).
        drawing : fastvi.drawing.Drawing, optional
            Instead of the model's (a Result read by :meth:`Result.load` or unpickled keeps
            only a scene's drawing).
        fps : float, default 30
            Frames per second of the animation.
        duration : float, optional
            Seconds of animation for the whole run: ``round(duration · fps)`` frames. Default:
            the run in real time, at most 20 s (a longer run plays faster; the time label then
            shows the speed-up).
        every : int, optional
            Instead of ``duration``: a frame at every ``every``-th saved sample.
        trail : float, default 1.0
            Seconds of simulated time of the path left behind by ``trail_points`` (0 or None:
            no trail, ``numpy.inf``: the whole path).
        trail_points : sequence of int, optional
            Indices of the drawing's points that leave a trail (default: the last moving
            point, a pendulum's tip).
        dpi : float, default 80
            Pixels per inch (the figure is about 5.5 inches wide). A GIF keeps every frame in
            memory until it is written (≈ 0.2 MB a frame at the default size).
        progress : bool, optional
            A progress bar (tqdm) while the frames are drawn; default: on a terminal, from
            100 frames on.

        Returns
        -------
        pathlib.Path
            The file written.

        Raises
        ------
        ValueError
            The model has no drawing (the message says how to give one), or an argument is
            out of range.
        RuntimeError
            An ``.mp4`` path without ffmpeg installed.
        """
        from .animation import render

        return render(self, path, new_figure(path, (5.5, 5.5)), drawing=drawing, fps=fps,
                      duration=duration, every=every, trail=trail, trail_points=trail_points,
                      dpi=dpi, progress=progress)

    def plot_trajectory(self, points=None, path=None, *, drawing=None):
        """The paths of chosen points of the mechanism over the run, in the plane or in space.

        The mechanism is drawn at the first sample (faded) and the last, and the path of
        each chosen point through every saved sample (or, with dense output, eight times
        as many points of the trajectory). Needs matplotlib and a drawing (see
        :meth:`animate`).

        Parameters
        ----------
        points : sequence of int, optional
            Indices of the drawing's points whose paths are drawn (default: every moving
            point that the drawing marks).
        path : str or path-like, optional
            Save the figure there (PNG, PDF, … by extension).
        drawing : fastvi.drawing.Drawing, optional
            Instead of the model's.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from .animation import draw_paths

        fig = draw_paths(self, new_figure(path, (6, 6)), points=points, drawing=drawing)
        return finish_figure(fig, path)


class NoDenseOutput:
    """:attr:`Result.sol` of a run without ``dense_output=True``: false in a test, and
    calling it (or reading its attributes) raises an error that says what to pass."""

    MESSAGE = ("`Result.sol` needs dense output: pass `dense_output=True` to fastvi.integrate "
               "(it keeps every step's control points, 8 (s+1) n bytes a step), or `t_eval=` to get "
               "samples at given times")

    def __bool__(self) -> bool:
        return False

    def __call__(self, *args, **kwargs):
        raise ValueError(self.MESSAGE)

    def __getattr__(self, name):
        if name.startswith("__"):  # copy, pickle and friends probe dunders: not a user's call
            raise AttributeError(name)
        raise ValueError(self.MESSAGE)

    def __repr__(self) -> str:
        return "NoDenseOutput(pass dense_output=True to fastvi.integrate)"


@dataclass(repr=False)
class Result(TrajectoryResult):
    """Trajectory of :func:`fastvi.integrate` at the saved steps.

    Attributes
    ----------
    t : ndarray (K,)
        Times of the samples; ``t[0] = t0`` is the (projected) initial state.
    q, v, p : ndarray (K, n)
        Positions, velocities ``v = M⁻¹p`` and momenta.
    energy : ndarray (K,)
        ``H = ½ vᵀ M v + V(t, q)``.
    work : ndarray (K,) or None
        For a model with forces or time: the work done on the system since ``t0`` by the
        forces (``∫ F·v dt``), the time-dependent potential (``∫ ∂V/∂t dt``) and driving
        constraints (``∫ λ·g_t dt``), quadratured on each step's polynomial; see
        :attr:`energy_balance`. None for a conservative model.
    work_forces : ndarray (K,) or None
        The part of :attr:`work` done by the applied forces (``∫ F·v dt``: dampers, motors,
        springs given as forces); the rest, :attr:`work_driven`, is done by the
        time-dependent potential and the driving constraints. None for a conservative model.
    constraint_residual, velocity_residual : ndarray (K,)
        ``max |g(t_k, q_k)|`` and ``max |G v_k + g_t|`` over the steps since the previous
        sample.
    newton_iterations : ndarray (K,)
        Newton iterations spent since the previous sample.
    stats : dict
        ``steps``; ``newton_iterations`` (total); ``max_residual``; ``recovered_steps``;
        times in seconds: ``integration_time`` (the compiled loop), ``setup_time``
        (validation, the first-use model check, compiling the model's callbacks and
        loading or compiling the kernels), of which ``compile_time`` (callbacks and
        kernels), and ``wall_time`` (the total, as before the split).
    status : Status
        ``Status.SUCCESS``, ``Status.TERMINATED`` (a terminal event) or the reason the run
        stopped early.
    method : Method
    h : float
    failed_step : int or None
    model_name : str
    drawing : fastvi.drawing.Drawing or None
        The model's drawing, for :meth:`animate` and :meth:`plot_trajectory`.
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    p: np.ndarray
    energy: np.ndarray
    constraint_residual: np.ndarray
    velocity_residual: np.ndarray
    newton_iterations: np.ndarray
    stats: dict
    status: Status
    method: Method
    h: float
    failed_step: int | None = None
    model_name: str = field(default="model")
    work: np.ndarray | None = None
    work_forces: np.ndarray | None = None
    t_events: list | None = None
    q_events: list | None = None
    v_events: list | None = None
    sol: object = field(default_factory=NoDenseOutput)
    drawing: object = field(default=None, repr=False, compare=False)

    @property
    def work_driven(self):
        """``work − work_forces``: the work done since ``t0`` by the time-dependent potential
        and the driving constraints (prescribed motions, moving supports), or None for a
        conservative model or a result without the split."""
        if self.work is None or self.work_forces is None:
            return None
        return self.work - self.work_forces

    def _label(self) -> str:
        if "adaptive" in self.stats:  # h is then the step where the motion is slow
            return f"{self.method.name} adaptive (K_r = {self.stats['adaptive']:g})"
        return self.method.name

    def summary(self) -> str:
        """One line with the figures a user checks first."""
        return super().summary().replace(f": {self._label()},", f": method {self._label()},", 1)

    def save(self, path) -> None:
        """Write the arrays, stats and method to a compressed ``.npz`` file (read back by
        :meth:`load`), and a scene's drawing as the scene's name and arguments."""
        save_npz(path, "Result", result_arrays(self))

    @classmethod
    def load(cls, path) -> "Result":
        """Read a :class:`Result` written by :meth:`save`.

        Parameters
        ----------
        path : str or path-like
            A ``.npz`` file from :meth:`save` (files from fastvi 0.1, which lack the model
            name and failed step, load too).

        Returns
        -------
        Result

        Raises
        ------
        ValueError
            ``path`` was written by another class's ``save`` (the message names it).
        """
        with open_npz(path, "Result") as stored:
            return result_from(stored, cls=cls)


# ---------------------------------------------------------------------------- storage
#: the key of the name of the class whose ``save`` wrote a file (files that
#: :meth:`Result.save` wrote before there was one hold a Result)
KIND = "fastvi_kind"


class Stored:
    """The arrays of an open ``.npz`` file under a key prefix, read like the file itself.

    ``files`` lists the keys that start with the prefix, without it, and ``stored[key]``
    reads ``prefix + key``: a result nested in another's file reads as a file of its own
    (:func:`fastvi.drawing.loaded` takes one).
    """

    def __init__(self, data, prefix: str = "", files=None):
        self._data, self._prefix = data, prefix
        self.files = list(data.files) if files is None else files
        self._order = {k: i for i, k in enumerate(self.files)}
        self._sorted = None

    def __getitem__(self, key: str) -> np.ndarray:
        return self._data[self._prefix + key]

    def __contains__(self, key: str) -> bool:
        return key in self._order

    def under(self, prefix: str) -> "Stored":
        """The arrays whose keys start with ``prefix`` (after this view's own)."""
        # the keys with a prefix are a range of the sorted keys: an ensemble's file of N
        # members is read in O(N log N), not by N scans of all its keys
        if self._sorted is None:
            self._sorted = sorted(self.files)
        first = bisect.bisect_left(self._sorted, prefix)
        last = first
        while last < len(self._sorted) and self._sorted[last].startswith(prefix):
            last += 1
        keys = sorted(self._sorted[first:last], key=self._order.__getitem__)
        return Stored(self._data, self._prefix + prefix, [k[len(prefix):] for k in keys])


class SavedResult:
    """:meth:`save` and :meth:`load` of the derivative results (a mixin): one compressed
    ``.npz`` file, the trajectory :class:`Result` inside, read back without pickle.

    Subclasses define ``_arrays()`` (the arrays to write) and the classmethod
    ``_from_stored(stored, model)`` (the result from a :class:`Stored`).
    """

    def save(self, path) -> None:
        """Write the result to one compressed ``.npz`` file, its trajectory inside (read
        back by :meth:`load`, without pickle).

        The model is not written (its callbacks are compiled functions): :meth:`load`
        takes it where a method needs it.

        Parameters
        ----------
        path : str or path-like
            The file (NumPy adds ``.npz`` to a name without it).
        """
        save_npz(path, type(self).__name__, self._arrays())

    @classmethod
    def load(cls, path, model=None):
        """Read a result of this class written by :meth:`save`.

        Parameters
        ----------
        path : str or path-like
            A ``.npz`` file from this class's :meth:`save`.
        model : fastvi.Model, optional
            The model of the run (its name and ``n`` are checked against the file's), for
            the methods that need it: :meth:`fastvi.SensitivityResult.tangent_residual`,
            of an ensemble's members too. Without it everything else works.

        Returns
        -------
        SensitivityResult, AdjointResult or EnsembleSensitivityResult
            Of the class ``load`` is called on, equal to the one saved bit for bit (its
            trajectory :class:`Result` too).

        Raises
        ------
        ValueError
            ``path`` was written by another class's ``save`` (the message names it and
            the ``load`` to use), or ``model`` is not the run's.
        TypeError
            ``model`` is not a :class:`fastvi.Model`.
        """
        with open_npz(path, cls.__name__) as stored:
            return cls._from_stored(stored, model)


def save_npz(path, kind: str, arrays: dict) -> None:
    """Write ``arrays`` to a compressed ``.npz``, tagged with ``kind`` (the class that
    writes them, which :func:`open_npz` checks)."""
    np.savez_compressed(path, **{KIND: np.array(kind)}, **arrays)


@contextmanager
def open_npz(path, kind: str):
    """The arrays of a file that ``kind.save`` wrote, as a :class:`Stored` (no pickle).

    Raises
    ------
    ValueError
        ``path`` holds another class's result (the message names the class that wrote it
        and its ``load``), or arrays no fastvi result wrote.
    """
    data = np.load(path, allow_pickle=False)
    if not hasattr(data, "files"):
        raise ValueError(f"`path` {os.fspath(path)!r} holds one bare array (a .npy file), not a "
                         f"{kind}: {kind}.load reads the .npz files that {kind}.save writes")
    with data:
        found = (str(data[KIND]) if KIND in data.files
                 else "Result" if {"t", "method"} <= set(data.files) else None)
        if found is None:
            raise ValueError(f"`path` {os.fspath(path)!r} is a .npz file that no fastvi result "
                             f"wrote: {kind}.load reads the files that {kind}.save writes")
        if found != kind:
            raise ValueError(f"`path` {os.fspath(path)!r} was written by {found}.save, not by "
                             f"{kind}.save: read it with fastvi.{found}.load")
        yield Stored(data)


def stats_arrays(stats: dict) -> dict:
    """A dict of scalars (or arrays) as the arrays ``stats_{key}``."""
    return {f"stats_{k}": v for k, v in stats.items()}


def stats_from(stored: Stored) -> dict:
    """The dict :func:`stats_arrays` wrote: scalars back as Python numbers and strings."""
    stats = {}
    for key in stored.files:
        if key.startswith("stats_"):
            value = stored[key]
            stats[key[6:]] = value.item() if value.ndim == 0 else value
    return stats


def result_arrays(result: Result, prefix: str = "") -> dict:
    """The arrays :meth:`Result.save` writes for ``result``, each key after ``prefix``
    (the trajectory nested in another result's file)."""
    stats = dict(result.stats)
    rec = stats.pop("recovered_steps", [])
    arrays = dict(
        t=result.t, q=result.q, v=result.v, p=result.p, energy=result.energy,
        constraint_residual=result.constraint_residual, velocity_residual=result.velocity_residual,
        newton_iterations=result.newton_iterations, h=result.h, method=result.method.name,
        status=int(result.status), model_name=result.model_name,
        failed_step=-1 if result.failed_step is None else int(result.failed_step),
        stats_recovered_steps=np.asarray(rec, dtype=np.int64).reshape(-1, 2),
        **({} if result.work is None else {"work": result.work}),
        **({} if result.work_forces is None else {"work_forces": result.work_forces}),
        **stats_arrays(stats), **_drawing.saved(result.drawing),
    )
    return {prefix + k: v for k, v in arrays.items()}


def matching_model(model, result: Result, kind: str):
    """``model``, given to ``kind.load`` for ``result`` read from a file: None, or the
    :class:`fastvi.Model` of the run (its name and size checked against the trajectory's)."""
    if model is None:
        return None
    from .model import Model  # the model imports the kernels, which a result does not need

    if not isinstance(model, Model):
        raise TypeError(f"`model` of {kind}.load must be the fastvi.Model of the run (or None), "
                        f"got {type(model).__name__}")
    n = result.q.shape[1]
    if model.name != result.model_name or model.n != n:
        raise ValueError(f"`model` of {kind}.load is {model.name!r} with n = {model.n}, but the "
                         f"file holds a run of {result.model_name!r} with n = {n}: pass the model "
                         f"that the run used")
    return model


def result_from(stored: Stored, prefix: str = "", *, cls=Result) -> Result:
    """The :class:`Result` (or ``cls``) whose arrays :func:`result_arrays` wrote under
    ``prefix``."""
    data = stored.under(prefix) if prefix else stored
    arrays = {k: data[k] for k in ("t", "q", "v", "p", "energy", "constraint_residual",
                                   "velocity_residual", "newton_iterations")}
    stats = stats_from(data)
    rec = stats.get("recovered_steps")
    stats["recovered_steps"] = ([] if rec is None or np.size(rec) == 0 else
                                [tuple(int(x) for x in row) for row in np.reshape(rec, (-1, 2))])
    failed = int(data["failed_step"]) if "failed_step" in data else -1
    name = str(data["model_name"]) if "model_name" in data else "model"
    work = data["work"] if "work" in data else None
    forces = data["work_forces"] if "work_forces" in data else None
    return cls(**arrays, stats=stats, status=Status(int(data["status"])),
               method=_method(str(data["method"])), h=float(data["h"]),
               failed_step=None if failed < 0 else failed, model_name=name, work=work,
               work_forces=forces, drawing=_drawing.loaded(data))


# ---------------------------------------------------------------------------- plotting helpers
def _coordinate_groups(coordinates, n: int) -> list:
    """``[(title or None, [indices])]``: the panels of :meth:`TrajectoryResult.plot`."""
    def indices(seq, name):
        try:
            idx = [int(i) for i in seq]
        except (TypeError, ValueError):
            raise TypeError(f"`{name}` must be a sequence of coordinate indices, got {seq!r}") from None
        bad = [i for i in idx if not 0 <= i < n]
        if bad:
            raise ValueError(f"`{name}` holds indices outside 0…{n - 1} (n = {n}): {bad}")
        return idx

    if coordinates is None:
        return [(None, list(range(n)))]
    if isinstance(coordinates, dict):
        if not coordinates:
            raise ValueError("`coordinates` as a mapping needs at least one group")
        return [(str(k), indices(v, f"coordinates[{k!r}]")) for k, v in coordinates.items()]
    return [(None, indices(coordinates, "coordinates"))]


def new_figure(path, figsize):
    """A figure that does not touch pyplot's state when it is only saved to ``path``.

    With a path the figure gets its own Agg canvas (``matplotlib.use`` would switch the
    backend for the whole process, breaking the caller's interactive windows); without
    one it comes from pyplot, so that notebooks and ``plt.show()`` display it.
    """
    if path is not None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=figsize)
        FigureCanvasAgg(fig)
        return fig
    import matplotlib.pyplot as plt

    return plt.figure(figsize=figsize)


def finish_figure(fig, path):
    if path is not None:
        fig.savefig(path, dpi=120)
    return fig


def residual_panel(ax, t, series: dict) -> None:
    """Log-scale residuals with exact zeros shown at the bottom edge, labelled as such."""
    nonzero = [np.asarray(y)[np.asarray(y) > 0] for y in series.values()]
    nonzero = np.concatenate(nonzero) if nonzero else np.zeros(0)
    if nonzero.size:
        lo, hi = float(nonzero.min()), float(nonzero.max())
    else:
        lo, hi = 1e-16, 1e-15
    lo_lim, hi_lim = 10 ** (math.floor(math.log10(lo)) - 0.5), 10 ** (math.ceil(math.log10(hi)) + 0.5)
    for label, y in series.items():
        y = np.asarray(y, dtype=float)
        line, = ax.semilogy(t, np.where(y > 0, y, np.nan), lw=0.8, label=label)
        zeros = y == 0
        if zeros.any():
            ax.plot(t[zeros], np.full(int(zeros.sum()), lo_lim * 1.5), ls="none", marker="o", ms=3,
                    mfc="none", color=line.get_color(), label=f"{label} exact 0")
    ax.set_ylim(lo_lim, hi_lim)
    ax.set_ylabel("residual")
    ax.legend(fontsize="small", loc="upper right")
