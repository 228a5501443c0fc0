r"""Guards that run before any kernel: sizes of the model's callbacks, and event functions.

The kernels call compiled code without bounds checks, so a callback or an event function
that writes past its output or into its inputs corrupts memory. Two guards stand between
them and a kernel:

* **Sizes, always.** :func:`sizes` evaluates every callback of the model twice into guarded
  buffers (:mod:`fastvi.check`: the output and each input followed by a guard zone, all
  filled with a NaN of a payload no computation produces) and raises
  :class:`fastvi.ModelCheckError` on a write past the declared output, into an input, or an
  entry left unset. It costs well under a millisecond once the callbacks are compiled, so
  :func:`fastvi.integrate` runs it even with ``check=False``, which skips only the
  comparison of the derivatives with finite differences.
* **Event functions**, at their first use in a run (:func:`events`): the signature first (an
  event in SciPy's style ``ev(t, y)`` is named as such, before numba reports a generic
  typing error), then one evaluation at the initial state inside a guarded buffer. A write
  into ``q``, ``v`` or ``params`` (or past their ends) is refused; a value that is NaN only
  when the memory after the inputs is NaN reads past the end of ``q`` or ``v`` (an event
  that is NaN either way is left alone: NaN is how an event says "not defined here").
"""

from __future__ import annotations

import inspect
import weakref

import numpy as np

from . import check as check_
from ._numba import quiet
from .model import call_callback

__all__ = ["sizes", "events", "EventFunctionError"]

#: the signature every event function has (SciPy's ``(t, y)`` does not fit: ``y`` is split)
EVENT_SIGNATURE = "event(t, q, v, params) -> float"


#: the models whose callbacks passed the size check in this process
_SIZED: "weakref.WeakSet" = weakref.WeakSet()


class EventFunctionError(ValueError):
    """An event function with a wrong signature, that writes into its inputs or reads past
    their ends (raised before any kernel ran)."""


def sizes(model, q, v, params, t: float) -> None:
    """The size part of the model check, once per model (skipped when the full check or
    this one already passed).

    Raises
    ------
    fastvi.ModelCheckError
        A callback writes outside its declared output or into an input, or leaves an entry
        of its output unset.
    """
    if model.checked or model in _SIZED:
        return
    check_.check_sizes(model, q, v, params=params, t=t)
    _SIZED.add(model)  # by object: a pickled model is checked again where it lands


def _positional_count(fn):
    """``(required, accepts_four)`` positional parameters of ``fn``, or None when unknown."""
    py = getattr(fn, "py_func", fn)
    try:
        sig = inspect.signature(py)
    except (TypeError, ValueError):
        return None
    kinds = [p.kind for p in sig.parameters.values()]
    if inspect.Parameter.VAR_POSITIONAL in kinds:
        return None
    pos = [p for p in sig.parameters.values()
           if p.kind in (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)]
    required = sum(p.default is inspect.Parameter.empty for p in pos)
    return required, len(pos) >= 4 >= required


def signatures(events) -> None:
    """Refuse event functions that cannot take ``(t, q, v, params)``, naming SciPy's
    ``(t, y)`` convention when that is what they follow (before numba compiles them)."""
    from .events import as_list

    for i, fn in enumerate(as_list(events)):
        counted = _positional_count(fn)
        if counted is None or counted[1]:
            continue
        required = counted[0]
        name = getattr(getattr(fn, "py_func", fn), "__qualname__", repr(fn))
        scipy = (" — SciPy's solve_ivp convention `ev(t, y)`; in fastvi the state comes split into "
                 "positions and velocities and the parameters follow: write it as "
                 "`def ev(t, q, v, params): return …` (y[:n] is q, y[n:] is v)" if required == 2 else "")
        raise EventFunctionError(
            f"`events[{i}]` (function `{name}`) takes {required} positional argument"
            f"{'s' if required != 1 else ''}{scipy}; fastvi calls every event function as "
            f"{EVENT_SIGNATURE}")


def events(model, ev, q, v, params, t: float) -> None:
    """Evaluate each compiled event of ``ev`` (:func:`fastvi.events.prepare`) once at
    ``(t, q, v)`` inside a guarded buffer.

    Raises
    ------
    EventFunctionError
        It wrote into ``q``, ``v`` or ``params`` or past their ends, or it reads past the
        end of ``q`` or ``v`` (NaN when the memory after them is NaN, finite otherwise).
    """
    n = model.n
    p = model.kernel_params(params, t)
    pad = n * n + 2 * n + check_.GUARD_MARGIN
    starts, at = [], 0
    for length in (1, n, n, p.shape[0]):  # out, q, v, params, each followed by a guard
        starts.append(at)
        at += length + pad
    lay = np.array([1, n, n, p.shape[0]] + starts[1:], dtype=np.int64)
    f = np.empty(at)
    u = f.view(np.uint64)
    q = np.ascontiguousarray(q, dtype=np.float64)
    v = np.ascontiguousarray(v, dtype=np.float64)
    # a write of the value an input already holds (v[0] = 0 at rest) changes nothing: the
    # writes are looked for at a second state too, with every entry distinct and non-zero
    probe_q = q + 0.01 * (1.0 + np.arange(n)) / n * max(1.0, float(np.max(np.abs(q))))
    probe_v = v + 0.5 + np.arange(n) / n
    for e in range(ev.count):
        fn = ev.fns[e]
        where = f"`events[{e}]`"
        for qq, vv in ((probe_q, probe_v), (q, v)):
            with quiet():
                status = check_.guarded_call(fn, f, u, qq, vv, p, lay, check_.GUARD_FILL[0],
                                               check_._NOTHING_ZEROED)
            if status == check_._OUTSIDE:
                raise EventFunctionError(
                    f"{where} {_what_changed(f, u, lay, qq, vv, p)} (n = {n}). Event functions must "
                    f"only read their arguments, {EVENT_SIGNATURE}: the kernels pass the "
                    "integrator's own state; copy an input (`q.copy()`) before changing it")
        value = f[0]  # at the initial state (the last evaluation)
        if np.isfinite(value):
            continue
        # the guards are NaN: is the value NaN only because it read them?
        plain = _plain(fn, q, v, p, n)
        if np.isfinite(plain):
            raise EventFunctionError(
                f"{where} reads past the end of `q` or `v` (it returned {plain:g} with the memory "
                f"after them zeroed and NaN with it NaN; q and v have n = {n} entries, indices "
                f"0…{n - 1}), at t = {t:g}")
        # NaN with finite memory after the inputs too: the event's own NaN (an event may be
        # NaN where it is not defined, e.g. a flip below the pivot: no crossing is counted)


def _plain(fn, q, v, p, n):
    """The event with its inputs followed by zeros (not NaN) instead of guards."""
    pad = n * n + 2 * n + check_.GUARD_MARGIN
    qq, vv, pp = (np.concatenate([x, np.zeros(pad)]) for x in (q, v, p))
    out = np.zeros(1 + pad)
    with quiet():
        call_callback(fn, qq, vv, pp, out)
    return float(out[0])


def _what_changed(f, u, lay, q, v, p) -> str:
    """Which input (or guard past it) a guarded event evaluation changed, in words."""
    size, nq, nv, npar, qs, vs, ps = (int(x) for x in lay)
    fill = check_.GUARD_FILL[0]
    for name, start, src, end in (("q", qs, q, vs), ("v", vs, v, ps), ("params", ps, p, u.shape[0])):
        now = f[start:start + src.shape[0]]
        changed = np.flatnonzero(~((now == src) | (np.isnan(now) & np.isnan(src))))
        if changed.size:
            entries = ", ".join(str(int(i)) for i in changed[:4])
            return f"wrote into its input `{name}` (entr{'y' if changed.size == 1 else 'ies'} {entries})"
        if np.any(u[start + src.shape[0]:end] != fill):
            return f"wrote past the end of its input `{name}`"
    return "wrote past the end of its output"
