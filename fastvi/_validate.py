"""Argument validation shared by every public entry point.

Each validator returns the cleaned value; each message names the argument in backticks,
states the rule, and shows the value received.
"""

from __future__ import annotations

import difflib
import math
import warnings

import numpy as np

from .tables import Method, method as _method

#: |g(q0)| (relative to the size of q0) above which initial data are rejected, not projected.
CONSISTENCY_TOL = 1e-6
#: below this the projection of initial data is round-off and happens silently.
SILENT_PROJECTION = 1e-12
#: Newton tolerance on the scaled increment of the control points (see fastvi.integrate).
DEFAULT_TOL = 1e-14
DEFAULT_MAX_ITER = 30

_EXAMPLE_NAMES = [f"P{s}L-Q{r}{q}{v}" for s in range(1, 7) for r in range(1, 9) for q in "GL"
                  for v in ("", "-NE-CE", "-NL-CN", "-NL-CE")]


def vector(x, name: str, n: int) -> np.ndarray:
    """A finite float64 vector of length ``n``."""
    try:
        arr = np.asarray(x)
    except Exception:  # noqa: BLE001 - anything numpy cannot read
        raise TypeError(f"`{name}` must be an array of {n} floats, got {type(x).__name__}") from None
    if arr.dtype.kind not in "fiu" or arr.dtype == bool:
        raise TypeError(f"`{name}` must be an array of real numbers, got dtype {arr.dtype}")
    if arr.shape != (n,):
        raise ValueError(f"`{name}` must have shape ({n},), got {arr.shape}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}` must be finite, got {arr}")
    return arr


def params(p, model) -> np.ndarray:
    if p is None:
        return model.params
    arr = vector(p, "params", model.params.shape[0])
    _warn_moved_masses(arr, model)
    return arr


def _warn_moved_masses(P, model) -> None:
    """Warn where the parameters ``P`` ((k,), or (N, k) by member) move an entry the model's
    constant mass matrix was built from (:attr:`fastvi.Model.mass_params`)."""
    moved = [l for l in getattr(model, "mass_params", ()) if np.any(P[..., l] != model.params[l])]
    if moved:
        warnings.warn(mass_params_warning(moved, "`params` changes"), UserWarning, stacklevel=4)


def mass_params_warning(moved, what: str) -> str:
    """Why a change of (or a derivative by) the parameters ``moved`` that built a constant
    mass matrix reaches only the model's callbacks."""
    names = ", ".join(f"params[{l}]" for l in moved)
    return (f"{what} {names}, from which the model's constant mass matrix was built "
            f"(`Model.mass_params`): that matrix is data of the model and does not follow "
            f"`params`, so only the potential and the other callbacks see the new value. To "
            f"change a mass, build the model again (a scene: e.g. fastvi.scenes.pendulum(m=2.0))")


def step_size(h) -> float:
    """The step ``h``: a positive, finite span of time (:func:`duration`)."""
    return duration(h, "h")


def duration(x, name: str) -> float:
    """A positive, finite span of time named ``name`` in the error."""
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise TypeError(f"`{name}` must be a float (seconds), got {x!r}")
    x = float(x)
    if not (x > 0.0 and math.isfinite(x)):
        raise ValueError(f"`{name}` must be positive and finite, got {x}")
    return x


def flag(x, name: str) -> bool:
    """A True/False option, named in the error."""
    if not isinstance(x, (bool, np.bool_)):
        raise TypeError(f"`{name}` must be True or False, got {x!r}")
    return bool(x)


def optional_flag(x, name: str):
    """None (let fastvi choose), True or False, named in the error."""
    if x is None:
        return None
    if not isinstance(x, (bool, np.bool_)):
        raise TypeError(f"`{name}` must be None, True or False, got {x!r}")
    return bool(x)


def count(x, name: str, least: int) -> int:
    """An integer ``>= least`` named ``name`` in the error (an integral float is accepted)."""
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)):
        if isinstance(x, (float, np.floating)) and float(x).is_integer():
            x = int(x)
        else:
            raise TypeError(f"`{name}` must be an integer, got {x!r}")
    if x < least:
        raise ValueError(f"`{name}` must be >= {least}, got {x}")
    return int(x)


def conservative(model, name: str) -> None:
    """Refuse a model with forces or time for a baseline that integrates only conservative,
    autonomous models."""
    if model.timed:
        raise ValueError(f"the `{name}` baseline integrates conservative, autonomous models only; "
                         f"model {model.name!r} has a force or time-dependent callbacks: use "
                         "fastvi.integrate")


def start_time(t0) -> float:
    """The start time ``t0``: a finite float."""
    if isinstance(t0, bool) or not isinstance(t0, (int, float, np.integer, np.floating)):
        raise TypeError(f"`t0` must be a float, got {t0!r}")
    t0 = float(t0)
    if not math.isfinite(t0):
        raise ValueError(f"`t0` must be finite, got {t0}")
    return t0


def end_time(t_end, t0: float) -> float:
    """The final time ``t_end``: a finite float after ``t0``."""
    if isinstance(t_end, bool) or not isinstance(t_end, (int, float, np.integer, np.floating)):
        raise TypeError(f"`t_end` must be a float, got {t_end!r}")
    t_end = float(t_end)
    if not (t_end > t0 and math.isfinite(t_end)):
        after = "positive" if t0 == 0.0 else f"after `t0` = {t0:g}"
        raise ValueError(f"`t_end` must be finite and {after}, got {t_end}")
    return t_end


def step_count(h: float, t_end, n_steps, t0: float = 0.0) -> int:
    """Exactly one of ``t_end`` and ``n_steps``; ``t_end − t0`` must be a multiple of ``h``."""
    if (t_end is None) == (n_steps is None):
        raise ValueError("give exactly one of `t_end` and `n_steps`"
                         f" (got t_end={t_end!r}, n_steps={n_steps!r})")
    if n_steps is not None:
        return count(n_steps, "n_steps", 1)
    span = end_time(t_end, t0) - t0
    k = round(span / h)
    if k < 1 or abs(k * h - span) > 1e-9 * span:
        start = "" if t0 == 0.0 else " − t0"
        raise ValueError(
            f"`t_end`{start} = {span} is not a whole number of steps of `h` = {h} "
            f"(({'t_end' + start})/h = {span / h:.6g}); fixed-step integration needs "
            f"t_end = {'t0 + ' if t0 else ''}n·h: pass `n_steps` or choose h = {span / max(1, k):.6g}"
        )
    return int(k)


def save_every(k) -> int:
    return count(k, "save_every", 1)


def tolerance(tol) -> float:
    if isinstance(tol, bool) or not isinstance(tol, (int, float, np.integer, np.floating)):
        raise TypeError(f"`tol` must be a float, got {tol!r}")
    tol = float(tol)
    if not (0.0 < tol < 1e-2):
        raise ValueError(f"`tol` must be in (0, 1e-2), got {tol}")
    return tol


def max_iter(k) -> int:
    return count(k, "max_iter", 1)


def newton(mode) -> int:
    """The Newton variant by name (see :func:`fastvi.integrate`), as the kernels' integer."""
    from .kernels.layout import NEWTON_MODES

    if not isinstance(mode, str) or mode not in NEWTON_MODES:
        raise ValueError(f"`newton` must be one of {sorted(NEWTON_MODES)}, got {mode!r}")
    return NEWTON_MODES[mode]


def solver(value) -> str:
    """One of :data:`fastvi.structure.SOLVERS`, named in the error otherwise."""
    from .structure import SOLVERS

    if not isinstance(value, str) or value not in SOLVERS:
        raise ValueError(f"`solver` must be one of {', '.join(map(repr, SOLVERS))}, got {value!r}")
    return value


def newton_options(tol_, max_iter_, mode):
    """The validated :class:`~fastvi.kernels.layout.NewtonOptions` of a run."""
    from .kernels.layout import NewtonOptions

    return NewtonOptions(tolerance(tol_), max_iter(max_iter_), newton(mode))


def adaptive(Kr, model, t_end, n_steps, t0: float, *, events, dense_output, recover) -> float | None:
    """The energy scale ``K_r`` of ``integrate(..., adaptive=K_r)`` (None: fixed steps), and
    what an adaptive run needs: ``t_end``, a conservative autonomous model, no events, dense
    output or recovery."""
    if Kr is None:
        return None
    if isinstance(Kr, bool) or not isinstance(Kr, (int, float, np.integer, np.floating)):
        raise TypeError(f"`adaptive` must be None or an energy scale K_r > 0 (a float), got {Kr!r}")
    Kr = float(Kr)
    if not (Kr > 0.0 and math.isfinite(Kr)):
        raise ValueError(f"`adaptive` (the energy scale K_r of the step density) must be positive "
                         f"and finite, got {Kr}; pass None for fixed steps")
    if n_steps is not None or t_end is None:
        raise ValueError("adaptive steps need `t_end` (the number of steps is not known in "
                         "advance), not `n_steps`")
    start_time(t_end)
    if not float(t_end) > t0:
        raise ValueError(f"`t_end` must be after `t0` = {t0:g}, got {t_end}")
    if model.timed:
        raise ValueError(f"adaptive steps follow the kinetic energy on the energy shell, which model "
                         f"{model.name!r} (with a force or time-dependent callbacks) does not keep: "
                         "use fixed steps")
    for name, on in (("events", events is not None), ("dense_output", bool(dense_output)),
                     ("recover", bool(recover))):
        if on:
            raise ValueError(f"`adaptive` cannot be combined with `{name}` (it assumes steps of "
                             "one length); use fixed steps")
    return Kr


def recover(k) -> int:
    """Number of halvings for the opt-in failed-step recovery (0 = off, at most 10)."""
    k = count(k, "recover", 0)
    if k > 10:
        raise ValueError(f"`recover` must be at most 10 halvings (1024 substeps), got {k}")
    return k


def method(name) -> Method:
    try:
        return _method(name)
    except ValueError as exc:
        if isinstance(name, str):
            close = difflib.get_close_matches(name.strip().upper(), _EXAMPLE_NAMES, n=3, cutoff=0.6)
            if close:
                raise ValueError(f"{exc}. Did you mean: {', '.join(close)}?") from None
        raise


def _min_norm_solve(S: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least-squares solve of the symmetric ``S y = b``: near a singular position of the
    constraints ``G M⁻¹ Gᵀ`` is ill-conditioned and a plain solve would refuse or blow up."""
    return np.linalg.lstsq(S, b, rcond=1e-15)[0]


def mass_metric(M: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``M``, or for a singular ``M`` the definite ``M + Gᵀ W G`` that the kernels invert in
    its place (:func:`fastvi.kernels.linalg.augmented_mass`): equal to ``M`` on ``ker G``,
    so a projection onto the constraints in this metric is the one in the metric of ``M``."""
    try:
        np.linalg.cholesky(0.5 * (M + M.T))
        return M
    except np.linalg.LinAlgError:
        from .kernels.linalg import augmented_mass

        out = np.empty_like(M)
        augmented_mass(np.ascontiguousarray(M), np.ascontiguousarray(G), out, M.shape[0], G.shape[0])
        return out


def tangent_definite(M: np.ndarray, G: np.ndarray, where: str = "`q0`") -> None:
    """Refuse a singular mass matrix that is not definite on the tangent space ``ker G``:
    there the motion would not be determined. Names the coordinates of the failing direction."""
    _, sv, Vt = np.linalg.svd(G)
    rank = int(np.sum(sv > 1e-12 * max(float(sv[0]), 1e-300)))
    Z = Vt[rank:].T
    if Z.shape[1] == 0:
        return
    lam, y = np.linalg.eigh(Z.T @ M @ Z)
    scale = max(float(np.max(np.abs(np.diag(M)))), 1e-300)
    if lam[0] > 1e-10 * scale:
        return
    u = Z @ y[:, 0]
    coords = np.nonzero(np.abs(u) > 0.1 * np.abs(u).max())[0]
    raise ValueError(
        f"the mass matrix is singular on the tangent space of the constraints at {where}: the "
        f"motion along {u[coords].round(3).tolist()} in coordinates {[f'q[{i}]' for i in coords]} "
        f"has no inertia (Zᵀ M Z has eigenvalue {lam[0]:.3g}): give those coordinates mass, or "
        "add the constraints that determine them")


def _nearest_on_constraints(model, q0, g, G, metric, prm, t0, scale):
    """``(q*, G(q*))``: the point of ``g(t0, q) = 0`` nearest ``q0`` in the metric ``M̄0`` of
    ``q0``, i.e. the solution of ``M̄0 (q − q0) + G(q)ᵀ μ = 0``, ``g(q) = 0``.

    A projection with this definition has a derivative (the implicit function theorem on
    those equations, :func:`fastvi._discrete.initial_tangent`); the iteration that reaches
    it does not matter. Each iteration solves the equations linearised with ``∇²g`` left
    out: ``q ← q0 − W S⁻¹ (g(q) − G (q − q0))``, ``W = M̄0⁻¹ G(q)ᵀ``, ``S = G W``. Its
    first step is the Gauss–Newton step from ``q0``; it then converges at a rate of the
    order of ``|μ|`` (the offset) times the constraints' curvature, a few iterations for
    offsets below ``CONSISTENCY_TOL``."""
    q = q0
    for _ in range(20):
        W = np.linalg.solve(metric, G.T)
        q_next = q0 - W @ _min_norm_solve(G @ W, g - G @ (q - q0))
        step = float(np.max(np.abs(q_next - q)))
        q = q_next
        g = model.constraint_value(q, prm, t0)
        G = model.constraint_jacobian_value(q, prm, t0)
        if np.max(np.abs(g)) <= 4e-16 * scale and step <= 4e-16 * scale:
            break
    return q, G


def initial_state(model, q0: np.ndarray, v0: np.ndarray, prm: np.ndarray, t0: float = 0.0):
    """Check M(q0), G(q0), and project (q0, v0) onto ``g(t0, q) = 0``, ``G v + g_t = 0``.

    Data off the constraint manifold by more than ``CONSISTENCY_TOL`` (relative) raise;
    smaller violations are projected, with a warning when the move exceeds round-off:
    ``q0`` to the nearest point of ``g = 0`` in the metric ``M̄`` of ``q0``
    (:func:`_nearest_on_constraints`), then ``v0`` to the nearest velocity with
    ``G v + g_t = 0`` there, in the metric there.
    """
    M = model.mass_matrix(q0, prm)
    if not np.all(np.isfinite(M)):
        raise ValueError(f"the mass matrix at `q0` is not finite: {M}")
    try:
        if not model.mass_singular:  # a singular constant M is checked on ker G below
            np.linalg.cholesky(0.5 * (M + M.T))
        # np.allclose(M, M.T, rtol=1e-10, atol=1e-14 max|M|), at a fifth of its cost
        absM = np.abs(M)
        sym = bool(np.all(np.abs(M - M.T) <= 1e-14 * absM.max() + 1e-10 * absM.T))
    except np.linalg.LinAlgError:
        sym = False
    if not sym:
        raise ValueError(f"the mass matrix at `q0` must be symmetric positive definite, got {M}")
    if not np.isfinite(model.potential_energy(q0, prm, t0)):
        raise ValueError("the potential energy at `q0` is not finite (callback `potential`)")
    if model.m == 0:
        return q0, v0
    scale = max(1.0, float(np.max(np.abs(q0))))
    at = f"(t0 = {t0:g}, q0)" if model.time_dependent else "`q0`"
    g = model.constraint_value(q0, prm, t0)
    if not np.all(np.isfinite(g)):
        raise ValueError(f"callback `constraint` returned non-finite values at {at}: {g}")
    G = model.constraint_jacobian_value(q0, prm, t0)
    if not np.all(np.isfinite(G)):
        raise ValueError(f"callback `constraint_jacobian` returned non-finite values at {at}: {G}")
    gmax = float(np.max(np.abs(g)))
    if gmax > CONSISTENCY_TOL * scale:
        gname = f"g(t0, q0) (t0 = {t0:g})" if model.time_dependent else "g(q0)"
        raise ValueError(
            f"`q0` violates the constraints: max|{gname}| = {gmax:.3e} > {CONSISTENCY_TOL:.0e}·{scale:g}; "
            "start from a consistent state: `fastvi.consistent_state(model, q0, v0, fixed=...)` builds one "
            "from this guess (keeping the coordinates you list in `fixed`), and the scenes' "
            "`initial_state` helpers give one from natural coordinates"
        )
    sv = np.linalg.svd(G, compute_uv=False)
    if sv.size < model.m or sv[-1] <= 1e-14 * max(sv[0], 1e-300):
        raise ValueError(
            f"the constraint Jacobian at `q0` must have full row rank {model.m}; "
            f"its singular values are {sv}"
        )
    if model.mass_singular:
        tangent_definite(M, G)
    q = q0.copy()
    if gmax > 4e-16 * scale:
        q, G = _nearest_on_constraints(model, q0, g, G, mass_metric(M, G), prm, t0, scale)
        if model.mass_matrix_constant is None:
            M = model.mass_matrix(q, prm)
    moved = float(np.max(np.abs(q - q0)))
    if gmax > SILENT_PROJECTION * scale:
        warnings.warn(f"`q0` was projected onto the constraints (max|g| was {gmax:.2e}; "
                      f"q moved by {moved:.2e})", stacklevel=3)
    Minv_Gt = np.linalg.solve(mass_metric(M, G), G.T)
    gt = model.constraint_time_derivative_value(q, prm, t0)
    gv = G @ v0 + gt
    vscale = max(1.0, float(np.max(np.abs(v0))))
    gvmax = float(np.max(np.abs(gv)))
    if gvmax > CONSISTENCY_TOL * vscale * max(1.0, scale):
        hidden, name = (("G v0 + g_t = 0 at t0", "G v0 + g_t") if model.time_dependent
                        else ("G(q0) v0 = 0", "G v0"))
        raise ValueError(
            f"`v0` violates the hidden constraint {hidden}: max|{name}| = {gvmax:.3e}; "
            "start from a consistent state: `fastvi.consistent_state(model, q0, v0, fixed=..., t=t0)` "
            f"changes the velocities you do not list in `fixed` (least, in the metric of M) so "
            f"that {hidden}"
        )
    v = v0 - Minv_Gt @ _min_norm_solve(G @ Minv_Gt, gv)
    if gvmax > SILENT_PROJECTION * vscale * max(1.0, scale):
        warnings.warn(f"`v0` was projected onto the hidden constraint (max|G v0 + g_t| was {gvmax:.2e}; "
                      f"v moved by {float(np.max(np.abs(v - v0))):.2e})", stacklevel=3)
    return q, v


# ----------------------------------------------------------------------------- ensembles
def member_vectors(x, name: str, n: int) -> np.ndarray:
    """An (N, n) float64 array, N >= 1: one row per ensemble member, each row a :func:`vector`."""
    try:
        arr = np.asarray(x)
    except Exception:  # noqa: BLE001 - anything numpy cannot read
        raise TypeError(f"`{name}` must be an (N, {n}) array of floats, got {type(x).__name__}") from None
    if arr.ndim != 2 or arr.shape[0] < 1 or arr.shape[1] != n:
        raise ValueError(f"`{name}` must have shape (N, {n}) with one row per member (N >= 1), "
                         f"got {arr.shape}")
    out = np.empty(arr.shape, dtype=np.float64)
    for i in range(arr.shape[0]):
        out[i] = vector(arr[i], f"{name}[{i}]", n)
    return out


def member_params(p, model, N: int) -> np.ndarray:
    """Parameters per member, (N, k): None (the model's), one (k,) vector for all, or (N, k)."""
    k = model.params.shape[0]
    if p is None:
        return np.tile(model.params, (N, 1))  # a fresh writable array: kernels see one array type
    arr = np.asarray(p)
    if arr.ndim == 1:
        return np.tile(params(arr, model), (N, 1))
    if arr.ndim != 2 or arr.shape != (N, k):
        raise ValueError(f"`params` must be None, shape ({k},) (shared) or ({N}, {k}) (one row per "
                         f"member), got shape {arr.shape}")
    arr = member_vectors(arr, "params", k)
    _warn_moved_masses(arr, model)
    return arr


def ensemble_save(save):
    """``"final"``, ``"diagnostics"`` or a positive integer stride."""
    if isinstance(save, str):
        if save in ("final", "diagnostics"):
            return save
        raise ValueError(f"`save` must be 'final', 'diagnostics' or a positive integer stride, got {save!r}")
    return count(save, "save", 1)


def threads(t):
    """None (numba's current setting) or a thread count in [1, NUMBA_NUM_THREADS]."""
    if t is None:
        return None
    import numba

    t = count(t, "threads", 1)
    if t > numba.config.NUMBA_NUM_THREADS:
        raise ValueError(
            f"`threads` must be <= {numba.config.NUMBA_NUM_THREADS} (numba's thread pool, set by the "
            f"environment variable NUMBA_NUM_THREADS before numba starts), got {t}"
        )
    return t
