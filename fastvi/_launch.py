"""Calling a compiled kernel without numba's per-call typing of its arguments.

A numba dispatcher types every argument of every call to find the compiled version. For
scalars and arrays its C fast path is quick, but the kernels take named tuples of arrays and a
tuple of ``cfunc`` callbacks, which fall back to numba's Python ``typeof``: ≈ 0.8 ms of a
1 ms ``integrate`` call of 2 steps went there (``docs/decisions/0009-launcher.md``). A
:class:`Launcher` keys the arguments by numba's own C type fingerprint
(``numba._dispatcher.compute_fingerprint``, the key of the dispatcher's type cache; a callback
by its signature, a named tuple by its class) and calls the compiled entry point it found for
that key before, which still unboxes the arguments but no longer types them.

Same argument types, same machine code: the entry point is the one the dispatcher would
call. A key it has not seen (a new model kind, sizes, layout) goes through the dispatcher's
own typing and compilation once.
"""

import functools
import inspect
import time
import weakref

from numba.core.ccallback import CFunc
from numba.core.types import WrapperAddressProtocol

from ._numba import quiet

try:
    from numba._dispatcher import compute_fingerprint as _fingerprint
except ImportError:  # pragma: no cover - numba moved it: type every call, as the dispatcher does
    _fingerprint = None

__all__ = ["Launcher"]


class _NoKey(Exception):
    """An argument the key does not cover: the call goes through the dispatcher."""


#: one small integer per distinct callback signature, and each callback's: hashing numba's
#: Signature objects at every call cost as much as the typing this module avoids
_SIGNATURES: dict = {}
_TOKENS = weakref.WeakKeyDictionary()


def _signature_token(f, sig) -> int:
    tok = _TOKENS.get(f)
    if tok is None:
        tok = _SIGNATURES.setdefault(sig, len(_SIGNATURES))
        _TOKENS[f] = tok
    return tok


def _key(value):
    """A hashable key equal for two values exactly when numba types them alike."""
    if isinstance(value, CFunc):
        return _signature_token(value, value._sig)
    if isinstance(value, WrapperAddressProtocol):
        # typed as the first-class function of its signature, like a CFunc of that signature
        # (the stages compiled for a model's sizes or a structured plan,
        # fastvi.kernels.step._TwinStage)
        return _signature_token(value, value.signature())
    if isinstance(value, tuple):
        try:
            return type(value), _fingerprint(value)
        except (NotImplementedError, TypeError, ValueError):
            # a tuple holding callbacks (ModelData.fns, Events.fns): element by element
            return (type(value),) + tuple(_key(v) for v in value)
    try:
        return _fingerprint(value)
    except (NotImplementedError, TypeError, ValueError):
        raise _NoKey from None


def _with_tail(entry, tail, *args):
    return entry(*args, *tail)


class Launcher:
    """A kernel called through its compiled entry points, one per argument-type key.

    Parameters
    ----------
    kernel : numba dispatcher (or a plain function under ``NUMBA_DISABLE_JIT``)
        Called with its arguments positional; trailing ones left out take their defaults.
    """

    def __init__(self, kernel):
        self.kernel = kernel
        self._entry = {}
        self._jit = hasattr(kernel, "compile") and _fingerprint is not None
        fn = getattr(kernel, "py_func", kernel)
        params = list(inspect.signature(fn).parameters.values())
        self._arity = len(params)
        self._defaults = tuple(p.default for p in params if p.default is not p.empty)

    def bind(self, *args):
        """The callable for arguments typed like ``args`` and the seconds it took to make it
        ready (compile, or load from numba's cache; 0.0 when it was ready).

        The callable is the compiled entry point: call it only with arguments of the same
        types (the same objects, or ones built the same way), every one positional.
        """
        if not self._jit:
            return self.kernel, 0.0
        try:
            key = tuple(_key(a) for a in args)
        except _NoKey:
            key = None
        entry = self._entry.get(key) if key is not None else None
        if entry is not None:
            return entry, 0.0
        t = time.perf_counter()
        # numba compiles for every parameter: the defaults left out are typed and passed too
        tail = self._defaults[len(self._defaults) - (self._arity - len(args)):] \
            if len(args) < self._arity else ()
        with quiet():
            entry = self.kernel.compile(tuple(self.kernel.typeof_pyval(a) for a in args + tail))
        if tail:
            entry = functools.partial(_with_tail, entry, tail)
        if key is not None:
            self._entry[key] = entry
        return entry, time.perf_counter() - t

    def __call__(self, *args):
        """Call the kernel (its compiled entry point when ``args`` are typed like a call
        before)."""
        return self.bind(*args)[0](*args)
