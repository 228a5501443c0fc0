"""Mechanical models as compiled callbacks.

A :class:`Model` turns plain Python functions (numba's nopython subset) into ``numba.cfunc``
callbacks that all share **one signature**, :data:`CALLBACK_SIGNATURE`::

    void cb(float64* q, float64* v, float64* params, float64* out)

``q`` is the configuration (n), ``v`` the second vector argument (a velocity (n) or, for
the constraint Hessian, the impulse vector (m); unused otherwise), ``params`` the flat
parameter vector (k), and ``out`` the output written in place (C order for matrices).
Because every callback has this one type, the kernels take them as first-class function
values and compile once for every model (and are cached on disk).

You never write that signature yourself: pass ordinary functions on arrays and the
``Model`` wraps each in a cfunc, with the array sizes baked in (``numba.carray``). Values
the functions need go in ``params`` rather than in closures, so one compiled model serves
every parameter value (a closure constant is frozen at compile time).

User functions, with ``q, v`` of shape (n,), ``eta`` of shape (m,), ``params`` of shape (k,):

==========================  =============================================  ==============
argument                    function                                        ``out`` shape
==========================  =============================================  ==============
``mass``                    ``mass(q, params, out)``: M(q), or an array     (n, n)
``potential``               ``potential(q, params) -> float``: V(q)         --
``potential_grad``          ``potential_grad(q, params, out)``: ∇V          (n,)
``kinetic_grad``            ``kinetic_grad(q, v, params, out)``: ∂T/∂q      (n,)
``constraint``              ``constraint(q, params, out)``: g(q)            (m,)
``constraint_jacobian``     ``constraint_jacobian(q, params, out)``: G      (m, n)
``potential_hessian``       ``potential_hessian(q, params, out)``: ∇²V      (n, n)
``constraint_hessian``      ``constraint_hessian(q, eta, params, out)``:    (n, n)
                            ``Σ_a eta_a ∇²g_a(q)``
``kinetic_hessian``         ``kinetic_hessian(q, v, params, out)``: ∂²T/∂q² (n, n)
``momentum_jacobian``       ``momentum_jacobian(q, v, params, out)``:       (n, n)
                            ``∂(M(q) v)/∂q``, entry [a, b] = ∂(Mv)_a/∂q_b
==========================  =============================================  ==============

The last four are optional: a missing one is replaced by central finite differences of the
first derivative it differentiates (inside the kernel, without allocation). They only enter
the Newton matrix, so they change the Newton convergence rate, not the solution.

Forces and time (optional; time always first):

===============================  ==========================================  ==============
argument                         function                                     ``out`` shape
===============================  ==========================================  ==============
``force``                        ``force(t, q, v, params, out)``: F(t, q, v)  (n,)
``force_jacobian_q``             ``(t, q, v, params, out)``: ∂F/∂q            (n, n)
``force_jacobian_v``             ``(t, q, v, params, out)``: ∂F/∂v            (n, n)
``constraint_time_derivative``   ``(t, q, params, out)``: ∂g/∂t               (m,)
===============================  ==========================================  ==============

With ``time_dependent=True`` the potential and constraint callbacks of the first table take
``t`` first as well (``potential(t, q, params)``, ``constraint(t, q, params, out)``, …). The
compiled signature stays the one above: the time travels in a hidden entry ``params[k]``
after the user's ``k`` parameters, written by the kernels before each evaluation and read by
the wrappers (:meth:`Model.kernel_params`); the other callbacks never look at it.

Derivatives by the parameters θ = ``params`` (optional; ``Model(param_derivatives={slot: fn
or 0})``, for the sensitivities and the adjoint):

===========================  ==============================================  ================
slot (:data:`PARAM_SLOTS`)   function: the arguments of that callback        ``out`` shape
===========================  ==============================================  ================
``mass``                     ``(q, params, out)``: ``out[l] = ∂M/∂θ_l``      (k, n, n)
``kinetic_grad``             ``(q, v, params, out)``: ``∂(∂T/∂q)/∂θ_l``      (k, n)
``potential_grad``           ``(q, params, out)``: ``∂(∇V)/∂θ_l``            (k, n)
``constraint``               ``(q, params, out)``: ``∂g/∂θ_l``               (k, m)
``constraint_jacobian``      ``(q, params, out)``: ``∂G/∂θ_l``               (k, m, n)
``force``                    ``(t, q, v, params, out)``: ``∂F/∂θ_l``         (k, n)
===========================  ==============================================  ================

``0`` declares a callback independent of θ; ``Model(param_patterns=...)`` declares where a
derivative of ``kinetic_grad``, ``potential_grad``, ``force`` or ``constraint`` may be
non-zero, and such a derivative writes only those entries. When they cover every callback θ enters
(:attr:`Model.param_derivatives_exact`), the linearised step uses them instead of
five-point differences of the whole step in each θ_l; they are compiled on first use
(:meth:`Model.param_derivative_data`), never by a plain integration.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import types as types_module
import warnings
from collections.abc import Mapping
from typing import Callable

import numba as nb
import numpy as np
from numba import carray, types

from ._numba import njit, ptr
from .kernels import layout as lay
from .kernels.layout import SECOND as _SECOND
from .kernels.layout import FD_T, FD_T_POINTS, PARAM_SLOTS, PATTERNED_PARAM_SLOTS, SLOTS

__all__ = ["Model", "CALLBACK_SIGNATURE", "SLOTS", "PARAM_SLOTS"]


#: The one signature of every compiled model callback: ``void(q*, v*, params*, out*)``.
CALLBACK_SIGNATURE = types.void(
    types.CPointer(types.float64),
    types.CPointer(types.float64),
    types.CPointer(types.float64),
    types.CPointer(types.float64),
)

@nb.cfunc(CALLBACK_SIGNATURE, cache=True)
def _absent(q, v, params, out):  # pragma: no cover - never called: flags skip it
    pass


@njit
def call_callback(fn, q, v, params, out):
    """Evaluate one compiled callback from Python (validation, diagnostics, baselines)."""
    fn(ptr(q), ptr(v), ptr(params), ptr(out))


#: the callback signature as a ctypes prototype: Python calls a callback by its address in
#: ≈ 4 µs, where numba's dispatcher of :func:`call_callback` re-types the callback argument
#: on every call (≈ 16 µs; a dozen evaluations in every ``integrate`` call's validation)
_DIRECT = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                           ctypes.c_void_p)


def direct_callback(cf):
    """The compiled callback ``cf`` (a ``numba.cfunc`` of :data:`CALLBACK_SIGNATURE`) as a
    ctypes function of the four addresses ``(q, v, params, out)``: a call from Python costs
    a few µs instead of :func:`call_callback`'s re-typing."""
    return _DIRECT(cf.address)


# --------------------------------------------------------------------------- callback compile
# Compiling a callback costs ~0.1 s (numba typing + LLVM), several per model: ≈ 0.5–1 s per
# Model and per process. Two caches cut it: compiled callbacks are reused within the process
# for the same function object and sizes (_CALLBACKS), and the wrappers of importable
# functions are cached on disk by numba (the cache key includes a fingerprint of the
# function's source, see _fingerprint). The user's function itself is jitted once per process
# (_JITTED): the sizes are baked into the wrapper only, so a chain of 8 links and one of 64
# share the compiled `constraint` and compile only their thin wrappers.

#: (kind, function, n, m, k) -> cfunc, most recent last; bounded so that a loop creating
#: models from fresh lambdas does not keep every compiled module alive.
_CALLBACKS: dict = {}
_CALLBACKS_MAX = 512
#: (function, fingerprint) -> its numba dispatcher, most recent last, bounded like _CALLBACKS;
#: the fingerprint in the key: a constant the function reads, changed, compiles it anew
_JITTED: dict = {}


def _templates(n, m, k, tag):
    """One wrapper per callback kind around the global ``jf`` (the user's jitted function).

    ``jf`` is deliberately a global, not a closure variable: numba keys its on-disk cache
    on the closure's values, and a dispatcher pickles with a per-process id, which would
    make every process miss. The closure holds only the sizes and ``tag`` (the source
    fingerprint), so the key identifies the user's function across processes.

    Kinds ending in ``@t`` take the time first: the kernels pass it in the hidden entry
    ``p[k]`` that follows the user's ``k`` parameters (the user sees ``params`` of length k).
    Kinds ``<slot>/θ`` are the derivatives by the parameters of the callback ``<slot>``
    (``Model(param_derivatives=...)``): the same inputs, ``out`` of shape ``(k,)`` + the
    callback's output shape.
    """
    nn = (n, n)

    def potential(q, v, p, out):
        tag  # noqa: B018 - part of the cache key
        out[0] = jf(carray(q, (n,)), carray(p, (k,)))  # noqa: F821

    def matrix(q, v, p, out):  # mass, potential_hessian
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(p, (k,)), carray(out, nn))  # noqa: F821

    def potential_grad(q, v, p, out):
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(p, (k,)), carray(out, (n,)))  # noqa: F821

    def constraint(q, v, p, out):
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(p, (k,)), carray(out, (m,)))  # noqa: F821

    def constraint_jacobian(q, v, p, out):
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(p, (k,)), carray(out, (m, n)))  # noqa: F821

    def constraint_hessian(q, v, p, out):
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(v, (m,)), carray(p, (k,)), carray(out, nn))  # noqa: F821

    def kinetic_grad(q, v, p, out):
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(v, (n,)), carray(p, (k,)), carray(out, (n,)))  # noqa: F821

    def velocity_matrix(q, v, p, out):  # kinetic_hessian, momentum_jacobian
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(v, (n,)), carray(p, (k,)), carray(out, nn))  # noqa: F821

    # ---- time first: t is the hidden entry p[k]
    def potential_t(q, v, p, out):
        tag  # noqa: B018
        out[0] = jf(p[k], carray(q, (n,)), carray(p, (k,)))  # noqa: F821

    def matrix_t(q, v, p, out):  # potential_hessian
        tag  # noqa: B018
        jf(p[k], carray(q, (n,)), carray(p, (k,)), carray(out, nn))  # noqa: F821

    def potential_grad_t(q, v, p, out):
        tag  # noqa: B018
        jf(p[k], carray(q, (n,)), carray(p, (k,)), carray(out, (n,)))  # noqa: F821

    def constraint_t(q, v, p, out):  # constraint, constraint_time_derivative
        tag  # noqa: B018
        jf(p[k], carray(q, (n,)), carray(p, (k,)), carray(out, (m,)))  # noqa: F821

    def constraint_jacobian_t(q, v, p, out):
        tag  # noqa: B018
        jf(p[k], carray(q, (n,)), carray(p, (k,)), carray(out, (m, n)))  # noqa: F821

    def constraint_hessian_t(q, v, p, out):
        tag  # noqa: B018
        jf(p[k], carray(q, (n,)), carray(v, (m,)), carray(p, (k,)), carray(out, nn))  # noqa: F821

    def force_t(q, v, p, out):
        tag  # noqa: B018
        jf(p[k], carray(q, (n,)), carray(v, (n,)), carray(p, (k,)), carray(out, (n,)))  # noqa: F821

    def force_matrix_t(q, v, p, out):  # force_jacobian_q, force_jacobian_v
        tag  # noqa: B018
        jf(p[k], carray(q, (n,)), carray(v, (n,)), carray(p, (k,)), carray(out, nn))  # noqa: F821

    def event_t(q, v, p, out):  # an event function of fastvi.integrate(events=...)
        tag  # noqa: B018
        out[0] = jf(p[k], carray(q, (n,)), carray(v, (n,)), carray(p, (k,)))  # noqa: F821

    # ---- derivatives by the parameters: out[l] = ∂f/∂θ_l, shape (k,) + the shape of f
    kn, km, kmn, knn = (k, n), (k, m), (k, m, n), (k, n, n)

    def mass_p(q, v, p, out):
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(p, (k,)), carray(out, knn))  # noqa: F821

    def kinetic_grad_p(q, v, p, out):
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(v, (n,)), carray(p, (k,)), carray(out, kn))  # noqa: F821

    def potential_grad_p(q, v, p, out):
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(p, (k,)), carray(out, kn))  # noqa: F821

    def potential_grad_p_t(q, v, p, out):
        tag  # noqa: B018
        jf(p[k], carray(q, (n,)), carray(p, (k,)), carray(out, kn))  # noqa: F821

    def constraint_p(q, v, p, out):
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(p, (k,)), carray(out, km))  # noqa: F821

    def constraint_jacobian_p(q, v, p, out):
        tag  # noqa: B018
        jf(carray(q, (n,)), carray(p, (k,)), carray(out, kmn))  # noqa: F821

    def force_p_t(q, v, p, out):
        tag  # noqa: B018
        jf(p[k], carray(q, (n,)), carray(v, (n,)), carray(p, (k,)), carray(out, kn))  # noqa: F821

    return {"potential": potential, "mass": matrix, "potential_hessian": matrix,
            "potential_grad": potential_grad, "constraint": constraint,
            "constraint_jacobian": constraint_jacobian, "constraint_hessian": constraint_hessian,
            "kinetic_grad": kinetic_grad, "kinetic_hessian": velocity_matrix,
            "momentum_jacobian": velocity_matrix,
            "potential@t": potential_t, "potential_hessian@t": matrix_t,
            "potential_grad@t": potential_grad_t, "constraint@t": constraint_t,
            "constraint_jacobian@t": constraint_jacobian_t,
            "constraint_hessian@t": constraint_hessian_t,
            "constraint_time_derivative@t": constraint_t,
            "force@t": force_t, "force_jacobian_q@t": force_matrix_t,
            "force_jacobian_v@t": force_matrix_t, "event@t": event_t,
            "mass/θ": mass_p, "kinetic_grad/θ": kinetic_grad_p,
            "potential_grad/θ": potential_grad_p, "potential_grad/θ@t": potential_grad_p_t,
            "constraint/θ": constraint_p, "constraint_jacobian/θ": constraint_jacobian_p,
            "force/θ@t": force_p_t}


#: callbacks that take the time first when the model is ``time_dependent``
_TIME_AWARE = ("potential", "potential_grad", "potential_hessian", "constraint",
               "constraint_jacobian", "constraint_hessian")
#: callbacks that always take the time first
_ALWAYS_TIMED = ("force", "force_jacobian_q", "force_jacobian_v", "constraint_time_derivative")


def _source_digest(path: str, memo: dict) -> bytes:
    if path not in memo:
        try:
            with open(path, "rb") as f:
                memo[path] = hashlib.sha256(f.read()).digest()
        except OSError:
            memo[path] = b""
    return memo[path]


def _fingerprint(fn) -> int | None:
    """A 62-bit fingerprint of ``fn``'s compiled meaning, or None if it cannot be cached.

    It hashes the source files of ``fn`` and of the functions, dispatchers and modules its
    code names (recursively), the values of the plain constants it reads from globals, and
    the jit options. Functions without a source file (interactive sessions, ``python -c``),
    closures and lambdas are not cached on disk: their meaning is not in a file.
    """
    py = getattr(fn, "py_func", fn)
    code = getattr(py, "__code__", None)
    if code is None or py.__closure__ or "<" in getattr(py, "__qualname__", "<"):
        return None
    if not os.path.isfile(code.co_filename):
        return None
    h = hashlib.sha256()
    h.update(repr(sorted(getattr(fn, "targetoptions", {}).items())).encode())
    memo: dict = {}
    seen = set()

    def visit(f):
        f = getattr(f, "py_func", f)
        c = getattr(f, "__code__", None)
        if c is None or id(f) in seen:
            return
        seen.add(id(f))
        h.update(f"{f.__module__}.{f.__qualname__}".encode())
        h.update(_source_digest(c.co_filename, memo))
        h.update(c.co_code)
        g = getattr(f, "__globals__", {})
        codes = [c] + [x for x in c.co_consts if hasattr(x, "co_names")]
        for cc in codes:
            for name in cc.co_names:
                value = g.get(name)
                if value is None:
                    continue
                if isinstance(value, (int, float, complex, bool, str, bytes, tuple)):
                    h.update(f"{name}={value!r}".encode())
                elif isinstance(value, np.ndarray):
                    h.update(name.encode() + value.tobytes())
                elif isinstance(value, types_module.ModuleType):
                    h.update(_source_digest(getattr(value, "__file__", None) or "", memo))
                elif callable(value):
                    visit(value)

    visit(py)
    return int.from_bytes(h.digest()[:8], "little") >> 2


def _wrap(kind: str, fn: Callable, n: int, m: int, k: int):
    """The cfunc of :data:`CALLBACK_SIGNATURE` for ``fn`` (sizes baked in), compiled once.

    Reused for the same function object and sizes within the process; loaded from numba's
    on-disk cache when ``fn`` lives in a source file (see :func:`_fingerprint`).
    """
    try:
        key = (kind, fn, n, m, k)
        cached = _CALLBACKS.pop(key, None)
    except TypeError:  # an unhashable callable object: compile every time
        key, cached = None, None
    if cached is None:
        cached = _compile_callback(kind, fn, n, m, k)
    if key is not None:
        _CALLBACKS[key] = cached  # re-inserted: most recently used last
        while len(_CALLBACKS) > _CALLBACKS_MAX:
            del _CALLBACKS[next(iter(_CALLBACKS))]
    return cached


def _wrap_all(slots, functions: dict, kind: Callable, n: int, m: int, k: int) -> tuple:
    """The cfuncs of ``slots`` in order: ``functions[slot]`` wrapped as the template
    ``kind(slot)``, the no-op :func:`_absent` where ``functions`` has none."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", nb.NumbaExperimentalFeatureWarning)
        return tuple(_wrap(kind(slot), functions[slot], n, m, k) if slot in functions else _absent
                     for slot in slots)


def _jitted(fn: Callable, tag):
    """``fn`` as a numba dispatcher, one per function object, fingerprint and process."""
    if isinstance(fn, nb.core.dispatcher.Dispatcher):
        return fn
    key = (fn, tag)
    try:
        jf = _JITTED.pop(key, None)
    except TypeError:  # an unhashable callable object
        return nb.njit(fn)
    if jf is None:
        jf = nb.njit(fn)
    _JITTED[key] = jf
    while len(_JITTED) > _CALLBACKS_MAX:
        del _JITTED[next(iter(_JITTED))]
    return jf


def _compile_callback(kind: str, fn: Callable, n: int, m: int, k: int):
    tag = _fingerprint(fn)
    jf = _jitted(fn, tag)
    template = _templates(n, m, k, 0 if tag is None else tag)[kind]
    # __name__: numba rebuilds a cached function's environment by importing that module
    namespace = {"__name__": __name__, "jf": jf, "carray": carray}
    cb = types_module.FunctionType(template.__code__, namespace,
                                   template.__name__, None, template.__closure__)
    try:
        return nb.cfunc(CALLBACK_SIGNATURE, cache=tag is not None)(cb)
    except Exception as exc:  # numba raises many types (TypingError, UnsupportedBytecodeError, …)
        name = getattr(getattr(fn, "py_func", fn), "__qualname__", repr(fn))
        kind = kind.split("@")[0]
        lines = []
        for ln in str(exc).splitlines():
            if __file__ in ln or os.path.basename(__file__) + '"' in ln:
                break  # from here on numba describes fastvi's wrapper, not the user's code
            if ln.strip() and (not lines or ln != lines[-1]):
                lines.append(ln)
        detail = "\n".join("    " + ln for ln in lines[:12])
        raise TypeError(
            f"callback `{kind}` (function `{name}`) could not be compiled by numba in nopython "
            f"mode. Everything a callback calls must be compiled too: decorate helper functions "
            f"with `@numba.njit`, and use only numba's subset of Python and NumPy (no f-string "
            f"format specs, no Python objects); the documented signature is in "
            f"`fastvi.model`. numba said ({type(exc).__name__}):\n{detail}"
        ) from None


def _as_int(value, name: str, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"`{name}` must be an integer, got {value!r}")
    if value < least:
        raise ValueError(f"`{name}` must be >= {least}, got {value}")
    return int(value)


def _as_params(params, name: str = "params") -> np.ndarray:
    arr = np.asarray(params, dtype=np.float64) if not isinstance(params, np.ndarray) else params
    if arr.dtype != np.float64:
        try:
            arr = arr.astype(np.float64, casting="same_kind")
        except TypeError:
            raise TypeError(f"`{name}` must be a float64 vector, got dtype {arr.dtype}") from None
    if arr.ndim != 1:
        raise ValueError(f"`{name}` must be a 1-D vector, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}` must be finite, got {arr}")
    return np.ascontiguousarray(arr)


class Model:
    r"""A mechanical system with Lagrangian, constraints and (optionally) forces and time.

    ``L(t, q, v) = ½ vᵀ M(q) v − V(t, q)``, constraints ``g(t, q) = 0``, non-conservative
    forces ``F(t, q, v)``. A conservative, autonomous model (the default) has neither forces nor time: its
    callbacks take no ``t`` and the kernels skip the force and time code entirely.

    Parameters
    ----------
    n : int
        Number of (redundant) coordinates.
    m : int, default 0
        Number of holonomic constraints. ``m = 0`` means an unconstrained model: no
        constraint callbacks, and the kernels skip the constraint rows entirely.
    params : array_like, shape (k,)
        Parameter vector handed to every callback (float64).
    mass : ndarray (n, n) or (n,), or callable
        Constant symmetric positive definite mass matrix, its diagonal as a vector (point
        masses in Cartesian coordinates: ``M = diag(mass)``), or ``mass(q, params, out)``.
        With a constant matrix no kinetic-energy callbacks are called at all; with a
        diagonal one the kernels use ``M v`` and ``M⁻¹`` elementwise (and, in large
        mechanisms, the pattern of ``G`` for the Schur complement and the projection).
        With constraints a constant ``M`` may be only positive semidefinite, as long as
        it is definite on the tangent space of the constraints, ``Zᵀ M Z ≻ 0`` for a basis
        ``Z`` of ``ker G(q)`` (a lamina or a slender rod in director coordinates has a zero
        director inertia): the first integration checks this at ``q0`` and names the
        coordinates where it fails, and the step never inverts ``M`` itself but
        ``M + Gᵀ W G``, which equals ``M`` on ``ker G`` (``docs/method.md``, "Singular mass
        matrices").
    potential, potential_grad : callable
        ``V(q)`` and ``∇V(q)``.
    kinetic_grad : callable, optional
        ``∂T/∂q = ½ vᵀ (∂M/∂q) v``; required when ``mass`` is a function.
    constraint, constraint_jacobian : callable, optional
        ``g(q)`` (m,) and ``G(q) = ∂g/∂q`` (m, n); required when ``m > 0``.
    potential_hessian, constraint_hessian, kinetic_hessian, momentum_jacobian : callable, optional
        Exact second derivatives (see the module docstring). Missing ones are replaced by
        finite differences of the first derivatives. ``potential_hessian=0`` declares the
        potential linear in q, ``∇²V = 0`` (uniform gravity in Cartesian coordinates): the
        kernels then evaluate ``∇V`` once a trajectory instead of at every quadrature
        point of every Newton iteration (0.83–0.89× the time of a double-pendulum step,
        ``docs/decisions/0007-size-specialized-kernels.md``), and Newton's matrix has no
        potential-Hessian block.
        :meth:`check` verifies the declaration (finite differences of ``potential_grad``
        against zero).
    force : callable, optional
        ``force(t, q, v, params, out)`` writes the generalized non-conservative force
        ``F(t, q, v)`` (n): damping, actuation, prescribed loads. It enters the discrete
        Lagrange–d'Alembert principle quadratured by the action's own rule, so a method of
        order 2s stays of order 2s (``docs/custom-model.md``, "Forces and time").
    force_jacobian_q, force_jacobian_v : callable, optional
        ``force_jacobian_q(t, q, v, params, out)``: ``∂F/∂q``, and ``force_jacobian_v``:
        ``∂F/∂v`` (n, n), entry [a, b] = ∂F_a/∂q_b (∂v_b). Finite differences otherwise.
        Like the other second derivatives they only enter Newton's matrix.
        ``force_jacobian_q=0`` declares a force independent of q (viscous damping): the
        Newton matrix then has no ∂F/∂q block, which for a large mechanism saves an
        ``n × n`` output per quadrature point. :meth:`check` verifies it.
    force_jacobian_pattern : array_like, optional
        The entries of ``∂F/∂q`` and ``∂F/∂v`` that may be non-zero: an (n, n) boolean
        array, or a pair ``(rows, cols)`` of index arrays (a damping force's diagonal). The
        kernels zero what they read before each call, so ``force_jacobian_q`` and
        ``force_jacobian_v`` need write **only the entries of the pattern** (every one of
        them) instead of an ``n × n`` output per quadrature point. :meth:`check` names a
        non-zero written outside it.
    time_dependent : bool, default False
        The potential and the constraints depend on time: every potential and constraint
        callback then takes the time first — ``potential(t, q, params)``,
        ``potential_grad(t, q, params, out)``, ``potential_hessian(t, q, params, out)``,
        ``constraint(t, q, params, out)``, ``constraint_jacobian(t, q, params, out)``,
        ``constraint_hessian(t, q, eta, params, out)`` — and constraints may drive the
        system (rheonomic: a prescribed crank angle, a moving support). The mass matrix
        stays a function of ``q`` only.
    constraint_time_derivative : callable, optional
        ``constraint_time_derivative(t, q, params, out)``: ``∂g/∂t`` (m); only with
        ``time_dependent=True``. A central difference in ``t`` of ``constraint`` otherwise.
    constraint_jacobian_pattern : array_like, optional
        The entries of ``G`` that may be non-zero, for large sparse mechanisms: an (m, n)
        boolean array, or a pair ``(rows, cols)`` of index arrays. With a pattern the
        kernels hand ``constraint_jacobian`` an ``out`` that is zero outside it, so the
        callback need write **only the entries of the pattern** (an O(m n) ``out[:, :] = 0``
        per call is what made a 256-link chain's step grow like N^1.4), and the structured
        solves use it instead of detecting it (:mod:`fastvi.structure`). :meth:`check` (and
        the automatic check of the first integration) verifies it: a non-zero written
        outside the pattern, or a derivative ``∂g_a/∂q_b`` that finite differences find
        non-zero where the pattern says zero, is reported naming the entry. It implies the
        pattern of ``Σ_c η_c ∇²g_c``: the entries ``(a, b)`` of two coordinates that share
        a constraint (``∂²g_c/∂q_a∂q_b`` vanishes unless g_c depends on both), which
        ``constraint_hessian`` is handed zeroed and need write alone
        (:attr:`constraint_hessian_pattern`).
    param_derivatives : mapping, optional
        Exact derivatives by the parameters θ = ``params`` of the callbacks θ can enter:
        ``{slot: function or 0}`` with slots from :data:`PARAM_SLOTS` (``"mass"``,
        ``"kinetic_grad"``, ``"potential_grad"``, ``"constraint"``,
        ``"constraint_jacobian"``, ``"force"``). A function takes the arguments of the
        callback of that slot and writes ``out`` of shape ``(k,)`` + that callback's output
        shape, ``out[l] = ∂f/∂θ_l``; ``0`` declares that the callback does not depend on θ.
        Given for every such callback of the model, the linearised step of the
        sensitivities and the adjoint uses them instead of differences in θ
        (``docs/custom-model.md``, "Derivatives by the parameters"). Not for a
        ``time_dependent`` model with constraints.
    param_patterns : mapping, optional
        ``{slot: pattern}``: the entries of a derivative by θ that may be non-zero, for the
        slots whose derivative is an (k, n) or (k, m) array (``"kinetic_grad"``,
        ``"potential_grad"``, ``"force"``, ``"constraint"``) and given as a function in
        ``param_derivatives``. A pattern is a boolean array of that shape or a pair
        ``(l, a)`` of index arrays. The kernels then read only those entries, and the
        function need write **only those** (as with ``constraint_jacobian_pattern``): a
        parameter of a large mechanism usually moves a few coordinates' forces, and the
        dense ``(k, n)`` output per call is what made the adjoint by every parameter of a
        chain cost O(N²) a step. :meth:`check` reports a non-zero written outside it.
    mass_params : sequence of int, optional
        Entries of ``params`` a constant ``mass`` was built from (a scene's masses). The
        constant mass matrix is data of the model: a run's ``params`` do not rebuild it,
        so a run whose ``params`` change one of these entries warns (the new value reaches
        the potential and the other callbacks, not the inertia), and so does a derivative
        that names one in ``param_index`` (it is the derivative of those callbacks alone).
        To change a mass, build the model again (a scene: ``fastvi.scenes.pendulum(m=2.0)``).
    fixed_params : sequence of int, optional
        Entries of ``params`` that are data the callbacks read rather than quantities:
        indices, counts, kinds (a tree's parent of each body, a mechanism's joint table).
        The derivatives by the parameters (:func:`fastvi.sensitivity`,
        :func:`fastvi.adjoint`, :class:`fastvi.TrajectoryFit`) leave them out by default,
        and naming one there is an error: a difference in such an entry changes what the
        model is, not a quantity of it.
    name : str, optional
        A label used in summaries and error messages.

    Attributes
    ----------
    drawing : fastvi.drawing.Drawing or None
        How to draw a configuration, for :meth:`fastvi.Result.animate` (None unless set;
        every scene has one). Not pickled: a scene model is rebuilt with its drawing.
    checked : bool
        True once :meth:`check` (or the automatic check of the first integration) passed;
        :func:`fastvi.integrate` then skips its check. Models built by the library
        (:mod:`fastvi.bodies`) start checked. A model unpickled elsewhere starts unchecked.
    param_derivatives_checked : bool
        True once :meth:`check` compared the derivatives by the parameters
        (``param_derivatives``) with differences and they passed.
    recipe : tuple or None
        ``(scene, kwargs)`` for a model built by a function of :mod:`fastvi.scenes`: how it
        is rebuilt when pickled (None for a model built from user functions).

    Notes
    -----
    The callbacks are compiled on first use (≈ 0.1 s each). A compiled callback is reused
    by every ``Model`` built from the same function object with the same sizes in the
    process, and, for functions defined in a source file, cached on disk by numba, so a
    new process loads it in milliseconds (the cache is invalidated when the file of the
    function, or of the functions and modules its code names, changes). As with
    ``numba.njit``, global values a function reads are frozen when it is compiled: pass
    values that change through ``params``. The integration kernels are compiled once for
    all models and cached on disk.
    """

    def __init__(
        self,
        n: int,
        m: int = 0,
        *,
        params=(),
        mass,
        potential: Callable,
        potential_grad: Callable,
        kinetic_grad: Callable | None = None,
        constraint: Callable | None = None,
        constraint_jacobian: Callable | None = None,
        potential_hessian: Callable | None = None,
        constraint_hessian: Callable | None = None,
        kinetic_hessian: Callable | None = None,
        momentum_jacobian: Callable | None = None,
        force: Callable | None = None,
        force_jacobian_q: Callable | None = None,
        force_jacobian_v: Callable | None = None,
        force_jacobian_pattern=None,
        time_dependent: bool = False,
        constraint_time_derivative: Callable | None = None,
        constraint_jacobian_pattern=None,
        param_derivatives=None,
        param_patterns=None,
        fixed_params=(),
        mass_params=(),
        name: str | None = None,
    ):
        self.n = _as_int(n, "n", 1)
        self.m = _as_int(m, "m", 0)
        self.params = _as_params(params)
        #: entries of ``params`` the derivatives leave out (sorted indices)
        self.fixed_params = _as_fixed(fixed_params, self.params.shape[0])
        #: entries of ``params`` the constant mass matrix was built from (sorted indices)
        self.mass_params = _as_fixed(mass_params, self.params.shape[0], "mass_params")
        self.name = name or "model"
        self.recipe = None  # set by the scenes: pickled as this recipe
        self.drawing = None  # a fastvi.drawing.Drawing (the scenes set one)
        #: ∇²V = 0 was declared (``potential_hessian=0``): ∇V is evaluated once a trajectory
        self.linear_potential = _is_zero(potential_hessian)
        if self.linear_potential:
            potential_hessian = None
        #: ∂F/∂q = 0 was declared (``force_jacobian_q=0``): the force depends on t and v only
        self.force_independent_of_q = _is_zero(force_jacobian_q)
        if self.force_independent_of_q:
            force_jacobian_q = None
        funcs = dict(
            kinetic_grad=kinetic_grad,
            potential=potential,
            potential_grad=potential_grad,
            constraint=constraint,
            constraint_jacobian=constraint_jacobian,
            potential_hessian=potential_hessian,
            constraint_hessian=constraint_hessian,
            kinetic_hessian=kinetic_hessian,
            momentum_jacobian=momentum_jacobian,
            force=force,
            force_jacobian_q=force_jacobian_q,
            force_jacobian_v=force_jacobian_v,
            constraint_time_derivative=constraint_time_derivative,
        )
        if not isinstance(time_dependent, (bool, np.bool_)):
            raise TypeError(f"`time_dependent` must be True or False, got {time_dependent!r}")
        self.time_dependent = bool(time_dependent)
        if force is None:
            if self.force_independent_of_q or force_jacobian_pattern is not None:
                which = "force_jacobian_q=0" if self.force_independent_of_q else "force_jacobian_pattern"
                raise ValueError(f"`{which}` was given without `force`; pass the force itself too")
            for key in ("force_jacobian_q", "force_jacobian_v"):
                if funcs[key] is not None:
                    raise ValueError(f"`{key}` was given without `force`; pass the force itself too")
        if constraint_time_derivative is not None and not self.time_dependent:
            raise ValueError("`constraint_time_derivative` was given but `time_dependent=False`: "
                             "constraints that depend on time need `time_dependent=True` (and then "
                             "every potential and constraint callback takes `t` first)")
        if callable(mass):
            if self.mass_params:
                raise ValueError("`mass_params` names the parameters a constant mass matrix was "
                                 "built from; a mass function reads `params` itself: drop "
                                 "`mass_params`")
            funcs["mass"] = mass
            self.mass_matrix_constant = None
            self.mass_singular = False
            if kinetic_grad is None:
                raise ValueError(
                    "`kinetic_grad` (∂T/∂q) is required when `mass` is a function of q"
                )
        else:
            M = np.array(mass, dtype=np.float64)
            if M.shape == (self.n,):
                M = np.diag(M)
            if M.shape != (self.n, self.n):
                raise ValueError(f"`mass` must be an ({self.n}, {self.n}) array, its diagonal ({self.n},) "
                                 f"or a function, got shape {M.shape}")
            #: M is singular: only definite on the tangent space of the constraints, which
            #: :func:`fastvi._validate.initial_state` checks at ``q0``
            self.mass_singular = _check_mass(M, "mass", self.m)
            self.mass_matrix_constant = M
            for key in ("kinetic_grad", "kinetic_hessian", "momentum_jacobian"):
                if funcs[key] is not None:
                    raise ValueError(f"`{key}` must not be given with a constant mass matrix (it is zero)")
        for key in ("potential", "potential_grad"):
            if not callable(funcs[key]):
                raise TypeError(f"`{key}` must be a function, got {funcs[key]!r}")
        if self.m > 0:
            for key in ("constraint", "constraint_jacobian"):
                if not callable(funcs[key]):
                    raise ValueError(f"`{key}` is required when m = {self.m} > 0")
        else:
            for key in ("constraint", "constraint_jacobian", "constraint_hessian",
                        "constraint_time_derivative"):
                if funcs[key] is not None:
                    raise ValueError(f"`{key}` was given but m = 0; pass the number of constraints `m`")
        for key, fn in funcs.items():
            if fn is not None and not callable(fn):
                hint = ", 0 (∇V does not depend on q)" if key == "potential_hessian" else ""
                raise TypeError(f"`{key}` must be a function{hint} or None, got {fn!r}")
        self._functions = {k: v for k, v in funcs.items() if v is not None}
        if constraint_jacobian_pattern is not None and self.m == 0:
            raise ValueError("`constraint_jacobian_pattern` was given but m = 0: a model without "
                             "constraints has no G")
        self.constraint_jacobian_pattern = _as_pattern(constraint_jacobian_pattern, (self.m, self.n),
                                                       "constraint_jacobian_pattern")
        self.force_jacobian_pattern = _as_pattern(force_jacobian_pattern, (self.n, self.n),
                                                  "force_jacobian_pattern")
        #: the derivatives by θ given as functions, and the slots declared 0
        self._param_functions, self._param_zero = self._param_derivatives(param_derivatives)
        #: {slot: boolean (k,) + output shape}: the entries of a derivative by θ that may be
        #: non-zero (``param_patterns``)
        self.param_patterns = self._param_patterns(param_patterns)
        self._compiled = None
        self._param_data = None
        #: :meth:`check` compared the derivatives by θ with differences, and they passed
        self.param_derivatives_checked = False
        self._mass_arg = mass
        self.checked = False

    def _param_derivatives(self, given):
        """Validate ``param_derivatives``: ``({slot: function}, {slots declared 0})``."""
        name = "param_derivatives"
        if given is None:
            return {}, frozenset()
        if not isinstance(given, Mapping):
            raise TypeError(f"`{name}` must be a mapping {{slot: function or 0}} with slots from "
                            f"{', '.join(PARAM_SLOTS)}, got {type(given).__name__}")
        k = self.params.shape[0]
        if k == 0:
            raise ValueError(f"`{name}` was given but the model has no parameters (k = 0): "
                             "leave it out")
        if self.time_dependent and self.m > 0:
            raise ValueError(f"`{name}` is not supported for a time_dependent model with "
                             "constraints (derivatives by θ of rheonomic constraints): leave it "
                             "out, and fastvi differences the step in θ instead")
        functions, zero = {}, set()
        for slot, fn in given.items():
            if slot not in PARAM_SLOTS:
                raise ValueError(f"`{name}` has the unknown slot {slot!r}; the slots are "
                                 f"{', '.join(PARAM_SLOTS)}")
            if slot not in self._functions:
                why = {"mass": "its mass matrix is constant (data, not a function of θ)",
                       "constraint": f"m = {self.m}", "constraint_jacobian": f"m = {self.m}"}.get(
                    slot, f"it has no `{slot}`")
                raise ValueError(f"`{name}[{slot!r}]` was given but the model has no `{slot}` "
                                 f"callback ({why}): remove that entry")
            if _is_zero(fn):
                zero.add(slot)
            elif callable(fn):
                functions[slot] = fn
            else:
                raise TypeError(f"`{name}[{slot!r}]` must be a function or 0 (the callback does "
                                f"not depend on θ), got {fn!r}")
        return functions, frozenset(zero)

    def _param_patterns(self, given):
        """Validate ``param_patterns``: ``{slot: boolean array (k,) + output shape}``."""
        name = "param_patterns"
        if given is None:
            return {}
        if not isinstance(given, Mapping):
            raise TypeError(f"`{name}` must be a mapping {{slot: pattern}}, got "
                            f"{type(given).__name__}")
        patterns = {}
        for slot, pattern in given.items():
            if slot not in PATTERNED_PARAM_SLOTS:
                raise ValueError(f"`{name}` has the slot {slot!r}; a pattern is for "
                                 f"{', '.join(PATTERNED_PARAM_SLOTS)}")
            if slot not in self._param_functions:
                raise ValueError(f"`{name}[{slot!r}]` was given but `param_derivatives` has no "
                                 f"function for {slot!r}: give it, or remove the pattern")
            shape = (self.params.shape[0],) + self.output_shape(slot)
            patterns[slot] = _as_pattern(pattern, shape, f"{name}[{slot!r}]")
        return patterns

    # ------------------------------------------------------------------ pickling as a recipe
    def __reduce__(self):
        # Compiled cfuncs cannot travel between processes; a model travels as the recipe
        # that rebuilds it (scene name and arguments, or importable user functions) and is
        # recompiled on arrival (the kernels themselves come from the on-disk cache).
        if self.recipe is not None:
            scene, kwargs = self.recipe
            return (_scene_from_recipe, (scene, kwargs, self.params))
        in_main = []
        named = list(self._functions.items())
        named += [(f"param_derivatives[{s!r}]", fn) for s, fn in self._param_functions.items()]
        for key, fn in named:
            qual = getattr(fn, "__qualname__", "")
            if "<locals>" in qual or "<lambda>" in qual:
                raise TypeError(
                    f"this Model cannot be pickled: `{key}` is {qual!r}, not a module-level "
                    "function; define the model's functions at module level so workers can import them"
                )
            if getattr(getattr(fn, "py_func", fn), "__module__", None) == "__main__":
                in_main.append(f"`{key}` ({qual})")
        if in_main:
            # pickle stores a reference `__main__.name`: it resolves only in a process that
            # runs the same script, never in a Dask worker, which then fails far from here
            warnings.warn(
                f"model {self.name!r} is pickled with functions defined in `__main__` (the "
                f"script being run): {', '.join(in_main)}. A Dask or process-pool worker cannot "
                "import them and will fail to load the model; move the model's functions into a "
                "module (a .py file next to the script) and import them from there",
                RuntimeWarning, stacklevel=2,
            )
        funcs = {k: v for k, v in self._functions.items() if k != "mass"}
        if self.linear_potential:
            funcs["potential_hessian"] = 0
        if self.force_independent_of_q:
            funcs["force_jacobian_q"] = 0
        kwargs = dict(params=self.params, mass=self._mass_arg, name=self.name,
                      time_dependent=self.time_dependent,
                      constraint_jacobian_pattern=self.constraint_jacobian_pattern,
                      force_jacobian_pattern=self.force_jacobian_pattern,
                      param_derivatives=self._param_arg(), param_patterns=self.param_patterns,
                      fixed_params=self.fixed_params, mass_params=self.mass_params,
                      **funcs)
        return (_model_from_kwargs, (self.n, self.m, kwargs))

    # ------------------------------------------------------------------ compiled form
    @property
    def has_force(self) -> bool:
        """Whether the model has a non-conservative force."""
        return "force" in self._functions

    @property
    def timed(self) -> bool:
        """Whether any callback reads the time (a force, or ``time_dependent``): the kernels
        pass it in a hidden entry after the parameters (:meth:`kernel_params`), and the
        results carry the work of forces and time."""
        return self.time_dependent or self.has_force

    @property
    def constraint_hessian_pattern(self) -> np.ndarray | None:
        """The entries of ``Σ_c η_c ∇²g_c`` that may be non-zero, (n, n) boolean, implied by
        :attr:`constraint_jacobian_pattern` (None without it): ``(a, b)`` where one
        constraint's pattern holds both coordinates. An exact ``constraint_hessian`` is
        handed an ``out`` zeroed there and need write only those entries."""
        P = self.constraint_jacobian_pattern
        if P is None:
            return None
        Pf = P.astype(np.float64)  # counts, exact in floats, by BLAS (an int product is not)
        return (Pf.T @ Pf) > 0

    def _kind(self, slot: str) -> str:
        if slot in _ALWAYS_TIMED or (self.time_dependent and slot in _TIME_AWARE):
            return slot + "@t"
        return slot

    def kernel_params(self, params=None, t: float = 0.0) -> np.ndarray:
        """The parameter vector the compiled callbacks receive: ``params`` (default the
        model's) followed by one hidden entry holding the time ``t``, which the kernels
        overwrite at every evaluation (time-aware callbacks read it; the others never look).
        A fresh array of length k + 1."""
        p = self.params if params is None else np.asarray(params, dtype=np.float64)
        return np.append(p, float(t))

    def kernel_data(self, params=None, t: float = 0.0):
        """The :class:`fastvi.kernels.layout.ModelData` the kernels receive: the callbacks,
        flags, constant mass and :meth:`kernel_params` (one type for every model)."""
        return lay.ModelData(*self._compile(), self.kernel_params(params, t))

    def _compile(self):
        if self._compiled is None:
            k = self.params.shape[0]
            cfs = _wrap_all(SLOTS, self._functions, self._kind, self.n, self.m, k)
            flags = np.zeros(lay.FLAGS_SIZE, dtype=np.int64)
            flags[lay.F_N] = self.n
            flags[lay.F_M] = self.m
            flags[lay.F_MASSFN] = int("mass" in self._functions)
            for slot, index in zip(_SECOND, lay.F_EXACT):
                flags[index] = int(slot in self._functions)
            M = self.mass_matrix_constant
            Mc = np.ascontiguousarray(M if M is not None else np.zeros((self.n, self.n)))
            # a diagonal constant M lets the kernels use M v and M⁻¹ elementwise
            flags[lay.F_DIAG] = int(M is not None and np.count_nonzero(M - np.diag(np.diag(M))) == 0)
            flags[lay.F_AUGMENT] = int(self.mass_singular)
            flags[lay.F_FORCE] = int(self.has_force)
            flags[lay.F_EX_FJQ] = int("force_jacobian_q" in self._functions)
            flags[lay.F_EX_FJV] = int("force_jacobian_v" in self._functions)
            flags[lay.F_TIME] = int(self.time_dependent)
            flags[lay.F_EX_GT] = int("constraint_time_derivative" in self._functions)
            flags[lay.F_TSLOT] = k
            flags[lay.F_LINPOT] = int(self.linear_potential)
            flags[lay.F_FORCE_Q0] = int(self.force_independent_of_q)
            flags[lay.F_FJ_PATTERN] = int(self.force_jacobian_pattern is not None)
            flags[lay.F_CH_PATTERN] = int(self.constraint_jacobian_pattern is not None)
            self._compiled = (cfs, flags, Mc)
        return self._compiled

    def kernel_arguments(self):
        """``(callbacks, flags, constant_mass)``: what the kernels receive for this model.

        ``callbacks`` is the tuple of cfuncs in :data:`SLOTS` order (absent ones are a
        no-op that the kernels never call), ``flags`` the int64 vector indexed by the
        ``F_*`` names of :mod:`fastvi.kernels.layout`. The kernels' parameter vector is
        :meth:`kernel_params`.
        """
        return self._compile()

    # ------------------------------------------------------------------ derivatives by θ
    @property
    def param_derivatives(self) -> frozenset:
        """The slots (:data:`PARAM_SLOTS`) whose derivative by the parameters the model was
        given, as a function or declared ``0`` (empty without ``param_derivatives``)."""
        return frozenset(self._param_functions) | self._param_zero

    @property
    def param_derivatives_zero(self) -> frozenset:
        """The slots (:data:`PARAM_SLOTS`) whose derivative by the parameters the model
        declared ``0``: the callback does not depend on θ."""
        return frozenset(self._param_zero)

    @property
    def param_derivatives_exact(self) -> bool:
        """Whether the derivatives by θ cover every callback θ can enter: ``mass`` when it is
        a function, ``kinetic_grad``, ``potential_grad``, ``constraint`` and
        ``constraint_jacobian`` when m > 0, and ``force``. Only then does the linearised
        step use them instead of differences in θ."""
        needed = {slot for slot in PARAM_SLOTS if slot in self._functions}
        return bool(self.param_derivatives) and needed <= self.param_derivatives

    def _param_arg(self):
        """``param_derivatives`` as given to the constructor (None when there were none)."""
        if not self.param_derivatives:
            return None
        return {**self._param_functions, **dict.fromkeys(self._param_zero, 0)}

    def _param_kind(self, slot: str) -> str:
        """The template kind of the derivative by θ of ``slot`` (timed like the slot)."""
        kind = self._kind(slot)
        return slot + "/θ" + ("@t" if kind.endswith("@t") else "")

    def param_derivative_data(self):
        """The model's derivatives by θ as the linearised step reads them, a
        :class:`fastvi.kernels.layout.ParamData` ``(fns, given, exact, fptr, fidx, cptr,
        cidx)``, the last four the rows of :attr:`param_patterns` the kernels read.

        ``fns`` holds the compiled derivatives in :data:`PARAM_SLOTS` order (the no-op of an
        absent callback where the model has none or declared ``0``), with the numba type of
        :meth:`kernel_data`'s callbacks, so one compiled kernel serves every model; ``given``
        (int64, shape (6,)) is 1 where ``fns`` holds a derivative; ``exact`` is 1 when
        :attr:`param_derivatives_exact`, else 0 (then the kernels difference the step in θ).
        A kernel calls ``fns[slot]`` with the pointers of the plain callback of that slot
        (``(q, q, p, out)``, or ``(q, v, p, out)`` for ``kinetic_grad`` and ``force``) and
        ``p`` from :meth:`kernel_params`.

        Compiled on the first call (≈ 0.1 s per derivative, from numba's disk cache for
        functions in source files) and kept: plain integrations never compile them.
        """
        if self._param_data is None:
            k = self.params.shape[0]
            fns = _wrap_all(PARAM_SLOTS, self._param_functions, self._param_kind, self.n, self.m, k)
            given = np.array([int(slot in self._param_functions) for slot in PARAM_SLOTS],
                             dtype=np.int64)
            self._param_data = lay.ParamData(fns, given, int(self.param_derivatives_exact),
                                             *self._param_rows())
        return self._param_data

    def _param_rows(self):
        """``(fptr, fidx, cptr, cidx)``: per parameter ``l``, the coordinates ``a`` where
        ``∂F/∂θ_l`` may be non-zero (``fidx[fptr[l]:fptr[l + 1]]``, the union over the given
        ``kinetic_grad``, ``potential_grad`` and ``force``), and the constraints where
        ``∂g/∂θ_l`` may be (``cidx``). Empty ``ptr``: dense, where a given derivative has
        no pattern (:attr:`param_patterns`) or none is given, and where the output has fewer
        than :data:`PATTERN_MIN_ENTRIES` entries (the kernels zero what they read before
        each call, so a derivative that writes its pattern only is read right densely)."""
        empty = (np.zeros(0, dtype=np.int64),) * 2

        def rows(slots):
            given = [slot for slot in slots if slot in self._param_functions]
            if not given or any(slot not in self.param_patterns for slot in given):
                return empty
            if self.param_patterns[given[0]].size < PATTERN_MIN_ENTRIES:
                return empty
            mask = np.logical_or.reduce([self.param_patterns[slot] for slot in given])
            ptr = np.zeros(mask.shape[0] + 1, dtype=np.int64)
            ptr[1:] = np.cumsum(mask.sum(axis=1))
            return ptr, np.nonzero(mask)[1].astype(np.int64)

        return rows(("kinetic_grad", "potential_grad", "force")) + rows(("constraint",))

    def param_derivative_value(self, slot: str, q, v=None, params=None, t: float = 0.0):
        """The derivative by θ of the callback ``slot`` (a name of :data:`PARAM_SLOTS`) at
        ``(t, q, v)``, evaluated through its compiled form as the kernels call it: an array
        of shape ``(k,) + output_shape(slot)`` with ``[l] = ∂f/∂θ_l`` (zeros for a declared
        ``0``). ``v`` is the velocity of ``kinetic_grad`` and ``force`` (default ``q``);
        ``t`` matters only for a force or a ``time_dependent`` model.

        Raises
        ------
        ValueError
            ``slot`` is not a name of :data:`PARAM_SLOTS`, or the model was not given its
            derivative (:attr:`param_derivatives`).
        """
        if slot not in PARAM_SLOTS:
            raise ValueError(f"`slot` must be one of {', '.join(PARAM_SLOTS)}, got {slot!r}")
        shape = (self.params.shape[0],) + self.output_shape(slot)
        if slot in self._param_zero:
            return np.zeros(shape)
        if slot not in self._param_functions:
            given = ", ".join(s for s in PARAM_SLOTS if s in self.param_derivatives) or "none"
            raise ValueError(f"the model has no derivative by θ of `{slot}` (given: {given}); "
                             "see `Model(param_derivatives=...)`")
        direct = self.__dict__.get("_param_direct")
        if direct is None:
            direct = self._param_direct = {
                name: direct_callback(cf)
                for name, cf in zip(PARAM_SLOTS, self.param_derivative_data().fns)}
        return _evaluate(direct[slot], q, v, self.kernel_params(params, t), shape)

    @property
    def has_exact_second_derivatives(self) -> dict[str, bool]:
        """Which second derivatives are exact (the rest use finite differences); a declared
        ``potential_hessian=0`` is exact."""
        return {s: s in self._functions or (s == "potential_hessian" and self.linear_potential)
                for s in _SECOND}

    @property
    def callbacks(self) -> frozenset:
        """The names (:data:`SLOTS`) of the callbacks this model was given; the kernels
        difference or skip the others."""
        return frozenset(self._functions)

    # ------------------------------------------------------------------ evaluation from Python
    def callback_value(self, slot: str, q, v=None, params=None, t: float = 0.0):
        """The callback ``slot`` (a name of :data:`SLOTS`) at ``(t, q, v)``, as the kernels
        call it: a float for ``potential``, else an array of the slot's output shape
        ((n,), (m,), (m, n) or (n, n)). ``v`` is the callback's second input (the velocity,
        or ``η`` for ``constraint_hessian``; default ``q``); ``t`` matters only for a
        ``time_dependent`` model or a force.

        Raises
        ------
        ValueError
            ``slot`` is not a name of :data:`SLOTS`, or the model was not given that
            callback (:attr:`callbacks`; the kernels difference or skip it). A declared
            ``potential_hessian=0`` or ``force_jacobian_q=0`` gives zeros.
        """
        if slot not in SLOTS:
            raise ValueError(f"`slot` must be one of {', '.join(SLOTS)}, got {slot!r}")
        if (slot == "potential_hessian" and self.linear_potential
                or slot == "force_jacobian_q" and self.force_independent_of_q):
            return np.zeros((self.n, self.n))  # declared: ∇V (F) does not depend on q
        if slot not in self._functions:
            hint = " (its mass is constant: see `mass_matrix`)" if slot == "mass" else ""
            raise ValueError(f"the model has no `{slot}` callback{hint}; it has "
                             f"{', '.join(s for s in SLOTS if s in self._functions)}")
        return self._eval(slot, q, v, params=params, shape=self.output_shape(slot), t=t)

    def output_shape(self, slot: str) -> tuple:
        """The shape of the output the callback ``slot`` (a name of :data:`SLOTS`) writes:
        ``()`` for ``potential``, else (n,), (m,), (m, n) or (n, n) (the table at the top of
        :mod:`fastvi.model`)."""
        n, m = self.n, self.m
        return {"potential": (), "kinetic_grad": (n,), "potential_grad": (n,), "force": (n,),
                "constraint": (m,), "constraint_time_derivative": (m,),
                "constraint_jacobian": (m, n)}.get(slot, (n, n))

    def _eval(self, slot: str, q, v=None, params=None, shape=(), t: float = 0.0):
        direct = self.__dict__.get("_direct")
        if direct is None:
            direct = self._direct = {name: direct_callback(cf)
                                     for name, cf in zip(SLOTS, self._compile()[0])}
        return _evaluate(direct[slot], q, v, self.kernel_params(params, t), shape)

    def mass_matrix(self, q, params=None) -> np.ndarray:
        """M(q), shape (n, n)."""
        if self.mass_matrix_constant is not None:
            return self.mass_matrix_constant.copy()
        return self._eval("mass", q, params=params, shape=(self.n, self.n))

    def potential_energy(self, q, params=None, t: float = 0.0) -> float:
        """V(t, q) (``t`` is ignored unless the model is ``time_dependent``)."""
        return self._eval("potential", q, params=params, t=t)

    def constraint_value(self, q, params=None, t: float = 0.0) -> np.ndarray:
        """g(t, q), shape (m,)."""
        if self.m == 0:
            return np.zeros(0)
        return self._eval("constraint", q, params=params, shape=(self.m,), t=t)

    def constraint_jacobian_value(self, q, params=None, t: float = 0.0) -> np.ndarray:
        """G(t, q) = ∂g/∂q, shape (m, n)."""
        if self.m == 0:
            return np.zeros((0, self.n))
        return self._eval("constraint_jacobian", q, params=params, shape=(self.m, self.n), t=t)

    def constraint_time_derivative_value(self, q, params=None, t: float = 0.0) -> np.ndarray:
        """g_t = ∂g/∂t at (t, q), shape (m,): the callback, or a central difference in ``t``
        of the constraint (zero for a model that is not ``time_dependent``)."""
        if self.m == 0 or not self.time_dependent:
            return np.zeros(self.m)
        if "constraint_time_derivative" in self._functions:
            return self._eval("constraint_time_derivative", q, params=params, shape=(self.m,), t=t)
        # the kernels' rule (kernels.step._d_dt): the same points, weights and order of sums
        dt = FD_T * max(1.0, abs(t))
        out = np.zeros(self.m)
        for at, weight in FD_T_POINTS:
            out += weight * self.constraint_value(q, params, t + at * dt)
        return out * (1.0 / (12.0 * dt))

    def force_value(self, t, q, v, params=None) -> np.ndarray:
        """F(t, q, v), shape (n,) (zeros for a model without force)."""
        if not self.has_force:
            return np.zeros(self.n)
        return self._eval("force", q, v, params=params, shape=(self.n,), t=t)

    def energy(self, q, v, params=None, t: float = 0.0) -> float:
        """H = ½ vᵀ M(q) v + V(t, q)."""
        v = np.asarray(v, dtype=np.float64)
        return 0.5 * v @ self.mass_matrix(q, params) @ v + self.potential_energy(q, params, t)

    def check(self, q, v=None, **options):
        """Compare every supplied derivative callback with finite differences.

        Each first and second derivative is compared with central differences (Richardson
        extrapolated) of the callback it differentiates, at ``(q, v)`` and at a few random
        nearby states; see :func:`fastvi.check.check_model` for the options.

        Parameters
        ----------
        q : array_like (n,)
            Configuration (need not satisfy the constraints).
        v : array_like (n,), optional
            Velocity for the kinetic-energy derivatives (default: random).
        **options
            ``params``, ``t``, ``n_random``, ``radius``, ``rtol``, ``seed``, ``raise_on_error``,
            ``param_derivatives`` (default True: the derivatives by θ too).

        Returns
        -------
        fastvi.check.CheckReport
            Printable table: one line per callback (``<slot>/θ`` for the derivatives by
            the parameters).

        Raises
        ------
        fastvi.ModelCheckError
            Naming the first callback that disagrees beyond tolerance.
        """
        from .check import check_model

        return check_model(self, q, v, **options)

    def __repr__(self) -> str:
        kind = "constant" if self.mass_matrix_constant is not None else "q-dependent"
        extra = (", force" if self.has_force else "") + (", time-dependent" if self.time_dependent else "")
        return (f"Model({self.name!r}, n={self.n}, m={self.m}, {kind} mass, "
                f"k={self.params.shape[0]} params{extra})")


def _evaluate(direct, q, v, p, shape):
    """Call a compiled callback by its ctypes prototype ``direct`` at ``(q, v)`` with the
    kernels' parameter vector ``p``: a fresh array of ``shape`` (a float for ``()``)."""
    q = np.ascontiguousarray(q, dtype=np.float64)
    v = q if v is None else np.ascontiguousarray(v, dtype=np.float64)
    out = np.zeros(shape if shape else (1,))
    direct(q.ctypes.data, v.ctypes.data, p.ctypes.data, out.ctypes.data)
    return out if shape else float(out[0])


def _model_from_kwargs(n, m, kwargs):
    return Model(n, m, **kwargs)


def _as_fixed(fixed, k: int, name: str = "fixed_params") -> tuple:
    """``fixed_params`` (or ``name``) as sorted unique indices into the ``k`` parameters."""
    idx = np.atleast_1d(np.asarray(fixed if fixed is not None else (), dtype=object))
    out = set()
    for i in idx:
        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)):
            raise TypeError(f"`{name}` must be parameter indices (ints), got {fixed!r}")
        if not 0 <= int(i) < k:
            raise ValueError(f"`{name}` entry {int(i)} is out of range for k = {k} "
                             "parameters")
        out.add(int(i))
    return tuple(sorted(out))


def _is_zero(x) -> bool:
    """``potential_hessian=0``: the number zero (not False, not an array)."""
    return (isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))
            and x == 0)


def _scene_from_recipe(scene, kwargs, params):
    from .scenes import SCENES

    model = SCENES[scene](**kwargs)
    model.params = params
    return model


def _as_pattern(pattern, shape: tuple, name: str):
    """A pattern of non-zeros ``name`` as a boolean array of ``shape`` (None stays None):
    given as such an array, or as a pair of index arrays ``(rows, cols)`` into the first
    dimension and the rest (flattened)."""
    if pattern is None:
        return None
    rows_n, cols_n = shape[0], int(np.prod(shape[1:]))
    if isinstance(pattern, tuple) and len(pattern) == 2:
        rows, cols = (np.asarray(x) for x in pattern)
        if rows.shape != cols.shape or rows.ndim != 1 or not (
                np.issubdtype(rows.dtype, np.integer) and np.issubdtype(cols.dtype, np.integer)):
            raise ValueError(f"`{name}` as (rows, cols) needs two 1-D integer arrays of one length, "
                             f"got shapes {rows.shape} and {cols.shape}")
        if rows.size and (rows.min() < 0 or rows.max() >= rows_n or cols.min() < 0
                          or cols.max() >= cols_n):
            raise ValueError(f"`{name}`: an index is outside the shape ({rows_n}, {cols_n}) (rows "
                             f"in 0…{rows_n - 1}, columns in 0…{cols_n - 1})")
        mask = np.zeros((rows_n, cols_n), dtype=bool)
        mask[rows, cols] = True
        return mask.reshape(shape)
    mask = np.asarray(pattern)
    if mask.dtype != bool or mask.shape != tuple(shape):
        raise ValueError(f"`{name}` must be a {tuple(shape)} boolean array or a pair (rows, cols) "
                         f"of index arrays, got {mask.dtype} array of shape {mask.shape}")
    return np.array(mask)


#: the size ``k n`` (``k m``) of a derivative by θ from which the kernels read it over its
#: pattern: below, the dense loops, compiled for the sizes, cost less than the pattern's
#: indirection (chains of 2 and 4 links: 0.06–0.07 against 0.10–0.14 µs a parameter a step;
#: 8 links and more: the pattern's loops cost less)
PATTERN_MIN_ENTRIES = 256


#: eigenvalues of a constant mass matrix below this times its largest count as zero
MASS_RANK_RTOL = 1e-12


def _check_mass(M: np.ndarray, name: str, m: int) -> bool:
    """Check a constant mass matrix: symmetric and positive definite, or, with constraints,
    positive semidefinite (then definiteness on the constraints' tangent space is checked at
    ``q0``). Returns whether ``M`` is singular."""
    if not np.all(np.isfinite(M)):
        raise ValueError(f"`{name}` must be finite")
    if not np.allclose(M, M.T, rtol=1e-12, atol=1e-14 * np.max(np.abs(M))):
        raise ValueError(f"`{name}` must be symmetric")
    try:
        np.linalg.cholesky(M)
        return False
    except np.linalg.LinAlgError:
        pass
    lam, vec = np.linalg.eigh(M)
    top = max(float(lam[-1]), 0.0)
    if top == 0.0 or lam[0] < -MASS_RANK_RTOL * top:
        raise ValueError(f"`{name}` must be positive definite, or positive semidefinite in a "
                         f"constrained model; its eigenvalues range over [{lam[0]:.3g}, {lam[-1]:.3g}]")
    if m == 0:
        zero = vec[:, lam <= MASS_RANK_RTOL * top]
        null = np.nonzero(np.abs(zero).max(axis=1) > 1e-8)[0]
        raise ValueError(f"`{name}` is singular (zero along coordinates {null.tolist()}) and the "
                         "model has no constraints to fix those coordinates: give them mass, or "
                         "add the constraints that determine them")
    return True
