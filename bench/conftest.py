"""Benchmark session hooks: the generic/specialized ratio table of ``test_bench_core.py``.

Benchmarks that want a ratio tag themselves with ``benchmark.extra_info[RATIO_KEY] =
{"method": ..., "impl": "generic" | "sized" | "specialized", "block": int}``; every other benchmark
in ``bench/`` is ignored here. The rounds of all blocks of one contender are pooled; the
table (ratio of the pooled medians, of the pooled minima, and of the medians block by
block) is printed at the end of the run and stored in the ``--benchmark-json`` file under
the same key.
"""

from __future__ import annotations

import statistics

import pytest

RATIO_KEY = "fastvi_yardstick"  # same literal in test_bench_core.py (importing a conftest is fragile)


def _rounds(benchmarks):
    """{method: {impl: {block: [round times]}}} of the tagged benchmarks that produced data."""
    out: dict = {}
    for bench in benchmarks:
        tag = getattr(bench, "extra_info", {}).get(RATIO_KEY)
        stats = getattr(bench, "stats", None)
        data = list(getattr(stats, "data", None) or [])
        if not tag or not data:
            continue
        blocks = out.setdefault(tag["method"], {}).setdefault(tag["impl"], {})
        blocks.setdefault(tag.get("block", 0), []).extend(data)
    return out


def _pairs(by_method):
    for method, by_impl in by_method.items():
        for impl in ("generic", "sized"):
            if impl in by_impl and "specialized" in by_impl:
                yield (method, impl), by_impl[impl], by_impl["specialized"]


def ratio_table(benchmarks) -> list[dict]:
    """Rows ``{method, impl, ratio, ratio_min, block_ratios, rounds}``: ``impl`` (the generic
    kernels, or the size-specialized ones: ``sized``) / the hand-specialized yardstick, of
    the pooled medians (the figure reported), of the pooled minima (the rounds least
    disturbed by other load on the machine) and of the medians of each block."""
    rows = []
    for (method, impl), gen, spe in _pairs(_rounds(benchmarks)):
        g = [t for b in gen.values() for t in b]
        sp = [t for b in spe.values() for t in b]
        blocks = sorted(set(gen) & set(spe))
        rows.append(dict(
            method=method,
            impl=impl,
            ratio=statistics.median(g) / statistics.median(sp),
            ratio_min=min(g) / min(sp),
            block_ratios=[statistics.median(gen[b]) / statistics.median(spe[b]) for b in blocks],
            rounds=[len(g), len(sp)],
        ))
    return rows


def pytest_benchmark_update_json(config, benchmarks, output_json):
    rows = ratio_table(benchmarks)
    if rows:
        output_json[RATIO_KEY] = dict(ratios=rows)


@pytest.hookimpl(trylast=True)  # after pytest-benchmark's own tables
def pytest_terminal_summary(terminalreporter, exitstatus, config):
    session = getattr(config, "_benchmarksession", None)
    rows = ratio_table(getattr(session, "benchmarks", []) or [])
    if not rows:
        return
    tr = terminalreporter
    tr.write_sep("-", "fastvi: generic cfunc kernel / hand-specialized yardstick")
    tr.write_line(f"{'method':<10} {'kernels':<8} {'medians':>8} {'minima':>8}  "
                  f"{'per block (medians)':<22} {'rounds':>7}")
    for row in rows:
        blocks = " ".join(f"{r:.2f}" for r in row["block_ratios"])
        rounds = "/".join(str(k) for k in row["rounds"])
        tr.write_line(f"{row['method']:<10} {row['impl']:<8} {row['ratio']:>8.2f} "
                      f"{row['ratio_min']:>8.2f}  "
                      f"{blocks:<22} {rounds:>7}")


@pytest.fixture(scope="session")
def print_uncaptured(pytestconfig):
    """``emit(fn)`` calls ``fn(write)`` with output going to the terminal, not to pytest's
    capture (a module fixture's teardown output is captured otherwise); ``write`` prints a
    line, ``fn`` may also use ``write.sep(title)`` for a separator line."""

    def emit(fn):
        capman = pytestconfig.pluginmanager.get_plugin("capturemanager")
        tr = pytestconfig.pluginmanager.get_plugin("terminalreporter")

        def write(line=""):
            (tr.write_line if tr is not None else print)(line)

        write.sep = (lambda title: (tr.write_line(""), tr.write_sep("-", title))) if tr is not None \
            else (lambda title: print(f"\n---- {title}"))
        if capman is None:
            fn(write)
            return
        with capman.global_and_fixture_disabled():
            fn(write)

    return emit
