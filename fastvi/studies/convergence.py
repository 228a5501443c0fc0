"""Measured orders of convergence: the log–log slope with the round-off plateau trimmed."""

from __future__ import annotations

import numpy as np

#: errors below this are round-off, not discretisation error
PLATEAU = 1e-12
MIN_POINTS = 3


def observed_order(hs, errors, plateau: float = PLATEAU, min_points: int = MIN_POINTS):
    """Least-squares slope of log(error) against log(h), round-off plateau trimmed.

    Points with ``error < plateau`` are dropped, and so is every point at a smaller ``h``
    than one where the error stopped decreasing (the plateau has begun).

    Returns
    -------
    order : float
        The slope (nan if fewer than ``min_points`` points remain).
    used : ndarray of bool
        Which points entered the fit.
    """
    hs = np.asarray(hs, float)
    errors = np.asarray(errors, float)
    idx = np.argsort(-hs)  # largest h first
    used = np.zeros(len(hs), bool)
    prev = np.inf
    for i in idx:
        e = errors[i]
        if not np.isfinite(e) or e < plateau or e >= prev:
            break
        used[i] = True
        prev = e
    if used.sum() < min_points:
        return float("nan"), used
    slope = np.polyfit(np.log(hs[used]), np.log(errors[used]), 1)[0]
    return float(slope), used


def drift_slope(t, err, windows: int = 20):
    """Slope of a straight line fitted to the per-window maximum of ``|err|`` over time.

    A variational integrator's energy error oscillates without growing: this slope,
    relative to the error's size, is ~0. A drifting method shows a positive slope.

    Returns
    -------
    slope : float  (error units per time unit)
    window_max : ndarray (windows,)
    """
    t = np.asarray(t, float)
    err = np.abs(np.asarray(err, float))
    edges = np.linspace(0, len(t), windows + 1).astype(int)
    tm = np.array([t[a:b].mean() for a, b in zip(edges[:-1], edges[1:])])
    em = np.array([err[a:b].max() for a, b in zip(edges[:-1], edges[1:])])
    slope = np.polyfit(tm, em, 1)[0]
    return float(slope), em
