r"""Lyapunov exponents of the discrete flow: :func:`lyapunov_spectrum`, :func:`largest_lyapunov`.

The tangent vectors are carried by :func:`fastvi.sensitivity` — the exact derivatives of
the map the integrator computes — and re-orthonormalised at the end of each segment
(Benettin et al. 1980; Shimada and Nagashima 1979): ``docs/sensitivities.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _validate as valid
from ._discrete import checked_model
from .sensitivity import sensitivity

__all__ = ["lyapunov_spectrum", "LyapunovSpectrum", "largest_lyapunov"]


@dataclass
class LyapunovSpectrum:
    r"""Finite-time Lyapunov exponents of :func:`lyapunov_spectrum`.

    Attributes
    ----------
    t : ndarray (J,)
        The ends of the segments, ``t_j = t0 + j · segment``, ``j = 1 … J``.
    exponents : ndarray (d,)
        The estimates at ``t_J``: ``running[-1]``, largest first (up to the finite-time
        scatter of exponents that are nearly equal).
    running : ndarray (J, d)
        ``running[j - 1, i] = λ_i(t_j) = (1/(j · segment)) Σ_{l ≤ j} growth[l - 1, i]``.
    growth : ndarray (J, d)
        ``log |R_ii|`` of segment ``j``: the logarithm of the growth of the ``i``-dimensional
        volume spanned by the first ``i`` vectors, divided by that of the first ``i − 1``
        (the segment's local exponents times ``segment``).
    segment : float
        The renormalisation interval (s).
    dimension : int
        ``2(n − m)``, the dimension of the tangent space of the constrained phase space.
    """

    t: np.ndarray
    exponents: np.ndarray
    running: np.ndarray
    growth: np.ndarray
    segment: float
    dimension: int


def lyapunov_spectrum(model, q0, v0, *, h: float, t_end: float, segment: float = 1.0,
                      count: int | None = None, method="P2L-Q3G", seed: int = 0,
                      start=None, t0: float = 0.0) -> LyapunovSpectrum:
    r"""The ``count`` largest Lyapunov exponents from the discrete tangent flow (QR method).

    Benettin's standard method (Shimada–Nagashima, Benettin et al.): ``d = count`` tangent
    vectors, the columns of ``Y_0``, are carried over each segment of ``segment`` seconds by
    one :func:`sensitivity` call, ``Y_j' = DΦ Y_{j-1}`` (one solve per vector and step with
    the step's exact Newton matrix); their end values are factored ``Y_j' = Y_j R_j`` (QR,
    ``Y_j`` orthonormal, ``R_j`` upper triangular) and the ``Y_j`` start the next segment:

    .. math::

        λ_i(t_J) = \frac{1}{t_J - t_0} \sum_{j=1}^{J} \log |(R_j)_{ii}|, \qquad t_J = t_0 + J\,\text{segment},

    ``λ_1 ≥ λ_2 ≥ …`` as ``t_J → ∞`` (Oseledets' theorem): ``λ_1 + … + λ_i`` is the growth
    rate of ``i``-dimensional volumes.

    The vectors live in the tangent space of the constrained phase space ``g(q) = 0``,
    ``G(q) M(q)⁻¹ p = 0``, of dimension ``2(n − m)`` (:func:`fastvi.tangent_space`); the
    norm is the Euclidean one of ``(δq, δp)`` ∈ ℝ²ⁿ restricted to that space — the same as
    the coordinates of the vectors in an orthonormal basis of it. Another norm changes the
    finite-time values, not the limits. For a conservative model the step is symplectic on
    that space, so the exponents come in pairs ``λ_i + λ_{2(n−m)+1−i} = 0``, two of them
    zero (the direction of the flow and the one across the energy surfaces). At finite
    ``t`` they are paired up to ``O(1/t)``: the step preserves ``Yᵀ J Y``, so the sum of
    all ``2(n − m)`` estimates is exactly

    .. math::

        \sum_i λ_i(t) = \frac{1}{2t} \log
        \frac{\det(Z_0^T J Z_0)}{\det(Z_t^T J Z_t)},

    ``Z`` an orthonormal basis of the tangent space at the start and at ``t``
    (:func:`fastvi.tangent_space`): the Euclidean volume of that space is not the
    symplectic one.

    A forced model — time-dependent constraints or potential, or a force that changes in
    time — is followed in time: each segment starts where the last one ended, at
    ``t0 + j · segment``, so the estimates do not depend on ``segment`` (up to round-off).
    A conservative forced model's step is still symplectic: its exponents come in pairs
    summing to zero and obey the sum above, but none is zero.

    Parameters
    ----------
    model, q0, v0, h, method :
        As :func:`sensitivity`: an autonomous model or a forced one (time-dependent
        constraints or potential, forces that change in time); dissipative forces make
        the sum of the exponents negative.
    t_end : float
        The span, a whole number of segments: the run ends at ``t0 + t_end``.
    segment : float, default 1.0
        Renormalisation interval, a whole number of steps ``h``: short enough that the
        vectors neither overflow nor align numerically (``(λ_1 − λ_d) · segment ≪ 30``).
    count : int, optional
        How many exponents, ``1 … 2(n − m)`` (default: all ``2(n − m)``).
    seed : int, default 0
        Seed of the random start vectors (normal raw directions ``(δq0, δv0)``, projected
        onto the tangent space like :func:`sensitivity`'s directions).
    start : array_like (2n, count), optional
        Start vectors ``(δq0, δv0)`` instead of random ones; projected likewise, and must
        stay independent after the projection.
    t0 : float, default 0.0
        The time of ``(q0, v0)``: where a forced model's drive starts.

    Returns
    -------
    LyapunovSpectrum
        ``exponents`` (count,), the running estimates ``running`` (J, count) at ``t``
        (J,), and the logarithms ``growth`` (J, count) of each segment.

    Raises
    ------
    ValueError
        ``segment`` not a whole number of steps, ``t_end`` not a whole number of segments,
        ``count`` out of range, or ``start`` of the wrong shape or dependent.
    fastvi.IntegrationError
        A step failed (see :func:`sensitivity`).

    References
    ----------
    I. Shimada, T. Nagashima, A numerical approach to ergodic problem of dissipative
    dynamical systems, Prog. Theor. Phys. 61 (1979) 1605–1616. G. Benettin, L. Galgani,
    A. Giorgilli, J.-M. Strelcyn, Lyapunov characteristic exponents for smooth dynamical
    systems and for Hamiltonian systems; a method for computing all of them, Meccanica 15
    (1980) 9–20 and 21–30.

    Examples
    --------
    >>> import numpy as np, fastvi
    >>> dp = fastvi.scenes.double_pendulum()
    >>> q0, v0 = dp.initial_state(np.pi / 2, np.pi / 2)
    >>> spec = fastvi.lyapunov_spectrum(dp, q0, v0, h=0.01, t_end=20.0)
    >>> spec.exponents.shape                           # 2(n − m) = 4
    (4,)
    >>> bool(spec.exponents[0] > 0.3)                  # chaotic
    True
    """
    checked_model(model)
    h = valid.step_size(h)
    t0 = valid.start_time(t0)
    segment, t_end = valid.duration(segment, "segment"), valid.duration(t_end, "t_end")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"`seed` must be an integer, got {seed!r}")
    steps = int(round(segment / h))
    segments = int(round(t_end / segment))
    if steps < 1 or abs(steps * h - segment) > 1e-9 * segment:
        raise ValueError(f"`segment` = {segment:g} must be a whole number of steps `h` = {h:g}")
    if segments < 1 or abs(segments * segment - t_end) > 1e-9 * t_end:
        raise ValueError(f"`t_end` = {t_end:g} must be a whole number of segments ({segment:g} s)")
    n, k = model.n, model.params.shape[0]
    dim = 2 * (n - model.m)
    d = dim if count is None else valid.count(count, "count", 1)
    if not 1 <= d <= dim:
        raise ValueError(f"`count` = {count} must be between 1 and 2(n − m) = {dim}, the "
                         "dimension of the tangent space")
    if start is None:
        w = np.random.default_rng(seed).normal(size=(2 * n, d))
    else:
        w = np.array(start, dtype=float)
        if w.ndim == 1:
            w = w[:, None]
        if w.shape != (2 * n, d) or not np.all(np.isfinite(w)):
            raise ValueError(f"`start` must hold {d} finite start vectors (δq0, δv0) as columns, "
                             f"shape ({2 * n}, {d}); got shape {w.shape}")
    q, v, t = np.array(q0, dtype=float), np.array(v0, dtype=float), t0
    growth = np.empty((segments, d))
    for j in range(segments):
        raw = np.vstack([w, np.zeros((k, d))])  # the parameters stay fixed
        # each segment starts at the time the last one ended: a forced model's drive runs on
        s = sensitivity(model, q, v, h=h, n_steps=steps, wrt=raw, save_every=steps,
                        method=method, t0=t)
        # the start's own triangle too: the first segment's vectors are merely projected,
        # and the next ones are re-projected at the re-projected state (round-off)
        r0 = _triangle(np.vstack([s.dq[0], s.dp[0]]), "start")
        r1 = _triangle(np.vstack([s.dq[-1], s.dp[-1]]), "end")
        growth[j] = np.log(np.abs(np.diag(r1))) - np.log(np.abs(np.diag(r0)))
        # Y_j = Y_j' R_j⁻¹, taken in (δq, δv) — the same linear combinations — to feed back
        w = np.linalg.solve(r1.T, np.vstack([s.dq[-1], s.dv[-1]]).T).T
        q, v, t = s.result.q[-1].copy(), s.result.v[-1].copy(), float(s.result.t[-1])
    elapsed = segment * np.arange(1, segments + 1)
    running = np.cumsum(growth, axis=0) / elapsed[:, None]
    return LyapunovSpectrum(t0 + elapsed, running[-1].copy(), running, growth, segment, dim)


def _triangle(Y, where):
    """``R`` of the QR factorisation of the tangent vectors ``Y`` (2n, d)."""
    r = np.linalg.qr(Y, mode="r")
    diag = np.abs(np.diag(r))
    if not np.all(diag > 1e-13 * max(diag.max(), 1e-300)):
        raise ValueError(f"the tangent vectors became dependent at the {where} of a segment: "
                         "pass independent `start` vectors, or a shorter `segment`")
    return r


def largest_lyapunov(model, q0, v0, *, h: float, t_end: float, segment: float = 1.0,
                     method="P2L-Q3G", seed: int = 0, t0: float = 0.0) -> np.ndarray:
    r"""Running estimate of the largest Lyapunov exponent from the discrete tangent flow.

    :func:`lyapunov_spectrum` with one vector (Benettin's method): one tangent vector,
    random at the start and projected onto the tangent space of the constraints, is carried
    over each segment of ``segment`` seconds and renormalised, its growth factor ``g_j``
    taken in the Euclidean norm of ``(δq, δp)``:

    .. math:: λ(t_J) = \frac{1}{t_J} \sum_{j=1}^{J} \log g_j, \qquad t_J = J\,\text{segment}.

    A regular (quasi-periodic) motion gives ``λ → 0`` like ``log t / t``; a chaotic one a
    positive limit. The norm and the start vector change only the transient.

    Parameters
    ----------
    model, q0, v0, h, t_end, segment, method, seed, t0 :
        As :func:`lyapunov_spectrum`.

    Returns
    -------
    ndarray (J,)
        ``λ(t_j)`` at ``t_j = t0 + j · segment``, ``j = 1 … J``.

    Examples
    --------
    >>> import numpy as np, fastvi
    >>> dp = fastvi.scenes.double_pendulum()
    >>> q0, v0 = dp.initial_state(0.1, 0.1)          # small oscillations: regular
    >>> lam = fastvi.largest_lyapunov(dp, q0, v0, h=0.01, t_end=50.0)
    >>> bool(abs(lam[-1]) < 0.02)
    True
    """
    return lyapunov_spectrum(model, q0, v0, h=h, t_end=t_end, segment=segment, count=1,
                             method=method, seed=seed, t0=t0).running[:, 0]
