r"""Model checks: output sizes first, then every derivative against finite differences.

**Sizes.** The callbacks are compiled with their array sizes baked in and without bounds
checks, so a callback that writes more entries than its declared output (``Model(4, 1, …)``
whose constraint writes two values, a gradient writing ``out[n]``, a Jacobian written as
``(n, m)``) would write into whatever memory follows it, and one that leaves an entry unset
hands the kernels stale values. Before anything else, :func:`check_model` therefore calls
every callback twice at the given state inside one buffer of its own, laid out as
``out | guard | q | guard | v | guard | params | guard`` and filled with a NaN of a payload no
computation produces (a different one in each call). It then requires that exactly the
declared entries of ``out`` changed, both times, to the same values: a write past the end, a
write into an input, an entry never set, and an entry read before it was set (``out[i] += …``)
each raise :class:`ModelCheckError` naming the callback, the declared shape and what was
written. The guard (``n² + 2n + 64`` entries) is longer than what the usual mistakes reach (a
transposed ``(n, m)`` write into an ``(m, n)`` output reaches flat index ``n² − 1`` at most). Every
later evaluation of the check goes through the same guarded buffers.

**Declared patterns.** A model with ``constraint_jacobian_pattern`` is handed an ``out``
that is zero outside the pattern and writes only the pattern's entries; the guarded call
then requires every entry *of the pattern* to be set, takes the entries outside it that
the callback left alone as the zeros the kernels provide, and names any non-zero written
there. The comparison of ``G`` with finite differences of ``g`` says so when its worst
entry lies outside the pattern (the pattern misses a non-zero). G's pattern implies that of
``constraint_hessian`` (the pairs of coordinates that share a constraint), which is handed
an ``out`` zeroed over it and may leave any entry of it unset.

**Derivatives.** A variational integrator with a wrong gradient is not unstable, it is
*silently wrong*: it conserves the energy of a different Lagrangian. :func:`check_model` (also
:meth:`fastvi.Model.check`) therefore compares every supplied derivative callback with
finite differences of the callback it differentiates,

==========================  ================================================
callback                    compared with finite differences of
==========================  ================================================
``kinetic_grad``            ``T(q) = ½ vᵀ M(q) v`` (the ``mass`` callback)
``momentum_jacobian``       ``M(q) v`` (the ``mass`` callback)
``kinetic_hessian``         ``kinetic_grad``
``potential_grad``          ``potential``
``potential_hessian``       ``potential_grad``
``constraint_jacobian``     ``constraint``
``constraint_hessian``      ``Gᵀ η`` (the ``constraint_jacobian`` callback),
                            for ``η = e_1 … e_m`` and a random ``η``
==========================  ================================================

and checks that a ``mass`` callback returns a symmetric matrix. A model's derivatives by the
parameters (``Model(param_derivatives=...)``, rows ``<slot>/θ``) are compared with the same
differences of the callback ``<slot>`` in each parameter ``θ_l`` (a declared ``0`` with
differences that must vanish), after their own size check. The checks run in dependency
order: first derivatives (against the functions they differentiate) at every state, then
second derivatives, each only if the first derivative it is compared with passed at every
state (otherwise it is reported as *skipped*, "not checked: depends on …"), so the callback
blamed first is the first wrong one, from any state. The comparison runs at the
given state and at a few random nearby states (a wrong derivative can agree by accident at a
special point, e.g. ``x = 0``). The callbacks are evaluated through the compiled cfuncs, so
what is checked is exactly what the kernels call.

Finite differences use three central differences with steps ``h, h/2, h/4``
(``h = 10⁻³·max(1, |q_b|)``) combined by Richardson extrapolation: the reference is
accurate to about ``10⁻¹²`` relative for smooth callbacks, and the difference of the two
extrapolations estimates its error. A derivative ``D`` passes when

.. math::

    \max |D - D_{FD}| \le \text{rtol}\,\max(|D|, |D_{FD}|) + 10\,e_{FD} + 100\,\varepsilon\,|f|/h_{min},

with ``e_FD`` the estimated finite-difference error and the last term the round-off of
differencing ``f``. With the default ``rtol = 1e-6`` a genuine mistake (a sign, a factor,
a transposed index, a missing term) fails by many orders of magnitude.

:func:`fastvi.integrate` runs a cheap version (the initial state and one nearby state) the
first time a model is integrated (sizes included: a few milliseconds); pass ``check=False``
to skip it, at your own risk.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp

from ._numba import njit, ptr, quiet
from .model import PARAM_SLOTS, SLOTS, Model, direct_callback
from .structure import greedy_colours

__all__ = ["check_model", "CheckReport", "CheckRow", "ModelCheckError", "DEFAULT_RTOL"]

#: Relative tolerance of a derivative against its finite-difference reference.
DEFAULT_RTOL = 1e-6
#: Largest central-difference step, relative to ``max(1, |q_b|)`` (then h/2, h/4).
FD_STEP = 1e-3
#: Random nearby states checked by :func:`check_model` by default (and by integrate: 1).
#: constraint Hessians are checked against every unit impulse e_a up to this many
#: constraints, against this many of them (drawn at random) and two random η beyond
MAX_UNIT_ETAS = 8
#: up to this n every evaluation of a callback goes through the guarded buffers
GUARD_ALL_CALLS_UP_TO_N = 64
DEFAULT_RANDOM_STATES = 3
#: Size of the random perturbation of the nearby states, relative to ``max(1, |q|)``.
DEFAULT_RADIUS = 1e-2
_NOISE = 10.0  # safety factor on the estimated finite-difference error
#: the bytes the differences by the parameters take at once (:func:`_fd_by_blocks`), and
#: the arrays of the derivative's size :func:`_fd` holds at once (three differences, two
#: extrapolations, the result and its error estimate)
FD_BLOCK_BYTES = 64 * 2**20
_FD_ARRAYS = 7
_ROUNDOFF = 100.0 * np.finfo(float).eps

# What each derivative callback is compared with (in the order the checks run: a second
# derivative is checked against its first derivative only if that one passed).
_REFERENCE = {
    "mass": "its transpose (symmetry)",
    "kinetic_grad": "FD of ½vᵀM(q)v (mass)",
    "momentum_jacobian": "FD of M(q)v (mass)",
    "potential_grad": "FD of potential",
    "constraint_jacobian": "FD of constraint",
    "kinetic_hessian": "FD of kinetic_grad",
    "potential_hessian": "FD of potential_grad",
    "constraint_hessian": "FD of Gᵀη (constraint_jacobian)",
    "force_jacobian_q": "FD in q of force",
    "force_jacobian_v": "FD in v of force",
    "constraint_time_derivative": "FD in t of constraint",
    **{f"{slot}/θ": f"FD in θ of {slot}" for slot in PARAM_SLOTS},  # names of _theta
}
_PARENT = {
    "kinetic_hessian": "kinetic_grad",
    "potential_hessian": "potential_grad",
    "constraint_hessian": "constraint_jacobian",
}


@dataclass(frozen=True)
class CheckRow:
    """One comparison of a callback with its finite-difference reference at one state.

    Attributes
    ----------
    callback : str
        The callback checked (a name of :data:`fastvi.model.SLOTS`).
    reference : str
        What it was compared with.
    state : int
        0 for the given state, ``1 …`` for the random nearby states.
    error : float
        ``max |D − D_FD|`` over the entries (absolute).
    scale : float
        ``max(|D|, |D_FD|)``: the size relative errors refer to.
    allowed : float
        The largest ``error`` that passes (absolute; see the module docstring).
    index : tuple of int
        Entry of ``D`` where the error is largest.
    status : {"ok", "wrong", "skipped"}
        ``"skipped"`` when the reference could not be computed (non-finite values near the
        state, or the first derivative it differentiates is itself wrong).
    note : str
        Extra detail (``η`` used, reason for skipping, non-finite output).
    """

    callback: str
    reference: str
    state: int
    error: float
    scale: float
    allowed: float
    index: tuple = ()
    status: str = "ok"
    note: str = ""

    @property
    def ok(self) -> bool:
        """True unless the callback disagreed with its reference."""
        return self.status != "wrong"

    @property
    def relative_error(self) -> float:
        """``error / scale`` (``error`` itself when the scale is zero)."""
        return self.error / self.scale if self.scale > 0 else self.error


@dataclass
class CheckReport:
    """Outcome of :func:`check_model`: one :class:`CheckRow` per comparison.

    ``str(report)`` is a table with one line per callback (the worst comparison over the
    states checked); ``report.ok`` is True when every callback agreed.

    Attributes
    ----------
    model_name : str
    rows : list of CheckRow
    states : list of (q, v) pairs
        The states checked: the given one first, then the random nearby ones.
    rtol : float
    evaluations : int
        Callback evaluations spent.
    wall_time : float
        Seconds spent (including compiling the model's callbacks if that had not happened).
    """

    model_name: str
    rows: list = field(default_factory=list)
    states: list = field(default_factory=list)
    rtol: float = DEFAULT_RTOL
    evaluations: int = 0
    wall_time: float = 0.0

    @property
    def ok(self) -> bool:
        """True when no callback disagreed with its reference."""
        return all(r.ok for r in self.rows)

    @property
    def checked(self) -> list[str]:
        """Callbacks compared at least once, in check order."""
        return list(dict.fromkeys(r.callback for r in self.rows if r.status != "skipped"))

    @property
    def failures(self) -> list[str]:
        """Callbacks that disagreed with their reference at some state, in check order."""
        return list(dict.fromkeys(r.callback for r in self.rows if not r.ok))

    def worst(self, callback: str) -> CheckRow:
        """The comparison of ``callback`` with the largest error relative to what is allowed."""
        rows = [r for r in self.rows if r.callback == callback]
        if not rows:
            raise KeyError(f"callback {callback!r} was not checked; checked: {self.checked}")
        return max(rows, key=_badness)

    def __str__(self) -> str:
        n_states = len(self.states)
        head = (f"derivative check of {self.model_name!r}: {n_states} state(s) (the given one and "
                f"{n_states - 1} random nearby), rtol = {self.rtol:.0e}, {self.evaluations} "
                f"callback evaluations, {self.wall_time * 1e3:.1f} ms")
        lines = [head, f"{'callback':<21} {'compared with':<32} {'max rel. error':>14} "
                       f"{'allowed':>9}  result"]
        for cb in dict.fromkeys(r.callback for r in self.rows):
            w = self.worst(cb)
            allowed = w.allowed / w.scale if w.scale > 0 else w.allowed
            res = {"ok": "ok", "wrong": "WRONG", "skipped": "skipped"}[w.status]
            if w.status == "wrong":
                where = "given state" if w.state == 0 else f"nearby state {w.state}"
                res += f" (at {where}, entry {list(w.index)}{'; ' + w.note if w.note else ''})"
            elif w.status == "skipped":
                res += f" ({w.note})"
            lines.append(f"{cb:<21} {w.reference:<32} {w.relative_error:>14.2e} {allowed:>9.1e}  {res}")
        if not self.rows:
            lines.append("(no derivative callbacks to check)")
        return "\n".join(lines)

    def raise_if_wrong(self) -> None:
        """Raise :class:`ModelCheckError` if any callback disagreed with its reference."""
        if not self.ok:
            raise ModelCheckError(self)


class ModelCheckError(ValueError):
    """A model callback writes outside its declared output, or disagrees with its reference.

    Sizes are checked first (a write past the end of ``out`` or into an input, an entry of
    ``out`` never set), then derivatives against finite differences of the functions they
    differentiate.

    Attributes
    ----------
    callback : str
        The first wrong callback, in check order (sizes first, then first derivatives, then
        second ones).
    callbacks : list of str
        Every wrong callback.
    report : CheckReport
        The comparison table up to the failure.
    """

    def __init__(self, report: CheckReport):
        self.report = report
        self.callbacks = report.failures
        self.callback = self.callbacks[0]
        size = [r for r in report.rows if r.status == "wrong" and r.reference.startswith(_SIZE_REFERENCE)]
        if size:  # a size / unset-entry error: the check stopped there
            risk = ("the structured solves would take the declared pattern and miss these entries"
                    if "_pattern`" in size[0].note else
                    "`check=False` would skip this check and let the kernels write out of bounds")
            super().__init__(f"model {report.model_name!r}: {size[0].note}. (Raised before any "
                             f"kernel ran; {risk}.)")
            return
        w = report.worst(self.callback)
        where = "the given state" if w.state == 0 else f"random nearby state {w.state}"
        detail = f"; {w.note}" if w.note else ""
        others = [c for c in self.callbacks if c != self.callback]
        also = f" Also wrong: {', '.join(f'`{c}`' for c in others)}." if others else ""
        super().__init__(
            f"model {report.model_name!r}: callback `{self.callback}` disagrees with its reference "
            f"({w.reference}): max relative error {w.relative_error:.2e} at {where}, entry "
            f"{list(w.index)}{detail} (allowed {w.allowed / w.scale if w.scale > 0 else w.allowed:.1e})."
            f"{also} Fix the callback, or pass check=False to fastvi.integrate to skip this check."
            f"\n{report}"
        )


def _theta(slot: str) -> str:
    """The name of the derivative by the parameters of the callback ``slot`` in reports."""
    return f"{slot}/θ"


def _badness(row: CheckRow) -> float:
    if row.status == "skipped":
        return -1.0
    return row.error / row.allowed if row.allowed > 0 else (np.inf if row.error > 0 else 0.0)


# ----------------------------------------------------------------------------- guarded evaluation
# The callbacks are compiled with their output sizes baked in and no bounds checks, so a
# callback that writes past its declared output writes into whatever memory follows. Here
# every evaluation gets one buffer laid out as
#
#     out (declared size) | guard | q | guard | v | guard | params | guard
#
# filled with a NaN whose payload no computation produces: anything the callback writes
# outside the declared `out` lands in a guard zone (or an input) of our own buffer and shows
# up as a changed bit pattern, instead of corrupting the heap. The guard is longer than any
# plausible mistake: a transposed (n, m) write into an (m, n) output reaches flat index
# (n−1)·n + m − 1 < n², a loop over the wrong count at most n² as well.
GUARD_FILL = np.array([0x7FF80BADF00D0001, 0x7FF80BADF00D0002], dtype=np.uint64)
GUARD_MARGIN = 64
_OK, _UNSET, _OUTSIDE = 0, 1, 2
#: a callback with a declared pattern (``constraint_jacobian_pattern``) wrote a non-zero
#: outside it (set in Python after the guarded call, which knows nothing of patterns)
_OFF_PATTERN = 3
_ENTRY: list = []  # compiled entry point of guarded_call, once known

_DIMS = dict(mass=("n", "n"), kinetic_grad=("n",), potential=(), potential_grad=("n",),
             constraint=("m",), constraint_jacobian=("m", "n"), potential_hessian=("n", "n"),
             constraint_hessian=("n", "n"), kinetic_hessian=("n", "n"), momentum_jacobian=("n", "n"),
             force=("n",), force_jacobian_q=("n", "n"), force_jacobian_v=("n", "n"),
             constraint_time_derivative=("m",))
_DIMS.update({_theta(slot): ("k",) + _DIMS[slot] for slot in PARAM_SLOTS})
_MEANING = dict(constraint_jacobian="out[a, b] = ∂g_a/∂q_b", momentum_jacobian="out[a, b] = ∂(M v)_a/∂q_b")
_SIZE_REFERENCE = "declared output shape"


@njit
def _intact(f, u, start, end, src, length, fill):
    """``f[start:start+length]`` still equals ``src`` and the guard up to ``end`` the fill."""
    for i in range(length):
        if f[start + i] != src[i] and not (np.isnan(f[start + i]) and np.isnan(src[i])):
            return False
    for i in range(start + length, end):
        if u[i] != fill:
            return False
    return True


@njit
def guarded_call(fn, f, u, q, v, p, lay, fill, zero):
    """Evaluate ``fn`` with its ``out``, ``q``, ``v``, ``params`` inside the guarded buffer
    ``f`` (``u`` is the same memory as uint64), ``out`` zero at the flat entries ``zero``
    (what the kernels zero for it) and the fill elsewhere, and say whether it wrote exactly
    the declared output: ``_OK``, ``_UNSET`` (a declared entry still holds the fill), or
    ``_OUTSIDE`` (a guard or an input changed). Compiled, so a guarded evaluation costs
    about what a plain one does (the dispatch from Python dominates both)."""
    size, nq, nv, npar, qs, vs, ps = lay[0], lay[1], lay[2], lay[3], lay[4], lay[5], lay[6]
    for i in range(u.shape[0]):
        u[i] = fill
    for i in zero:
        f[i] = 0.0
    for i in range(nq):
        f[qs + i] = q[i]
    for i in range(nv):
        f[vs + i] = v[i]
    for i in range(npar):
        f[ps + i] = p[i]
    fn(ptr(f[qs:]), ptr(f[vs:]), ptr(f[ps:]), ptr(f))
    if not (_intact(f, u, size, qs, q, 0, fill) and _intact(f, u, qs, vs, q, nq, fill)
            and _intact(f, u, vs, ps, v, nv, fill) and _intact(f, u, ps, u.shape[0], p, npar, fill)):
        return _OUTSIDE
    for i in range(size):
        if u[i] == fill:
            return _UNSET
    return _OK


_NOTHING_ZEROED = np.zeros(0, dtype=np.int64)


class _Callbacks:
    """The model's compiled callbacks, evaluated from Python into guarded buffers.

    Every call checks that the callback wrote each declared entry of ``out`` and nothing
    else; on the first violation :meth:`diagnose` re-runs it with two different fill values
    and raises :class:`ModelCheckError` saying what was written.
    """

    def __init__(self, model: Model, params: np.ndarray, report: "CheckReport", t: float = 0.0,
                 by_params: bool = False):
        cfs = model.kernel_arguments()[0]
        self.fn = dict(zip(SLOTS, cfs))
        self.direct = {}  # the callbacks called by address (large models, :meth:`__call__`)
        self.present = set(model.callbacks)
        self.shape = {slot: model.output_shape(slot) for slot in SLOTS}
        if by_params and model.param_derivatives:
            # the derivatives by θ given as functions, under their report names (`<slot>/θ`)
            k = model.params.shape[0]
            for slot, fn, given in zip(PARAM_SLOTS, *model.param_derivative_data()[:2]):
                self.fn[_theta(slot)] = fn
                self.shape[_theta(slot)] = (k,) + model.output_shape(slot)
                if given:
                    self.present.add(_theta(slot))
        # the kernels' parameter vector: a time-aware model reads t from a hidden last entry
        self.p = model.kernel_params(params, t)
        self.t = float(t)
        self.timed = model.timed
        self.n, self.m, self.k = model.n, model.m, self.p.shape[0]
        self.report = report
        self.count = 0
        self.sized = set()  # slots whose guarded size check passed
        # slots with a declared pattern of non-zeros: the kernels hand them an `out` that is
        # zero outside it, and they need write only the pattern (Model docstring)
        self.pattern = {}
        if model.constraint_jacobian_pattern is not None:
            self.pattern["constraint_jacobian"] = model.constraint_jacobian_pattern.ravel()
        # ... and slots handed an `out` zeroed over their pattern too, which write only their
        # non-zeros there: the constraint Hessian, whose pattern (implied by G's) holds
        # entries that vanish all the same (a chain's ∂²g/∂x∂y)
        self.zeroed = {}  # slot: the flat entries handed zeroed
        if model.constraint_hessian_pattern is not None:
            self.pattern["constraint_hessian"] = model.constraint_hessian_pattern.ravel()
            self.zeroed["constraint_hessian"] = np.flatnonzero(self.pattern["constraint_hessian"])
        if model.force_jacobian_pattern is not None:
            for slot in ("force_jacobian_q", "force_jacobian_v"):
                self.pattern[slot] = model.force_jacobian_pattern.ravel()
        for slot, mask in model.param_patterns.items() if by_params else ():
            self.pattern[_theta(slot)] = mask.ravel()
        n, m = self.n, self.m
        self.pad = n * n + 2 * n + GUARD_MARGIN
        self.layout, self.length, self.size = {}, {}, {}
        for slot, shape in self.shape.items():
            size = int(np.prod(shape)) if shape else 1
            nv = m if slot == "constraint_hessian" else n
            starts, at = [], 0
            for length in (size, n, nv, self.k):  # out, q, v, params, each followed by a guard
                starts.append(at)
                at += length + self.pad
            self.layout[slot] = np.array([size, n, nv, self.k] + starts[1:], dtype=np.int64)
            self.size[slot] = size
            self.length[slot] = at
        # one buffer for every slot, each guarded evaluation filling the head it needs, as
        # long as the longest slot evaluated so far: the guards take four n² each, and a
        # buffer per slot held hundreds of MB for a large model (and reserved k n² for the
        # derivatives by θ of its n × n slots, which few models give)
        self._buffer = np.empty(0)

    def _run(self, slot: str, q, v, fill: int):
        """One guarded evaluation: ``(status, buffer as float64, as uint64)``, the buffer
        valid until the next evaluation."""
        if self._buffer.shape[0] < self.length[slot]:
            self._buffer = np.empty(self.length[slot])
        f = self._buffer[:self.length[slot]]
        u = f.view(np.uint64)
        lay = self.layout[slot]
        # the entry point below takes these as C-contiguous float64 vectors without checking
        q = np.ascontiguousarray(q, dtype=np.float64)
        v = q if v is None else np.ascontiguousarray(v, dtype=np.float64)
        args = (self.fn[slot], f, u, q, v[:lay[2]], self.p, lay, GUARD_FILL[fill],
                self.zeroed.get(slot, _NOTHING_ZEROED))
        if _ENTRY:
            status = _ENTRY[0](*args)
        else:
            with quiet():
                status = guarded_call(*args)
            # the dispatcher re-derives the type of the callback argument on every call (15 µs,
            # most of an evaluation); every argument here has one fixed type, so later calls go
            # straight to the compiled entry point
            _ENTRY[:] = [cres.entry_point for cres in guarded_call.overloads.values()][:1]
        self.count += 1
        mask = self.pattern.get(slot)
        if mask is not None and status in (_OK, _UNSET):
            status = self._apply_pattern(slot, f, u, mask, GUARD_FILL[fill])
        return status, f, u

    def _apply_pattern(self, slot: str, f, u, mask, fill):
        """After a guarded call of a callback with a declared pattern: entries outside it that
        the callback left alone become the zeros the kernels provide; returns ``_OFF_PATTERN``
        if it wrote a non-zero outside the pattern, ``_UNSET`` if it left an entry of the
        pattern unset, else ``_OK``."""
        size = self.size[slot]
        out, bits = f[:size], u[:size]
        off = ~mask
        zeroed = slot in self.zeroed
        left = bits == fill
        out[left if zeroed else off & left] = 0.0
        if np.any(out[off] != 0.0):
            return _OFF_PATTERN
        return _UNSET if not zeroed and np.any(bits[mask] == fill) else _OK

    def at(self, slot: str, t: float, q: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """``self(slot, q, v)`` at time ``t`` (the check's own time is restored after)."""
        if not self.timed or t == self.t:
            return self(slot, q, v)
        self.p[-1] = t
        try:
            return self(slot, q, v)
        finally:
            self.p[-1] = self.t

    def with_params(self, slot: str, params: np.ndarray, q: np.ndarray,
                    v: np.ndarray | None = None) -> np.ndarray:
        """``self(slot, q, v)`` with the parameters ``params`` (the check's own are restored
        after)."""
        k = params.shape[0]
        kept = self.p[:k].copy()
        self.p[:k] = params
        try:
            return self(slot, q, v)
        finally:
            self.p[:k] = kept

    def __call__(self, slot: str, q: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        if slot in self.sized and self.n > GUARD_ALL_CALLS_UP_TO_N:
            # large models (issue 12): the guard of every call costs O(n²), the finite
            # differences make O(n) calls, so once the two guarded calls of check_size passed
            # the slot is evaluated plainly (measured 91 s → s for chain(256), n = 512)
            out = np.zeros(self.shape[slot] or (1,))
            q = np.ascontiguousarray(q, dtype=np.float64)
            v = q if v is None else np.ascontiguousarray(v, dtype=np.float64)
            direct = self.direct.get(slot)
            if direct is None:
                direct = self.direct[slot] = direct_callback(self.fn[slot])
            direct(q.ctypes.data, v.ctypes.data, self.p.ctypes.data, out.ctypes.data)
            self.count += 1
            mask = self.pattern.get(slot)
            if mask is not None and np.any(out.ravel()[~mask] != 0.0):
                self.diagnose(slot, q, v)
            return out if self.shape[slot] else out.reshape(())
        status, f, _ = self._run(slot, q, v, 0)
        if status != _OK:
            self.diagnose(slot, q, v)
        shape = self.shape[slot]
        out = f[:self.size[slot]].copy()
        return out.reshape(shape) if shape else out.reshape(())

    def sized_all(self) -> None:
        """Every slot has passed :meth:`check_size`: a large model calls its callbacks by
        address from here on, and the guarded buffer (four ``n²`` guards, 160 MiB for a
        chain of 1 024 links) is let go; a diagnosis allocates it again."""
        if self.n > GUARD_ALL_CALLS_UP_TO_N:
            self._buffer = np.empty(0)

    def check_size(self, slot: str, q: np.ndarray, v: np.ndarray | None = None) -> None:
        """Two evaluations with different fills: every declared entry written, nothing else,
        and the same values both times (a value read from ``out`` before it was set differs)."""
        size = int(self.layout[slot][0])
        s0, _, u = self._run(slot, q, v, 0)
        first = u[:size].copy()
        s1, _, u = self._run(slot, q, v, 1)
        if s0 != _OK or s1 != _OK or not np.array_equal(first, u[:size]):
            self.diagnose(slot, q, v)
        self.sized.add(slot)

    def diagnose(self, slot: str, q, v=None, state: int = 0) -> None:
        """Raise :class:`ModelCheckError` if ``slot`` writes outside its declared output,
        into its inputs, or leaves a declared entry unset (two calls, two fill values)."""
        size, nq, nv, npar, qs, vs, ps = (int(x) for x in self.layout[slot])
        after = []
        for fill in (0, 1):
            _, f, u = self._run(slot, q, v, fill)
            expected = np.full(u.shape, GUARD_FILL[fill], dtype=np.uint64)
            ef = expected.view(np.float64)
            ef[qs:qs + nq] = q
            ef[vs:vs + nv] = (q if v is None else v)[:nv]
            ef[ps:ps + npar] = self.p
            after.append((u.copy(), expected))
        (a0, b0), (a1, b1) = after
        written = (a0 != b0) | (a1 != b1)
        problem = None
        past = np.flatnonzero(written[size:qs]) + size
        if past.size:
            problem = self._past_end(slot, past, written[:qs])
        if problem is None:
            ends = (vs, ps, written.shape[0])
            vname = "eta" if slot == "constraint_hessian" else "v"
            for (name, start, length), end in zip((("q", qs, nq), (vname, vs, nv), ("params", ps, npar)), ends):
                hit = np.flatnonzero(written[start:end])
                if hit.size:
                    inside = hit[hit < length]
                    what = (f"changed entry {int(inside[0])} of its input `{name}`" if inside.size else
                            f"wrote past the end of its input `{name}` ({length} entries)")
                    problem = (f"`{slot}` {what}; a callback must write only into `out` "
                               "(copy an input before modifying it)", int(hit[0]))
                    break
        mask = self.pattern.get(slot)
        if problem is None and mask is not None:
            off = np.flatnonzero(~mask & ((a0[:size].view(np.float64) != 0.0)
                                          | (a1[:size].view(np.float64) != 0.0)))
            if off.size:
                idx = [self._index(slot, int(i)) for i in off[:4]]
                more = f" and {off.size - 4} more" if off.size > 4 else ""
                declared = (f"param_patterns[{slot[:-2]!r}]" if slot.endswith("/θ")
                            else "force_jacobian_pattern" if slot.startswith("force_jacobian")
                            else "constraint_jacobian_pattern" if slot == "constraint_hessian"
                            else f"{slot}_pattern")
                where = ("the pairs of coordinates that share a constraint in the model's "
                         f"`{declared}`" if slot == "constraint_hessian" else
                         f"the model's `{declared}`")
                problem = (f"`{slot}` wrote non-zeros at {', '.join(map(str, idx))}{more}, outside "
                           f"{where} ({int(mask.sum())} entries declared): add the "
                           "entries to the pattern, or fix the function", int(off[0]))
        if problem is None:
            left = (a0[:size] == GUARD_FILL[0]) & (a1[:size] == GUARD_FILL[1])
            if slot in self.zeroed:  # what the kernels zero, the callback may leave
                left[:] = False
            elif mask is not None:
                left &= mask
            unset = np.flatnonzero(left)
            if unset.size:
                problem = (self._unset(slot, unset), int(unset[0]))
        if problem is None:
            stale = np.flatnonzero(a0[:size] != a1[:size])
            if stale.size:
                idx = self._index(slot, int(stale[0]))
                problem = (f"`{slot}` entry {idx} depends on what `out` held before the call (read "
                           "before it was set, e.g. `out[i] += …`); `out` is not zeroed for you: "
                           "set every entry", int(stale[0]))
        if problem is None:  # pragma: no cover - the fast check and this one see the same writes
            problem = (f"`{slot}` wrote outside its declared output", 0)
        message, flat = problem
        row = CheckRow(slot, f"{_SIZE_REFERENCE} {self.shape[slot] or (1,)}", state, np.inf, 0.0, 0.0,
                       (flat,), "wrong", message)
        self.report.rows.append(row)
        self.report.evaluations = self.count
        raise ModelCheckError(self.report)

    def _declares(self, slot: str) -> str:
        dims = dict.fromkeys(_DIMS[slot])
        size = dict(n=self.n, m=self.m, k=self.k - 1)  # self.k counts the hidden time entry
        return ", ".join(f"{d} = {size[d]}" for d in dims)

    def _index(self, slot: str, flat: int) -> list:
        shape = self.shape[slot]
        return [int(i) for i in np.unravel_index(flat, shape)] if shape else [0]

    def _past_end(self, slot: str, past: np.ndarray, written: np.ndarray):
        shape = self.shape[slot]
        count = int(past.max()) + 1
        decl = self._declares(slot)
        if len(shape) < 2:
            dim = _DIMS[slot][0] if _DIMS[slot] else "n"
            return (f"`{slot}` wrote {count} entries but the model declares {decl} (out shape "
                    f"{shape or (1,)}); check `{dim}` or the function", int(past[0]))
        msg = (f"`{slot}` wrote past the end of its output: up to flat index {count - 1} ({count} "
               f"entries) but the model declares {decl} (out shape {shape}, {int(np.prod(shape))} "
               "entries, C order); wrong shape or transposed?")
        if len(shape) > 2:  # a derivative by θ of a matrix: (k, rows, cols)
            return msg, int(past[0])
        rows, cols = shape
        # the pattern of an (cols, rows) array written as out[b, a] into the (rows, cols) buffer
        transposed = np.zeros(written.shape, dtype=bool)
        transposed[(np.arange(cols)[:, None] * cols + np.arange(rows)[None, :]).ravel()] = True
        if rows != cols and np.array_equal(written, transposed):
            meaning = f" ({_MEANING[slot]})" if slot in _MEANING else ""
            msg += (f" The entries written are exactly those of a ({cols}, {rows}) array: the "
                    f"transpose was written; write the ({rows}, {cols}) matrix{meaning}")
        return msg, int(past[0])

    def _unset(self, slot: str, unset: np.ndarray) -> str:
        idx = [self._index(slot, int(i)) for i in unset[:4]]
        more = f" and {unset.size - 4} more" if unset.size > 4 else ""
        shape = self.shape[slot] or (1,)
        if len(shape) == 1:
            dim = _DIMS[slot][0]
            hint = f"check `{dim}` or the function"
        else:
            hint = f"start with `out[{', '.join(':' * len(shape))}] = 0.0` if most entries vanish"
        return (f"`{slot}` never wrote entr{'y' if unset.size == 1 else 'ies'} "
                f"{', '.join(map(str, idx))}{more} of its output (out shape {shape}, the model declares "
                f"{self._declares(slot)}), or only updated it (`out[i] += …`); `out` is not zeroed "
                f"for you, every entry must be set on every call: {hint}")


def _absmax(x: np.ndarray) -> float:
    return float(np.abs(x).max()) if x.size else 0.0


def _richardson(f, q: np.ndarray, cols, quotient):
    """The coordinates ``cols`` of ``q`` moved together by ``±h/k``, ``h = FD_STEP ·
    max(1, |q_b|)``, ``k = 1, 2, 4``; ``quotient(fp, fm, qp, qm)`` forms each central
    difference quotient from the evaluations and the points (whose rounded steps it
    divides by). Returns the twice Richardson-extrapolated quotient, its error estimate
    (the difference of the last two extrapolations), ``max |f|`` over the evaluations and
    the smallest step."""
    base = FD_STEP * np.maximum(1.0, np.abs(q[cols]))
    D, fscale, hmin = [], 0.0, np.inf
    for k in (1.0, 2.0, 4.0):
        qp, qm = q.copy(), q.copy()
        qp[cols] += base / k
        qm[cols] -= base / k
        fp, fm = np.asarray(f(qp), dtype=float), np.asarray(f(qm), dtype=float)
        fscale = max(fscale, _absmax(fp), _absmax(fm))
        D.append(quotient(fp, fm, qp, qm))
        hmin = min(hmin, float((qp[cols] - q[cols]).min()))
    r1 = (4.0 * D[1] - D[0]) / 3.0
    r2 = (4.0 * D[2] - D[1]) / 3.0
    return r2, np.abs(r2 - r1), fscale, hmin


def _fd(f, q: np.ndarray):
    """Richardson-extrapolated central differences of ``f`` along each coordinate.

    Returns ``(J, est, fscale, hmin)`` with ``J[..., b] ≈ ∂f/∂q_b``, ``est`` the estimated
    error of ``J``, ``fscale = max |f|`` over the evaluations, and the smallest step.
    """
    n = q.shape[0]
    f0 = np.asarray(f(q), dtype=float)
    J = np.empty(f0.shape + (n,))
    est = np.empty_like(J)
    fscale, hmin = _absmax(f0), np.inf
    for b in range(n):
        J[..., b], est[..., b], fs, hm = _richardson(
            f, q, [b], lambda fp, fm, qp, qm: (fp - fm) / (qp[b] - qm[b]))
        fscale, hmin = max(fscale, fs), min(hmin, hm)
    return J, est, fscale, hmin


def _fd_by_groups(f, q: np.ndarray, pattern: np.ndarray):
    """:func:`_fd` of ``f(q)`` (m, ...) whose row ``c`` depends only on the coordinates of
    row ``c`` of ``pattern`` (m, n): a constraint, or a constraint's gradient, on the
    coordinates the constraint involves.

    Coordinates that share no row are perturbed together (Curtis–Powell–Reid groups, a
    greedy colouring of ``patternᵀ pattern``): each row meets at most one coordinate ``b``
    of a group, and its differences are ``∂f_c/∂q_b``. A chain of links needs four groups
    instead of ``n`` coordinates. Yields ``(rows, b, ref, est)`` per group — the rows the
    group moves, the coordinate of each, and their derivatives and error estimates
    ``(len(rows), ...)`` — then, last, ``(fscale, hmin)`` as :func:`_fd` gives them."""
    m, n = pattern.shape
    P = sp.csr_matrix(pattern.astype(np.int64))
    colour = greedy_colours(((P.T @ P) > 0).tolil().rows)  # coordinates sharing a row
    f0 = np.asarray(f(q), dtype=float)
    fscale, hmin = _absmax(f0), np.inf
    for g in range(int(colour.max()) + 1 if n else 0):
        cols = np.flatnonzero(colour == g)
        rr, bb = np.nonzero(pattern[:, cols])
        if rr.size == 0:
            continue
        b = cols[bb]  # the one coordinate of the group in each of the rows rr
        per_row = (-1,) + (1,) * (f0.ndim - 1)
        ref, est, fs, hm = _richardson(
            f, q, cols, lambda fp, fm, qp, qm: (fp[rr] - fm[rr]) / (qp[b] - qm[b]).reshape(per_row))
        fscale, hmin = max(fscale, fs), min(hmin, hm)
        yield rr, b, ref, est
    yield fscale, hmin


def _fd_contracted_by_groups(G, q: np.ndarray, E: np.ndarray, pattern: np.ndarray):
    r""":func:`_fd` of the constraint Jacobian ``G(q)`` (m, n) by :func:`_fd_by_groups`,
    contracted with each row ``η_j`` of ``E``: ``(contracted, fscale, hmin)``, where
    ``contracted(j)`` gives ``(ref, est)`` with ``ref ≈ Σ_c η_jc ∂G_c/∂q`` (the constraint
    Hessian, (n, n)) and ``est = Σ_c |η_jc| est_c``. Of each group's differences only the
    entries of G's pattern are kept, ``∂G_ca/∂q_b`` for the coordinates ``a`` of row ``c``
    (G is zero elsewhere at every q: the guarded calls hold it to its pattern), and each
    contraction is formed when asked: two ``n × n`` arrays at a time, nothing of size
    ``m n²``, ``len(E) n²`` or ``m n`` a group."""
    n = pattern.shape[1]
    P = sp.csr_matrix(pattern)
    kept = []  # per group: (rows c, their coordinate b, the column a, ∂G_ca/∂q_b, its error)
    fscale, hmin = 0.0, np.inf
    for item in _fd_by_groups(G, q, pattern):
        if len(item) == 2:
            fscale, hmin = item
            continue
        rr, b, r2, err = item
        counts = np.diff(P.indptr)[rr]
        at = np.repeat(np.arange(rr.size), counts)  # each kept entry's place in rr
        a = np.concatenate([P.indices[P.indptr[c]:P.indptr[c + 1]] for c in rr])
        kept.append((rr[at], b[at], a, r2[at, a], err[at, a]))
    absE = np.abs(E)

    def contracted(j):
        # accumulated transposed, (b, a): ref_t[b, a] += η_jc ∂G_ca/∂q_b over the rows c
        ref_t, est_t = np.zeros((n, n)), np.zeros((n, n))
        for c, b, a, r2, err in kept:
            np.add.at(ref_t, (b, a), E[j, c] * r2)
            np.add.at(est_t, (b, a), absE[j, c] * err)
        return ref_t.T, est_t.T

    return contracted, fscale, hmin


def _declared_zero(callback: str, state: int, f, x: np.ndarray, rtol: float, note: str,
                   rng: np.random.Generator) -> CheckRow:
    """A derivative declared 0 (``potential_hessian=0``, ``force_jacobian_q=0``, a ``0`` by
    θ) against differences of ``f`` along one random direction ``w`` of ``x``:
    ``d/dt f(x + t w) = 0`` for every ``w``, one difference instead of one per entry of
    ``x``. A derivative that is not zero is non-zero along almost every direction; only
    then do the callers difference entry by entry, to name it. ``w`` is drawn from
    ``rng`` (the check's own, after its states and impulses: reproducible by ``seed``)."""
    w = rng.standard_normal(x.shape[0]) * np.maximum(1.0, np.abs(x))
    J, est, fs, hm = _fd(lambda t: f(x + t[0] * w), np.zeros(1))
    return _compare(callback, state, np.zeros(J.shape[:-1]), (J[..., 0], est[..., 0], fs, hm),
                    rtol, note + ", along a random direction")


def _symmetry(M: np.ndarray, k: int) -> CheckRow:
    if not np.all(np.isfinite(M)):
        return CheckRow("mass", _REFERENCE["mass"], k, np.inf if k == 0 else np.nan, 0.0, 0.0, (),
                        "wrong" if k == 0 else "skipped", "returned non-finite values")
    asym = np.abs(M - M.T)
    idx = tuple(int(i) for i in np.unravel_index(int(np.argmax(asym)), asym.shape))
    scale = float(np.abs(M).max())
    allowed = _ROUNDOFF * scale  # a symmetric formula gives exact symmetry
    return CheckRow("mass", _REFERENCE["mass"], k, float(asym.max()), scale, allowed, idx,
                    "ok" if asym.max() <= allowed else "wrong")


def _compare(callback: str, state: int, exact: np.ndarray, fd, rtol: float, note: str = "") -> CheckRow:
    """One row of the report: ``exact`` against the reference ``fd = (ref, est, fscale,
    hmin)`` (:func:`_fd`)."""
    ref = fd[0]
    row = _compare_blocks(callback, state, [(exact, *fd)], rtol, note)
    exact = np.asarray(exact, dtype=float)
    if row.status == "wrong" and np.isfinite(row.error) and exact.ndim == 2 \
            and exact.shape[0] == exact.shape[1] > 1 \
            and float(np.abs(exact.T - ref).max()) <= row.allowed:
        row = replace(row, note=(note + "; " if note else "")
                      + "it matches the transpose of the reference: wrong shape or transposed?")
    return row


def _compare_blocks(callback: str, state: int, blocks, rtol: float, note: str = "") -> CheckRow:
    """:func:`_compare` of arrays that come in blocks along their first axis: ``blocks``
    yields ``(exact, ref, est, fscale, hmin)`` for each (:func:`_fd_by_blocks`), and the
    row is that of the whole arrays, with one block in memory at a time."""
    reference = _REFERENCE[callback]
    error, scale, noise, idx, offset, fscale, hmin = 0.0, 0.0, 0.0, None, 0, 0.0, np.inf
    for ex, rf, es, fs, hm in blocks:
        ex = np.asarray(ex, dtype=float)
        if not np.all(np.isfinite(ex)):
            bad = np.argwhere(~np.isfinite(ex))[0] if ex.ndim else ()
            bad = tuple(int(i) + (offset if j == 0 else 0) for j, i in enumerate(bad))
            if state > 0:  # a random nearby state may lie outside the model's domain
                return CheckRow(callback, reference, state, np.nan, 0.0, 0.0, bad, "skipped",
                                "non-finite values at this nearby state")
            return CheckRow(callback, reference, state, np.inf, 0.0, 0.0, bad, "wrong",
                            (note + "; " if note else "") + "returned non-finite values")
        if not (np.all(np.isfinite(rf)) and np.all(np.isfinite(es))):
            return CheckRow(callback, reference, state, np.nan, 0.0, 0.0, (), "skipped",
                            "reference not finite near this state")
        if ex.size:
            diff = np.abs(ex - rf)
            at = np.unravel_index(int(np.argmax(diff)), diff.shape)
            if idx is None or float(diff[at]) > error:
                error = float(diff[at])
                idx = tuple(int(i) + (offset if j == 0 else 0) for j, i in enumerate(at))
            scale = max(scale, float(np.abs(ex).max()), float(np.abs(rf).max()))
            noise = max(noise, float(es.max()) if es.size else 0.0)
        fscale, hmin = max(fscale, fs), min(hmin, hm)
        offset += ex.shape[0] if ex.ndim else 0
    allowed = rtol * scale + _NOISE * noise + _ROUNDOFF * fscale / hmin
    return CheckRow(callback, reference, state, error, scale, allowed, idx or (),
                    "ok" if error <= allowed else "wrong", note)


def _fd_by_blocks(f, prm: np.ndarray, out_size: int, budget: int = None):
    """:func:`_fd` of ``f(θ)`` by the parameters, in blocks of parameters whose differences
    take about ``budget`` bytes (:data:`FD_BLOCK_BYTES`): yields ``(lo, hi, ref, est,
    fscale, hmin)`` for ``θ_lo … θ_{hi−1}``, ``ref`` and ``est`` of shape
    ``(hi − lo, *f.shape)`` (the derivative's layout, ``out[l] = ∂f/∂θ_l``). A large
    model's ``G`` (m, n) by its k parameters would take ``8 k m n`` bytes in each of the
    differences' arrays at once."""
    budget = FD_BLOCK_BYTES if budget is None else budget
    k = prm.shape[0]
    step = max(1, budget // (_FD_ARRAYS * 8 * max(out_size, 1)))
    for lo in range(0, k, step):
        hi = min(k, lo + step)

        def part(th, lo=lo, hi=hi):
            full = prm.copy()
            full[lo:hi] = th
            return f(full)

        J, est, fscale, hmin = _fd(part, prm[lo:hi])
        yield lo, hi, np.moveaxis(J, -1, 0), np.moveaxis(est, -1, 0), fscale, hmin


def check_model(model: Model, q, v=None, *, params=None, t: float = 0.0,
                n_random: int = DEFAULT_RANDOM_STATES, radius: float = DEFAULT_RADIUS,
                rtol: float = DEFAULT_RTOL, seed: int = 0, raise_on_error: bool = True,
                param_derivatives: bool = True) -> CheckReport:
    r"""Compare every derivative callback of ``model`` with finite differences.

    Parameters
    ----------
    model : Model
    q : array_like (n,)
        The configuration to check at. It need not satisfy the constraints.
    v : array_like (n,), optional
        The velocity for the kinetic-energy derivatives (default: random, ``~N(0, 1)``).
    params : array_like (k,), optional
        Parameter vector (default: the model's).
    t : float, default 0.0
        The time of the check, for a model with forces or time-dependent callbacks
        (``∂g/∂t`` is compared with a difference in ``t`` around it).
    n_random : int, default 3
        Random nearby states checked in addition to ``(q, v)``:
        ``q + radius·max(1, |q|)·ξ``, ``v + radius·max(1, |v|)·ξ'`` with ``ξ, ξ' ~ N(0, I)``.
    radius : float, default 1e-2
        Relative size of the perturbation of the nearby states.
    rtol : float, default 1e-6
        Relative tolerance (on top of the estimated finite-difference error).
    seed : int, numpy.random.Generator or None, default 0
        Seed of the random nearby states, of the random ``η`` and of the random directions
        a declared zero is compared along (reproducible reports), as
        :func:`numpy.random.default_rng` takes it.
    raise_on_error : bool, default True
        Raise :class:`ModelCheckError` when a callback disagrees; otherwise only return the
        report (``report.ok`` is False).
    param_derivatives : bool, default True
        Also compare the model's derivatives by the parameters (``Model(param_derivatives=
        ...)``, compiled here if they were not yet) with central differences of their
        callbacks in each parameter. The automatic check of :func:`fastvi.integrate` leaves
        them out (a plain run never compiles them); a model that passed with them has
        ``model.param_derivatives_checked`` set.

    Returns
    -------
    CheckReport
        ``print(report)`` shows one line per callback: what it was compared with, the
        largest relative error over the states, the tolerance, and the verdict.

    Raises
    ------
    ModelCheckError
        Naming the first wrong callback (``.callback``) with the report attached. A callback
        that writes outside its declared output (or into an input), or leaves an entry of it
        unset, raises before any finite-difference comparison, even with
        ``raise_on_error=False``: its values cannot be trusted and calling it from a kernel
        would corrupt memory.

    Notes
    -----
    The finite-difference steps assume coordinates of order one (``h = 10⁻³ max(1, |q_b|)``):
    for a model in, say, micrometres the reference is coarse, its error estimate widens the
    tolerance, and only gross mistakes are caught; choose units accordingly. Non-finite
    values at a random nearby state (outside the model's domain) skip that state; at the
    given state they count as wrong.

    A model that passes is marked as checked, and :func:`fastvi.integrate` then skips its
    automatic check. Costs ``≈ 6 n`` callback evaluations per derivative and state (a few
    microseconds each): milliseconds for small models, far below compiling the callbacks.

    Examples
    --------
    >>> import fastvi
    >>> model = fastvi.scenes.pendulum()
    >>> report = model.check([0.6, -0.8], [0.8, 0.6])
    >>> report.ok
    True
    """
    t0 = time.perf_counter()
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    n, m = model.n, model.m
    q = _vector(q, "q", n)
    rng = np.random.default_rng(seed)
    v = rng.standard_normal(n) if v is None else _vector(v, "v", n)
    prm = model.params if params is None else _vector(params, "params", model.params.shape[0])
    if isinstance(n_random, bool) or not isinstance(n_random, (int, np.integer)) or n_random < 0:
        raise ValueError(f"`n_random` must be a non-negative integer, got {n_random!r}")
    if not (isinstance(radius, (int, float, np.floating)) and 0 < radius < 1):
        raise ValueError(f"`radius` must be in (0, 1), got {radius!r}")
    if not (isinstance(rtol, (int, float, np.floating)) and 0 < rtol < 1):
        raise ValueError(f"`rtol` must be in (0, 1), got {rtol!r}")

    states = [(q, v)]
    qs, vs = max(1.0, float(np.abs(q).max())), max(1.0, float(np.abs(v).max()))
    for _ in range(int(n_random)):
        states.append((q + radius * qs * rng.standard_normal(n), v + radius * vs * rng.standard_normal(n)))
    # every unit impulse e_a for small m; for large mechanisms a random subset of them and
    # random dense η: each η costs an (n, n) comparison
    units = range(m) if m <= MAX_UNIT_ETAS else sorted(rng.choice(m, MAX_UNIT_ETAS, replace=False))
    etas = [np.eye(m)[a] for a in units]
    n_units = len(etas)
    etas += [rng.standard_normal(m) for _ in range(1 if m <= MAX_UNIT_ETAS else 2)] if m > 1 else []
    E = np.array(etas).reshape(len(etas), m)
    report = CheckReport(model.name, states=states, rtol=float(rtol))
    if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not np.isfinite(t):
        raise ValueError(f"`t` must be a finite float, got {t!r}")
    by_params = bool(param_derivatives) and bool(model.param_derivatives)
    cb = _Callbacks(model, prm, report, float(t), by_params)
    has = cb.present.__contains__

    # 1. Sizes, before anything else: every callback once, into guarded buffers filled with
    # two different values (entries written past the end, into the inputs, or never).
    eta0 = 1.0 + np.arange(m) / max(m, 1)
    for slot in SLOTS + tuple(map(_theta, PARAM_SLOTS)):
        if has(slot):
            cb.check_size(slot, q, eta0 if slot == "constraint_hessian" else v)
    cb.sized_all()

    # 2. First derivatives against the functions they differentiate, at every state, then
    # 3. second derivatives against the first ones, only where that first one passed
    # everywhere: a wrong G makes the FD reference of the constraint Hessian wrong too.
    def each_state(slot, compare):
        for k, (qk, vk) in enumerate(states):
            rows = compare(k, qk, vk)
            report.rows.extend(rows if isinstance(rows, list) else [rows])

    if has("mass"):
        each_state("mass", lambda k, qk, vk: _symmetry(cb("mass", qk), k))
        each_state("kinetic_grad", lambda k, qk, vk: _compare(
            "kinetic_grad", k, cb("kinetic_grad", qk, vk), _fd(lambda x: 0.5 * vk @ cb("mass", x) @ vk, qk), rtol))
        if has("momentum_jacobian"):
            each_state("momentum_jacobian", lambda k, qk, vk: _compare(
                "momentum_jacobian", k, cb("momentum_jacobian", qk, vk), _fd(lambda x: cb("mass", x) @ vk, qk), rtol))
    each_state("potential_grad", lambda k, qk, vk: _compare(
        "potential_grad", k, cb("potential_grad", qk), _fd(lambda x: cb("potential", x), qk), rtol))
    if m:
        each_state("constraint_jacobian", lambda k, qk, vk: _pattern_note(model, _compare(
            "constraint_jacobian", k, cb("constraint_jacobian", qk), _fd(lambda x: cb("constraint", x), qk), rtol)))
    if has("force_jacobian_q") or model.force_independent_of_q:
        # force_jacobian_q=0 declares ∂F/∂q = 0: compared like a callback returning zeros
        declared = model.force_independent_of_q

        def force_q_row(k, qk, vk):
            note = "declared 0 (force independent of q)" if declared else ""
            if declared:
                row = _declared_zero("force_jacobian_q", k, lambda x: cb("force", x, vk), qk, rtol,
                                     note, rng)
                if row.status != "wrong":
                    return row
            return _compare("force_jacobian_q", k,
                            np.zeros((n, n)) if declared else cb("force_jacobian_q", qk, vk),
                            _fd(lambda x: cb("force", x, vk), qk), rtol, note)

        each_state("force_jacobian_q", force_q_row)
    if has("force_jacobian_v"):
        each_state("force_jacobian_v", lambda k, qk, vk: _compare(
            "force_jacobian_v", k, cb("force_jacobian_v", qk, vk), _fd(lambda x: cb("force", qk, x), vk), rtol))
    if has("constraint_time_derivative"):
        tt = np.array([float(t)])
        each_state("constraint_time_derivative", lambda k, qk, vk: _compare(
            "constraint_time_derivative", k, cb("constraint_time_derivative", qk),
            _t_column(_fd(lambda x: cb.at("constraint", float(x[0]), qk), tt)), rtol))

    # the derivatives by θ against differences of their callbacks in each parameter θ_l
    def by_params_row(slot, k, qk, vk):
        name = _theta(slot)
        size = int(np.prod(cb.shape[slot] or (1,)))
        exact = cb(name, qk, vk) if has(name) else None
        if exact is None:
            row = _declared_zero(name, k, lambda th: cb.with_params(slot, th, qk, vk), prm, rtol,
                                 "declared 0 (independent of θ)", rng)
            if row.status != "wrong":
                return row
        blocks = ((np.zeros_like(ref) if exact is None else exact[lo:hi], ref, est, fs, hm)
                  for lo, hi, ref, est, fs, hm in
                  _fd_by_blocks(lambda th: cb.with_params(slot, th, qk, vk), prm, size))
        return _compare_blocks(name, k, blocks, rtol,
                               "" if has(name) else "declared 0 (independent of θ)")

    for slot in PARAM_SLOTS if by_params else ():
        if slot in model.param_derivatives:
            each_state(_theta(slot), lambda k, qk, vk, _s=slot: by_params_row(_s, k, qk, vk))

    def hessian_rows(slot, k, qk, vk):
        if slot == "kinetic_hessian":
            return _compare(slot, k, cb(slot, qk, vk), _fd(lambda x: cb("kinetic_grad", x, vk), qk), rtol)
        if slot == "potential_hessian":
            # potential_hessian=0 declares ∇²V = 0: compared like a callback returning zeros
            exact = np.zeros((n, n)) if model.linear_potential else cb(slot, qk)
            note = "declared 0 (potential linear in q)" if model.linear_potential else ""
            if model.linear_potential:
                row = _declared_zero(slot, k, lambda x: cb("potential_grad", x), qk, rtol, note,
                                     rng)
                if row.status != "wrong":
                    return row
            return _compare(slot, k, exact, _fd(lambda x: cb("potential_grad", x), qk), rtol, note)
        G = lambda x: cb("constraint_jacobian", x)  # noqa: E731
        pattern = model.constraint_jacobian_pattern
        if pattern is None:
            dG, est, fscale, hmin = _fd(G, qk)  # (m, n, n)
            refs = np.einsum("jc,cab->jab", E, dG)
            ests = np.einsum("jc,cab->jab", np.abs(E), est)
            contracted = lambda j: (refs[j], ests[j])  # noqa: E731
        else:  # a large model's: its G's pattern, O(n²) memory instead of O(m n²)
            contracted, fscale, hmin = _fd_contracted_by_groups(G, qk, E, pattern)
        rows = []
        for j, eta in enumerate(etas):
            note = f"η = e_{int(np.argmax(eta))}" if j < n_units else "random η"
            rows.append(_compare(slot, k, cb(slot, qk, eta),
                                 (*contracted(j), fscale * np.abs(eta).sum(), hmin), rtol, note))
        return rows

    for slot in ("kinetic_hessian", "potential_hessian", "constraint_hessian"):
        if not has(slot) and not (slot == "potential_hessian" and model.linear_potential):
            continue
        parent = _PARENT[slot]
        if parent in report.failures:
            report.rows.append(CheckRow(slot, _REFERENCE[slot], 0, np.nan, 0.0, 0.0, (), "skipped",
                                        f"not checked: depends on `{parent}`, which is wrong"))
            continue
        each_state(slot, lambda k, qk, vk, _s=slot: hessian_rows(_s, k, qk, vk))

    report.evaluations = cb.count
    report.wall_time = time.perf_counter() - t0
    if report.ok:
        model.checked = True
        model.param_derivatives_checked = model.param_derivatives_checked or by_params
    elif raise_on_error:
        raise ModelCheckError(report)
    return report


def _pattern_note(model: Model, row: CheckRow) -> CheckRow:
    """Say so when G is wrong at an entry its declared pattern calls zero: the callback left
    it out because the pattern does (the kernels would never see that derivative)."""
    mask = model.constraint_jacobian_pattern
    if row.status != "wrong" or mask is None or len(row.index) != 2 or mask[row.index]:
        return row
    note = (f"entry {list(row.index)} is outside the declared `constraint_jacobian_pattern`, but "
            "finite differences of `constraint` find it non-zero: the pattern misses a non-zero")
    return replace(row, note=(row.note + "; " if row.note else "") + note)


def _t_column(fd):
    """An FD result over the one-entry vector ``[t]`` as the derivative itself (drop the axis)."""
    J, est, fscale, hmin = fd
    return J[..., 0], est[..., 0], fscale, hmin


def check_sizes(model: Model, q, v=None, *, params=None, t: float = 0.0) -> None:
    """Only the first part of :func:`check_model`: every callback evaluated twice at ``(q, v)``
    into guarded buffers (well under a millisecond once compiled).

    Raises
    ------
    ModelCheckError
        A callback writes outside its declared output or into an input, or leaves an entry
        of its output unset.
    """
    if not isinstance(model, Model):
        raise TypeError(f"`model` must be a fastvi.Model, got {type(model).__name__}")
    q = _vector(q, "q", model.n)
    v = np.ones(model.n) if v is None else _vector(v, "v", model.n)
    prm = model.params if params is None else _vector(params, "params", model.params.shape[0])
    cb = _Callbacks(model, prm, CheckReport(model.name, states=[(q, v)]), t)
    eta0 = 1.0 + np.arange(model.m) / max(model.m, 1)
    for slot in SLOTS:
        if slot in cb.present:
            cb.check_size(slot, q, eta0 if slot == "constraint_hessian" else v)


def _vector(x, name: str, n: int) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != (n,):
        raise ValueError(f"`{name}` must have shape ({n},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}` must be finite, got {arr}")
    return np.ascontiguousarray(arr)
