r"""Classical RK4 on the index-1 form of a constrained :class:`~fastvi.Model` (the yardstick).

Paper B compares its variational integrators with a "traditional Runge–Kutta method". This
is that method on the *same* model callbacks as the integrator, so a comparison is between
discretisations, never between two codings of the physics. The index-3 DAE
``d/dt(M v) − ∂T/∂q + ∇V + Gᵀλ = 0``, ``g(q) = 0`` is differentiated twice in time:

    [ M(q)  G(q)ᵀ ] [ a ]   [ f(q, v)  ]        f = ∂T/∂q(q, v) − ∇V(q) − (∂(M v)/∂q) v,
    [ G(q)   0    ] [ λ ] = [ −(Ġ v)   ]        (Ġ v)_c = vᵀ ∇²g_c(q) v,

an ODE ``q̇ = v``, ``v̇ = a(q, v)`` integrated with the classical four-stage Runge–Kutta
method (order 4). Its solution satisfies ``g(q) = 0`` only as far as the discretisation
and round-off allow: the residuals drift (``|G v|`` linearly, ``|g|`` quadratically in
time, at the size of the local error). With ``project=True`` each step ends with the
orthogonal projection in the metric ``M`` onto ``g(q) = 0`` (simplified Newton) and then
onto ``G(q) v = 0``, which removes the constraint drift but not the energy drift.

Large models with a diagonal constant mass solve the saddle system through ``G M⁻¹ Gᵀ``
over the pattern of G, banded or sparse (:func:`workspace`, issue 12): an evaluation costs
O(nnz(G)) instead of the dense O((n + m)³) LU.

The kernels take the model's cfunc tuple as an argument, like :mod:`fastvi.kernels.step`,
so they compile once for every model. Second derivatives the model does not supply exactly
(``∂(M v)/∂q`` and ``∇²g``) are replaced by a central difference along ``v``.

References
----------
Paper B, section 5 (comparison with Runge–Kutta). E. Hairer, G. Wanner, *Solving Ordinary
Differential Equations II*, section VII.2 (index reduction, projection methods).
"""

from __future__ import annotations

import time
from collections import namedtuple
from dataclasses import dataclass, field

import numpy as np

from .. import _validate as check
from .._numba import hot, njit, ptr
from ..kernels.banded import gmg_factor, gmg_solve, gt_times
from ..kernels.layout import SI_GCOL, SI_GPTR, SI_HEADER, SI_S, SOLVE_DENSE
from ..kernels.linalg import lu_factor, lu_solve
from ..model import Model
from ..results import TrajectoryResult
from ..status import MESSAGES, Status

__all__ = ["rk4", "BaselineResult", "acceleration", "make_workspace", "workspace"]

from ..kernels.layout import CHESS as _CHESS
from ..kernels.layout import CJAC as _CJAC
from ..kernels.layout import CON as _CON
from ..kernels.layout import F_CH_PATTERN as _F_CH_PATTERN
from ..kernels.layout import F_EX_CHESS as _F_EXACT_CHESS
from ..kernels.layout import F_EX_MJAC as _F_EXACT_MJAC
from ..kernels.layout import F_M as _F_M
from ..kernels.layout import F_MASSFN as _F_MASSFN
from ..kernels.layout import F_N as _F_N
from ..kernels.layout import KGRAD as _KGRAD
from ..kernels.layout import MASS as _MASS
from ..kernels.layout import MJAC as _MJAC
from ..kernels.layout import POT as _POT
from ..kernels.layout import PGRAD as _PGRAD

_FD_REL = 6.0554544523933395e-06  # cbrt(machine epsilon): central differences' best step
#: simplified-Newton sweeps of the position projection (it converges linearly, fast)
PROJECTION_MAX_ITER = 20
#: the position projection stops at this max|g|, relative to max(1, |q|)
PROJECTION_TOL = 4e-16

from ..kernels.layout import NONFINITE as _NONFINITE  # noqa: E402
from ..kernels.layout import OK as _OK  # noqa: E402
from ..kernels.layout import SINGULAR_CONSTRAINTS as _SINGULAR  # noqa: E402


@dataclass(repr=False)
class BaselineResult(TrajectoryResult):
    """Trajectory of a baseline integrator, with the fields of :class:`fastvi.Result` it shares.

    Attributes
    ----------
    t : ndarray (K,)
    q, v : ndarray (K, n)
    energy : ndarray (K,)
        ``H = ½ vᵀ M(q) v + V(q)``.
    constraint_residual, velocity_residual : ndarray (K,)
        ``max |g(q)|`` and ``max |G(q) v|`` (over the steps since the previous sample).
    stats : dict
        ``steps``, ``rhs_evaluations``, ``wall_time`` (s, excluding compilation).
    status : Status
    name : str
        ``"RK4"``, ``"RK4+proj"`` or ``"SciPy <method>"``.
    h : float
        The fixed step, or ``nan`` for an adaptive SciPy run.
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    energy: np.ndarray
    constraint_residual: np.ndarray
    velocity_residual: np.ndarray
    stats: dict
    status: Status
    name: str
    h: float
    model_name: str = field(default="model")
    failed_step: int | None = None

    def _label(self) -> str:
        return self.name


#: scratch of one RK4 trajectory (:func:`make_workspace`)
Workspace = namedtuple("Workspace", [
    "K",  # (n+m, n+m) [M Gᵀ; G 0], factored in place
    "rhs",  # (n+m,) right-hand side, then (a, λ)
    "piv",  # (n+m,) its pivots
    "M",  # (n, n) M(q)
    "Cq",  # (n, n) ∂(M v)/∂q
    "Hc",  # (n, n) constraint Hessian, or M at q ± ε v
    "G", "Gp", "Gm",  # (m, n) G, and G at q ± ε v
    "dV", "dT", "qa",  # (n,) ∇V, ∂T/∂q, q ± ε v
    "g", "unit",  # (m,) g, a unit impulse for the Hessian contraction
    "stages",  # (10, n) RK stages k1…k4 of q and of v, the stage q and v
    "pot",  # (1,) potential value
    "lam", "pivm",  # (m,) multipliers and pivots of a structured G M⁻¹ Gᵀ
    "si", "sb",  # the projection's plan (fastvi.structure.plan(model, None)): dense if zero
])
#: the saved samples of :func:`run`: time, q, v, energy, and the maxima of |g|, |G v| over
#: the steps since the previous sample
Samples = namedtuple("Samples", ["t", "q", "v", "energy", "g", "gv"])
#: entries of the observation vector filled by :func:`observe`
OBS_H, OBS_G, OBS_GV = range(3)
OBS_SIZE = 3
#: entries of ``run``'s ``info``: steps done, samples written
RUN_STEPS, RUN_SAVED = range(2)
RUN_INFO_SIZE = 2


@njit
def make_workspace(n, m):
    """Scratch for one trajectory: the saddle-point system and stage vectors (the dense
    path; :func:`workspace` adds a large model's structured plan)."""
    N = n + m
    mm = max(m, 1)
    return Workspace(
        np.zeros((N, N)), np.zeros(N), np.zeros(N, dtype=np.int64),
        np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n)),
        np.zeros((mm, n)), np.zeros((mm, n)), np.zeros((mm, n)),
        np.zeros(n), np.zeros(n), np.zeros(n),
        np.zeros(mm), np.zeros(mm),
        np.zeros((10, n)),
        np.zeros(1),
        np.zeros(mm), np.zeros(mm, dtype=np.int64),
        np.zeros(SI_HEADER, dtype=np.int64), np.zeros(1),
    )


def workspace(model, prm=None, solver: str = "auto"):
    """:func:`make_workspace` for ``model``, with the structured plan of its projection
    ``G M⁻¹ Gᵀ`` (banded or sparse, :func:`fastvi.structure.plan` with ``meth=None``) when
    the model is large with a diagonal constant mass: an evaluation then costs O(nnz(G)),
    not O((n + m)³)."""
    from .. import structure

    ws = make_workspace(model.n, model.m)
    p = structure.plan(model, None, prm, solver)
    if p.si[SI_S] != SOLVE_DENSE:
        ws = ws._replace(si=p.si.copy(), sb=p.sb.copy())
    return ws


@hot
def _mass(fns, flags, Mc, prm, q, M):
    n = q.shape[0]
    if flags[_F_MASSFN] != 0:
        fns[_MASS](ptr(q), ptr(q), ptr(prm), ptr(M))
    else:
        for a in range(n):
            for c in range(n):
                M[a, c] = Mc[a, c]


@hot
def _fd_step(q, v):
    """Central-difference step along ``v``: relative to |q|, measured in units of |v|."""
    qs = 1.0
    vs = 0.0
    for a in range(q.shape[0]):
        qs = max(qs, abs(q[a]))
        vs = max(vs, abs(v[a]))
    if vs == 0.0:
        return 0.0
    return _FD_REL * qs / vs


@hot
def _jacobians_along_v(fns, prm, q, v, eps, qa, Gp, Gm):
    """``Gp``, ``Gm`` = G(q ± ε v): the central difference of ``Ġ v``."""
    n = q.shape[0]
    for c in range(n):
        qa[c] = q[c] + eps * v[c]
    fns[_CJAC](ptr(qa), ptr(qa), ptr(prm), ptr(Gp))
    for c in range(n):
        qa[c] = q[c] - eps * v[c]
    fns[_CJAC](ptr(qa), ptr(qa), ptr(prm), ptr(Gm))


@hot
def _saddle(M, G, n, m, K):
    """K = [M Gᵀ; G 0]."""
    for a in range(n):
        for c in range(n):
            K[a, c] = M[a, c]
        for c in range(m):
            K[a, n + c] = G[c, a]
            K[n + c, a] = G[c, a]
    for c in range(m):
        for d in range(m):
            K[n + c, n + d] = 0.0


@hot
def _acceleration_structured(fns, flags, Mc, prm, q, v, a, ws):
    """:func:`acceleration` of a large model with a diagonal constant mass, over the pattern
    of G: ``(G M⁻¹ Gᵀ) λ = G M⁻¹ f + Ġ v`` factored banded or sparse, ``a = M⁻¹ (f − Gᵀ λ)``,
    ``f = −∇V``. ``Ġ v`` is a central difference of G along v (two Jacobian calls where the
    exact Hessian would take m calls with dense (n, n) outputs); for constraints quadratic in
    q, as the chains', it is exact up to round-off."""
    n = flags[_F_N]
    m = flags[_F_M]
    si, sb = ws.si, ws.sb
    G, Gp, Gm, dV, qa, lam = ws.G, ws.Gp, ws.Gm, ws.dV, ws.qa, ws.lam
    fns[_PGRAD](ptr(q), ptr(q), ptr(prm), ptr(dV))
    fns[_CJAC](ptr(q), ptr(q), ptr(prm), ptr(G))
    eps = _fd_step(q, v)
    if eps > 0.0:
        _jacobians_along_v(fns, prm, q, v, eps, qa, Gp, Gm)
    gp = si[SI_GPTR]
    gc = si[SI_GCOL]
    for c in range(m):
        acc = 0.0
        dgv = 0.0
        for k in range(si[gp + c], si[gp + c + 1]):
            i = si[gc + k]
            acc -= G[c, i] * dV[i] / Mc[i, i]
            if eps > 0.0:
                dgv += (Gp[c, i] - Gm[c, i]) * v[i]
        lam[c] = acc + (dgv * (0.5 / eps) if eps > 0.0 else 0.0)
    if gmg_factor(si, sb, G, Mc, m, ws.pivm) != 0:
        return _SINGULAR
    gmg_solve(si, sb, lam, m, ws.pivm)
    for i in range(n):
        a[i] = -dV[i]
    gt_times(si, G, lam, a, -1.0, m)
    for i in range(n):
        a[i] /= Mc[i, i]
        if not np.isfinite(a[i]):
            return _NONFINITE
    for c in range(m):
        ws.rhs[n + c] = lam[c]
    return _OK


@hot
def _project_structured(fns, flags, Mc, prm, q, v, ws):
    """:func:`_project` of a large model with a diagonal constant mass: the same
    corrections, ``δ = −M⁻¹ Gᵀ (G M⁻¹ Gᵀ)⁻¹ r``, over the pattern of G."""
    n = flags[_F_N]
    m = flags[_F_M]
    si, sb, G, gv, lam = ws.si, ws.sb, ws.G, ws.g, ws.lam
    gp = si[SI_GPTR]
    gc = si[SI_GCOL]
    qs = 1.0
    for i in range(n):
        qs = max(qs, abs(q[i]))
    fns[_CJAC](ptr(q), ptr(q), ptr(prm), ptr(G))
    if gmg_factor(si, sb, G, Mc, m, ws.pivm) != 0:
        return _SINGULAR
    for _ in range(PROJECTION_MAX_ITER):
        fns[_CON](ptr(q), ptr(q), ptr(prm), ptr(gv))
        gmax = 0.0
        for c in range(m):
            gmax = max(gmax, abs(gv[c]))
            lam[c] = gv[c]
        if not np.isfinite(gmax):
            return _NONFINITE
        if gmax <= PROJECTION_TOL * qs:
            break
        gmg_solve(si, sb, lam, m, ws.pivm)
        _sub_minv_gt(si, G, lam, Mc, q, m)
    fns[_CJAC](ptr(q), ptr(q), ptr(prm), ptr(G))
    if gmg_factor(si, sb, G, Mc, m, ws.pivm) != 0:
        return _SINGULAR
    for c in range(m):
        acc = 0.0
        for k in range(si[gp + c], si[gp + c + 1]):
            i = si[gc + k]
            acc += G[c, i] * v[i]
        lam[c] = acc
    gmg_solve(si, sb, lam, m, ws.pivm)
    _sub_minv_gt(si, G, lam, Mc, v, m)
    return _OK


@hot
def _sub_minv_gt(si, G, lam, Mc, x, m):
    """``x −= M⁻¹ Gᵀ λ`` over the pattern of G (diagonal ``M``)."""
    gp = si[SI_GPTR]
    gc = si[SI_GCOL]
    for c in range(m):
        e = lam[c]
        for k in range(si[gp + c], si[gp + c + 1]):
            i = si[gc + k]
            x[i] -= G[c, i] * e / Mc[i, i]


@hot
def acceleration(fns, flags, Mc, prm, q, v, a, ws):
    """Solve the index-1 system at ``(q, v)`` for the acceleration ``a`` (n,), in place.

    Returns a status code (0, or ``SINGULAR_CONSTRAINTS`` if ``[M Gᵀ; G 0]`` is singular,
    or ``NONFINITE``). The multipliers ``λ`` are left in ``ws.rhs[n:]``.
    """
    n = flags[_F_N]
    m = flags[_F_M]
    if m > 0 and ws.si[SI_S] != SOLVE_DENSE:
        return _acceleration_structured(fns, flags, Mc, prm, q, v, a, ws)
    K, rhs, piv, M = ws.K, ws.rhs, ws.piv, ws.M
    Cq, Hc = ws.Cq, ws.Hc
    G, Gp, Gm = ws.G, ws.Gp, ws.Gm
    dV, dT, qa = ws.dV, ws.dT, ws.qa
    unit = ws.unit
    _mass(fns, flags, Mc, prm, q, M)
    fns[_PGRAD](ptr(q), ptr(q), ptr(prm), ptr(dV))
    for i in range(n):
        rhs[i] = -dV[i]
    if flags[_F_MASSFN] != 0:
        fns[_KGRAD](ptr(q), ptr(v), ptr(prm), ptr(dT))
        for i in range(n):
            rhs[i] += dT[i]
        # − (∂(M v)/∂q) v: the part of d/dt (M v) that is not M a
        if flags[_F_EXACT_MJAC] != 0:
            fns[_MJAC](ptr(q), ptr(v), ptr(prm), ptr(Cq))
            for i in range(n):
                acc = 0.0
                for c in range(n):
                    acc += Cq[i, c] * v[c]
                rhs[i] -= acc
        else:
            eps = _fd_step(q, v)
            if eps > 0.0:
                for sgn in (1.0, -1.0):
                    for c in range(n):
                        qa[c] = q[c] + sgn * eps * v[c]
                    fns[_MASS](ptr(qa), ptr(qa), ptr(prm), ptr(Hc))
                    for i in range(n):
                        acc = 0.0
                        for c in range(n):
                            acc += Hc[i, c] * v[c]
                        rhs[i] -= sgn * acc * (0.5 / eps)
    if m > 0:
        fns[_CJAC](ptr(q), ptr(q), ptr(prm), ptr(G))
        # −(Ġ v)_c = −vᵀ ∇²g_c v
        if flags[_F_EXACT_CHESS] != 0:
            for c in range(m):
                for d in range(m):
                    unit[d] = 0.0
                unit[c] = 1.0
                if flags[_F_CH_PATTERN] != 0:  # it writes the shared coordinates' entries
                    for i in range(n):
                        for j in range(n):
                            Hc[i, j] = 0.0
                fns[_CHESS](ptr(q), ptr(unit), ptr(prm), ptr(Hc))
                acc = 0.0
                for i in range(n):
                    for j in range(n):
                        acc += v[i] * Hc[i, j] * v[j]
                rhs[n + c] = -acc
        else:
            eps = _fd_step(q, v)
            for c in range(m):
                rhs[n + c] = 0.0
            if eps > 0.0:
                _jacobians_along_v(fns, prm, q, v, eps, qa, Gp, Gm)
                for c in range(m):
                    acc = 0.0
                    for i in range(n):
                        acc += (Gp[c, i] - Gm[c, i]) * v[i]
                    rhs[n + c] = -acc * (0.5 / eps)
    _saddle(M, G, n, m, K)
    if lu_factor(K, piv, n + m) != 0:
        return _SINGULAR
    lu_solve(K, piv, rhs, n + m)
    for i in range(n):
        a[i] = rhs[i]
        if not np.isfinite(a[i]):
            return _NONFINITE
    return _OK


@hot
def _project(fns, flags, Mc, prm, q, v, ws):
    """M-orthogonal projection of q onto g = 0 (simplified Newton), then of v onto G v = 0.

    Both corrections solve ``[M Gᵀ; G 0] [δ; μ] = [0; −r]`` (r = g, then G v), which gives
    ``δ = −M⁻¹Gᵀ (G M⁻¹ Gᵀ)⁻¹ r``, the smallest correction in the kinetic-energy norm.
    """
    n = flags[_F_N]
    m = flags[_F_M]
    if ws.si[SI_S] != SOLVE_DENSE:
        return _project_structured(fns, flags, Mc, prm, q, v, ws)
    K, rhs, piv, M = ws.K, ws.rhs, ws.piv, ws.M
    G = ws.G
    gv = ws.g
    qs = 1.0
    for i in range(n):
        qs = max(qs, abs(q[i]))
    _mass(fns, flags, Mc, prm, q, M)
    fns[_CJAC](ptr(q), ptr(q), ptr(prm), ptr(G))
    _saddle(M, G, n, m, K)
    if lu_factor(K, piv, n + m) != 0:
        return _SINGULAR
    for _ in range(PROJECTION_MAX_ITER):
        fns[_CON](ptr(q), ptr(q), ptr(prm), ptr(gv))
        gmax = 0.0
        for c in range(m):
            gmax = max(gmax, abs(gv[c]))
        if not np.isfinite(gmax):
            return _NONFINITE
        if gmax <= PROJECTION_TOL * qs:
            break
        for i in range(n):
            rhs[i] = 0.0
        for c in range(m):
            rhs[n + c] = -gv[c]
        lu_solve(K, piv, rhs, n + m)
        for i in range(n):
            q[i] += rhs[i]
    _mass(fns, flags, Mc, prm, q, M)
    fns[_CJAC](ptr(q), ptr(q), ptr(prm), ptr(G))
    _saddle(M, G, n, m, K)
    if lu_factor(K, piv, n + m) != 0:
        return _SINGULAR
    for i in range(n):
        rhs[i] = 0.0
    for c in range(m):
        acc = 0.0
        for i in range(n):
            acc += G[c, i] * v[i]
        rhs[n + c] = -acc
    lu_solve(K, piv, rhs, n + m)
    for i in range(n):
        v[i] += rhs[i]
    return _OK


@hot
def _stage(fns, flags, Mc, prm, q, v, c, kq, kv, kq_next, kv_next, ws):
    """The next stage from ``(q, v) + c (kq, kv)``: its velocity into ``kq_next``, its
    acceleration into ``kv_next``; returns the status of :func:`acceleration`."""
    n = flags[_F_N]
    qs, vs = ws.stages[8], ws.stages[9]
    for i in range(n):
        qs[i] = q[i] + c * kq[i]
        vs[i] = v[i] + c * kv[i]
        kq_next[i] = vs[i]
    return acceleration(fns, flags, Mc, prm, qs, vs, kv_next, ws)


@hot
def rk4_step(fns, flags, Mc, prm, h, q, v, ws):
    """One classical RK4 step of ``(q̇, v̇) = (v, a(q, v))``, in place."""
    n = flags[_F_N]
    S = ws.stages
    kq1, kq2, kq3, kq4, kv1, kv2, kv3, kv4 = S[0], S[1], S[2], S[3], S[4], S[5], S[6], S[7]
    for i in range(n):
        kq1[i] = v[i]
    st = acceleration(fns, flags, Mc, prm, q, v, kv1, ws)
    # c = 0.5 * h: the same rounding as the product 0.5 * h * k written out
    if st == _OK:
        st = _stage(fns, flags, Mc, prm, q, v, 0.5 * h, kq1, kv1, kq2, kv2, ws)
    if st == _OK:
        st = _stage(fns, flags, Mc, prm, q, v, 0.5 * h, kq2, kv2, kq3, kv3, ws)
    if st == _OK:
        st = _stage(fns, flags, Mc, prm, q, v, h, kq3, kv3, kq4, kv4, ws)
    if st != _OK:
        return st
    h6 = h / 6.0
    for i in range(n):
        q[i] += h6 * (kq1[i] + 2.0 * kq2[i] + 2.0 * kq3[i] + kq4[i])
        v[i] += h6 * (kv1[i] + 2.0 * kv2[i] + 2.0 * kv3[i] + kv4[i])
    return _OK


@hot
def observe(fns, flags, Mc, prm, q, v, ws, out):
    """``out[OBS_H]``, ``out[OBS_G]``, ``out[OBS_GV]`` = H, max|g|, max|G v| at ``(q, v)``."""
    n = flags[_F_N]
    m = flags[_F_M]
    M, G, gv, pot = ws.M, ws.G, ws.g, ws.pot
    structured = m > 0 and ws.si[SI_S] != SOLVE_DENSE  # diagonal constant M, pattern of G
    fns[_POT](ptr(q), ptr(q), ptr(prm), ptr(pot))
    e = pot[0]
    if structured:
        for i in range(n):
            e += 0.5 * Mc[i, i] * v[i] * v[i]
    else:
        _mass(fns, flags, Mc, prm, q, M)
        for i in range(n):
            acc = 0.0
            for c in range(n):
                acc += M[i, c] * v[c]
            e += 0.5 * v[i] * acc
    out[OBS_H] = e
    out[OBS_G] = 0.0
    out[OBS_GV] = 0.0
    if m > 0:
        fns[_CON](ptr(q), ptr(q), ptr(prm), ptr(gv))
        fns[_CJAC](ptr(q), ptr(q), ptr(prm), ptr(G))
        si = ws.si
        for c in range(m):
            out[OBS_G] = max(out[OBS_G], abs(gv[c]))
            acc = 0.0
            if structured:
                for k in range(si[si[SI_GPTR] + c], si[si[SI_GPTR] + c + 1]):
                    i = si[si[SI_GCOL] + k]
                    acc += G[c, i] * v[i]
            else:
                for i in range(n):
                    acc += G[c, i] * v[i]
            out[OBS_GV] = max(out[OBS_GV], abs(acc))


@njit
def run(fns, flags, Mc, prm, h, q, v, n_total, save_every, project, smp, ws, info):
    """Advance ``(q, v)`` by ``n_total`` RK4 steps, saving every ``save_every``-th (and the last).

    ``smp`` (:data:`Samples`) from slot 1 on; the residuals are maxima over the steps since
    the previous sample. ``info[RUN_STEPS]``, ``info[RUN_SAVED]`` receive the steps done and
    the samples written. Returns a status code.
    """
    T, Qs, Vs, En, Gr, GVr = smp.t, smp.q, smp.v, smp.energy, smp.g, smp.gv
    n = flags[_F_N]
    obs = np.zeros(OBS_SIZE)
    win_g = 0.0
    win_gv = 0.0
    j = 1
    for k in range(n_total):
        st = rk4_step(fns, flags, Mc, prm, h, q, v, ws)
        if st == _OK and project and flags[_F_M] > 0:
            st = _project(fns, flags, Mc, prm, q, v, ws)
        if st != _OK:
            info[RUN_STEPS] = k
            info[RUN_SAVED] = j
            return st
        observe(fns, flags, Mc, prm, q, v, ws, obs)
        win_g = max(win_g, obs[OBS_G])
        win_gv = max(win_gv, obs[OBS_GV])
        if (k + 1) % save_every == 0 or k + 1 == n_total:
            T[j] = (k + 1) * h
            for i in range(n):
                Qs[j, i] = q[i]
                Vs[j, i] = v[i]
            En[j] = obs[OBS_H]
            Gr[j] = win_g
            GVr[j] = win_gv
            win_g = 0.0
            win_gv = 0.0
            j += 1
    info[RUN_STEPS] = n_total
    info[RUN_SAVED] = j
    return _OK


def rk4(model: Model, q0, v0, *, h: float, t_end: float | None = None, n_steps: int | None = None,
        project: bool = False, save_every: int = 1, params=None,
        on_failure: str = "raise", solver: str = "auto") -> BaselineResult:
    r"""Integrate ``model`` with classical RK4 on its index-1 formulation.

    Parameters
    ----------
    model : Model
    q0, v0 : array_like (n,)
        Initial state; projected onto ``g = 0``, ``G v = 0`` exactly as by
        :func:`fastvi.integrate`, so both start from the same point.
    h : float
        Step size.
    t_end, n_steps :
        Exactly one (``t_end`` a whole number of steps).
    project : bool, default False
        Project ``q`` onto ``g(q) = 0`` and then ``v`` onto ``G(q) v = 0`` (in the ``M``
        metric) after every step.
    save_every : int, default 1
        Keep every k-th step (and the last); residuals are maxima over the skipped steps.
    params : array_like (k,), optional
        Parameters for this run (default: the model's).
    on_failure : {"raise", "return"}
        On a singular ``[M Gᵀ; G 0]`` or a non-finite state raise ``RuntimeError``, or
        return the partial result with its ``status`` set.
    solver : {"auto", "dense", "banded", "sparse"}, default "auto"
        How ``[M Gᵀ; G 0]`` is solved, as in :func:`fastvi.integrate`: ``"auto"`` solves a
        large model with a diagonal constant mass through ``G M⁻¹ Gᵀ`` over the pattern of
        G (banded or sparse LU; ``Ġ v`` then by a central difference along ``v``), a small
        one densely.

    Returns
    -------
    BaselineResult
        ``stats["rhs_evaluations"] = 4·steps``.

    Notes
    -----
    Order 4 in ``q`` and ``v``; neither the energy nor (without projection) the constraints
    are conserved: their errors grow with time, which is the contrast paper B draws.
    """
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    if on_failure not in ("raise", "return"):
        raise ValueError(f"`on_failure` must be 'raise' or 'return', got {on_failure!r}")
    if not isinstance(project, (bool, np.bool_)):
        raise TypeError(f"`project` must be True or False, got {project!r}")
    n = model.n
    q0 = check.vector(q0, "q0", n)
    v0 = check.vector(v0, "v0", n)
    prm = check.params(params, model)
    check.conservative(model, "rk4")
    h = check.step_size(h)
    total = check.step_count(h, t_end, n_steps)
    every = check.save_every(save_every)
    q0, v0 = check.initial_state(model, q0, v0, prm)

    fns, flags, Mc = model.kernel_arguments()
    K = total // every + 1 + (1 if total % every else 0)
    T, Qs, Vs = np.zeros(K), np.zeros((K, n)), np.zeros((K, n))
    En, Gr, GVr = np.zeros(K), np.zeros(K), np.zeros(K)
    ws = workspace(model, prm, check.solver(solver))
    q, v = q0.copy(), v0.copy()
    obs = np.zeros(OBS_SIZE)
    observe(fns, flags, Mc, prm, q, v, ws, obs)
    Qs[0], Vs[0], En[0], Gr[0], GVr[0] = q0, v0, obs[OBS_H], obs[OBS_G], obs[OBS_GV]
    info = np.zeros(RUN_INFO_SIZE)
    t0 = time.perf_counter()
    status = run(fns, flags, Mc, prm, h, q, v, total, every, bool(project),
                 Samples(T, Qs, Vs, En, Gr, GVr), ws, info)
    wall = time.perf_counter() - t0
    steps, J = int(info[RUN_STEPS]), int(info[RUN_SAVED])
    status = Status(status)
    res = BaselineResult(
        t=T[:J].copy(), q=Qs[:J].copy(), v=Vs[:J].copy(), energy=En[:J].copy(),
        constraint_residual=Gr[:J].copy(), velocity_residual=GVr[:J].copy(),
        stats=dict(steps=steps, rhs_evaluations=4 * steps, wall_time=wall),
        status=status, name="RK4+proj" if project else "RK4", h=h, model_name=model.name,
        failed_step=None if status == 0 else steps,
    )
    if status != 0 and on_failure == "raise":
        raise RuntimeError(f"{MESSAGES[status]} (RK4 baseline, status {int(status)} "
                           f"{status.name}, at step {steps}, t = {steps * h:.6g}, h = {h:g})")
    return res

