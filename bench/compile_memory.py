"""What the first compile of the kernels costs in time and memory (docs/benchmarks.md,
"Compile and set-up time").

    .venv/bin/python bench/compile_memory.py [--methods=P2L-Q3G,P3L-Q4G] [--warm] [--time]
    NUMBA_OPT=2 .venv/bin/python bench/compile_memory.py --time   # LLVM at -O2 (default 3)

Runs in a fresh numba cache (a temporary ``NUMBA_CACHE_DIR``, so nothing is loaded and
nothing this run compiles is kept) unless ``--warm`` (the repository's own cache: what a
process pays once the kernels are cached). The double pendulum, the generic kernels first,
then ``specialize=True`` for each method; after each: wall and process CPU time, resident
memory and its peak (``/proc/self/status``), and at the end the resident memory after
``gc.collect()`` and glibc's ``malloc_trim(0)``. ``--time``: then the CPU time a step of
each sized method (h = 0.01, 20 000 steps, best of 7), to compare the code that other
compile settings (``NUMBA_OPT``) produce. Linux only (``/proc``). Takes ≈ 2.5 min for the
generic kernels and ≈ 3.5 min a method cold; seconds warm.
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


def _timed(what: str, fn) -> None:
    w, c = time.perf_counter(), time.process_time()
    fn()
    _report(what, time.perf_counter() - w, time.process_time() - c)


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
