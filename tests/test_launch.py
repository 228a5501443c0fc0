"""The launcher calls a kernel's compiled entry point only for arguments typed like before.

An entry point unboxes its arguments without checking their types, so a key that confused two
types (an int32 array for an int64 one, a callback of another signature, a named tuple of
another class) would hand the kernel memory it misreads: these tests would see a wrong sum.
"""

from collections import namedtuple

import numba
import numpy as np
import pytest

from fastvi._launch import Launcher

Pair = namedtuple("Pair", "a b")
Other = namedtuple("Other", "a b")

jit = pytest.mark.skipif(numba.config.DISABLE_JIT, reason="entry points need the JIT")


@numba.njit
def _total(x, pair, f):
    s = 0.0
    for i in range(x.shape[0]):
        s += x[i]
    return s + pair.a[0] + pair.b + f(1.0)


@numba.cfunc("float64(float64)")
def _plus_one(t):
    return t + 1.0


@numba.cfunc("float64(float64)")
def _times_ten(t):
    return 10.0 * t


@numba.cfunc("float32(float64)")
def _single(t):
    return t + 0.5


@jit
def test_same_types_reuse_the_entry_point_and_give_the_dispatchers_answer():
    run = Launcher(_total)
    x = np.arange(4.0)
    first, seconds = run.bind(x, Pair(np.ones(1), 2), _plus_one)
    assert seconds > 0.0
    again, seconds = run.bind(np.zeros(7), Pair(np.full(3, 5.0), 9), _times_ten)
    assert again is first and seconds == 0.0
    assert run(np.zeros(7), Pair(np.full(3, 5.0), 9), _times_ten) == 0.0 + 5.0 + 9 + 10.0
    assert run(x, Pair(np.ones(1), 2), _plus_one) == _total(x, Pair(np.ones(1), 2), _plus_one)


@jit
@pytest.mark.parametrize("change", ["dtype", "ndim_layout", "named_tuple", "signature", "int"])
def test_a_different_type_gets_its_own_entry_point(change):
    run = Launcher(_total)
    base = (np.arange(4.0), Pair(np.ones(1), 2), _plus_one)
    first, _ = run.bind(*base)
    x, pair, f = base
    if change == "dtype":
        x = np.arange(4, dtype=np.float32)
    elif change == "ndim_layout":
        x = np.arange(8.0)[::2]
    elif change == "named_tuple":
        pair = Other(np.ones(1), 2)
    elif change == "signature":
        f = _single
    else:
        pair = Pair(np.ones(1), 2.5)
    other, seconds = run.bind(x, pair, f)
    assert other is not first and seconds > 0.0
    assert run(x, pair, f) == pytest.approx(_total.py_func(x, pair, f))
    assert run.bind(*base)[0] is first
