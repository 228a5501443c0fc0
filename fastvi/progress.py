"""A progress line for long runs: a tqdm bar on a terminal, plain lines in logs.

Used by :func:`fastvi.integrate`, :func:`fastvi.integrate_ensemble`,
:func:`fastvi.sensitivity` and :meth:`fastvi.Result.animate` (``progress=True``).
"""

from __future__ import annotations

import math
import sys
import time

__all__ = ["ProgressBar", "UPDATES"]

#: progress updates of a run with ``progress=True``: its steps go through the kernel in this
#: many chunks (a kernel call cannot report from inside its loop)
UPDATES = 50


class ProgressBar:
    """One updating progress line on a terminal (tqdm); plain lines otherwise.

    On a TTY the line is a :class:`tqdm.tqdm` bar rewritten in place (and ended with a
    newline when the run finishes). When the stream is a file or a pipe (a log, CI, a
    notebook's captured stderr) a full line is written at most every ``interval`` seconds
    and at the end, so logs stay readable: tqdm rewrites its line with ``\\r`` there too,
    which a log shows as one ever longer line.

    Parameters
    ----------
    total : int
        Units of work (steps, or member-steps).
    unit : str
        What is counted.
    stream : file-like, default ``sys.stderr``
    interval : float
        Minimum seconds between plain lines (terminal updates are throttled to 0.1 s).
    label : str
        The text the line starts with.
    """

    def __init__(self, total: int, unit: str = "steps", stream=None, interval: float = 5.0,
                 label: str = "fastvi"):
        self.total, self.unit, self.label = max(int(total), 1), unit, label
        self.stream = sys.stderr if stream is None else stream
        isatty = getattr(self.stream, "isatty", None)
        self.tty = bool(isatty()) if callable(isatty) else False
        self.t0 = time.perf_counter()
        self._last = -math.inf
        self._bar = None
        if self.tty:
            from tqdm import tqdm

            # miniters=1 with mininterval: at most one redraw per interval, none skipped
            self._bar = tqdm(total=self.total, unit=unit, file=self.stream, mininterval=0.1,
                             miniters=1, dynamic_ncols=True, leave=True,
                             bar_format="{desc}: {n}/{total} {unit} ({percentage:3.0f}%)"
                                        "{postfix} |{bar:20}| {elapsed}, {rate_fmt}",
                             desc=label)
        self.interval = 0.1 if self.tty else float(interval)

    @property
    def interval(self) -> float:
        """Minimum seconds between two lines (on a terminal: between two redraws)."""
        return self._interval

    @interval.setter
    def interval(self, seconds: float) -> None:
        self._interval = float(seconds)
        if self._bar is not None:
            self._bar.mininterval = self._interval

    def update(self, done: int, extra: str = "", final: bool = False) -> None:
        """Report ``done`` units of work so far; ``final`` ends the line.

        Parameters
        ----------
        done : int
            Units done since the start (not since the last update).
        extra : str
            Appended to the line (e.g. the simulated time).
        final : bool
            Write the line even within ``interval`` and end it.
        """
        if self._bar is not None:
            self._bar.set_postfix_str(extra, refresh=False)
            self._bar.update(max(0, int(done) - self._bar.n))
            if final:
                self._bar.close()
            return
        now = time.perf_counter()
        if not final and now - self._last < self.interval:
            return
        self._last = now
        el = now - self.t0
        frac = min(1.0, done / self.total)
        rate = done / max(el, 1e-9)
        text = (f"{self.label}: {done}/{self.total} {self.unit} ({100 * frac:3.0f}%)"
                + (f", {extra}" if extra else "") + f", {el:.1f} s, {rate:.3g} {self.unit}/s")
        self.stream.write(text + "\n")
        self.stream.flush()

    def close(self, done: int, extra: str = "") -> None:
        """Write the last line.

        Parameters
        ----------
        done : int
            Units done in all.
        extra : str
            Appended to the line.
        """
        self.update(done, extra, final=True)
