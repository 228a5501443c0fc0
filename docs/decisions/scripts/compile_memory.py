"""What the first compile of the kernels costs in time and memory (docs/benchmarks.md,
"Compile and set-up time").

    .venv/bin/python docs/decisions/scripts/compile_memory.py [--methods=P2L-Q3G,P3L-Q4G] [--warm] [--time]
    NUMBA_OPT=2 .venv/bin/python docs/decisions/scripts/compile_memory.py --time   # LLVM at -O2 (default 3)
    .venv/bin/python docs/decisions/scripts/compile_memory.py --events   # where each compile's time goes

Runs in a fresh numba cache (a temporary ``NUMBA_CACHE_DIR``, so nothing is loaded and
nothing this run compiles is kept) unless ``--warm`` (the repository's own cache: what a
process pays once the kernels are cached). The double pendulum, the generic kernels first,
then ``specialize=True`` for each method; after each: wall and process CPU time, resident
memory and its peak (``/proc/self/status``), and at the end the resident memory after
``gc.collect()`` and glibc's ``malloc_trim(0)``. ``--time``: then the CPU time a step of
each sized method (h = 0.01, 20 000 steps, best of 7), to compare the code that other
compile settings (``NUMBA_OPT``) produce. Linux only (``/proc``). Takes ≈ 2.5 min for the
generic kernels and ≈ 3.5 min a method cold; seconds warm. ``--events``: after each
stage, the time numba's event log puts in LLVM (``numba:llvm_lock``, summed) and the
longest compiles by function (nested: a caller's time includes its callees').
"""
import ctypes
import gc
import os
import sys
import tempfile
import time

ARGS = dict(a.lstrip("-").split("=", 1) if "=" in a else (a.lstrip("-"), "1") for a in sys.argv[1:])
if "warm" not in ARGS:
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="fastvi-cold-")  # before numba loads

import numba.core.event  # noqa: E402

import fastvi  # noqa: E402


def _status(key: str) -> int:
    with open(f"/proc/{os.getpid()}/status") as f:
        for line in f:
            if line.startswith(key):
                return int(line.split()[1]) // 1024
    raise RuntimeError(f"{key} not in /proc/self/status")


def _report(what: str, wall: float, cpu: float) -> None:
    print(f"{what:<24} wall {wall:7.1f} s  CPU {cpu:7.1f} s  resident {_status('VmRSS'):6d} MB"
          f"  peak {_status('VmHWM'):6d} MB", flush=True)


class _CompileLog(numba.core.event.Listener):
    """numba's compile events, (kind, function, seconds, depth), while ``--events``."""

    def __init__(self):
        self.records = []
        self._open = []
        for kind in ("numba:compile", "numba:llvm_lock"):
            numba.core.event.register(kind, self)

    def on_start(self, event):
        self._open.append((event, time.perf_counter()))

    def on_end(self, event):
        e, t = self._open.pop()
        d = e.data.get("dispatcher") if isinstance(e.data, dict) else None
        name = f"{d.py_func.__module__}.{d.py_func.__qualname__}" if d is not None else ""
        self.records.append((e.kind, name, time.perf_counter() - t, len(self._open)))

    def report(self):
        llvm = sum(r[2] for r in self.records if r[0] == "numba:llvm_lock")
        print(f"    LLVM (numba:llvm_lock) {llvm:.1f} s in all; longest compiles:")
        top = sorted((r for r in self.records if r[0] == "numba:compile"), key=lambda r: -r[2])
        for _, name, secs, depth in top[:5]:
            print(f"    {secs:7.1f} s  depth {depth}  {name}")
        self.records.clear()


_LOG = _CompileLog() if "events" in ARGS else None


def _timed(what: str, fn) -> None:
    w, c = time.perf_counter(), time.process_time()
    fn()
    _report(what, time.perf_counter() - w, time.process_time() - c)
    if _LOG is not None:
        _LOG.report()


def main() -> None:
    methods = ARGS.get("methods", "P2L-Q3G").split(",")
    print(f"NUMBA_CACHE_DIR={os.environ.get('NUMBA_CACHE_DIR', '(the package cache)')}")
    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(1.0, 0.5)
    _report("start", 0.0, 0.0)
    _timed("generic kernels", lambda: fastvi.integrate(model, q0, v0, h=0.01, n_steps=10))
    for m in methods:
        _timed(f"sized {m}", lambda: fastvi.integrate(model, q0, v0, h=0.01, n_steps=10,
                                                      method=m, specialize=True))
    gc.collect()
    _report("after gc.collect()", 0.0, 0.0)
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
        _report("after malloc_trim(0)", 0.0, 0.0)
    except (OSError, AttributeError):
        print("malloc_trim: not glibc")
    if "time" in ARGS:
        for m in methods:
            best = float("inf")
            for _ in range(7):
                c = time.process_time()
                fastvi.integrate(model, q0, v0, h=0.01, n_steps=20000, method=m,
                                 specialize=True, save_every=20000)
                best = min(best, time.process_time() - c)
            print(f"sized {m}: {best / 20000 * 1e6:.3f} µs a step (best of 7, whole call)")


if __name__ == "__main__":
    main()
