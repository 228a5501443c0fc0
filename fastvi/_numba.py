"""One place for numba settings: every kernel is compiled with these options."""

import contextlib
import warnings

import numba as nb

# First-class function values (our cfunc callbacks) are "experimental" in numba's words;
# they are the documented way to pass compiled callbacks and we test them, so the warning
# is only noise for users.
warnings.filterwarnings("ignore", category=nb.NumbaExperimentalFeatureWarning)

_OPTIONS = dict(cache=True, nogil=True, error_model="numpy", boundscheck=False)


def njit(fn=None, **extra):
    """``numba.njit`` with fastvi's options (on-disk cache, no GIL, numpy error model)."""
    opts = {**_OPTIONS, **extra}
    if fn is None:
        return lambda f: nb.njit(**opts)(f)
    return nb.njit(**opts)(fn)


@contextlib.contextmanager
def quiet():
    """Context in which numba's first-class-function warning is silenced.

    The module-level filter above is overridden by callers' own filters (``-W error``,
    ``warnings.catch_warnings``); every kernel call from Python goes through this too.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", nb.NumbaExperimentalFeatureWarning)
        yield
