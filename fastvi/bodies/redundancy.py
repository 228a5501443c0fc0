r"""Degrees of freedom and redundant constraints, by a rank-revealing QR factorisation.

A mechanism with a closed loop may have more joint equations than independent ones: the
Bricard linkage has six revolute joints (30 equations on five bodies, 30 velocities), of
which only 29 are independent, so it moves with one degree of freedom where Grübler's count
says none. Its Jacobian ``G`` has rank ``m − 1`` everywhere; the multipliers are then not
unique, and the step's Newton matrix is singular. fastvi keeps an independent subset.

At a consistent configuration the velocities allowed by the bodies' own constraints are
the twists ``v = T ξ``: for a rigid body ``φ̇ = u``, ``ḋ_I = w × d_I`` (``ξ = (u, w)``), for a
point mass ``ẋ = u``. The joint rows act on them through ``G_J T``, and

.. math::

    \operatorname{rank} G = 6 N_\text{rigid} + \operatorname{rank}(G_J T), \qquad
    \text{dof} = n - \operatorname{rank} G = 6 N_\text{rigid} + 3 N_\text{points} - \operatorname{rank}(G_J T).

:func:`analyse` factors ``(G_J T)ᵀ Π = Q R`` with column pivoting (``scipy.linalg.qr``): the
pivot order picks the joint rows greedily, largest independent part first, and those whose
``|R_kk|`` falls below ``rtol · |R_00|`` are the redundant ones (Exudyn's
``ComputeSystemDegreeOfFreedom`` reports the same numbers). :func:`recheck` follows the
smallest singular value of the kept rows along a trajectory: a value that falls towards
zero means the kept subset is losing rank there and another choice is needed.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

__all__ = ["DegreesOfFreedom", "analyse", "twist_basis", "recheck", "RankCheck"]

#: |R_kk| / |R_00| below which a joint row counts as redundant
RANK_RTOL = 1e-10


@dataclass(frozen=True)
class DegreesOfFreedom:
    """What :func:`analyse` found at the reference configuration.

    Attributes
    ----------
    coordinates : int
        ``n``.
    equations : int
        All constraint rows (the bodies' own and the joints').
    rank : int
        Rank of ``G``.
    dof : int
        ``n − rank``.
    redundant : tuple of str
        Labels of the rows dropped as redundant (``"joint name: equation"``).
    redundant_rows, kept_rows : tuple of int
        Indices into the full list of rows.
    sigma_min : float
        Smallest singular value of the kept joint rows in twist coordinates (``G_J T``), a
        measure of how far the kept rows are from losing rank.
    """

    coordinates: int
    equations: int
    rank: int
    dof: int
    redundant: tuple
    redundant_rows: tuple
    kept_rows: tuple
    sigma_min: float

    def __str__(self) -> str:
        text = (f"{self.coordinates} coordinates, {self.equations} equations of rank {self.rank}: "
                f"{self.dof} degree(s) of freedom")
        if self.redundant:
            text += f"; {len(self.redundant)} redundant: " + ", ".join(self.redundant)
        return text


def twist_basis(bodies, offsets, q: np.ndarray) -> np.ndarray:
    """``T`` (n × k): the velocities the bodies' own constraints allow at ``q``, six columns
    per rigid body (``u``, then ``w``) and three per point mass."""
    n = q.shape[0]
    cols = sum(6 if b.size == 12 else 3 for b in bodies)
    T = np.zeros((n, cols))
    c = 0
    for body in bodies:
        o = offsets[body]
        T[o: o + 3, c: c + 3] = np.eye(3)
        if body.size == 12:
            for i in range(3):
                d = q[o + 3 + 3 * i: o + 6 + 3 * i]
                # ḋ = w × d = −d̂ w
                T[o + 3 + 3 * i: o + 6 + 3 * i, c + 3: c + 6] = -np.array(
                    [[0.0, -d[2], d[1]], [d[2], 0.0, -d[0]], [-d[1], d[0], 0.0]])
            c += 6
        else:
            c += 3
    return T


def analyse(G: np.ndarray, T: np.ndarray, joint_rows, labels, rtol: float = RANK_RTOL):
    """Rank, degrees of freedom and the redundant joint rows of ``G`` at a consistent state.

    Parameters
    ----------
    G : ndarray (m, n)
        All rows, evaluated at the reference configuration.
    T : ndarray (n, k)
        :func:`twist_basis`.
    joint_rows : sequence of int
        The rows that belong to joints (the others are the bodies' own, never redundant).
    labels : sequence of str
        A label per row.
    rtol : float
        Relative size of a pivot below which a row is redundant.

    Returns
    -------
    DegreesOfFreedom
    """
    m, n = G.shape
    joint_rows = np.asarray(joint_rows, dtype=int)
    own = np.setdiff1d(np.arange(m), joint_rows)
    redundant: list[int] = []
    sigma = np.inf
    rank_j = 0
    if joint_rows.size:
        B = G[joint_rows] @ T  # (m_J, k)
        _, R, piv = sla.qr(B.T, mode="economic", pivoting=True)
        diag = np.abs(np.diag(R))
        scale = diag[0] if diag.size else 0.0
        rank_j = int(np.sum(diag > rtol * max(scale, 1e-300))) if scale > 0 else 0
        redundant = sorted(int(joint_rows[i]) for i in piv[rank_j:])
        kept = np.sort(piv[:rank_j])
        sigma = float(np.linalg.svd(B[kept], compute_uv=False)[-1]) if kept.size else np.inf
    rank = own.size + rank_j
    kept_rows = tuple(int(i) for i in range(m) if i not in set(redundant))
    return DegreesOfFreedom(coordinates=n, equations=m, rank=rank, dof=n - rank,
                            redundant=tuple(labels[i] for i in redundant),
                            redundant_rows=tuple(redundant), kept_rows=kept_rows, sigma_min=sigma)


@dataclass(frozen=True)
class RankCheck:
    """The smallest singular value of the kept joint rows (twist coordinates) along a run.

    Attributes
    ----------
    t : ndarray (K,)
    sigma_min : ndarray (K,)
    ratio : float
        ``min(sigma_min) / sigma_min[0]``.
    ok : bool
        ``ratio >= threshold``.
    """

    t: np.ndarray
    sigma_min: np.ndarray
    ratio: float
    ok: bool


def recheck(model, result=None, *, q=None, t=None, every: int = 1, threshold: float = 1e-3,
            warn: bool = True) -> RankCheck:
    """Follow the conditioning of the kept rows along a trajectory.

    Parameters
    ----------
    model : fastvi.Model
        Built by :meth:`fastvi.bodies.Mechanism.build`.
    result : fastvi.Result, optional
        Its samples ``q`` and ``t``; or pass ``q`` (K, n) and ``t`` (K,).
    every : int, default 1
        Check every ``every``-th sample (and the last).
    threshold : float, default 1e-3
        Warn (``RuntimeWarning``) when ``σ_min`` falls below this fraction of its initial value:
        the kept rows are close to dependent there, and the multipliers (and the step's
        Newton matrix) ill-conditioned.
    warn : bool, default True

    Returns
    -------
    RankCheck
    """
    asm = model.assembly
    if result is not None:
        q, t = result.q, result.t
    q = np.atleast_2d(np.asarray(q, dtype=float))
    t = np.zeros(q.shape[0]) if t is None else np.asarray(t, dtype=float)
    idx = list(range(0, q.shape[0], max(1, int(every))))
    if idx[-1] != q.shape[0] - 1:
        idx.append(q.shape[0] - 1)
    rows = np.asarray(asm.joint_row_indices, dtype=int)
    sig = np.empty(len(idx))
    for k, i in enumerate(idx):
        G = model.constraint_jacobian_value(q[i], t=float(t[i]))
        B = G[rows] @ twist_basis(asm.bodies, asm.offsets, q[i])
        sig[k] = np.linalg.svd(B, compute_uv=False)[-1] if rows.size else np.inf
    ratio = float(sig.min() / sig[0]) if rows.size and sig[0] > 0 else 1.0
    ok = ratio >= threshold
    if warn and not ok:
        k = int(np.argmin(sig))
        warnings.warn(
            f"model {model.name!r}: the kept constraint rows approach dependence: their smallest "
            f"singular value fell to {sig[k]:.2e} ({ratio:.1e} of its initial {sig[0]:.2e}) at t = "
            f"{t[idx[k]]:.6g}; rebuild the model from a configuration near there so that another "
            "subset of rows is kept", RuntimeWarning, stacklevel=2)
    return RankCheck(t=t[idx], sigma_min=sig, ratio=ratio, ok=ok)
