"""One place for numba settings: every kernel is compiled with these options."""

import contextlib
import hashlib
import inspect
import warnings
from pathlib import Path

import numba as nb
from numba import types
from numba.core import caching, cgutils
from numba.core.extending import intrinsic, overload
from numba.core.imputils import impl_ret_borrowed

# First-class function values (our cfunc callbacks) are "experimental" in numba's words;
# they are the documented way to pass compiled callbacks and we test them, so the warning
# is only noise for users.
warnings.filterwarnings("ignore", category=nb.NumbaExperimentalFeatureWarning)

_PACKAGE = Path(__file__).resolve().parent
_STAMP: list = []


def _package_stamp() -> str:
    """The stamp of every kernel (once per process): the hash of the package sources that
    compiled code is made of — the modules defining ``njit``/``hot``/``cfunc`` functions, the
    named tuples the kernels take and the status codes they return."""
    if not _STAMP:
        h = hashlib.sha256()
        for path in sorted(_PACKAGE.rglob("*.py")):
            text = path.read_bytes()
            if any(word in text for word in (b"njit", b"cfunc", b"@hot", b"namedtuple")) or path.name == "status.py":
                h.update(str(path.relative_to(_PACKAGE)).encode())
                h.update(text)
        _STAMP.append(h.hexdigest())
    return _STAMP[0]


#: a module-level name that opts a module outside the package into the package stamp
#: (``tests/yardstick.py``: it compiles ``fastvi.kernels.linalg`` into its own kernels)
STAMP_OPT_IN = "FASTVI_CACHE_STAMP"


class _PackageStampMixin:
    """Invalidate a cached kernel when any compiled fastvi source changes.

    numba checks only the file that defines a cached function, but ``drive.run`` inlines
    ``step`` from another file: an edit to ``step.py`` alone would leave a stale ``run`` in
    the cache. Stamping every kernel with the hash of the package's compiled sources closes
    that hole. A module outside the package that compiles fastvi's kernels into its own (a benchmark's
    hand-written kernel) opts in with a true module-level ``FASTVI_CACHE_STAMP``; its stamp
    is then the package's and its own file's. Other modules (users' callbacks) keep numba's
    own rule.
    """

    _outside = False

    def get_source_stamp(self):
        if self._outside:
            return (_package_stamp(), super().get_source_stamp())
        return _package_stamp()

    @classmethod
    def from_function(cls, py_func, py_file):
        try:
            path = Path(py_file).resolve()
            inside = path.is_relative_to(_PACKAGE)
        except (OSError, ValueError):
            inside = False
        opted = bool(getattr(py_func, "__globals__", {}).get(STAMP_OPT_IN, False))
        if not (inside or opted):
            return None
        loc = super().from_function(py_func, py_file)
        if loc is not None and not inside:
            loc._outside = True
        return loc


def _numba_class(name: str):
    # numba 0.68 made these names public; older releases have them with a leading underscore
    return getattr(caching, name, None) or getattr(caching, "_" + name)


class _UserProvided(_PackageStampMixin, _numba_class("UserProvidedCacheLocator")):
    pass


class _InTree(_PackageStampMixin, _numba_class("InTreeCacheLocator")):
    pass


class _UserWide(_PackageStampMixin, _numba_class("UserWideCacheLocator")):
    pass


_LOCATORS = _numba_class("CacheImpl")._locator_classes
if not any(issubclass(c, _PackageStampMixin) for c in _LOCATORS):
    _LOCATORS[:0] = [_UserProvided, _InTree, _UserWide]

_OPTIONS = dict(cache=True, nogil=True, error_model="numpy", boundscheck=False)


def njit(fn=None, **extra):
    """``numba.njit`` with fastvi's options (on-disk cache, no GIL, numpy error model)."""
    opts = {**_OPTIONS, **extra}
    if fn is None:
        return lambda f: nb.njit(**opts)(f)
    return nb.njit(**opts)(fn)


def hot(fn):
    """:func:`njit` for the kernels of the time loop: compiled without reference counting.

    numba counts references to every array it extracts from a tuple or slices (an atomic
    increment and decrement per view): measured 0.9 µs of the 1.25 µs a residual of the
    double pendulum cost, several times its arithmetic
    (``docs/decisions/0006-kernels-without-reference-counting.md``). The kernels
    of the time loop allocate nothing and only borrow arrays that their caller keeps alive,
    so they need no reference counting. numba refuses to compile an allocation in such a
    function, which also enforces the no-allocation rule.
    """
    return nb.njit(**_OPTIONS, _nrt=False)(fn)


def hot_inline(fn):
    """:func:`hot`, inlined into its callers by numba: only for the small helpers of the
    step (a few lines, or a branch that a caller's arguments decide).

    numba types an inlined body again in every caller: inlining the step's large helpers
    made the first compile of ``integrate`` twice as long
    (``docs/decisions/0010-kernel-shape.md``). Those are plain :func:`hot` functions that
    take the named tuples by pointer (:func:`byref`), so that a call costs a few words."""
    return nb.njit(**_OPTIONS, _nrt=False, inline="always")(fn)


@contextlib.contextmanager
def quiet():
    """Context in which numba's first-class-function warning is silenced.

    The module-level filter above is overridden by callers' own filters (``-W error``,
    ``warnings.catch_warnings``); every kernel call from Python goes through this too.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", nb.NumbaExperimentalFeatureWarning)
        yield


@intrinsic
def ptr(typingctx, arr):
    """The data pointer of an array, for a model callback, with no reference counting.

    ``arr.ctypes`` does the same job but increments and decrements the array's reference
    count, atomically, on every call: measured 50 ns per callback on views such as
    ``ws[6][0]``, more than the model's own work. The array outlives the call (it is a local
    of the caller), so the bare pointer is safe.
    """

    def codegen(context, builder, signature, args):
        return context.make_array(signature.args[0])(context, builder, value=args[0]).data

    return types.CPointer(arr.dtype)(arr), codegen


# ----------------------------------------------------------------------------- by reference
@intrinsic
def byref(typingctx, x):
    """A pointer to a copy of the value ``x`` (a named tuple of arrays) in the caller's frame.

    numba passes a tuple to a function that it does not inline as its flattened fields: the
    workspace alone is some 370 machine words, copied at every call (a double-pendulum step
    whose helpers took the tuples by value cost 1.6–2× one that took them by pointer). A kernel passes ``byref(ws)`` instead, one word, and
    the callee reads the fields it needs through :func:`own`. Only arrays and scalars are
    copied into the slot, never array data, so writes through the callee's views land in
    the caller's arrays. The slot lives as long as the calling function's frame: pass the
    pointer down, never return it.
    """
    if isinstance(x, types.CPointer):
        return None
    sig = types.CPointer(x)(x)

    def codegen(context, builder, signature, args):
        dm = context.data_model_manager[signature.args[0]]
        slot = cgutils.alloca_once(builder, dm.get_data_type())
        builder.store(dm.as_data(builder, args[0]), slot)
        return slot

    return sig, codegen


@intrinsic
def erased(typingctx, p):
    """The pointer ``p`` (a :func:`byref` pointer) as an untyped ``void*``: what a time loop
    hands its per-step hook, so that the loop is compiled once whatever the hook's data
    (:func:`.kernels.drive.step_hook`, which types the hook to take it back)."""
    if not isinstance(p, types.CPointer):
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.voidptr))

    return types.voidptr(p), codegen


class CalledAs(types.WrapperAddressProtocol):
    """A compiled C function ``cf`` that numba types with the signature ``sig``, one its
    machine code takes the same way (pointers of other types, a generic stage's arguments):
    a compiled caller that holds it is not compiled again for ``cf``'s own types."""

    def __init__(self, cf, sig):
        self.cf, self.sig = cf, sig

    def __wrapper_address__(self):
        return self.cf.address

    def signature(self):
        return self.sig


@intrinsic
def own(typingctx, x):
    """The value behind a :func:`byref` pointer, or ``x`` itself when it is a value: kernels
    take either (tests call them with the named tuples themselves). An intrinsic, so that
    it is code in its caller, not a call: a function returning the workspace would copy all
    its fields through numba's return slot at every use."""
    if not isinstance(x, types.CPointer):
        # a borrowed reference: counted where numba counts references (not in hot kernels)
        return x(x), lambda context, builder, sig, args: impl_ret_borrowed(
            context, builder, sig.return_type, args[0])
    sig = x.dtype(x)

    def codegen(context, builder, signature, args):
        ty = signature.return_type
        dmm = context.data_model_manager
        if not isinstance(ty, types.BaseTuple):
            value = dmm[ty].load_from_data_pointer(builder, args[0])
        else:
            # field by field rather than one load of the whole aggregate: LLVM then drops
            # the loads of the fields a callee never reads
            fields = [dmm[t].load_from_data_pointer(builder, cgutils.gep_inbounds(builder, args[0], 0, i))
                      for i, t in enumerate(ty.types)]
            value = context.make_tuple(builder, ty, fields)
        return impl_ret_borrowed(context, builder, ty, value)

    return sig, codegen


# ----------------------------------------------------------------------------- compiled only where used
def only_if(kernel, field, default=None):
    """``kernel`` where its workspace argument's ``field`` is not None, else nothing.

    Returns a function with ``kernel``'s parameters that numba compiles, for each type of
    the workspace argument (the parameter named ``ws`` or ``ws_``, a named tuple or a
    :func:`byref` pointer to one), into a call of ``kernel`` when the field is typed as a
    value, or into ``return default`` when it is typed ``None``. A run-time branch would
    leave the code it skips to be compiled all the same: this is how a small model's step
    compiles without the large models' banded and sparse solvers (``Workspace.structured``).
    """
    params = list(inspect.signature(kernel.py_func).parameters)
    at = next(p for p in params if p in ("ws", "ws_"))
    args = ", ".join(params)
    scope = dict(kernel=kernel, default=default, types=types)
    exec(f"def call({args}):\n    return kernel({args})\n"  # noqa: S102 - names from a signature
         f"def skip({args}):\n    return default\n"
         f"def choose({args}):\n"
         f"    t = {at}.dtype if isinstance({at}, types.CPointer) else {at}\n"
         f"    if isinstance(t[t.fields.index({field!r})], types.NoneType):\n"
         f"        return skip\n"
         f"    return call\n", scope)
    stub = scope["call"]
    stub.__name__ = stub.__qualname__ = kernel.py_func.__name__
    stub.__doc__ = kernel.py_func.__doc__
    overload(stub, jit_options=dict(_nrt=False))(scope["choose"])
    return stub
