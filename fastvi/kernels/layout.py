"""The data the kernels share, named once.

Every layout a kernel reads — the callback slots of a model, the flags vector, the status
integers, the counters of a run, the workspace of one trajectory — is defined here and
imported by :mod:`fastvi.model`, the step and drive kernels, the RK4 baseline and the
yardstick kernel in ``tests/yardstick.py``. Kernels receive a handful of named tuples
instead of long positional argument lists:

``ModelData(fns, flags, Mc, prm)``
    the model's compiled callbacks (tuple in :data:`SLOTS` order), its int64 flags vector
    (indices ``F_*``), the constant mass matrix (zeros when ``M`` is a function) and the
    parameter vector of this trajectory, always built by
    :meth:`fastvi.Model.kernel_params` (k + 1 entries: the kernels write the time into the
    last one, so a bare ``model.params`` would be written past its end). Every model has
    this one type, so one compiled step serves conservative models and models with forces
    or time alike (which code runs is the flags' choice, :func:`is_timed`). Build it with
    :meth:`fastvi.Model.kernel_data`;
``NewtonOptions(tol, max_iter, mode)``
    the stopping tolerance, the iteration cap and the Newton variant (``NEWTON_*``);
``Tables`` (:meth:`fastvi.tables.Method.kernel_tables`)
    the basis and quadrature tables of the method;
``Workspace`` (:func:`make_workspace`)
    the scratch arrays of one trajectory, allocated once outside the time loop, and its
    sizes ``dims = (n, m, s, r, J)``: integers, or size markers whose lengths numba knows
    at compile time (:func:`specialize`); kernels read them with :func:`sizes`.

numba compiles named tuples to plain structs: attribute access costs nothing.
"""

from collections import namedtuple

import numba as nb
import numpy as np

from numba.core import types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic, overload

from .._numba import hot_inline, njit
from ..status import Status

# ----------------------------------------------------------------------------- model callbacks
#: Order of the callbacks in the tuple handed to the kernels.
SLOTS = (
    "mass",
    "kinetic_grad",
    "potential",
    "potential_grad",
    "constraint",
    "constraint_jacobian",
    "potential_hessian",
    "constraint_hessian",
    "kinetic_hessian",
    "momentum_jacobian",
    "force",
    "force_jacobian_q",
    "force_jacobian_v",
    "constraint_time_derivative",
)
(MASS, KGRAD, POT, PGRAD, CON, CJAC, PHESS, CHESS, KHESS, MJAC, FORCE, FJQ, FJV,
 GT) = range(len(SLOTS))
#: the optional second derivatives, in SLOTS order (finite differences when absent)
SECOND = SLOTS[PHESS:FORCE]
#: the optional derivatives of forces and time (finite differences when absent)
TIME_DERIVATIVES = ("force_jacobian_q", "force_jacobian_v", "constraint_time_derivative")

# ----------------------------------------------------------------------------- by the parameters
#: the callbacks whose output can depend on the parameters θ, in the order of the optional
#: derivatives by θ a model may give (``Model(param_derivatives=...)``): each writes
#: ``out[l] = ∂f/∂θ_l``, shape ``(k,) + shape of f``. A constant mass matrix is data, not a
#: function of θ; the Hessians enter only the Newton matrix and have none.
PARAM_SLOTS = ("mass", "kinetic_grad", "potential_grad", "constraint", "constraint_jacobian",
               "force")
(P_MASS, P_KGRAD, P_PGRAD, P_CON, P_CJAC, P_FORCE) = range(len(PARAM_SLOTS))
#: a model's derivatives by θ as the linearised step reads them: ``fns`` the compiled
#: callbacks in :data:`PARAM_SLOTS` order (a no-op where the model has none or declared
#: zero), ``given`` (int64, one per slot) 1 where ``fns`` holds a derivative, and ``exact``
#: 1 when they cover every callback of the model that θ can enter — else the kernels take
#: five-point differences in θ of the whole step. ``fptr``, ``fidx`` (int64): per parameter
#: ``l`` the coordinates ``fidx[fptr[l]:fptr[l + 1]]`` where ``∂F/∂θ_l`` (the derivatives of
#: ``kinetic_grad``, ``potential_grad`` and ``force``) may be non-zero, and ``cptr``,
#: ``cidx`` the constraints where ``∂g/∂θ_l`` may be: the kernels read only those entries
#: (``Model(param_patterns=...)``); an empty ``ptr`` reads every entry
ParamData = namedtuple("ParamData", ["fns", "given", "exact", "fptr", "fidx", "cptr", "cidx"])
#: the slots of :data:`PARAM_SLOTS` whose derivative by θ may be given a pattern of non-zeros
PATTERNED_PARAM_SLOTS = ("kinetic_grad", "potential_grad", "constraint", "force")

# ----------------------------------------------------------------------------- differences in time
#: eps^(1/5): the relative step of the five-point difference in time (error ~ eps^(4/5)) by
#: which the kernels and :class:`fastvi.Model` take ∂g/∂t and ∂V/∂t where no callback gives
#: them: the time derivatives enter the hidden constraint and the energy balance
FD_T = 7.4009597974140505e-04
#: the five points, as multiples of the step, and their weights (divided by 12 steps)
FD_T_POINTS = ((2.0, -1.0), (1.0, 8.0), (-1.0, -8.0), (-2.0, 1.0))

# ----------------------------------------------------------------------------- flags vector
# int64 vector built by Model.kernel_arguments: sizes, which callbacks exist, structure of M
F_N = 0  # n
F_M = 1  # m
F_MASSFN = 2  # M is a function of q (else the constant Mc)
F_EX_PHESS = 3  # exact potential Hessian given
F_EX_CHESS = 4  # exact constraint Hessian given
F_EX_KHESS = 5  # exact kinetic Hessian given
F_EX_MJAC = 6  # exact momentum Jacobian given
F_DIAG = 7  # the constant M is diagonal: M v elementwise, and M⁻¹ too unless F_AUGMENT
F_FORCE = 8  # a non-conservative force F(t, q, v) is given
F_EX_FJQ = 9  # exact ∂F/∂q given
F_EX_FJV = 10  # exact ∂F/∂v given
F_TIME = 11  # potential and constraints depend on time (rheonomic)
F_EX_GT = 12  # exact ∂g/∂t given
#: index of the hidden trailing entry of the kernel's parameter vector that carries the
#: time to the callbacks (= k, the number of user parameters; every model has the entry,
#: so that writing the time needs no branch). One callback signature serves every model:
#: the kernels write the time of each evaluation there, the wrappers of time-aware
#: callbacks read it, the others never look (docs/method.md §11).
F_TSLOT = 13
#: ∇V does not depend on q (``potential_hessian=0``: uniform gravity in Cartesian
#: coordinates). An autonomous potential's gradient is then evaluated once a trajectory
#: (``ws.Fg``) instead of at every quadrature point of every Newton iteration, and the
#: full Newton matrix has no potential-Hessian block.
F_LINPOT = 14
#: the constant M is singular (positive semidefinite, definite on the tangent space of the
#: constraints: a lamina's or a rod's director inertia): wherever the step needs M⁻¹ it
#: uses M̄ = M + Gᵀ W G (:func:`augmented_mass`), which agrees with M on ker G, so the
#: converged step is that of M itself
F_AUGMENT = 15
#: the force does not depend on q (``force_jacobian_q=0``: viscous damping): the Newton
#: matrix has no ∂F/∂q block, and no callback fills an n × n block of zeros for it
F_FORCE_Q0 = 16
#: the force's Jacobians write only the entries of ``force_jacobian_pattern``: the kernels
#: zero the block they read before each call
F_FJ_PATTERN = 17
#: ``constraint_hessian`` writes only the entries of the coordinates that share a constraint
#: (a model with ``constraint_jacobian_pattern``): the kernels zero the block they read
#: before each call, over its rows' spans where the plan has them
F_CH_PATTERN = 18
FLAGS_SIZE = 19
#: flag index of each optional second derivative, in SECOND order
F_EXACT = (F_EX_PHESS, F_EX_CHESS, F_EX_KHESS, F_EX_MJAC)

# ----------------------------------------------------------------------------- status codes
OK = int(Status.SUCCESS)
NEWTON_FAILED = int(Status.NEWTON_NOT_CONVERGED)
SINGULAR = int(Status.SINGULAR_JACOBIAN)
NONFINITE = int(Status.NONFINITE)
SINGULAR_MASS = int(Status.SINGULAR_MASS)
SINGULAR_CONSTRAINTS = int(Status.SINGULAR_CONSTRAINTS)

# ----------------------------------------------------------------------------- events
#: event functions a run can watch (a fixed-size tuple of callbacks: one kernel type)
EVENT_SLOTS = 8
#: positive returns of the time loop: a terminal event ended the run (not a failure), or
#: the event records need room before the next step (the driver grows them and resumes)
EVENT_TERMINAL = 1
EVENTS_FULL = 2
#: a positive return of the step and the time loop: the step needs the full Newton, whose
#: compiled stage the run does not have yet (:func:`.step.step_kernel` compiles it on
#: first need); nothing of the step was kept, so the driver retakes it with that stage
NEEDS_FULL_NEWTON = 3

# ----------------------------------------------------------------------------- Newton variants
#: full Newton: the exact Newton matrix assembled and factored at every iteration
NEWTON_FULL = 0
#: the mechanics matrix (mass and constraint-Jacobian blocks, Hessians dropped) solved
#: through its Schur complement on the impulses, with the full Newton as fallback
NEWTON_AUTO = 1
NEWTON_MODES = {"full": NEWTON_FULL, "auto": NEWTON_AUTO}

# ----------------------------------------------------------------------------- structured solves
# (issue 12) how each linear system of a step is solved, planned once per model and method
# by :func:`fastvi.structure.plan` and stored in two workspace arrays: ``ws.si`` (int64: the
# header below, then permutations and sparsity patterns at the offsets the header names) and
# ``ws.sb`` (float64: band storages and a right-hand-side scratch, at named offsets).
#: the solvers of a system: dense LU (linalg.py), banded LU with partial pivoting after a
#: fill-reducing ordering (banded.py), or a sparse LU with static pivots and a symbolic
#: factorisation computed once (sparse_lu.py; the Schur complement and the projection only)
SOLVE_DENSE, SOLVE_BANDED, SOLVE_SPARSE = 0, 1, 2
(SI_A, SI_A_KL, SI_A_KU, SI_A_PERM, SI_A_BAND,  # full Newton matrix (s n + J m rows)
 SI_SC, SI_SC_KL, SI_SC_KU, SI_SC_PERM, SI_SC_BAND,  # Schur complement (J m)
 SI_S, SI_S_KL, SI_S_KU, SI_S_PERM, SI_S_IPERM, SI_S_BAND,  # projection G M⁻¹ Gᵀ (m)
 SI_GPTR, SI_GCOL,  # pattern of G, compressed rows: columns of row c at si[GCOL + GPTR[c] …]
 SI_SPTR, SI_SCOL,  # pattern of G Gᵀ (m × m), compressed rows
 SI_RHS,  # offset in sb of the right-hand-side scratch
 # Schur complement and projection, banded or sparse: the length of the factor storage in
 # sb (at SI_SC_BAND / SI_S_BAND), the offset in si of the destination of each entry of the
 # pattern of G Gᵀ in that storage (Schur: block (j−1, j') at ((j−1) J + j') nnz(G Gᵀ)), and
 # for a sparse LU the offset in si of its descriptor (LU_* below)
 SI_SC_LEN, SI_SC_DST, SI_SC_LU,
 SI_S_LEN, SI_S_DST, SI_S_LU,
 # finite differences of the constraint Hessian by column groups (Curtis–Powell–Reid): the
 # number of groups (0: one column at a time), the offsets in si of the coordinates of each
 # group (pointers, coordinates) and of the Hessian entries (a, b) each group yields
 # (pointers, rows a, columns b)
 SI_HC_NG, SI_HC_CPTR, SI_HC_COLS, SI_HC_PPTR, SI_HC_ROWS, SI_HC_BCOL,
 # a banded Newton matrix: the offsets in si of each row's span of non-zeros, (lo, hi)
 # pairs with the columns lo … hi − 1, of the coupling of the coordinates (n rows: the
 # union of the Newton matrix's coordinate blocks and of Gᵀ G, symmetrised) and of G (m
 # rows). The exact Newton matrix is then assembled over these spans alone, and its
 # entries outside them are never written (they stay the zeros of the allocation); and of
 # the declared ``force_jacobian_pattern`` (n rows, 0: none), over which ∂F/∂v is added
 # without scanning each row for its non-zeros
 SI_BSPAN, SI_GSPAN, SI_FSPAN,
 # a banded Newton matrix too large to hold densely (the full Newton's, or the extended
 # step's of the derivatives, kernels/tangent.py): the offset in si of the map by which its
 # assembly writes straight into band storage (:data:`XMAP_HEADER`; 0: into the dense
 # ``ws.A``). It belongs to the workspace whose ``A`` was shaped for it: a workspace built
 # from another's plan takes that plan :func:`without_map`
 SI_XMAP) = range(37)
#: length of the header of ``ws.si``; with ``si[SI_SC]`` or ``si[SI_S]`` structured the
#: kernels use the pattern of G (a diagonal constant mass is then required), as with
#: ``si[SI_HC_NG]`` non-zero
SI_HEADER = 37
#: the map at ``si[SI_XMAP]`` (:func:`assembly_into_band`, read by
#: :func:`.banded.assembly_offset`): ``N``, ``n`` (0 for the step's own matrix), ``kl``,
#: ``ku`` and the length of the storage; for each of the matrix's ``N + n`` rows (and
#: columns: the same set) its index in the step's matrix ``K``, or ``N + a`` for the
#: extended step's own row (column) ``a``; for each index of ``K`` its position in the
#: banded ordering; ``(base, lo, hi)`` of each of the ``N + n`` rows of ``T_q`` (its columns
#: ``lo … hi − 1`` from ``base`` in the storage) and of each of the ``N`` columns of ``P_X``
#: (its rows ``lo … hi − 1``); the offset of the spare cell
(XM_N, XM_SIZE, XM_KL, XM_KU, XM_LEN) = range(5)
XMAP_HEADER = 5
#: descriptor of a sparse LU in ``ws.si`` (sparse_lu.py): offsets in si of its arrays, for
#: an N-row system in its fill-reducing order — position in the factor storage of each
#: pivot; of each column's entries below the diagonal (pointers, rows, positions); of each
#: row's entries right of the diagonal (pointers, columns, positions); and of the targets of
#: each pivot's rank-one update, |L_k| × |U_k| positions row by row (pointers, positions)
(LU_DIAG, LU_LPTR, LU_LROW, LU_LPOS, LU_UPTR, LU_UCOL, LU_UPOS, LU_WPTR, LU_WPOS) = range(9)
LU_HEADER = 9

# ----------------------------------------------------------------------------- workspace flags
# entries of the int64 ``ws.hold``: steps left on the full Newton after the mechanics
# iteration failed, whether M̄⁻¹ of a constant mass is prepared, how many previous
# steps of this trajectory the predictor may use (0 after a restart, at most 2), and
# whether ``ws.Fg`` holds the constant −∇V of a linear potential
H_FULL, H_MBAR, H_HIST, H_FG = range(4)
H_SIZE = 4

# ----------------------------------------------------------------------------- step output
# float64 vector filled by step(): Newton iterations, max|g(q1)|, max|G v1|, last residual,
# and whether the step fell back from the mechanics matrix to the full Newton
# and the work done on the system over the step by the forces, the time-dependent potential
# and driving constraints (Result.energy_balance; docs/method.md §11), then the part of that
# work done by the applied forces alone (Result.work_forces)
S_ITERS, S_G, S_GV, S_RES, S_FULL, S_WORK, S_WORK_F = range(7)
STEP_OUT_SIZE = 7

# ----------------------------------------------------------------------------- run counters
# float64 ``info`` vector of drive.run, kept across chunks
# (I_WORK: the work of forces and time since t0, the energy balance's right-hand side;
# I_T0: the start time of the run, so that step k starts at t0 + k h exactly; then the
# adaptive step of kernels/adapt.py, I_KR > 0 switching it on: the energy scale K_r, the
# energy E0 of the start, the end time, the time reached and its summation error, and the
# step density ρ_{k+1/2} of the next step, 0 before the first; I_WORK_F: the part of
# I_WORK done by the applied forces; I_DRIFT non-zero: I_DH becomes the maximum over the
# steps of |H − I_H0 − I_WORK|, the diagnostics policy of an ensemble's members)
(I_STEPS, I_ITERS, I_WIN_G, I_WIN_GV, I_WIN_IT, I_RES, I_FAILED, I_SLOT, I_FIRST, I_MAXRES,
 I_FULL, I_WORK, I_T0, I_KR, I_E0, I_TEND, I_T, I_TC, I_RHO, I_WORK_F, I_DRIFT, I_H0,
 I_DH) = range(23)
INFO_SIZE = 23

# ----------------------------------------------------------------------------- ensembles
#: save modes of ``run_member``
SAVE_FINAL, SAVE_STRIDE, SAVE_DIAGNOSTICS = 0, 1, 2
# columns of the per-member int64 rows ``ist``
E_STATUS, E_STEPS, E_FAILED, E_SAVED = range(4)
E_SIZE = 4
# columns of the per-member float64 rows ``fst``: Newton iterations (total), residual of the
# last step tried, max residual over good steps, max |H − H0|, max |g|, max |Gv|
F_ITERS, F_RES, F_MAXRES, F_DH, F_G, F_GV = range(6)
F_SIZE = 6

# ----------------------------------------------------------------------------- named tuples
#: the saved samples of one trajectory (drive.run): time, q, v, p, energy, and the maxima of
#: |g|, |G v| and the sum of Newton iterations over the steps since the previous sample, and
#: the work of forces and time since the start (zero for a conservative model), and the part
#: of it done by the applied forces
Samples = namedtuple("Samples", ["t", "q", "v", "p", "energy", "g", "gv", "iters", "work",
                                 "work_forces"])
ModelData = namedtuple("ModelData", ["fns", "flags", "Mc", "prm"])
NewtonOptions = namedtuple("NewtonOptions", ["tol", "max_iter", "mode"])
#: dense output and events of one trajectory (kernels/events.py): the event callbacks
#: (EVENT_SLOTS, the first ``count`` used), per event ``direction`` and ``terminal`` (int64),
#: the last grid values ``g``, the records ``t`` (E, cap), ``q``, ``v`` (E, cap, n) and their
#: counts ``n``; ``dense`` (steps, s+1, n) the control points of every step (0 rows: none);
#: scratch: ``Q`` (s+1, n) this step's control points, ``qk`` (n,) its start, ``qx``, ``vx``
#: (n,), ``ell``, ``dell`` (s+1,), ``scratch`` (1,)
Events = namedtuple("Events", ["fns", "count", "direction", "terminal", "g", "t", "q", "v", "n",
                               "dense", "Q", "qk", "qx", "vx", "ell", "dell", "scratch"])
Tables = namedtuple("Tables", ["b", "L", "Ld", "Lc", "E", "tau", "Ainv", "W", "mech",
                               "c", "d", "E2", "Am", "bL", "Lw"])
Tables.__doc__ = """Method tables read by the step kernel (see :class:`fastvi.tables.Method`).

b (r,), L, Ld (s+1, r), Lc (s+1, J+1), E (s+1, s+1), tau (s+1,) as in ``Method``; the
quadrature nodes c (r,) and constraint points d (J+1,) in [0, 1] (the times of the
callbacks of a time-aware model: ``t_k + c_i h``, ``t_k + d_j h``); for the
mechanics Newton matrix: Ainv (s, s) the inverse of ``A[ν, μ−1] = Σ_i b_i ℓ'_ν(c_i) ℓ'_μ(c_i)``
(ν = 0…s−1, μ = 1…s), W (J, J) ``W[j−1, j'] = Σ ℓ_μ(d_j) Ainv[μ−1, ν] ℓ_ν(d_j')``; mech
(bool) whether ``newton="auto"`` uses the mechanics matrix: not where ``A`` is singular (a
quadrature with fewer points than ``s``); E2 (s+3, s+1) the predictor from the last two
steps (:func:`fastvi.tables.hermite_predictor`): weights of the point ``τ_{s−1} − 1`` of the
step before, the last step's control points ``τ_μ`` and its end slope ``h v_k``, at
``1 + τ_ν``; Am
(s, s) the mass block ``Am[ν−1, μ−1] = Σ_i b_i ℓ'_ν(c_i) ℓ'_μ(c_i)``, ν, μ = 1…s, exactly
symmetric: for a constant ``M`` the mass part of ``∂S/∂Q^ν`` is ``(1/h) M Σ_μ Am[ν−1, μ−1]
ΔQ^μ``, and that of ``∂S/∂Q^0`` minus their sum (the mechanics residual's shortcut;
``fastvi.tables._mass_block``); bL (s+1,) ``bL[ν] = Σ_i b_i ℓ_ν(c_i)``: for a constant
∇V the potential's part of ``∂S/∂Q^ν`` is ``−h bL[ν] ∇V``; Lw (2, s+1) the barycentric
weights ``1 / Π_{k≠μ} (τ_μ − τ_k)`` (row 0) and the slopes ``ℓ'_μ(1)`` (row 1) of the
control-point basis: the predictor of a step whose length differs from the last ones'."""

Workspace = namedtuple(
    "Workspace",
    [
        "X",  # (N,) unknowns (ΔQ^1 … ΔQ^s, η_0 … η_{J−1})
        "R",  # (N,) residual, then the Newton increment
        "A",  # (N, N) full Newton matrix, factored in place
        "piv",  # (N,) its pivots
        "D",  # (s+1, n) ∂S_u/∂Q^ν
        "G",  # (J+1, m, n) G at the constraint points
        "qi", "vi", "F", "Pm", "fa", "fb",  # (n,) q(c_i), v(c_i), force, M v, scratch
        "Mi",  # (n, n) M(q(c_i))
        "Aq", "Cq", "Hc", "Ma",  # (n, n) ∂F/∂q, ∂(Mv)/∂q, constraint Hessian, fd scratch
        "Y",  # (J+1, m, n) (M̄⁻¹ G_jᵀ)ᵀ at the constraint points (row 0 also the projection's)
        "Gp", "Gm",  # (m, n) finite-difference scratch
        "g",  # (m,) g at a constraint point
        "etaJ",  # (m,) the end impulse of the projection
        "S",  # (m, m) G M⁻¹ Gᵀ of the projection, factored
        "pivm",  # (m,)
        "Mb",  # (n, n) M̄ = M(q_k) factored (configuration-dependent or full constant mass)
        "pivn",  # (n,)
        "pivp",  # (n,) pivots of M(q_{k+1}) in the end projection
        "minv",  # (n,) 1 / diag(M) for a diagonal constant mass
        "Sc",  # (J m, J m) Schur complement of the mechanics matrix, inverted (or factored: step._schur)
        "pivs",  # (J m,)
        "w",  # (J m,) scratch of the impulses' solve
        "Z",  # (s, n) stage scratch of the mechanics solve
        "U",  # (s, n) stage scratch of the mechanics solve
        "Xprev",  # (N,) the previous step's unknowns (predictor)
        "Xpp",  # (N,) the unknowns of the step before that (two-step predictor)
        "P",  # (n,) end momentum before the projection
        "hold",  # (H_SIZE,) int64, indices H_*: full-Newton steps left, M̄ factored, predictor history, Fg set
        "Fv",  # (n, n) ∂F/∂v of the non-conservative force
        "Fg",  # (n,) −∇V of a potential linear in q (F_LINPOT), set at a trajectory's first step
        "gt",  # (m,) ∂g/∂t at the step end (stays zero for an autonomous model)
        "time",  # (2,) t_k, t_{k+1} of the step being taken (set by the driver)
        "hist",  # (2,) the lengths of the last two steps (the predictor's: steps may vary)
        "Ew",  # (s+2, s+2) Lagrange weights of the predictor for steps of changing length
        "Ev", "E2v",  # (s+1, s+1), (s+3, s+1) its weights then, in the place of E and E2
        "si",  # int64: structured-solve plan (header SI_*, permutations, patterns)
        "sb",  # float64: band storages and scratch of the structured solves
        # None for a plan of dense solves only, True when something is structured: a
        # type-level switch, so that a small model's step compiles without the banded and
        # sparse solvers (_numba.only_if)
        "structured",
        "dims",  # (n, m, s, r, J): int64 sizes, or size markers (see :func:`specialize`)
    ],
)


@hot_inline
def is_timed(md):
    """Whether the model reads the time or has a force (its flags ``F_TIME``, ``F_FORCE``).

    A run-time test: a type-level switch compiled every kernel twice, once without the
    force and time code, for a conservative step a few per cent cheaper
    (``docs/decisions/0010-kernel-shape.md``)."""
    return md.flags[F_FORCE] != 0 or md.flags[F_TIME] != 0


@hot_inline
def linear_potential(md):
    """Whether ∇V is one vector over the trajectory (``ws.Fg``, set at a trajectory's first
    step by :func:`.step.linear_force`): a potential declared linear in q
    (``potential_hessian=0``) that does not depend on time."""
    return md.flags[F_LINPOT] != 0 and not (is_timed(md) and md.flags[F_TIME] != 0)


@hot_inline
def reciprocal_mass(flags):
    """Whether the mass matrix is constant, diagonal and invertible (the model's ``flags``):
    ``M⁻¹`` is then the reciprocals of its diagonal, ``G M⁻¹`` has G's pattern and
    ``∂(M v)/∂q`` is zero. Python calls it as ``reciprocal_mass.py_func``."""
    return flags[F_DIAG] != 0 and flags[F_MASSFN] == 0 and flags[F_AUGMENT] == 0


#: the shape of each workspace field in terms of the sizes (and ``N = s n + J m``,
#: ``mm = max(m, 1)``, ``Jm = max(J m, 1)``), and which are int64; ``dims`` is the sizes.
#: One table for the two ways a workspace is made: in NumPy by :func:`make_workspace`
#: (``integrate``: no compile) and inside an ensemble's parallel loop by
#: :func:`workspace_shaped` (the shapes of a single run's workspace), whose source is
#: generated from it.
_WS_SHAPES = dict(
    X="N", R="N", A="(N, N)", piv="N", D="(s + 1, n)", G="(J + 1, mm, n)",
    qi="n", vi="n", F="n", Pm="n", fa="n", fb="n", Mi="(n, n)",
    Aq="(n, n)", Cq="(n, n)", Hc="(n, n)", Ma="(n, n)", Y="(J + 1, mm, n)",
    Gp="(mm, n)", Gm="(mm, n)", g="mm", etaJ="mm", S="(mm, mm)", pivm="mm",
    Mb="(n, n)", pivn="n", pivp="n", minv="n", Sc="(Jm, Jm)", pivs="Jm", w="Jm",
    Z="(s, n)", U="(s, n)", Xprev="N", Xpp="N", P="n", hold="H_SIZE", Fv="(n, n)", Fg="n",
    gt="mm", time="2", hist="2", Ew="(s + 2, s + 2)",
    Ev="(s + 1, s + 1)", E2v="(s + 3, s + 1)", si="SI_HEADER", sb="1",
)
_WS_INT = {"piv", "pivm", "pivn", "pivp", "pivs", "hold", "si"}
assert tuple(_WS_SHAPES) + ("structured", "dims") == Workspace._fields


#: the fields the full Newton reads and writes (:func:`.step.newton_matrix`; ``Ma``, ``Gp``
#: and ``Gm`` as its difference scratch): up to ``(s n + J m)² + 5 n² + 2 m n`` floats, most
#: of a large mechanism's workspace. A step whose stages have no full Newton (``Stages.full == 0``,
#: :func:`.step.step_kernel`) returns ``NEEDS_FULL_NEWTON`` before it would touch them, so
#: its workspace may leave them empty (:func:`unused_fields`); ``step_kernel`` allocates
#: them (:func:`fit_newton_fields`) when it returns stages that take it.
NEWTON_FIELDS = ("A", "Aq", "Cq", "Hc", "Fv", "Ma", "Gp", "Gm")


def unused_fields(flags, si, newton):
    """The workspace fields that a step of a model with these ``flags``, under the plan
    ``si`` (:func:`fastvi.structure.plan`), never reads: each one's rule mirrors the test
    that guards its use in the kernels.

    * ``Mi``, M at the quadrature points: a mass function's alone (``F_MASSFN``);
    * ``Mb``, the factors of M̄: not a constant diagonal mass's, whose reciprocals
      (``minv``) the step multiplies by (``F_DIAG`` without ``F_AUGMENT``);
    * ``Sc``, the dense Schur complement of the mechanics matrix: not where the plan solves
      it banded (``si[SI_SC]``); ``S``, the dense ``G M⁻¹ Gᵀ`` of the end projection: not
      where the plan solves that one banded or sparse (``si[SI_S]``);
    * without the full Newton (``newton`` false), :data:`NEWTON_FIELDS`; with it, those of
      its blocks and scratch that the model's terms never need (:func:`_newton_unused`);
    * but ``Ma`` and ``Gp`` where the end projection is dense (it factors M(q_{k+1})
      there, and forms M⁻¹Gᵀ), and ``Gp`` for a time-dependent model (the work of time over
      a step reads ∂g/∂t into it)."""
    dense_projection = si[SI_S] == SOLVE_DENSE
    out = set()
    if flags[F_MASSFN] == 0:
        out.add("Mi")
    if flags[F_DIAG] != 0 and flags[F_AUGMENT] == 0:
        out.add("Mb")
    if si[SI_SC] != SOLVE_DENSE:
        out.add("Sc")
    if not dense_projection:
        out.add("S")
    out.update(NEWTON_FIELDS if not newton else _newton_unused(flags))
    if dense_projection:
        out -= {"Ma", "Gp"}
    if flags[F_TIME] != 0:
        out.discard("Gp")
    return frozenset(out)


def _newton_unused(flags):
    """The full Newton's fields that :func:`.step.newton_matrix` never reads for a model
    with these ``flags``: ``Cq`` = ∂(M v)/∂q without a mass function; ``Fv`` = ∂F/∂v
    without a force; ``Gp``, ``Gm``, the differences of G, where the model gives its
    constraint Hessian; ``Ma``, the scratch of a mass function's differences, without one.
    Each ``n × n`` or ``m × n``: 32 MiB apiece for a chain of 1 024 links. A wrong rule
    here would let a kernel write past an empty array: each one is the guard of the
    field's only uses in ``newton_matrix``, word for word."""
    out = set()
    if flags[F_MASSFN] == 0:
        out.update(("Cq", "Ma"))
    if flags[F_FORCE] == 0:
        out.add("Fv")
    if flags[F_EX_CHESS] != 0:
        out.update(("Gp", "Gm"))
    return out


def _sizes_env(n, m, s, r, J):
    env = dict(n=int(n), m=int(m), s=int(s), r=int(r), J=int(J), H_SIZE=H_SIZE, SI_HEADER=SI_HEADER)
    env.update(N=env["s"] * env["n"] + env["J"] * env["m"], mm=max(env["m"], 1),
               Jm=max(env["J"] * env["m"], 1))
    return env


def _shape(name, env):
    return eval(_WS_SHAPES[name], {}, env)  # noqa: S307 - the table above


def _field(name, env):
    return np.zeros(_shape(name, env), dtype=np.int64 if name in _WS_INT else np.float64)


def make_workspace(n, m, s, r, J, unused=frozenset()):
    """Scratch arrays for one trajectory (allocated once, outside the time loop), in NumPy.

    Every linear system is solved densely; :func:`fastvi.structure.workspace` replaces
    ``si``/``sb`` with a structured plan for large models, and leaves empty the fields its
    step never reads (``unused``: names of :func:`unused_fields`; an empty field has shape
    ``(0, 0)``, the type of every field it may name)."""
    env = _sizes_env(n, m, s, r, J)
    fields = [np.zeros((0, 0)) if name in unused else _field(name, env) for name in _WS_SHAPES]
    return Workspace(*fields, None, (env["n"], env["m"], env["s"], env["r"], env["J"]))


def fit_newton_fields(ws, flags):
    """Allocate the full Newton's fields (:data:`NEWTON_FIELDS`) that ``ws`` left empty and
    a model with these ``flags`` reads (:func:`unused_fields`), in place: the arrays
    themselves grow (to zeros), so every tuple that holds them — ``ws``, its loop view
    (:func:`loop_view`), a run's record of it — sees them. What :func:`.step.step_kernel`
    does whenever the stages it returns take the full Newton. ``A`` takes the shape of its
    band storage where ``ws.si`` has a map for it."""
    env = None
    unused = unused_fields(flags, ws.si, True)
    for name in NEWTON_FIELDS:
        a = getattr(ws, name)
        if a.size == 0 and name not in unused:
            env = env or _sizes_env(*(int(x) for x in ws.dims))
            shape = _shape(name, env)
            if name == "A" and ws.si[SI_XMAP] != 0:
                shape = (1, int(ws.si[ws.si[SI_XMAP] + XM_LEN]))
            a.resize(shape, refcheck=False)


#: the size of a dense Newton matrix above which a banded one is assembled straight into
#: band storage (:func:`assembly_into_band`): about a chain of 190 links. Below it, a dense
#: matrix that fits in the caches costs less than the map's few loads a write
#: (docs/decisions/0033-the-extended-matrix-in-band-storage.md).
BAND_ASSEMBLY_BYTES = 16 * 2 ** 20


def assembles_into_band(si, N):
    """Whether a Newton matrix of ``N`` rows under the plan ``si`` is assembled straight
    into band storage (:func:`assembly_into_band`): the plan factors it banded, assembles
    it over each row's span (``si[SI_BSPAN]``), and the dense matrix would exceed
    :data:`BAND_ASSEMBLY_BYTES`."""
    return (si[SI_A] == SOLVE_BANDED and si[SI_BSPAN] != 0
            and 8 * N * N > BAND_ASSEMBLY_BYTES)


def assembly_into_band(si, N, kl, ku, perm, index=None, tspan=None, xspan=None):
    """``(si', L)``: the plan ``si`` with the map of an assembly into band storage appended
    (at ``si'[SI_XMAP]``, :data:`XMAP_HEADER`), and the length ``L`` of the storage ``A[0]``
    it addresses (:func:`.banded.assembly_offset`): the band (``2 kl + ku + 1`` by ``N``, in
    the ordering ``perm``: :func:`.banded.band_factor`'s storage), then the extended step's
    rows of ``T_q`` over their spans ``tspan`` and columns of ``P_X`` over ``xspan``
    (``(lo, hi)`` pairs), then one spare cell for the entries outside them, which no one
    reads. ``index``: the index in ``K`` of each of the matrix's ``N + n`` rows and columns
    (``N + a`` for the extended step's own row ``a``). Without them the map is the step's
    own ``N × N`` matrix's. O(N (kl + ku + w)) floats, ``w`` the widest span, in place of
    the dense matrix."""
    if index is None:
        index, tspan, xspan = np.arange(N), np.zeros((N, 2), np.int64), np.zeros((N, 2), np.int64)
    n = index.shape[0] - N
    position = np.empty(N, dtype=np.int64)
    position[perm] = np.arange(N)
    tlen, xlen = tspan[:, 1] - tspan[:, 0], xspan[:, 1] - xspan[:, 0]
    band = (2 * kl + ku + 1) * N
    tbase = band + np.cumsum(tlen) - tlen
    xbase = band + tlen.sum() + np.cumsum(xlen) - xlen
    spare = band + tlen.sum() + xlen.sum()
    header = np.zeros(XMAP_HEADER, dtype=np.int64)
    header[[XM_N, XM_SIZE, XM_KL, XM_KU, XM_LEN]] = N, n, kl, ku, spare + 1
    out = np.concatenate([si, header, index, position, np.column_stack([tbase, tspan]).ravel(),
                          np.column_stack([xbase, xspan]).ravel(), [spare]]).astype(np.int64)
    out[SI_XMAP] = si.shape[0]
    return out, int(spare + 1)


def without_map(si):
    """The plan ``si`` without its map of :func:`assembly_into_band` (the map is its last
    part): for a workspace whose ``A`` is shaped otherwise."""
    if si[SI_XMAP] == 0:
        return si
    out = si[:si[SI_XMAP]].copy()
    out[SI_XMAP] = 0
    return out




#: the structured-solve plan's fields come last in a Workspace: si, sb, then dims
_PLAN_AT = Workspace._fields.index("si")
assert Workspace._fields[_PLAN_AT:] == ("si", "sb", "structured", "dims")


@njit
def with_plan(ws, si, sb, structured):
    """``ws`` with the structured-solve plan ``si``, ``sb`` of :func:`fastvi.structure.plan`
    (``sb`` is written by the solves: each trajectory needs its own copy; ``si`` is read
    only). What :func:`fastvi.structure.workspace` does in Python, for compiled callers."""
    return Workspace(*ws[:_PLAN_AT], si, sb, structured, ws.dims)


def loop_view(ws):
    """``ws`` as the step and the time loops take it: the same arrays and plan, its
    ``structured`` field ``None``.

    ``structured`` is a type-level switch (:func:`fastvi._numba.only_if`): a kernel typed
    with ``None`` there has no code for the banded and sparse solvers. Only the stages that
    solve need that code, and :func:`.step.step_kernel` compiles them for ``ws`` itself; the
    step and every time loop are compiled once, for this view, whatever the plan. The two
    types lay out their fields alike (``None`` and a boolean each take one aligned word,
    before the sizes), so the structured stages read the view's memory as their own."""
    return ws if ws.structured is None else ws._replace(structured=None)


@intrinsic
def as_loop_view(typingctx, p):
    """``p``, a pointer to a workspace (:func:`fastvi._numba.byref`), as a pointer to its
    :func:`loop_view`: the same memory, typed with ``structured`` None. A structured stage
    passes it to the helpers that solve nothing (the residual), which are then compiled once
    for both plans. A workspace passed by value (tests and profiles call the kernels so) is
    returned as it is when it is a loop view already."""
    if not isinstance(p, types.CPointer):
        if (isinstance(p, types.BaseNamedTuple) and "structured" in p.fields
                and isinstance(p.types[p.fields.index("structured")], types.NoneType)):
            return p(p), lambda context, builder, sig, args: impl_ret_borrowed(
                context, builder, sig.return_type, args[0])
        return None
    if not isinstance(p.dtype, types.BaseNamedTuple):
        return None
    t = p.dtype
    at = t.fields.index("structured")
    view = t if isinstance(t.types[at], types.NoneType) else types.NamedTuple(
        [types.none if i == at else x for i, x in enumerate(t.types)], t.instance_class)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(signature.return_type))

    return types.CPointer(view)(p), codegen


# ----------------------------------------------------------------------------- sizes
def dim(x):
    """A size as the kernels read it: an int, or the length of a *size marker* — a tuple of
    that many ``None`` — which numba types as ``UniTuple(none, k)``, so that inside a kernel
    the size is a compile-time constant (see :func:`specialize`)."""
    return len(x) if isinstance(x, tuple) else int(x)


@overload(dim)
def _dim(x):
    if isinstance(x, types.Integer):
        return lambda x: x
    if isinstance(x, types.BaseTuple):
        k = len(x)
        return lambda x: k
    return None


def _workspace_shaped_source():
    env = _sizes_env(2, 1, 2, 3, 2)  # any sizes: each field's number of axes
    args = []
    for k, name in enumerate(_WS_SHAPES):
        axes = np.ndim(np.empty(_shape(name, env), dtype=np.int8))
        shape = ", ".join(f"shapes[{k}, {a}]" for a in range(axes))
        args.append(f"np.zeros(({shape},){', dtype=np.int64' if name in _WS_INT else ''})")
    return ("def workspace_shaped(dims, shapes):\n"
            f"    return Workspace({', '.join(args)}, None, dims)\n")


def field_shapes(ws):
    """The shape of each of ``ws``'s arrays, (fields, 3) int64 in :data:`_WS_SHAPES` order
    (``si`` and ``sb`` empty: :func:`with_plan` gives them): what :func:`workspace_shaped`
    allocates again."""
    out = np.zeros((len(_WS_SHAPES), 3), dtype=np.int64)
    for k, name in enumerate(_WS_SHAPES):
        if name not in ("si", "sb"):
            a = getattr(ws, name)
            out[k, :a.ndim] = a.shape
    return out


_scope = dict(np=np, Workspace=Workspace)
exec(_workspace_shaped_source(), _scope)  # noqa: S102 - generated from the table above
# not cached itself (generated source has no file): it is compiled into the ensembles' members,
# whose cache holds it
workspace_shaped = nb.njit(nogil=True, error_model="numpy", boundscheck=False)(
    _scope["workspace_shaped"])
workspace_shaped.__doc__ = """A workspace of the sizes ``dims`` whose arrays have the shapes
``shapes`` (:func:`field_shapes` of a single run's workspace, its full Newton allocated):
the fields that run leaves empty stay empty, and a full Newton assembled into band storage
keeps its band-shaped ``A`` (its plan, with the map, goes with it). What a member of an
ensemble allocates inside the parallel loop."""


@hot_inline
def sizes(ws):
    """``(n, m, s, r, J)`` of the workspace ``ws``: run-time integers in the generic kernels,
    compile-time constants in the size-specialized ones (:func:`specialize`)."""
    d = ws.dims
    return dim(d[0]), dim(d[1]), dim(d[2]), dim(d[3]), dim(d[4])


def size_markers(dims):
    """``(n, m, s, r, J)`` as size markers: each size ``k`` a tuple of ``k`` ``None``."""
    return tuple((None,) * int(k) for k in dims)


def specialize(ws):
    """The workspace ``ws`` with its sizes turned into compile-time constants.

    A kernel typed with it compiles once for these sizes ``(n, m, s, r, J)`` (cached on disk
    like the generic ones), with every loop over coordinates, constraints, control points and
    quadrature points of known length, which LLVM unrolls (no loop set-up, vector-remainder
    code or run-time alias checks around loops of length 2–4). The step's sized stages are
    compiled for it (:func:`.step.step_kernel`, ``sized``); the arithmetic and its order are
    unchanged, so the trajectory equals the generic kernel's bit for bit. The sizes are the
    workspace's last field, so the generic and the sized workspace share the layout of all
    the others: the sized code reads the sizes from its type, never from memory."""
    return ws._replace(dims=size_markers(ws.dims))
