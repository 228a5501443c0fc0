r"""The linearised step: exact derivatives of the discrete flow (``docs/sensitivities.md``).

A step solves ``R(X; q_k, p_k, θ) = 0`` for its unknowns ``X = (ΔQ^1 … ΔQ^s, η_0 … η_{J−1})``
(:mod:`.step`), then reads off ``q_{k+1} = q_k + ΔQ^s`` and the momentum

    P = ∂S_u/∂Q^s − Σ_{j<J} ℓ_s(d_j) G_jᵀ η_j,   p_{k+1} = P − G(q_{k+1})ᵀ η_J,
    (G M⁻¹ Gᵀ) η_J = G M⁻¹ P   at q_{k+1}.

At the converged ``X`` its derivative along a direction ``(δq_k, δp_k, δθ)`` is

    K y = R_q δq_k + R_p δp_k + R_θ δθ,     K = ∂R/∂X (the exact Newton matrix), y = −δX
    δq_{k+1} = δq_k − y_s,   δP = P_q δq_k + P_θ δθ − P_X y

followed by the derivative of the projection (:func:`push`). ``R_q`` is the derivative at
fixed increments: ``q_k`` moves every control point, so ``R_q = Σ_{μ=0}^{s} ∂R/∂Q^μ`` in
absolute control points, of which the Newton matrix has the columns μ ≥ 1 only.

All of these blocks come from one call of :func:`.step.assemble` on an *extended* step
(:func:`extended_tables`): the step's own basis ``ℓ_0 … ℓ_s`` with one more function, the
constant 1 (zero slope, one at every constraint point). Its unknowns are
``(ΔQ^1 … ΔQ^s, T; η_0 … η_{J−1})`` with the translation ``T = 0``; as the basis functions
of the rows run over ``ℓ_0 … ℓ_s`` its rows are ``E_0 … E_{s−1}``, then ``P``, then the
constraint rows, and the column of ``T`` is ``R_q`` (moving ``q_k`` translates every
quadrature and constraint point and leaves the velocities alone). The one term that
``assemble`` has no reason to form, the constraint Hessian at ``q_k`` (the step's first
constraint point is ``q_k`` itself, fixed within a step), is added to that column here.
``K`` is gathered from the rest: the step's exact Newton matrix, assembled by the step's
own code with its second derivatives (the callbacks, or the same finite differences as the
full Newton). Derivatives by the parameters come from the model's own derivatives of its
callbacks by ``θ`` where it gives them (``Model(param_derivatives=...)``,
:class:`.layout.ParamData`): at fixed ``X`` the residual is linear in the callbacks'
values at its points, so ``R_θ`` is the same sums of their derivatives
(:func:`_theta_exact`, and :func:`_theta_pull` for the adjoint, which contracts them with
its cotangent instead). Otherwise they are five-point differences in ``θ`` (the kernels'
rule for differences in time, ``layout.FD_T``) of the extended residual and of the
projection (:func:`_theta_differences`). The step reaches these parts through a C function
compiled for what the run differentiates (:func:`theta_kind`): a run by the initial state
alone compiles none of them.

:func:`linearise` computes and factors these blocks once a step; :func:`push` applies the
step's derivative to any number of directions (one solve each), :func:`pull` its transpose
to a cotangent (one transposed solve: the discrete adjoint, :mod:`.adjoint`). Nothing here
allocates in the time loop; statuses, not exceptions, report failures.
"""

from collections import namedtuple

import numpy as np

import numba
from numba.core import types

from .._launch import _key
from .._numba import CalledAs, byref, erased, hot, hot_inline, njit, only_if, own, ptr, quiet
from .drive import run, step_hook
from .layout import specialize as layout_specialize
from .layout import (CHESS, CJAC, CON, F_AUGMENT, F_CH_PATTERN, F_EX_CHESS, F_EX_MJAC, F_MASSFN,
                     F_TIME, F_TSLOT, FD_T, FD_T_POINTS, I_SLOT, MASS, MJAC, NONFINITE, OK, SI_A,
                     SI_A_KL, SI_A_KU, SI_A_PERM, SI_BSPAN, SI_GSPAN, SI_S, SI_XMAP, SINGULAR,
                     SOLVE_BANDED, SOLVE_DENSE,
                     SINGULAR_CONSTRAINTS, SINGULAR_MASS, STEP_OUT_SIZE, P_CJAC, P_CON,
                     P_FORCE, P_KGRAD, P_MASS, P_PGRAD, ModelData, Samples, is_timed,
                     assembles_into_band, assembly_into_band, make_workspace, reciprocal_mass,
                     sizes, with_plan, without_map, workspace_shaped)
from .banded import (assembly_map, assembly_offset, band_factor, band_ld, band_solve,
                     band_solve_transposed, gmg_factor, gmg_solve)
# inlined: with the sizes as constants (sized_twin) the factorisations and solves unroll
from .linalg import augment_weights, augmented_mass, lu_factor_small, lu_solve_small
from .step import (ASSEMBLE_SIGNATURE, add_block, assemble_function, cached_cfunc, clear_rows,
                   fd_constraint_hessian, fd_momentum_jacobian, end_momentum, jacobian_rate,
                   linear_force, plan_spans)

__all__ = ["PointWork", "TangentWork", "extended_tables", "make_point_work",
           "make_tangent_work", "point", "point_terms", "linearise", "push", "pull",
           "lu_solve_transposed", "run_tangent", "differentiator", "sized_twin", "Members",
           "ASSEMBLE_TYPE", "sized_entry", "Linearised", "LinearisationArgs", "linearised",
           "linearise_by_address", "linearisation_args", "LINEARISED_TYPE", "THETA_TYPE",
           "theta_kind",
           "tangent_member", "point_work", "tangent_work", "index_maps", "step_band",
           "Sparsity", "make_sparsity"]

#: the second derivatives at a point of the constrained phase space, and their scratch
PointWork = namedtuple("PointWork", [
    "M",  # (n, n) M(q)
    "G",  # (m, n) G(q)
    "He",  # (n, n) Σ_c η_c ∇²g_c(q)
    "Hv",  # (m, n) ∂(G v)/∂q
    "Cq",  # (n, n) ∂(M v)/∂q (zero for a constant M)
    "Hs",  # (n, n) scratch: one constraint's Hessian
    "e",  # (m,) scratch: a unit impulse
    "qa",  # (n,) scratch of the differences
    "Ma",  # (n, n) scratch of the mass differences
    "Gp", "Gm",  # (m, n) scratch of the Jacobian differences
    "sp",  # the model's Sparsity
])

#: what the linearised step uses of a large model's structure (:func:`make_sparsity`);
#: empty arrays where it has none, or is small enough to be treated as dense
Sparsity = namedtuple("Sparsity", [
    "perm", "kl", "ku",  # the step's banded plan: fill-reducing ordering (N,), bandwidths
    "gptr", "gcol",  # the pattern of G by rows: the columns of row c at gcol[gptr[c] …]
    # groups of constraints whose patterns share no coordinate (the rows of group k at
    # grow[gsta[k] …]): one constraint Hessian for a group gives each member's own rows
    "gsta", "grow",
    # patterns of R_q, then P_q ((N + n) rows; the columns of row i at tcol[tptr[i] …]) and
    # of P_X (n rows), supersets from the step's Newton pattern: their products then cost
    # O(nnz), not O(N n) (banded plans only; empty: dense)
    "tptr", "tcol", "xptr", "xcol",
    # each row's span of non-zeros, (lo, hi) pairs (:func:`fastvi.structure.spans`), of
    # the coordinates' coupling (n rows: H_η, C_q) and of G (m rows: G, H_v, and G M⁻¹ of
    # a diagonal mass): the projection's products then cost O(nnz) (banded plans only)
    "bspan", "gspan",
])

#: the linearised step (:func:`linearise`) and the tangent state of the directions
TangentWork = namedtuple("TangentWork", [
    "pt",  # PointWork at q_{k+1}: M (factored), G, He, Hv, Cq
    "rows",  # (N,) int64: the rows of the extended Newton matrix that are the step's equations
    "cols",  # (N,) int64: its columns that are the step's unknowns
    "K", "piv",  # (N, N) the step's exact Newton matrix, factored ((1, 1) if banded); pivots
    # K in band storage, factored in the order ``sp.perm`` (banded plans only), and a
    # permuted right-hand side (N,)
    "ab", "t",
    "Tq",  # (N + n, n) R_q, then P_q, at fixed increments (empty: kept over their patterns)
    "PX",  # (n, N) P_X: ∂P/∂X (empty, as Tq)
    "tval", "xval",  # R_q, P_q and P_X over the patterns of ``sp`` (where it has them)
    "pidx",  # (np,) int64: the parameters differentiated
    "Rth",  # (N + n, np) R_θ, then P_θ
    "Pth",  # (n, np) ∂p_{k+1}/∂θ of the projection at fixed q_{k+1} and P
    "Yg",  # (m, n) G M⁻¹ at q_{k+1}
    "S", "pivm",  # (m, m) G M⁻¹ Gᵀ, factored; (m,)
    "pivn",  # (n,) pivots of M(q_{k+1})
    "dq", "dp",  # (d, n) the tangent state, one direction a row
    "th",  # (d, np) the parameter part of each direction (fixed over the run)
    "B",  # (d, N) right-hand sides, then y = −δX
    "dP", "dq1",  # (d, n) δP, δq_{k+1}
    "Rd",  # (N',) the extended residual's difference in θ
    "p1s", "v1s",  # (n,) the projection's outputs at a shifted θ
    "G1s",  # (m, n) G(q_{k+1}) at a shifted θ
    "w", "wb",  # (m,) scratch
    "z", "zb", "u",  # (n,) scratch
    "yb",  # (N,) scratch of the transposed solve
    "qk", "pk",  # (n,) the step's start
    "out",  # (STEP_OUT_SIZE,) scratch of the projection
    "pd",  # the model's derivatives by θ (.layout.ParamData)
    "Rk",  # (np, N') R_θ of the extended step by the model's derivatives by θ
    "tho",  # (k · max(n, m, m n if ∂G/∂θ, n² if ∂M/∂θ),) a derivative callback's output, flat
    "thF", "thP",  # (k, n) ∂F/∂θ and ∂(M v)/∂θ at a quadrature point
    "mu",  # (N',) the adjoint's cotangent on the rows of the extended step
    # Workspace of the extended step (n, m, s + 1, r, J). Last, as the sizes are last in
    # it: the sized twin (:func:`sized_twin`) then has the same layout but for those, and
    # the linearised step compiled for it reads a generic TangentWork by pointer as it is
    "ws",
])


# ----------------------------------------------------------------------------- set-up (Python)
def extended_tables(tabs, s, J):
    """The :class:`.layout.Tables` of the extended step: the basis ``ℓ_0 … ℓ_s`` and the
    constant function at index s + 1 (value 1 at every quadrature and constraint point,
    slope 0; see the module docstring). Its mass block ``Am`` gains a zero row and column
    (no slope), its ``bL`` the quadrature's sum of weights."""
    one = np.ones((1, tabs.L.shape[1]))
    L, Ld = np.vstack([tabs.L, one]), np.vstack([tabs.Ld, np.zeros_like(one)])
    Lc = np.vstack([tabs.Lc, np.ones((1, tabs.Lc.shape[1]))])
    Am = np.zeros((s + 1, s + 1))
    Am[:s, :s] = tabs.Am
    bL = np.concatenate([tabs.bL, [float(np.sum(tabs.b))]])
    for new, old in ((L, tabs.L), (Ld, tabs.Ld), (Lc, tabs.Lc), (Am, tabs.Am), (bL, tabs.bL)):
        # read-only like the method's own tables: the same type, so the step's compiled
        # assembly serves the extended step too (a writable copy compiled it again)
        new.setflags(write=old.flags.writeable)
    return tabs._replace(L=L, Ld=Ld, Lc=Lc, Am=Am, bL=bL)


def index_maps(n, m, s, J):
    """Rows and columns of the extended Newton matrix that are the step's own."""
    sx = s + 1
    rows = [nu * n + a for nu in range(s) for a in range(n)]
    rows += [sx * n + (j - 1) * m + c for j in range(1, J + 1) for c in range(m)]
    cols = [(mu - 1) * n + a for mu in range(1, s + 1) for a in range(n)]
    cols += [sx * n + j * m + c for j in range(J) for c in range(m)]
    return np.array(rows, dtype=np.int64), np.array(cols, dtype=np.int64)


@njit
def point_work(n, m, sp):
    """A :class:`PointWork` for ``n`` coordinates and ``m`` constraints of the structure
    ``sp`` (compiled: the ensemble's members build their own inside the parallel loop)."""
    mm = max(m, 1)
    return PointWork(np.zeros((n, n)), np.zeros((mm, n)), np.zeros((n, n)), np.zeros((mm, n)),
                     np.zeros((n, n)), np.zeros((n, n)), np.zeros(mm), np.zeros(n),
                     np.zeros((n, n)), np.zeros((mm, n)), np.zeros((mm, n)), sp)


def make_sparsity(band=None, patterns=None):
    """The :class:`Sparsity` of a model: ``band = (perm, kl, ku)`` the banded plan of its
    step's Newton matrix (:func:`step_band`), ``patterns`` the arrays of
    :func:`fastvi.structure.linearisation_patterns`; None: dense."""
    z = np.zeros(0, dtype=np.int64)
    perm, kl, ku = (z, 0, 0) if band is None else band
    p = patterns or {}
    if band is None:  # the patterns of R_q, P_q, P_X and the spans serve banded plans only
        p = {k: v for k, v in p.items() if k in ("gptr", "gcol", "gsta", "grow")}
    get = lambda k: p.get(k, z)  # noqa: E731
    return Sparsity(np.asarray(perm, dtype=np.int64), int(kl), int(ku), get("gptr"),
                    get("gcol"), get("gsta"), get("grow"), get("tptr"), get("tcol"),
                    get("xptr"), get("xcol"), get("bspan"), get("gspan"))


@njit
def tangent_work(xws, rows, cols, pidx, d, sp, pd, k, exact):
    """A :class:`TangentWork` for ``d`` directions around the extended step's workspace
    ``xws`` (sizes ``n, m, s + 1, r, J``), differentiating by the parameters ``pidx``
    (int64) of the ``k`` of a model whose derivatives by them are ``pd``
    (:class:`.layout.ParamData`), which give the step's (``exact``, :func:`_exact_in_theta`);
    ``rows``, ``cols`` from :func:`index_maps`; ``sp`` the model's :class:`Sparsity`."""
    n, m, sx, J = xws.dims[0], xws.dims[1], xws.dims[2], xws.dims[4]
    s = sx - 1
    N = s * n + J * m
    mm = max(m, 1)
    npar = max(pidx.shape[0], 1)
    # sizes first: a conditional expression among the arguments of the record's
    # constructor is bytecode numba cannot compile
    banded = sp.perm.shape[0] > 0
    Nd = 1 if banded else N
    Nb = band_ld(sp.kl, sp.ku) * N if banded else 1
    # an assembly into band storage (layout.assembly_into_band) leaves K where its factors go
    ab = xws.A[0] if xws.si[SI_XMAP] != 0 else np.zeros(Nb)
    # R_q, P_q and P_X dense only where they are not kept over their patterns
    Nt, nt = N + n, n
    if sp.tptr.shape[0] > 0:
        Nt, nt = 0, 0
    # the columns R_θ, P_θ: formed by differences, or from the model's derivatives (Rk)
    # for forward directions; the adjoint by the model's derivatives contracts them
    # unformed (a 1024-link chain by its 2 049 parameters: 256 MiB)
    Rr, Rc, Kr, Kc = N + n, npar, 0, 0
    if exact and d == 0:
        Rr, Rc = 0, 0
    if d > 0:
        Kr, Kc = npar, sx * n + J * m
    # a derivative callback's output: k × n or k × m, and the k × m × n of ∂G/∂θ or the
    # k × n × n of ∂M/∂θ only for a model that has them (a gigabyte for a chain of 256
    # links, whose G and M do not depend on θ)
    per = max(n, mm)
    if pd.given[P_CJAC] != 0:
        per = max(per, m * n)
    if pd.given[P_MASS] != 0:
        per = max(per, n * n)
    return TangentWork(
        point_work(n, m, sp), rows, cols, np.zeros((Nd, Nd)), np.zeros(N, dtype=np.int64),
        ab, np.zeros(N),
        np.zeros((Nt, nt)), np.zeros((nt, N)), np.zeros(max(sp.tcol.shape[0], 1)),
        np.zeros(max(sp.xcol.shape[0], 1)), pidx, np.zeros((Rr, Rc)),
        np.zeros((min(Rr, n), Rc)), np.zeros((mm, n)), np.zeros((mm, mm)), np.zeros(mm, dtype=np.int64),
        np.zeros(n, dtype=np.int64), np.zeros((d, n)), np.zeros((d, n)), np.zeros((d, npar)),
        np.zeros((d, N)), np.zeros((d, n)), np.zeros((d, n)), np.zeros(sx * n + J * m),
        np.zeros(n), np.zeros(n), np.zeros((mm, n)), np.zeros(mm), np.zeros(mm), np.zeros(n),
        np.zeros(n), np.zeros(n), np.zeros(N), np.zeros(n), np.zeros(n), np.zeros(STEP_OUT_SIZE),
        pd, np.zeros((Kr, Kc)), np.zeros(max(k, 1) * per),
        np.zeros((max(k, 1), n)), np.zeros((max(k, 1), n)), np.zeros(sx * n + J * m), xws)


def make_point_work(n, m):
    """A :class:`PointWork` for ``n`` coordinates and ``m`` constraints (dense)."""
    return point_work.py_func(int(n), int(m), make_sparsity())


def make_tangent_work(n, m, s, r, J, d, pidx, pd, k, sp=None, step_ws=None, exact=False):
    """A :class:`TangentWork` for ``d`` directions, differentiating by the parameters
    ``pidx`` of the ``k`` of a model whose derivatives by them are ``pd``
    (:meth:`fastvi.Model.param_derivative_data`), of :class:`Sparsity` ``sp`` (None: dense) whose step has the
    workspace ``step_ws`` (its structured-solve plan, if any, serves the extended step:
    grouped differences of the constraint Hessian, the projection's banded or sparse
    ``G M⁻¹ Gᵀ``): :func:`tangent_work` run by Python (compiling it costs 2.4 s; the
    ensemble's members run it compiled). ``exact``: ``pd`` gives the step's derivatives by
    θ (:func:`_exact_in_theta`), so that an adjoint (``d = 0``) forms no columns ``R_θ``;
    the default keeps room for them."""
    rows, cols = index_maps(n, m, s, J)
    sp = make_sparsity() if sp is None else sp
    structured = step_ws is not None and step_ws.structured
    step_si = without_map(step_ws.si) if structured else None  # the step's own A's map
    into_band = structured and _assembles_into_band(step_si, sp, n, s * n + J * m)
    xws = make_workspace(n, m, s + 1, r, J, unused=frozenset({"A"}) if into_band else frozenset())
    if into_band:
        si, A = _band_assembly(step_si, sp, rows, n, m, s * n + J * m)
        xws = xws._replace(A=A, si=si, sb=step_ws.sb.copy(), structured=True)
    elif structured:
        xws = xws._replace(si=step_si, sb=step_ws.sb.copy(), structured=True)
    return tangent_work.py_func(xws, rows, cols, np.asarray(pidx, dtype=np.int64), int(d), sp,
                                pd, int(k), bool(exact))


def _assembles_into_band(si, sp, n, N):
    """Whether the extended step of a structured model whose step's plan is ``si`` and whose
    :class:`Sparsity` is ``sp`` (``n`` coordinates, ``N`` unknowns) assembles its matrix
    straight into band storage: where ``K`` is banded, its own rows and columns are read
    over their patterns, the assembly writes over the rows' spans (a constant diagonal
    mass), and the dense matrix would be large (:func:`.layout.assembles_into_band`). Both
    give the same matrix bit for bit."""
    return assembles_into_band(si, N + n) and sp.perm.shape[0] > 0 and sp.tptr.shape[0] > 0


def _band_assembly(si, sp, rows, n, m, N):
    """The extended step's plan and matrix storage for an assembly into band storage
    (:func:`.layout.assembly_into_band`): ``K``'s band, the rows of ``T_q`` and the columns
    of ``P_X`` each over its span of the coupling (of G for a constraint's)."""
    ext = np.arange(N + n)
    index = np.empty(N + n, dtype=np.int64)
    index[rows] = np.arange(N)
    own = np.setdiff1d(ext, rows)  # the translation's rows and columns, s n … s n + n − 1
    index[own] = N + np.arange(n)
    # each extended row's (and column's) span: its coordinate's, or its constraint's
    first = own[-1] + 1  # (s + 1) n: the first constraint row, and impulse column
    span = np.empty((N + n, 2), dtype=np.int64)
    span[:first] = si[si[SI_BSPAN]: si[SI_BSPAN] + 2 * n].reshape(n, 2)[ext[:first] % n]
    if m:
        gspan = si[si[SI_GSPAN]: si[SI_GSPAN] + 2 * m].reshape(m, 2)
        span[first:] = gspan[(ext[first:] - first) % m]
    tspan = np.empty_like(span)
    tspan[index] = span  # row i of T_q: the extended row of index i
    xspan = tspan[:N]  # column j of P_X: the extended column of index j (rows, cols alike)
    xsi, L = assembly_into_band(si, N, int(sp.kl), int(sp.ku), sp.perm, index, tspan, xspan)
    return xsi, np.zeros((1, L))


def step_band(ws):
    """``(perm, kl, ku)``, the banded plan of the Newton matrix of the step whose workspace
    is ``ws`` (:func:`fastvi.structure.plan`), or None where that matrix is dense: the
    linearised step factors the same matrix, with the same ordering."""
    si = ws.si
    if si[SI_A] != SOLVE_BANDED:
        return None
    n, m, s, _, J = (int(x) for x in ws.dims)
    N = s * n + J * m
    return si[si[SI_A_PERM]: si[SI_A_PERM] + N].copy(), int(si[SI_A_KL]), int(si[SI_A_KU])


# ----------------------------------------------------------------------------- second derivatives
@hot
def _hessian(md, q, eta, out, pw, n, m):
    """``out = Σ_c η_c ∇²g_c(q)``: the callback, or the full Newton's differences of G."""
    if md.flags[F_EX_CHESS] != 0:
        if md.flags[F_CH_PATTERN] != 0:  # it writes the shared coordinates' entries alone
            clear_rows(out, n, n, pw.sp.bspan)
        md.fns[CHESS](ptr(q), ptr(eta), ptr(md.prm), ptr(out))
    else:
        fd_constraint_hessian(md.fns[CJAC], q, eta, md.prm, out, pw.qa, pw.Gp, pw.Gm, n, m)


@hot
def _mass(md, q, M, G, sp, n, m):
    """``M`` as the linearised step reads it at ``q``: the model's mass function; for a
    singular constant mass the definite ``M̄ = M + Gᵀ W G`` (:func:`.linalg.augmented_mass`),
    ``G`` evaluated into ``G`` on the way; else the constant (only its diagonal where it is
    inverted by its reciprocals: the caller's zeros stay off it)."""
    if md.flags[F_MASSFN] != 0:
        md.fns[MASS](ptr(q), ptr(q), ptr(md.prm), ptr(M))
    elif md.flags[F_AUGMENT] != 0:
        clear_rows(G, m, n, sp.gspan)
        md.fns[CJAC](ptr(q), ptr(q), ptr(md.prm), ptr(G))
        augmented_mass(md.Mc, G, M, n, m)
    elif reciprocal_mass(md.flags):
        for a in range(n):
            M[a, a] = md.Mc[a, a]
    else:
        for a in range(n):  # M is factored in place (_factor_projection): copied anew
            for b in range(n):
                M[a, b] = md.Mc[a, b]


@hot
def point(md_, q, v, eta, pw_):
    """Fill the :class:`PointWork` at ``(q, v)`` with impulse ``eta`` (m,): ``M(q)``,
    ``G(q)``, ``Σ η_c ∇²g_c``, ``∂(G v + g_t)/∂q`` (row c: ``(∇²g_c v)ᵀ``, plus
    ``∂G_c/∂t`` for time-dependent constraints, at the time the parameter vector carries)
    and ``∂(M v)/∂q``; for a singular constant ``M``, ``M̄``, ``∂(M̄ v + Gᵀ W g_t)/∂q``
    and the impulse of ``M`` (``eta`` is that of ``M̄``) in their place. Where ``pw.sp`` has groups of constraints, ``H_v`` is
    left to :func:`_grouped_hv` (the linearised step of a structured model)."""
    md, pw = own(md_), own(pw_)
    fns, flags, prm = md.fns, md.flags, md.prm
    n = q.shape[0]
    m = eta.shape[0]
    M, G, Hv, Cq, Hs, e = pw.M, pw.G, pw.Hv, pw.Cq, pw.Hs, pw.e
    _mass(md, q, M, G, pw.sp, n, m)
    if flags[F_MASSFN] != 0:
        if flags[F_EX_MJAC] != 0:
            fns[MJAC](ptr(q), ptr(v), ptr(prm), ptr(Cq))
        else:
            fd_momentum_jacobian(fns[MASS], q, v, prm, Cq, pw.qa, pw.Ma, n)
    elif not reciprocal_mass(flags):  # else nothing writes C_q: the allocation's zeros stay
        for a in range(n):
            for b in range(n):
                Cq[a, b] = 0.0
    if m == 0:
        return
    if flags[F_AUGMENT] == 0:  # (_mass evaluated G for M̄)
        clear_rows(G, m, n, pw.sp.gspan)
        fns[CJAC](ptr(q), ptr(q), ptr(prm), ptr(G))
    _hessian(md, q, eta, pw.He, pw, n, m)
    if flags[F_AUGMENT] != 0 and flags[F_TIME] != 0:
        # the step's impulse is that of M̄ = M + Gᵀ W G; M's is larger by W G v = −W g_t
        # (rheonomic constraints), and H_η is linear in the impulse
        augment_weights(md.Mc, G, e, n, m)
        for c in range(m):
            acc = 0.0
            for a in range(n):
                acc += G[c, a] * v[a]
            e[c] *= acc
        _hessian(md, q, e, Hs, pw, n, m)
        for a in range(n):
            for b in range(n):
                pw.He[a, b] += Hs[a, b]
    if pw.sp.gsta.shape[0] > 0:
        return  # H_v by groups: the caller's _grouped_hv
    for c in range(m):
        for i in range(m):
            e[i] = 0.0
        e[c] = 1.0
        _hessian(md, q, e, Hs, pw, n, m)
        for b in range(n):
            acc = 0.0
            for a in range(n):
                acc += Hs[b, a] * v[a]
            Hv[c, b] = acc
    if flags[F_TIME] != 0:
        # the rheonomic hidden constraint G v + g_t = 0: ∂g_t/∂q = ∂G/∂t
        jacobian_rate(md, q, prm[flags[F_TSLOT]], pw.Gp, pw.Gm)
        for c in range(m):
            for b in range(n):
                Hv[c, b] += pw.Gp[c, b]
    if flags[F_AUGMENT] != 0:
        # a singular constant M: on the constraints p = M v = M̄ v + Gᵀ W g_t with the definite
        # M̄ = M + Gᵀ W G (:func:`.linalg.augmented_mass`), so the projection is that of the
        # configuration-dependent mass M̄ (:func:`_mass`), whose ∂(M̄ v + Gᵀ W g_t)/∂q is
        # Gᵀ W H_v where G v + g_t = 0
        augment_weights(md.Mc, G, e, n, m)
        for a in range(n):
            for b in range(n):
                acc = 0.0
                for c in range(m):
                    acc += G[c, a] * e[c] * Hv[c, b]
                Cq[a, b] = acc


def point_terms(md, q, v, eta):
    """``(M, G, He, Hv, Cq)`` at ``(q, v)`` with impulse ``eta`` (:func:`point`), as new
    arrays: for the Python side (the initial tangent, the checks)."""
    n, m = len(q), len(eta)
    pw = make_point_work(n, m)
    point(md, np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(v, dtype=float),
          np.ascontiguousarray(eta, dtype=float), pw)
    return pw.M.copy(), pw.G[:m].copy(), pw.He.copy(), pw.Hv[:m].copy(), pw.Cq.copy()


@njit
def _sample_terms(md, Q, V, T, eta, pw, Ms, Gs, Hvs, Cqs):
    flags = md.flags
    n, m = Q.shape[1], eta.shape[0]
    for i in range(Q.shape[0]):
        if flags[F_TIME] != 0:
            md.prm[flags[F_TSLOT]] = T[i]
        point(md, Q[i], V[i], eta, pw)
        for a in range(n):
            for b in range(n):
                Ms[i, a, b] = pw.M[a, b]
                Cqs[i, a, b] = pw.Cq[a, b]
        for c in range(m):
            for b in range(n):
                Gs[i, c, b] = pw.G[c, b]
                Hvs[i, c, b] = pw.Hv[c, b]


@njit
def _sample_masses(md, Q, T, pw, Ms):
    flags = md.flags
    n, m = Q.shape[1], pw.G.shape[0]
    for i in range(Q.shape[0]):
        if flags[F_TIME] != 0:
            md.prm[flags[F_TSLOT]] = T[i]
        _mass(md, Q[i], Ms[i], pw.G, pw.sp, n, m)


def sample_masses(md, Q, T, m):
    """``M(q)`` at each sample ``Q[i]`` at time ``T[i]`` (K, n, n), as :func:`point` reads
    it (:func:`_mass`: the model's mass function, or for a singular constant mass ``M̄``) in
    one compiled loop: what the differences by θ of the momentum take at every sample."""
    K, n = Q.shape
    Ms = np.zeros((K, n, n))
    _sample_masses(md, np.ascontiguousarray(Q, dtype=float), np.ascontiguousarray(T, dtype=float),
                   make_point_work(n, m), Ms)
    return Ms


def sample_terms(md, Q, V, T, m):
    """``(Ms, Gs, Hvs, Cqs)``: ``M``, ``G``, ``H_v`` and ``C_q`` of :func:`point` (impulse
    zero) at each sample ``(Q[i], V[i])`` at time ``T[i]``, (K, n, n) and (K, m, n), in one
    compiled loop: a call of :func:`point_terms` a sample cost the dispatch's typing of the
    model's callbacks, about 1 ms, far more than the terms. ``md`` is the model's kernel
    data, whose time slot a time-dependent model's loop overwrites."""
    K, n = Q.shape
    Ms, Cqs = np.empty((K, n, n)), np.empty((K, n, n))
    Gs, Hvs = np.empty((K, m, n)), np.empty((K, m, n))
    _sample_terms(md, np.ascontiguousarray(Q, dtype=float), np.ascontiguousarray(V, dtype=float),
                  np.ascontiguousarray(T, dtype=float), np.zeros(m), make_point_work(n, m),
                  Ms, Gs, Hvs, Cqs)
    return Ms, Gs, Hvs, Cqs


@njit
def _sample_callback(md, slot, Q, V, T, out):
    flags = md.flags
    for i in range(Q.shape[0]):
        if flags[F_TIME] != 0:
            md.prm[flags[F_TSLOT]] = T[i]
        md.fns[slot](ptr(Q[i]), ptr(V[i]), ptr(md.prm), ptr(out[i]))


def sample_callback(md, slot, Q, T, shape, V=None):
    """The model's callback ``slot`` (:data:`.layout.SLOTS`: ``CON``, ``CJAC``, …) at each
    sample ``(Q[i], V[i])`` at time ``T[i]``, ``(K, *shape)`` (zeros where a callback
    declared to write its pattern alone writes nothing), in one compiled loop: the
    constraint terms the differences by θ of :meth:`fastvi.SensitivityResult.tangent_residual`
    take at every sample. ``V`` defaults to ``Q`` (the callbacks of ``q`` alone)."""
    Q = np.ascontiguousarray(Q, dtype=float)
    V = Q if V is None else np.ascontiguousarray(V, dtype=float)
    out = np.zeros((Q.shape[0], *shape))
    _sample_callback(md, slot, Q, V, np.ascontiguousarray(T, dtype=float), out)
    return out


@hot
def lu_solve_transposed(A, piv, b, N):
    """Solve ``Aᵀ x = b`` with the factors of :func:`.linalg.lu_factor` (``P A = L U``,
    reciprocal pivots on the diagonal); ``b`` is overwritten."""
    for i in range(N):  # Uᵀ
        s = b[i]
        for j in range(i):
            s -= A[j, i] * b[j]
        b[i] = s * A[i, i]
    for i in range(N - 1, -1, -1):  # Lᵀ (unit diagonal)
        s = b[i]
        for j in range(i + 1, N):
            s -= A[j, i] * b[j]
        b[i] = s
    for k in range(N - 1, -1, -1):  # Pᵀ
        p = piv[k]
        if p != k:
            t = b[k]
            b[k] = b[p]
            b[p] = t


#: inlined into the solves, as lu_solve_small
_lu_solve_transposed = hot_inline(lu_solve_transposed.py_func)


# ----------------------------------------------------------------------------- linearisation
@hot_inline
def _step_sizes(wx):
    """``(n, m, s, N)`` of the step whose extended workspace is ``wx``."""
    n, m, sx, _, J = sizes(wx)
    return n, m, sx - 1, (sx - 1) * n + J * m


@hot_inline
def _start_jacobian(md, qk, wx, sp, n, m):
    """``wx.G[0] = G(q_k)``: the extended step's first constraint point, as the step has it
    (at ``t_k`` for time-dependent constraints; leaves the time entry there)."""
    if md.flags[F_TIME] != 0:
        md.prm[md.flags[F_TSLOT]] = wx.time[0]
    G0 = wx.G[0]
    clear_rows(G0, m, n, sp.gspan)
    md.fns[CJAC](ptr(qk), ptr(qk), ptr(md.prm), ptr(G0))


@hot
def _theta_differences(md_, tx_, asm, h, q1, P, tw_):
    """``tw.Rth`` (the rows of R and of P) and ``tw.Pth`` (the projection at fixed
    ``q_{k+1}`` and ``P``): five-point differences in each parameter of ``tw.pidx``. Leaves
    ``md.prm`` as it found it. Returns a status code."""
    md, tw = own(md_), own(tw_)
    wx = tw.ws
    n, m, s, N = _step_sizes(wx)
    prow = s * n
    prm, Rd, rows, Rth, Pth, G1s = md.prm, tw.Rd, tw.rows, tw.Rth, tw.Pth, tw.G1s
    wxp = byref(wx)
    st = OK
    for i in range(tw.pidx.shape[0]):
        l = tw.pidx[i]
        th0 = prm[l]
        dt = FD_T * max(1.0, abs(th0))
        for k in range(Rd.shape[0]):
            Rd[k] = 0.0
        for a in range(n):
            Pth[a, i] = 0.0
        for sgn, wgt in FD_T_POINTS:
            prm[l] = th0 + sgn * dt
            linear_force(md, wx, tw.qk)
            if m > 0:
                _start_jacobian(md, tw.qk, wx, tw.pt.sp, n, m)
            st = asm(erased(md_), erased(tx_), h, byref(tw.qk), byref(tw.pk), erased(wxp),
                     N < 0)
            if st != OK:
                break
            for k in range(Rd.shape[0]):
                Rd[k] += wgt * wx.R[k]
            if m > 0:
                for c in range(m):
                    for a in range(n):
                        G1s[c, a] = 0.0
                md.fns[CJAC](ptr(q1), ptr(q1), ptr(prm), ptr(G1s))
            if md.flags[F_TIME] != 0:
                prm[md.flags[F_TSLOT]] = wx.time[1]
            st = end_momentum(md_, byref(q1), byref(P), byref(tw.p1s), byref(tw.v1s),
                              byref(G1s), wxp, byref(tw.out))
            if st != OK:
                break
            for a in range(n):
                Pth[a, i] += wgt * tw.p1s[a]
        prm[l] = th0
        linear_force(md, wx, tw.qk)
        if st != OK:
            return st
        inv = 1.0 / (12.0 * dt)
        for k in range(N):
            Rth[k, i] = Rd[rows[k]] * inv
        for a in range(n):
            Rth[N + a, i] = Rd[prow + a] * inv
            Pth[a, i] *= inv
    return OK


@hot_inline
def _at_point(md, wx, h, x):
    """The time the callbacks read set to ``t_k + x h``, as the step sets it."""
    if is_timed(md):
        md.prm[md.flags[F_TSLOT]] = wx.time[1] if x == 1.0 else wx.time[0] + x * h


@hot_inline
def _point_of(qk, X, Lt, i, sx, n, out):
    """``out = q_k + Σ_{ν=1}^{s+1} Lt[ν, i] ΔQ^ν``: the extended step's point ``i``."""
    for a in range(n):
        out[a] = qk[a]
    for nu in range(1, sx + 1):
        cl = Lt[nu, i]
        if cl != 0.0:
            off = (nu - 1) * n
            for a in range(n):
                out[a] += cl * X[off + a]


# The derivatives by θ from the model's own (``tw.pd``, :class:`.layout.ParamData`). At fixed
# unknowns the step's residual is linear in the values of the callbacks at its quadrature
# and constraint points (:func:`.step.residual`), so ``R_θ`` is the same sums with each
# value replaced by its derivative by θ: one call of each derivative a point serves all
# ``k`` parameters, and no residual is evaluated again. The forward directions need the
# columns of ``R_θ`` (:func:`_theta_exact`); the adjoint only ``μᵀ R_θ`` for its cotangent
# ``μ`` (:func:`_theta_pull`), which costs O(k n) a point instead of O(k n s).
# The helpers below take the records by pointer and are compiled once for both paths (inlined,
# each path typed them again: 7 s more of compiling).
@hot
def _theta_at_quadrature(md_, tx_, h, tw_, i):
    """At the extended step's quadrature point ``i``: ``tw.thF[l] = ∂F/∂θ_l`` with
    ``F = ∂T/∂q − ∇V + F_nc``, and ``tw.thP[l] = (∂M/∂θ_l) v``, for ``l`` in ``tw.pidx``."""
    md, tx, tw = own(md_), own(tx_), own(tw_)
    wx, pd, qk, pidx, o, thF, thP = tw.ws, tw.pd, tw.qk, tw.pidx, tw.tho, tw.thF, tw.thP
    n, _, s, _ = _step_sizes(wx)
    sx = s + 1
    fns, given, prm = pd.fns, pd.given, md.prm
    X, qi, vi = wx.X, wx.qi, wx.vi
    _at_point(md, wx, h, tx.c[i])
    _point_of(qk, X, tx.L, i, sx, n, qi)
    if given[P_KGRAD] != 0 or given[P_FORCE] != 0 or given[P_MASS] != 0:
        for a in range(n):
            vi[a] = 0.0
        inv_h = 1.0 / h
        for nu in range(1, sx + 1):
            cd = tx.Ld[nu, i] * inv_h
            off = (nu - 1) * n
            for a in range(n):
                vi[a] += cd * X[off + a]
    fp, fi = pd.fptr, pd.fidx
    for ii in range(pidx.shape[0]):
        l = pidx[ii]
        if fp.shape[0] > 0:
            for e in range(fp[l], fp[l + 1]):
                thF[l, fi[e]] = 0.0
        else:
            for a in range(n):
                thF[l, a] = 0.0
    if given[P_PGRAD] != 0:
        _add_by_theta(fns[P_PGRAD], qi, qi, prm, pidx, o, thF, n, -1.0, fp, fi)
    if given[P_KGRAD] != 0:
        _add_by_theta(fns[P_KGRAD], qi, vi, prm, pidx, o, thF, n, 1.0, fp, fi)
    if given[P_FORCE] != 0:
        _add_by_theta(fns[P_FORCE], qi, vi, prm, pidx, o, thF, n, 1.0, fp, fi)
    if given[P_MASS] != 0:  # else thP is never read
        _mass_times(fns[P_MASS], qi, vi, prm, pidx, o, thP, n)


@hot_inline
def _entries(ptr, l, size):
    """The range of the entries of parameter ``l`` in a :class:`.layout.ParamData` pattern
    ``ptr`` (``0 … size`` where it is dense: an empty ``ptr``)."""
    if ptr.shape[0] == 0:
        return 0, size
    return ptr[l], ptr[l + 1]


@hot_inline
def _entry(idx, ptr, e):
    """Entry ``e`` of a range of :func:`_entries`: ``idx[e]``, or ``e`` where dense."""
    return e if ptr.shape[0] == 0 else idx[e]


@hot_inline
def _add_by_theta(fn, q, v, prm, pidx, o, out, n, sign, fp, fi):
    """``out[l] += sign · ∂f/∂θ_l`` for ``l`` in ``pidx`` over the pattern ``fp``, ``fi``,
    ``f`` an (n,) callback whose derivative by θ is ``fn``."""
    # a callback with a pattern writes its own entries only, and `o` still holds the last
    # callback's: the entries read are zeroed first. The dense loops stay apart: compiled
    # for the sizes, they unroll
    if fp.shape[0] > 0:
        for ii in range(pidx.shape[0]):
            l = pidx[ii]
            for e in range(fp[l], fp[l + 1]):
                o[l * n + fi[e]] = 0.0
        fn(ptr(q), ptr(v), ptr(prm), ptr(o))
        for ii in range(pidx.shape[0]):
            l = pidx[ii]
            for e in range(fp[l], fp[l + 1]):
                a = fi[e]
                out[l, a] += sign * o[l * n + a]
    else:
        for ii in range(pidx.shape[0]):
            l = pidx[ii]
            for a in range(n):
                o[l * n + a] = 0.0
        fn(ptr(q), ptr(v), ptr(prm), ptr(o))
        for ii in range(pidx.shape[0]):
            l = pidx[ii]
            for a in range(n):
                out[l, a] += sign * o[l * n + a]


@hot_inline
def _mass_times(fn, q, v, prm, pidx, o, out, n):
    """``out[l] = (∂M/∂θ_l)(q) v`` for ``l`` in ``pidx``, by the derivative ``fn``."""
    fn(ptr(q), ptr(q), ptr(prm), ptr(o))
    for ii in range(pidx.shape[0]):
        l = pidx[ii]
        for a in range(n):
            acc = 0.0
            for c in range(n):
                acc += o[(l * n + a) * n + c] * v[c]
            out[l, a] = acc


@hot
def _at_constraint_point(md_, tx_, h, tw_, j, slot):
    """``tw.tho`` = the derivative by θ ``slot`` (``P_CON``: ``∂g/∂θ``, k × m; ``P_CJAC``:
    ``∂G/∂θ``, k × m × n, flat) at the extended step's constraint point ``j`` (``j = 0``:
    ``q_k`` at ``t_k``)."""
    md, tx, tw = own(md_), own(tx_), own(tw_)
    wx, o = tw.ws, tw.tho
    n, m, s, _ = _step_sizes(wx)
    _at_point(md, wx, h, tx.d[j])
    _point_of(tw.qk, wx.X, tx.Lc, j, s + 1, n, wx.qi)
    # a derivative of a patterned Jacobian may write its non-zeros only; the k × m of ∂g/∂θ
    # alone for the constraint (not the k × m × n of ∂G/∂θ: O(N³) for a chain), and nothing
    # for a constraint with a pattern by θ, of which the kernels read the entries it writes
    if slot == P_CJAC or tw.pd.cptr.shape[0] == 0:
        size = (md.prm.shape[0] - 1) * m * (n if slot == P_CJAC else 1)
        for kk in range(size):
            o[kk] = 0.0
    tw.pd.fns[slot](ptr(wx.qi), ptr(wx.qi), ptr(md.prm), ptr(o))


@hot
def _theta_exact(md_, tx_, h, tw_):
    """``tw.Rth`` (the rows of R, then of P) from the model's derivatives by θ at the
    extended step's unknowns."""
    tx, tw = own(tx_), own(tw_)
    wx, pd = tw.ws, tw.pd
    n, m, s, N = _step_sizes(wx)
    sx = s + 1
    J = sizes(wx)[4]
    given, X = pd.given, wx.X
    Rk, o, thF, thP, pidx = tw.Rk, tw.tho, tw.thF, tw.thP, tw.pidx
    fp, fi, cp, ci = pd.fptr, pd.fidx, pd.cptr, pd.cidx
    npar = pidx.shape[0]
    b, L, Ld, Lc = tx.b, tx.L, tx.Ld, tx.Lc
    for ii in range(npar):
        for kk in range(Rk.shape[1]):
            Rk[ii, kk] = 0.0
    if (given[P_PGRAD] != 0 or given[P_KGRAD] != 0 or given[P_FORCE] != 0
            or given[P_MASS] != 0):
        for i in range(b.shape[0]):
            _theta_at_quadrature(md_, tx_, h, tw_, i)
            for nu in range(sx):
                cl = h * b[i] * L[nu, i]
                cd = b[i] * Ld[nu, i]
                row = nu * n
                for ii in range(npar):
                    l = pidx[ii]
                    if given[P_MASS] != 0:
                        for a in range(n):
                            Rk[ii, row + a] += cl * thF[l, a] + cd * thP[l, a]
                    else:
                        lo, hi = _entries(fp, l, n)
                        for e in range(lo, hi):
                            a = _entry(fi, fp, e)
                            Rk[ii, row + a] += cl * thF[l, a]
    if m > 0 and given[P_CON] != 0:
        for j in range(1, J + 1):
            _at_constraint_point(md_, tx_, h, tw_, j, P_CON)
            row = sx * n + (j - 1) * m
            for ii in range(npar):
                l = pidx[ii]
                lo, hi = _entries(cp, l, m)
                for e in range(lo, hi):
                    c = _entry(ci, cp, e)
                    Rk[ii, row + c] += o[l * m + c]
    if m > 0 and given[P_CJAC] != 0:
        # −Σ_j ℓ_ν(d_j) (∂G_j/∂θ)ᵀ η_j
        for j in range(J):
            _at_constraint_point(md_, tx_, h, tw_, j, P_CJAC)
            col = sx * n + j * m
            for ii in range(npar):
                l = pidx[ii]
                for a in range(n):
                    acc = 0.0
                    for c in range(m):
                        acc += o[(l * m + c) * n + a] * X[col + c]
                    for nu in range(sx):
                        cl = Lc[nu, j]
                        if cl != 0.0:
                            Rk[ii, nu * n + a] -= cl * acc
    rows, Rth = tw.rows, tw.Rth
    for ii in range(npar):
        for kk in range(N):
            Rth[kk, ii] = Rk[ii, rows[kk]]
        for a in range(n):
            Rth[N + a, ii] = Rk[ii, s * n + a]


@hot
def _theta_projection(md_, tw_, q1, v1, eta):
    """``tw.Pth``: the derivative by θ of the projection ``p = P − Gᵀ η``,
    ``G M⁻¹ p = 0`` at fixed ``q_{k+1}`` and ``P``, from the model's derivatives by θ,
    with ``G``, ``Y = G M⁻¹`` and the factored ``S = G M⁻¹ Gᵀ`` of :func:`linearise`:

        S δη = G_θ v − Y M_θ v − Y G_θᵀ η,     p_θ = −G_θᵀ η − Gᵀ δη."""
    tw = own(tw_)
    pidx, Pth = tw.pidx, tw.Pth
    n, m = q1.shape[0], eta.shape[0]
    o, thP, u, w = tw.tho, tw.thP, tw.u, tw.w
    G, Yg = tw.pt.G, tw.Yg
    npar = pidx.shape[0]
    for ii in range(npar):
        for a in range(n):
            Pth[a, ii] = 0.0
    if m == 0:
        return
    _projection_terms(md_, tw_, q1, v1)
    gth = tw.pd.given[P_CJAC] != 0  # G_θ: its terms are zero without it
    for ii in range(npar):
        l = pidx[ii]
        base = l * m * n
        if gth:
            for a in range(n):
                acc = 0.0
                for c in range(m):
                    acc += o[base + c * n + a] * eta[c]
                u[a] = acc
            for c in range(m):
                acc = 0.0
                for a in range(n):
                    acc += o[base + c * n + a] * v1[a] - Yg[c, a] * (thP[l, a] + u[a])
                w[c] = acc
        else:
            for a in range(n):
                u[a] = 0.0
            for c in range(m):
                acc = 0.0
                for a in range(n):
                    acc -= Yg[c, a] * thP[l, a]
                w[c] = acc
        _solve_projection(tw, w, m, False)
        for a in range(n):
            acc = -u[a]
            for c in range(m):
                acc -= G[c, a] * w[c]
            Pth[a, ii] = acc


@hot
def _projection_terms(md_, tw_, q1, v1):
    """At ``q_{k+1}``: ``tw.tho = ∂G/∂θ`` (k, m, n flat; zero where the model declares
    none) and ``tw.thP[l] = (∂M/∂θ_l) v_{k+1}`` (zero for a constant mass)."""
    md, tw = own(md_), own(tw_)
    pd, pidx, o, thP = tw.pd, tw.pidx, tw.tho, tw.thP
    n, m = q1.shape[0], sizes(tw.ws)[1]
    for ii in range(pidx.shape[0]):
        for a in range(n):
            thP[pidx[ii], a] = 0.0
    if pd.given[P_MASS] != 0:
        _mass_times(pd.fns[P_MASS], q1, v1, md.prm, pidx, o, thP, n)
    if pd.given[P_CJAC] != 0:  # else G_θ = 0 and its terms are skipped
        for kk in range((md.prm.shape[0] - 1) * m * n):
            o[kk] = 0.0
        pd.fns[P_CJAC](ptr(q1), ptr(q1), ptr(md.prm), ptr(o))


@hot
def _theta_pull(md_, tx_, h, tw_, q1, v1, eta, yb, zb, wb, u, lth):
    """``lth += μᵀ R_θ`` and the projection's part, for the cotangent of :func:`pull`: ``yb``
    on the step's rows, ``zb`` on the rows of ``P`` (and the projection's ``λ_p + u``),
    ``wb`` = ``−S⁻ᵀ G λ_p``, ``u = M⁻ᵀ Gᵀ wb`` — contracted point by point with the
    model's derivatives by θ, never forming ``R_θ``:

        λ_pᵀ p_θ = −ηᵀ G_θ (λ_p + u) + wbᵀ G_θ v − uᵀ M_θ v."""
    md, tx, tw = own(md_), own(tx_), own(tw_)
    wx, pd = tw.ws, tw.pd
    n, m, s, N = _step_sizes(wx)
    sx = s + 1
    J = sizes(wx)[4]
    given, X = pd.given, wx.X
    o, thF, thP, pidx, mu, cF, cP = tw.tho, tw.thF, tw.thP, tw.pidx, tw.mu, tw.z, tw.zb
    fp, fi, cp, ci = pd.fptr, pd.fidx, pd.cptr, pd.cidx
    npar = pidx.shape[0]
    b, L, Ld, Lc = tx.b, tx.L, tx.Ld, tx.Lc
    for kk in range(N):  # with P's rows, every row of the extended step
        mu[tw.rows[kk]] = yb[kk]
    for a in range(n):
        mu[s * n + a] = zb[a]
    if m > 0 and (given[P_CJAC] != 0 or given[P_MASS] != 0):  # the projection, at q_{k+1}
        if md.flags[F_TIME] != 0:
            md.prm[md.flags[F_TSLOT]] = wx.time[1]
        _projection_terms(md_, tw_, q1, v1)
        for ii in range(npar):
            l = pidx[ii]
            base = l * m * n
            acc = 0.0
            if given[P_CJAC] != 0:  # else G_θ = 0
                for c in range(m):
                    for a in range(n):
                        g = o[base + c * n + a]
                        acc += g * (wb[c] * v1[a] - eta[c] * zb[a])
            for a in range(n):
                acc -= u[a] * thP[l, a]
            lth[ii] += acc
    # zb is free from here: the weights of the quadrature points' values
    if (given[P_PGRAD] != 0 or given[P_KGRAD] != 0 or given[P_FORCE] != 0
            or given[P_MASS] != 0):
        for i in range(b.shape[0]):
            for a in range(n):
                cF[a] = 0.0
                cP[a] = 0.0
            for nu in range(sx):
                cl = h * b[i] * L[nu, i]
                cd = b[i] * Ld[nu, i]
                for a in range(n):
                    cF[a] += cl * mu[nu * n + a]
                    cP[a] += cd * mu[nu * n + a]
            _theta_at_quadrature(md_, tx_, h, tw_, i)
            for ii in range(npar):
                l = pidx[ii]
                acc = 0.0
                if fp.shape[0] > 0:
                    for e in range(fp[l], fp[l + 1]):
                        acc += cF[fi[e]] * thF[l, fi[e]]
                else:
                    for a in range(n):
                        acc += cF[a] * thF[l, a]
                if given[P_MASS] != 0:
                    for a in range(n):
                        acc += cP[a] * thP[l, a]
                lth[ii] += acc
    if m > 0 and given[P_CON] != 0:
        for j in range(1, J + 1):
            _at_constraint_point(md_, tx_, h, tw_, j, P_CON)
            row = sx * n + (j - 1) * m
            for ii in range(npar):
                l = pidx[ii]
                acc = 0.0
                lo, hi = _entries(cp, l, m)
                for e in range(lo, hi):
                    c = _entry(ci, cp, e)
                    acc += mu[row + c] * o[l * m + c]
                lth[ii] += acc
    if m > 0 and given[P_CJAC] != 0:
        for j in range(J):
            for a in range(n):
                acc = 0.0
                for nu in range(sx):
                    acc += Lc[nu, j] * mu[nu * n + a]
                cF[a] = acc
            _at_constraint_point(md_, tx_, h, tw_, j, P_CJAC)
            col = sx * n + j * m
            for ii in range(npar):
                base = pidx[ii] * m * n
                acc = 0.0
                for c in range(m):
                    e = X[col + c]
                    for a in range(n):
                        acc += o[base + c * n + a] * e * cF[a]
                lth[ii] -= acc


@hot
def linearise(md_, h, argsp):
    """The blocks of the step's derivative (module docstring) at its converged unknowns
    ``X``, from the start ``tw.qk``, ``tw.pk`` at ``time`` = (t_k, t_{k+1}), to the end
    ``q1``, ``v1`` with the end impulse ``eta`` (m,) and ``P`` (the momentum before the
    projection); ``md_`` a pointer to the model, the rest in the :class:`LinearisationArgs`
    behind ``argsp``: pointers ``txp`` to the :func:`extended_tables` and ``twp`` to the
    :class:`TangentWork`, and ``asm`` the extended step's :func:`.step.assemble_function`.
    The parts by the parameters are the C function ``theta`` of the arguments
    (:func:`linearised`). Factors ``K``, ``M(q_{k+1})`` and ``G M⁻¹ Gᵀ``. Returns a status
    code (``SINGULAR``: the Newton matrix at the solution is singular, and the step has no
    derivative there).

    Compiled only as the C function of :func:`linearised` (its body, not a call of it:
    numba would optimise the code once more in a wrapper)."""
    a = own(argsp)
    tx_, tw_, asm, theta = a.txp, a.twp, a.asm, a.theta
    time, X, q1, v1, eta, P = a.time, a.X, a.q1, a.v1, a.eta, a.P
    md, tx, tw = own(md_), own(tx_), own(tw_)
    wx, pw = tw.ws, tw.pt
    n, m, s, N = _step_sizes(wx)
    sn = s * n
    tcol = sn  # the translation's column, and the first row of P
    Xx, A = wx.X, wx.A
    rows, cols, K, Tq, PX = tw.rows, tw.cols, tw.K, tw.Tq, tw.PX
    for k in range(sn):
        Xx[k] = X[k]
    for a in range(n):
        Xx[sn + a] = 0.0
    for k in range(N - sn):
        Xx[sn + n + k] = X[sn + k]
    wx.time[0] = time[0]
    wx.time[1] = time[1]
    if m > 0:
        _start_jacobian(md, tw.qk, wx, tw.pt.sp, n, m)
    # the matrix too (N > 0: a bool of run time)
    st = asm(erased(md_), erased(tx_), h, byref(tw.qk), byref(tw.pk), erased(byref(wx)), N > 0)
    if st != OK:
        return st
    if m > 0:
        # ∂/∂q_k of −ℓ_ν(d_0) G(q_k)ᵀ η_0: the step holds G(q_k) fixed, its matrix has no
        # such term
        Hs = pw.Hs
        if md.flags[F_TIME] != 0:
            md.prm[md.flags[F_TSLOT]] = time[0]  # the constraint at q_k, at t_k
        _hessian(md, tw.qk, X[sn:sn + m], Hs, pw, n, m)
        for nu in range(s + 1):
            cl = tx.Lc[nu, 0]
            if cl != 0.0:
                add_block(A, nu * n, tcol, -cl, Hs, n, n, wx.si, plan_spans(byref(wx))[0],
                          assembly_map(byref(wx)))
    sp = tw.pt.sp
    banded = sp.perm.shape[0] > 0
    if sp.tptr.shape[0] > 0:  # over the patterns: O(nnz)
        _sparse_blocks(wx, A, rows, cols, sp, tw.tval, tw.xval, N, n, sn)
    else:
        for i in range(N):
            ri = rows[i]
            for b in range(n):
                Tq[i, b] = A[ri, tcol + b]
        for a in range(n):
            for j in range(N):
                PX[a, j] = A[sn + a, cols[j]]
            for b in range(n):
                Tq[N + a, b] = A[sn + a, tcol + b]
    if not banded:
        for i in range(N):
            ri = rows[i]
            for j in range(N):
                K[i, j] = A[ri, cols[j]]
    if banded:
        if _band_factor(wx, A, rows, cols, sp, tw.ab, tw.piv, N) != 0:
            return SINGULAR
    elif lu_factor_small(K, tw.piv, N) != 0:
        return SINGULAR
    by_theta = tw.pidx.shape[0] > 0
    if by_theta:  # (the last argument is read by THETA_PULL only)
        st = theta(erased(md_), h, erased(argsp), THETA_COLUMNS, erased(byref(P)))
        if st != OK:
            return st
    if md.flags[F_TIME] != 0:
        md.prm[md.flags[F_TSLOT]] = time[1]  # the projection's time, as the step had it
    point(md_, q1, v1, eta, byref(pw))
    if m > 0 and pw.sp.gsta.shape[0] > 0:
        _grouped_hv(wx, md, q1, v1, pw, n, m)
    st = _factor_projection(md, tw, wx, pw, sp, n, m)
    if st == OK and by_theta:
        st = theta(erased(md_), h, erased(argsp), THETA_PROJECTION, erased(byref(P)))
    return st


@hot_inline
def _exact_in_theta(md, tw):
    """Whether the model's derivatives by θ give the step's: they cover every callback θ
    enters, and the projection is the plain one (not that of a singular constant mass)."""
    return tw.pd.exact != 0 and md.flags[F_AUGMENT] == 0


@hot_inline
def _factor_projection(md, tw, wx, pw, sp, n, m):
    """Factor ``M(q_{k+1})`` as needed and ``S = G M⁻¹ Gᵀ``, with ``Y = G M⁻¹`` into
    ``tw.Yg``. Returns a status code."""
    if m > 0:
        M, G, Yg, S = pw.M, pw.G, tw.Yg, tw.S
        if reciprocal_mass(md.flags):
            # G M⁻¹ by the reciprocals, as the LU of a diagonal M would (bit for bit), in
            # O(m n) instead of O(n³ + m n²): the large mechanisms' case
            for a in range(n):
                if not (M[a, a] != 0.0):
                    return SINGULAR_MASS
            gs = sp.gspan
            if gs.shape[0] > 0:  # G's pattern: the rest of Y keeps its zeros
                for c in range(m):
                    for a in range(gs[2 * c], gs[2 * c + 1]):
                        Yg[c, a] = G[c, a] * (1.0 / M[a, a])
            else:
                for a in range(n):
                    inv = 1.0 / M[a, a]
                    for c in range(m):
                        Yg[c, a] = G[c, a] * inv
            si = tw.ws.si
            if si[SI_S] != SOLVE_DENSE:  # the step's own plan for G M⁻¹ Gᵀ (banded.py)
                if _projection_factor(wx, G, md.Mc, m, tw.pivm) != 0:
                    return SINGULAR_CONSTRAINTS
                return OK
            if sp.gsta.shape[0] > 0:
                _sparse_gmg(wx, sp, Yg, G, S, m)
                if lu_factor_small(S, tw.pivm, m) != 0:
                    return SINGULAR_CONSTRAINTS
                return OK
        else:
            if lu_factor_small(M, tw.pivn, n) != 0:
                return SINGULAR_MASS
            for c in range(m):
                for a in range(n):
                    Yg[c, a] = G[c, a]
                lu_solve_small(M, tw.pivn, Yg[c], n)
        for c in range(m):
            for e in range(m):
                acc = 0.0
                for a in range(n):
                    acc += Yg[c, a] * G[e, a]
                S[c, e] = acc
        if lu_factor_small(S, tw.pivm, m) != 0:
            return SINGULAR_CONSTRAINTS
    return OK


# The structured solves below take the extended step's workspace ``ws`` only to be compiled
# away for a small model (``_numba.only_if``: its ``structured`` field is typed None), whose
# linearised step then carries no banded or sparse solver: a run-time branch would leave
# them to be compiled all the same.
@hot
def _band_factor(ws, A, rows, cols, sp, ab, piv, N):
    """Factor the band storage ``ab`` of ``K[perm][:, perm]`` (``sp.perm``), ``K`` the
    step's rows and columns of the extended matrix ``A``: :func:`.banded.band_pack` without
    forming ``K``, then :func:`.banded.band_factor`; or, where the assembly wrote ``K``
    straight into ``ab`` (``ws.si[SI_XMAP]``), the factorisation alone. Returns its
    status."""
    kl, ku, perm = sp.kl, sp.ku, sp.perm
    if ws.si[SI_XMAP] != 0:
        return band_factor(ab, piv, N, kl, ku)
    kv = kl + ku
    ld = band_ld(kl, ku)
    for k in range(ld * N):
        ab[k] = 0.0
    for j in range(N):
        cj = cols[perm[j]]
        for i in range(max(0, j - ku), min(N, j + kl + 1)):
            ab[ld * j + kv + i - j] = A[rows[perm[i]], cj]
    return band_factor(ab, piv, N, kl, ku)


@hot
def _band_solve(ws, sp, ab, piv, t, y, N, transposed):
    """``y ← K⁻¹ y`` (``K⁻ᵀ y`` if ``transposed``) with the factors of :func:`_band_factor`,
    in the step's ordering (``K[perm][:, perm]`` factored, so both sides are permuted
    alike); ``t`` (N,) scratch."""
    perm = sp.perm
    for i in range(N):
        t[i] = y[perm[i]]
    if transposed:
        band_solve_transposed(ab, piv, t, N, sp.kl, sp.ku)
    else:
        band_solve(ab, piv, t, N, sp.kl, sp.ku)
    for i in range(N):
        y[perm[i]] = t[i]


@hot
def _sparse_blocks(ws, A, rows, cols, sp, tv, xv, N, n, sn):
    """``tv``, ``xv`` ← ``R_q``, ``P_q`` and ``P_X`` of the extended matrix ``A`` over the
    patterns of ``sp`` (``sn = s n``: the translation's column, and the first row of P);
    from the storage that the map ``ws.si[SI_XMAP]`` gave them where there is one."""
    si = ws.si
    xm = assembly_map(ws)
    if xm[0] != 0:  # where the assembly put them (banded.assembly_offset)
        for i in range(N + n):
            ri = rows[i] if i < N else sn + i - N
            for k in range(sp.tptr[i], sp.tptr[i + 1]):
                tv[k] = A[0, assembly_offset(si, xm, ri, sn + sp.tcol[k])]
        for a in range(n):
            for k in range(sp.xptr[a], sp.xptr[a + 1]):
                xv[k] = A[0, assembly_offset(si, xm, sn + a, cols[sp.xcol[k]])]
        return
    for i in range(N + n):
        ri = rows[i] if i < N else sn + i - N
        for k in range(sp.tptr[i], sp.tptr[i + 1]):
            tv[k] = A[ri, sn + sp.tcol[k]]
    for a in range(n):
        for k in range(sp.xptr[a], sp.xptr[a + 1]):
            xv[k] = A[sn + a, cols[sp.xcol[k]]]


@hot
def _sparse_row(ws, sp, tv, i, x, acc):
    """``acc + Σ_b T_q[i, b] x[b]`` over the pattern of row ``i`` (:func:`_tq_row`)."""
    for k in range(sp.tptr[i], sp.tptr[i + 1]):
        acc += tv[k] * x[sp.tcol[k]]
    return acc


@hot
def _sparse_px_row(ws, sp, xv, a, y, acc):
    """``acc − Σ_j P_X[a, j] y[j]`` over the pattern of row ``a``."""
    for k in range(sp.xptr[a], sp.xptr[a + 1]):
        acc -= xv[k] * y[sp.xcol[k]]
    return acc


@hot
def _sparse_pull(ws, sp, tv, xv, zb, dq1b, yb, lq, N, n, sn, tw):
    """The products of :func:`pull` with ``P_X``, ``R_q`` and ``P_q`` over their patterns,
    as scatters row by row (each entry gathers its terms in the order of the dense sums),
    around the transposed solve."""
    for j in range(N):
        yb[j] = 0.0
    for a in range(n):
        for k in range(sp.xptr[a], sp.xptr[a + 1]):
            yb[sp.xcol[k]] -= xv[k] * zb[a]
    for a in range(n):
        yb[sn - n + a] -= dq1b[a]
    _solve(tw, yb, N, True)  # B̄ = K⁻ᵀ ȳ
    for b in range(n):
        lq[b] = dq1b[b]
    for a in range(n):
        for k in range(sp.tptr[N + a], sp.tptr[N + a + 1]):
            lq[sp.tcol[k]] += tv[k] * zb[a]
    for i in range(N):
        for k in range(sp.tptr[i], sp.tptr[i + 1]):
            lq[sp.tcol[k]] += tv[k] * yb[i]


@hot
def _grouped_hv(ws, md, q, v, pw, n, m):
    """``pw.Hv = ∂(G v)/∂q`` at ``q`` (row c: ``(∇²g_c v)ᵀ``, plus ``∂G_c/∂t`` for
    time-dependent constraints) by one constraint Hessian a group of ``pw.sp``: row b of a
    group's sum is that of the one constraint whose pattern holds b, and the others add
    zeros there. The rows of :func:`point` for ``m`` Hessians in O(n²) each."""
    sp, Hv, Hs, e = pw.sp, pw.Hv, pw.Hs, pw.e
    clear_rows(Hv, m, n, sp.gspan)
    for k in range(sp.gsta.shape[0] - 1):
        for i in range(m):
            e[i] = 0.0
        for i in range(sp.gsta[k], sp.gsta[k + 1]):
            e[sp.grow[i]] = 1.0
        _hessian(md, q, e, Hs, pw, n, m)
        for i in range(sp.gsta[k], sp.gsta[k + 1]):
            c = sp.grow[i]
            for jb in range(sp.gptr[c], sp.gptr[c + 1]):
                b = sp.gcol[jb]
                acc = 0.0
                for ja in range(sp.gptr[c], sp.gptr[c + 1]):
                    a = sp.gcol[ja]
                    acc += Hs[b, a] * v[a]
                Hv[c, b] = acc
    if md.flags[F_TIME] != 0:
        jacobian_rate(md, q, md.prm[md.flags[F_TSLOT]], pw.Gp, pw.Gm)
        for c in range(m):
            for b in range(n):
                Hv[c, b] += pw.Gp[c, b]


@hot
def _sparse_gmg(ws, sp, Yg, G, S, m):
    """``S = Y Gᵀ`` over the pattern of G, which ``Y = G M⁻¹`` has for a diagonal M:
    O(nnz(G) m) instead of O(m² n)."""
    for c in range(m):
        for e in range(m):
            S[c, e] = 0.0
        for ja in range(sp.gptr[c], sp.gptr[c + 1]):
            a = sp.gcol[ja]
            y = Yg[c, a]
            for e in range(m):
                S[c, e] += y * G[e, a]


@hot
def _projection_factor(ws, G, Mc, m, piv):
    """``G M⁻¹ Gᵀ`` (diagonal constant M) built and factored in the step's plan
    (:func:`.banded.gmg_factor`). Returns its status."""
    return gmg_factor(ws.si, ws.sb, G, Mc, m, piv)


@hot
def _projection_solve(ws, x, m, piv):
    """``x ← (G M⁻¹ Gᵀ)⁻¹ x`` with the factors of :func:`_projection_factor`."""
    gmg_solve(ws.si, ws.sb, x, m, piv)


_band_factor = only_if(_band_factor, "structured", 0)
_band_solve = only_if(_band_solve, "structured")
_projection_factor = only_if(_projection_factor, "structured", 0)
_projection_solve = only_if(_projection_solve, "structured")
_sparse_blocks = only_if(_sparse_blocks, "structured")
_grouped_hv = only_if(_grouped_hv, "structured")
_sparse_gmg = only_if(_sparse_gmg, "structured")
_sparse_row = only_if(_sparse_row, "structured", 0.0)
_sparse_px_row = only_if(_sparse_px_row, "structured", 0.0)
_sparse_pull = only_if(_sparse_pull, "structured")


@hot_inline
def _solve(tw, y, N, transposed):
    """``y ← K⁻¹ y`` (``K⁻ᵀ y`` if ``transposed``) with the factors of :func:`linearise`:
    dense, or banded (:func:`_band_solve`)."""
    if tw.pt.sp.perm.shape[0] > 0:
        _band_solve(tw.ws, tw.pt.sp, tw.ab, tw.piv, tw.t, y, N, transposed)
    elif transposed:
        _lu_solve_transposed(tw.K, tw.piv, y, N)
    else:
        lu_solve_small(tw.K, tw.piv, y, N)


@hot_inline
def _solve_projection(tw, x, m, transposed):
    """``x ← S⁻¹ x`` (``S⁻ᵀ x`` if ``transposed``), ``S = G M⁻¹ Gᵀ`` at ``q_{k+1}`` as
    :func:`linearise` factored it: dense, or in the step's plan (symmetric: its own
    transpose)."""
    if tw.ws.si[SI_S] != SOLVE_DENSE:
        _projection_solve(tw.ws, x, m, tw.pivm)
    elif transposed:
        _lu_solve_transposed(tw.S, tw.pivm, x, m)
    else:
        lu_solve_small(tw.S, tw.pivm, x, m)


@hot_inline
def _tq_row(tw, i, x, acc, n):
    """``acc + Σ_b T_q[i, b] x[b]``: row ``i`` of ``R_q`` (``P_q`` for i ≥ N) times ``x``,
    over its pattern where the model's :class:`Sparsity` has one."""
    sp = tw.pt.sp
    if sp.tptr.shape[0] > 0:
        acc = _sparse_row(tw.ws, sp, tw.tval, i, x, acc)
    else:
        for b in range(n):
            acc += tw.Tq[i, b] * x[b]
    return acc


@hot_inline
def _minus_product(out, x, A, y, rows, n, spans):
    """``out = x − A y`` (rows,) for ``A`` (rows, n), over the rows' spans of ``A`` (empty:
    all of it)."""
    if spans.shape[0] > 0:
        for a in range(rows):
            acc = x[a]
            for b in range(spans[2 * a], spans[2 * a + 1]):
                acc -= A[a, b] * y[b]
            out[a] = acc
    else:
        for a in range(rows):
            acc = x[a]
            for b in range(n):
                acc -= A[a, b] * y[b]
            out[a] = acc


@hot_inline
def _minus_transposed_g(z, G, w, m, n, spans):
    """``z −= Gᵀ w``: by the rows' spans of G (empty: all of it) scattered row by row, so
    that each entry takes its terms in the order of the dense sum."""
    if spans.shape[0] > 0:
        for e in range(m):
            for a in range(spans[2 * e], spans[2 * e + 1]):
                z[a] -= G[e, a] * w[e]
    else:
        for a in range(n):
            acc = z[a]
            for e in range(m):
                acc -= G[e, a] * w[e]
            z[a] = acc


@hot_inline
def _transposed_product(out, A, y, n, spans):
    """``out −= Aᵀ y`` (n,) for a matrix ``A`` whose pattern is symmetric, over the rows'
    spans (empty: all of it): column ``a`` of ``A`` has row ``a``'s span."""
    if spans.shape[0] > 0:
        for a in range(n):
            acc = 0.0
            for b in range(spans[2 * a], spans[2 * a + 1]):
                acc += A[b, a] * y[b]
            out[a] -= acc
    else:
        for a in range(n):
            acc = 0.0
            for b in range(n):
                acc += A[b, a] * y[b]
            out[a] -= acc


@hot
def push(tw_):
    r"""Apply the linearised step to every direction: ``tw.dq``, ``tw.dp`` (with the
    parameter parts ``tw.th``) become the directions at ``t_{k+1}``. The projection's part,
    with ``Y = G M⁻¹``, ``S = Y Gᵀ`` at ``q_{k+1}``:

        z = δP − H_η δq_{k+1},   S δη = Y (z − C_q δq_{k+1}) + H_v δq_{k+1},
        δp_{k+1} = z − Gᵀ δη + (∂p_{k+1}/∂θ) δθ

    (``H_η = Σ η_c ∇²g_c``, ``H_v = ∂(G v)/∂q``, ``C_q = ∂(M v)/∂q``): the derivative of
    ``p = P − Gᵀη`` and of the hidden constraint ``G M⁻¹ p = 0``. Returns a status code."""
    tw = own(tw_)
    pw = tw.pt
    n, m, s, N = _step_sizes(tw.ws)
    sn = s * n
    npar = tw.pidx.shape[0]
    Rth, PX, B, dP = tw.Rth, tw.PX, tw.B, tw.dP
    G, He, Hv, Cq, Yg = pw.G, pw.He, pw.Hv, pw.Cq, tw.Yg
    z, u, w = tw.z, tw.u, tw.w
    sp = pw.sp
    gs = sp.gspan
    sparse = sp.tptr.shape[0] > 0
    bad = False
    for c in range(tw.dq.shape[0]):
        dq, dp, th, y, dq1 = tw.dq[c], tw.dp[c], tw.th[c], B[c], tw.dq1[c]
        for i in range(N):
            acc = dp[i] if i < n else 0.0
            acc = _tq_row(tw, i, dq, acc, n)
            for l in range(npar):
                acc += Rth[i, l] * th[l]
            y[i] = acc
        _solve(tw, y, N, False)
        for a in range(n):
            dq1[a] = dq[a] - y[sn - n + a]
            acc = _tq_row(tw, N + a, dq, 0.0, n)
            for l in range(npar):
                acc += Rth[N + a, l] * th[l]
            if sparse:
                acc = _sparse_px_row(tw.ws, sp, tw.xval, a, y, acc)
            else:
                for j in range(N):
                    acc -= PX[a, j] * y[j]
            dP[c, a] = acc
        _minus_product(z, tw.dP[c], He, dq1, n, n, sp.bspan)
        if m > 0:
            _minus_product(u, z, Cq, dq1, n, n, sp.bspan)
            if gs.shape[0] > 0:
                for e in range(m):
                    acc = 0.0
                    for a in range(gs[2 * e], gs[2 * e + 1]):
                        acc += Yg[e, a] * u[a] + Hv[e, a] * dq1[a]
                    w[e] = acc
            else:
                for e in range(m):
                    acc = 0.0
                    for a in range(n):
                        acc += Yg[e, a] * u[a] + Hv[e, a] * dq1[a]
                    w[e] = acc
            _solve_projection(tw, w, m, False)
            _minus_transposed_g(z, G, w, m, n, gs)
        for a in range(n):
            x = z[a]
            for l in range(npar):
                x += tw.Pth[a, l] * th[l]
            dq[a] = dq1[a]
            dp[a] = x
            bad = bad or not (np.isfinite(x) and np.isfinite(dq1[a]))
    return NONFINITE if bad else OK


@hot
def pull(md_, h, argsp, lq, lp, lth):
    """The transpose of :func:`push`: the cotangent ``(lq, lp)`` at ``t_{k+1}`` becomes the
    one at ``t_k`` (in place), and ``lth`` (np,) gains the parameters' part
    (``lth += (∂x_{k+1}/∂θ)ᵀ λ_{k+1}``): from the model's derivatives by θ
    (:func:`_theta_pull`, through the arguments' ``theta``, at the step :func:`linearise`
    was given by the same :class:`LinearisationArgs` ``argsp``), or from the differences
    ``R_θ``, ``P_θ`` that :func:`linearise` made. One transposed solve with ``K``. Returns
    a status code."""
    tw = own(own(argsp).twp)
    pw = tw.pt
    n, m, s, N = _step_sizes(tw.ws)
    sn = s * n
    exact = _exact_in_theta(own(md_), tw)
    npar = 0 if exact else tw.pidx.shape[0]  # the columns of R_θ, P_θ (differences)
    Tq, Rth, PX = tw.Tq, tw.Rth, tw.PX
    G, He, Hv, Cq, Yg = pw.G, pw.He, pw.Hv, pw.Cq, tw.Yg
    zb, u, wb, yb, dq1b = tw.zb, tw.u, tw.wb, tw.yb, tw.z
    # dp1 = z − Gᵀ w + P_θ θ
    for l in range(npar):
        acc = 0.0
        for a in range(n):
            acc += tw.Pth[a, l] * lp[a]
        lth[l] += acc
    for a in range(n):
        zb[a] = lp[a]
        dq1b[a] = lq[a]
    bs, gs = pw.sp.bspan, pw.sp.gspan
    if m > 0:
        for e in range(m):  # w̄ = −G λp, then S⁻ᵀ w̄
            wb[e] = 0.0
        _minus_product(wb, wb, G, lp, m, n, gs)
        _solve_projection(tw, wb, m, True)
        if gs.shape[0] > 0:
            # ū = Yᵀ w̄ ; δq1 gains H_vᵀ w̄: scattered row by row, so that each entry
            # gathers its terms in the order of the dense sums below
            for a in range(n):
                u[a] = 0.0
                dq1b[a] = 0.0
            for e in range(m):
                for a in range(gs[2 * e], gs[2 * e + 1]):
                    u[a] += Yg[e, a] * wb[e]
                    dq1b[a] += Hv[e, a] * wb[e]
            for a in range(n):
                dq1b[a] = lq[a] + dq1b[a]
        else:
            for a in range(n):  # ū = Yᵀ w̄ ; δq1 gains H_vᵀ w̄
                acc = 0.0
                acc2 = 0.0
                for e in range(m):
                    acc += Yg[e, a] * wb[e]
                    acc2 += Hv[e, a] * wb[e]
                u[a] = acc
                dq1b[a] += acc2
        for a in range(n):  # u = z − C_q δq1
            zb[a] += u[a]
        _transposed_product(dq1b, Cq, u, n, bs)
    _transposed_product(dq1b, He, zb, n, bs)  # z = δP − H_η δq1
    # δP = P_q δq + P_θ θ − P_X y ;  δq1 = δq − y_s
    for l in range(npar):
        acc = 0.0
        for a in range(n):
            acc += Rth[N + a, l] * zb[a]
        lth[l] += acc
    sp = pw.sp
    if sp.tptr.shape[0] > 0:
        _sparse_pull(tw.ws, sp, tw.tval, tw.xval, zb, dq1b, yb, lq, N, n, sn, tw)
    else:
        for j in range(N):
            acc = 0.0
            for a in range(n):
                acc -= PX[a, j] * zb[a]
            yb[j] = acc
        for a in range(n):
            yb[sn - n + a] -= dq1b[a]
        _solve(tw, yb, N, True)  # B̄ = K⁻ᵀ ȳ
        for b in range(n):
            acc = dq1b[b]
            for a in range(n):
                acc += Tq[N + a, b] * zb[a]
            for i in range(N):
                acc += Tq[i, b] * yb[i]
            lq[b] = acc
    if exact and tw.pidx.shape[0] > 0:
        own(argsp).theta(erased(md_), h, erased(argsp), THETA_PULL, erased(byref(lth)))
    for a in range(n):
        lp[a] = yb[a]
    for l in range(npar):
        acc = 0.0
        for i in range(N):
            acc += Rth[i, l] * yb[i]
        lth[l] += acc
    bad = False
    for a in range(n):
        bad = bad or not (np.isfinite(lq[a]) and np.isfinite(lp[a]))
    for l in range(tw.pidx.shape[0]):  # a model's derivative by θ may be what is not finite
        bad = bad or not np.isfinite(lth[l])
    return NONFINITE if bad else OK


# ----------------------------------------------------------------------------- time loop
#: what :func:`_differentiate` needs besides the step: pointers to the extended tables and
#: the :class:`TangentWork` (set by :func:`run_tangent`), the directions' samples
#: (K, d, n), and the :class:`Linearised` step
TangentRun = namedtuple("TangentRun", ["txp", "twp", "dQ", "dP", "lin"])

#: the linearised step as C functions (:func:`linearised`): ``asm``, the extended step's
#: :func:`.step.assemble_function`, ``theta``, its parts by the parameters (of
#: :data:`THETA_SIGNATURE`, compiled for what the run differentiates), and ``step``,
#: :func:`linearise` called as ``step(md*, h, args*)`` with a pointer to its
#: :class:`LinearisationArgs`
Linearised = namedtuple("Linearised", ["asm", "theta", "step"])

#: the arguments of :func:`linearise` (and :func:`pull`) but the model and ``h``, as their
#: C functions take them: pointers to the extended tables and the :class:`TangentWork`, the
#: :class:`Linearised` step's ``asm`` and ``theta``, then the step's ``time`` = (t_k,
#: t_{k+1}), converged unknowns ``X``, end ``q1``, ``v1``, end impulse ``eta`` and ``P``
LinearisationArgs = namedtuple("LinearisationArgs", ["txp", "twp", "asm", "theta", "time", "X",
                                                     "q1", "v1", "eta", "P"])

#: the parts of the linearised step by the parameters, each a call of the ``theta`` of
#: :class:`Linearised`: the columns of ``R_θ`` (before the projection is factored), the
#: projection's ``P_θ`` (after), and the adjoint's contraction in :func:`pull`
THETA_COLUMNS, THETA_PROJECTION, THETA_PULL = 0, 1, 2
#: ``theta(md*, h, args*, part, lth*)``: ``lth`` the adjoint's (np,) gradient by θ, read by
#: ``THETA_PULL`` only
THETA_SIGNATURE = types.int64(types.voidptr, types.float64, types.voidptr, types.int64,
                              types.voidptr)


def _theta_none(md_, h, argsp, part, lthp):
    """``theta`` of a run that differentiates by no parameter (never called: the step calls it
    only for ``tw.pidx`` not empty)."""
    return OK


def _theta_by_model(md_, h, argsp, part, lthp):
    """``theta`` of forward directions by the model's derivatives by θ."""
    a = own(argsp)
    if part == THETA_COLUMNS:
        _theta_exact(md_, a.txp, h, a.twp)
    elif part == THETA_PROJECTION:
        _theta_projection(md_, a.twp, a.q1, a.v1, a.eta)
    return OK


def _theta_pull_by_model(md_, h, argsp, part, lthp):
    """``theta`` of the adjoint by the model's derivatives by θ: contracted in :func:`pull`,
    never formed."""
    if part != THETA_PULL:
        return OK
    a = own(argsp)
    tw = own(a.twp)
    _theta_pull(md_, a.txp, h, a.twp, a.q1, a.v1, a.eta, tw.yb, tw.zb, tw.wb, tw.u, own(lthp))
    return OK


def _theta_by_differences(md_, h, argsp, part, lthp):
    """``theta`` by differences in θ (a model without exact derivatives by θ): the columns
    of ``R_θ`` and ``P_θ`` at once, which :func:`push` and :func:`pull` read."""
    if part != THETA_COLUMNS:
        return OK
    a = own(argsp)
    return _theta_differences(md_, a.txp, a.asm, h, a.q1, a.P, a.twp)


#: what a run differentiates by θ (:func:`theta_kind`), and the ``theta`` compiled for it
THETA_NONE, THETA_BY_MODEL, THETA_PULL_BY_MODEL, THETA_BY_DIFFERENCES = range(4)
_THETA_BODIES = (_theta_none, _theta_by_model, _theta_pull_by_model, _theta_by_differences)


def theta_kind(md, tw):
    """How the linearised step of ``tw`` differentiates by the parameters: not at all
    (``tw.pidx`` empty), by the model's derivatives by θ for forward directions or for the
    adjoint (``tw`` without directions), or by differences in θ."""
    if tw.pidx.shape[0] == 0:
        return THETA_NONE
    if not _exact_in_theta.py_func(md, tw):
        # the columns R_θ, P_θ are then formed: make_tangent_work(exact=False) keeps them
        assert tw.Rth.shape[0] > 0, "the linearised step's work has no room for R_θ"
        return THETA_BY_DIFFERENCES
    return THETA_BY_MODEL if tw.dq.shape[0] > 0 else THETA_PULL_BY_MODEL


#: how the hooks' records hold :func:`linearise` (pointers erased: one type for every step)
LINEARISE_SIGNATURE = types.int64(types.voidptr, types.float64, types.voidptr)
_LINEARISED: dict = {}
_THETA: dict = {}


def linearised(md, tx, tw):
    """The :class:`Linearised` step for these types of model, extended tables and
    :class:`TangentWork` (generic, or its :func:`sized_twin`), compiled once as C functions
    (cached on disk). The time loop's hook and the adjoint's sweep call the linearised step
    through its address: numba would otherwise optimise its code again inside each of them
    (``docs/decisions/0028-the-linearised-step-and-its-assembly-by-address.md``).

    Its parts by the parameters are compiled only for what ``tw`` differentiates
    (:func:`theta_kind`): a run by the initial state alone compiles none of them
    (``docs/decisions/0029-the-parts-by-the-parameters-compiled-on-need.md``)."""
    key = (_key(md), _key(tx), _key(tw))
    kind = theta_kind(md, tw)
    if key not in _LINEARISED or (key, kind) not in _THETA:
        P, typeof = types.CPointer, numba.typeof
        a1 = typeof(np.zeros(1))
        args = P(types.NamedTuple([P(typeof(tx)), P(typeof(tw)), ASSEMBLE_TYPE, THETA_TYPE, a1,
                                   a1, a1, a1, a1, a1], LinearisationArgs))
        mdp, f64, i64 = P(typeof(md)), types.float64, types.int64
        with quiet():
            if key not in _LINEARISED:
                _LINEARISED[key] = (assemble_function(md, tx, tw.ws), CalledAs(
                    cached_cfunc(linearise.py_func, i64(mdp, f64, args)), LINEARISE_SIGNATURE))
            if (key, kind) not in _THETA:
                sig = (THETA_SIGNATURE if kind == THETA_NONE
                       else i64(mdp, f64, args, i64, P(a1)))
                _THETA[key, kind] = CalledAs(cached_cfunc(_THETA_BODIES[kind], sig),
                                             THETA_SIGNATURE)
    asm, step = _LINEARISED[key]
    return Linearised(asm, _THETA[key, kind], step)


@hot_inline
def linearisation_args(lin, txp, twp, time, X, q1, v1, eta, P):
    """The :class:`LinearisationArgs` of a step through ``lin`` (:class:`Linearised`)."""
    return LinearisationArgs(txp, twp, lin.asm, lin.theta, time, X, q1, v1, eta, P)


@hot_inline
def linearise_by_address(mdp, lin, txp, twp, h, time, X, q1, v1, eta, P):
    """:func:`linearise` through ``lin`` (:class:`Linearised`)."""
    args = linearisation_args(lin, txp, twp, time, X, q1, v1, eta, P)
    return lin.step(erased(mdp), h, erased(byref(args)))


def _differentiate(mdp, h, k, statep, wsp, infop, slot, runp):
    """After step ``k`` of :func:`.drive.run` (its per-step hook, :func:`differentiator`):
    :func:`linearise` and :func:`push` from the start ``tw.qk``,
    ``tw.pk`` to the new state, the directions saved where ``run`` saved the sample, and the
    new state kept as the next step's start. Returns a status code."""
    state, ws, info, tr = own(statep), own(wsp), own(infop), own(runp)
    tw = own(tr.twp)
    n = state.shape[1]
    m = sizes(tw.ws)[1]
    st = linearise_by_address(mdp, tr.lin, tr.txp, tr.twp, h, ws.time, ws.X, state[3], state[5],
                              ws.etaJ[:m], ws.P)
    if st == OK:
        st = push(tr.twp)
    if st != OK:
        return st
    if int(info[I_SLOT]) > slot:
        for c in range(tw.dq.shape[0]):
            for a in range(n):
                tr.dQ[slot, c, a] = tw.dq[c, a]
                tr.dP[slot, c, a] = tw.dp[c, a]
    for a in range(n):
        tw.qk[a] = state[0, a]
        tw.pk[a] = state[1, a]
    return OK


def differentiator(md, state, ws, info, tx, tw, dQ, sized=False):
    """:func:`_differentiate` compiled as the per-step hook of :func:`.drive.run`
    (:func:`.drive.step_hook`) for these argument types, and the :func:`linearised` step it
    calls: ``(each, lin)``, what :func:`run_tangent` takes.

    ``sized``: ``True`` compiles both for the model's sizes (:func:`sized_twin`),
    ``"cached"`` takes the sized ones if they are compiled already, ``False`` (or a
    structured model) the generic ones. All take the same generic ``tw``."""
    twin = sized_entry(_hook, (md, state, ws, info, tx, tw, dQ), md, tx, tw, sized)
    return twin or (_hook(md, state, ws, info, tx, tw, dQ, True), linearised(md, tx, tw))


def _hook(md, state, ws, info, tx, t, dQ, compile):
    P, typeof = types.CPointer, numba.typeof
    return step_hook(_differentiate, md, state, ws, info, (tx, t, dQ),
                     lambda: types.NamedTuple([P(typeof(tx)), P(typeof(t)), typeof(dQ),
                                               typeof(dQ), LINEARISED_TYPE], TangentRun),
                     compile)


#: how :class:`LinearisationArgs` holds :func:`.step.assemble_function`, and the hooks'
#: records the :class:`Linearised` step
ASSEMBLE_TYPE = types.FunctionType(ASSEMBLE_SIGNATURE)
THETA_TYPE = types.FunctionType(THETA_SIGNATURE)
LINEARISED_TYPE = types.NamedTuple([ASSEMBLE_TYPE, THETA_TYPE,
                                    types.FunctionType(LINEARISE_SIGNATURE)], Linearised)


def sized_entry(entry, args, md, tx, tw, sized):
    """``(entry(*args with tw sized, compile), the linearised step sized)`` for a small model
    asked ``sized`` (True: compiled now; "cached": only if the entry is compiled already),
    else None."""
    if not sized or tw.ws.structured is not None:
        return None
    twin = sized_twin(tw)
    args = tuple(twin if a is tw else a for a in args)
    fn = entry(*args, sized is True)
    return None if fn is None else (fn, linearised(md, tx, twin))


def sized_twin(tw):
    """``tw`` with its extended step's sizes as compile-time constants
    (:func:`.layout.specialize`): the type for which the linearised step is compiled with
    every loop over coordinates, constraints and control points of known length
    (``docs/decisions/0021-sized-linearised-step.md``). That code reads a generic ``tw``
    by pointer as it is: the two differ only in the sizes, the last field, which it takes
    from its type."""
    return tw._replace(ws=layout_specialize(tw.ws))


@hot
def run_tangent(md, tabs, tx, opts, h, state, ws, n_chunk, n_total, save_every, smp, info, sout,
                ev, stepk, stages, tw, dQ, dPs, each, lin):
    """:func:`.drive.run` with each step differentiated after it by ``each``
    (:func:`differentiator`, with its ``lin``): the samples of the trajectory into ``smp`` (the same steps as
    ``integrate``'s, bit for bit), and the directions at each sample into ``dQ``, ``dPs``
    (K, d, n). At most ``n_chunk`` steps a call, as ``run``: a call continues where the last
    one stopped (a progress display between them). Returns a status code;
    ``info[I_FAILED]`` is the failed step."""
    for a in range(state.shape[1]):  # the start of the next step (the hook keeps it too)
        tw.qk[a] = state[0, a]
        tw.pk[a] = state[1, a]
    return run(md, tabs, opts, h, state, ws, n_chunk, n_total, save_every, smp, info, sout, ev,
               stepk, stages, None, each,
               erased(byref(TangentRun(byref(tx), byref(tw), dQ, dPs, lin))))


@njit
def _started(tw, dq, dp, th):
    """``tw`` holding the initial tangent state ``dq``, ``dp`` and parameter parts ``th``."""
    for c in range(dq.shape[0]):  # loops: slice assignment compiled in 5 s
        for a in range(dq.shape[1]):
            tw.dq[c, a] = dq[c, a]
            tw.dp[c, a] = dp[c, a]
        for l in range(th.shape[1]):
            tw.th[c, l] = th[c, l]
    return tw


#: the ensemble of :func:`fastvi.sensitivity_ensemble` (:func:`.drive.run_members` with
#: :func:`tangent_member`), what every member reads: the model's callbacks, flags
#: and constant mass, the members' parameter rows ``P`` (N, k + 1), the tables, extended
#: tables and options, the step ``h``, the sizes ``dims`` = (n, m, s, r, J) and the
#: structured plan (``si``, ``sb``, ``structured``), the shapes of the single run's
#: workspace and of its extended step's (``shapes``, ``xshapes``: :func:`.layout.field_shapes`)
#: with the extended step's plan ``xsi``, which each member allocates again (a long chain's
#: matrices in band storage, with their maps), the starts ``X0`` (N, 3, n), the steps
#: and save stride, the members' samples ``smp`` (:class:`.layout.Samples` of arrays indexed
#: by member first, slot 0 filled), counters ``infos`` (N, INFO_SIZE), the events of a run
#: without events ``ev`` (read only), the step and its stages, ``rows``, ``cols`` of
#: :func:`index_maps`, the parameters differentiated ``pidx``, the model's
#: :class:`Sparsity` ``sp`` and derivatives by θ ``pd``, the initial tangent states
#: ``DQ``, ``DP`` (N, d, n) and parameter parts ``TH`` (N, d, np), the directions' samples
#: ``dQ``, ``dP`` (N, K, d, n), and the :func:`differentiator`'s ``each`` and ``lin``
Members = namedtuple("Members", [
    "fns", "flags", "Mc", "P", "tabs", "tx", "opts", "h", "dims", "si", "sb", "structured",
    "shapes", "xsi", "xshapes", "X0", "n_total", "save_every", "smp", "infos", "ev", "stepk",
    "stages", "rows", "cols", "pidx", "sp", "pd", "DQ", "DP", "TH", "dQ", "dP", "each", "lin"])


def tangent_member(i, membersp):
    """Member ``i`` of a :class:`Members` (a body of :func:`.drive.member_function`): its
    own workspaces, state and tangent state, then :func:`run_tangent`. Returns its
    status."""
    g = own(membersp)
    n, m, s, r, J = g.dims[0], g.dims[1], g.dims[2], g.dims[3], g.dims[4]
    # the step's workspace as the time loop takes it (layout.loop_view); the extended step's
    # with its plan, as make_tangent_work gives it
    ws = with_plan(workspace_shaped(g.dims, g.shapes), g.si, g.sb.copy(), None)
    xws = with_plan(workspace_shaped((n, m, s + 1, r, J), g.xshapes), g.xsi, g.sb.copy(),
                    g.structured)
    tw = _started(tangent_work(xws, g.rows, g.cols, g.pidx, g.DQ.shape[1], g.sp, g.pd,
                               g.P.shape[1] - 1, True), g.DQ[i],
                  g.DP[i], g.TH[i])
    state = np.zeros((6, n))
    for a in range(n):
        state[0, a] = g.X0[i, 0, a]
        state[1, a] = g.X0[i, 1, a]
        state[2, a] = g.X0[i, 2, a]
    md = ModelData(g.fns, g.flags, g.Mc, g.P[i])
    linear_force(md, tw.ws, g.X0[i, 0])
    a = g.smp
    smp = Samples(a.t[i], a.q[i], a.v[i], a.p[i], a.energy[i], a.g[i], a.gv[i], a.iters[i],
                  a.work[i], a.work_forces[i])
    return run_tangent(md, g.tabs, g.tx, g.opts, g.h, state, ws, g.n_total, g.n_total,
                       g.save_every, smp, g.infos[i], np.zeros(STEP_OUT_SIZE), g.ev, g.stepk,
                       g.stages, tw, g.dQ[i], g.dP[i], g.each, g.lin)
