"""Benchmark session hooks: the generic/specialized ratio table of ``test_bench_core.py``.

Benchmarks that want a ratio tag themselves with ``benchmark.extra_info[RATIO_KEY] =
{"method": ..., "impl": "generic" | "specialized"}``; every other benchmark in ``bench/``
is ignored here. The table is printed at the end of the run and stored in the
``--benchmark-json`` file under the same key.
"""

from __future__ import annotations

import pytest

RATIO_KEY = "fastvi_yardstick"  # same literal in test_bench_core.py (importing a conftest is fragile)
GOAL = 1.3  # issue 2, item 9: generic kernel within 1.3x of the hand-specialized one


def _medians(benchmarks):
    """{method: {impl: median seconds}} of the tagged benchmarks that produced data."""
    out: dict[str, dict[str, float]] = {}
    for bench in benchmarks:
        tag = getattr(bench, "extra_info", {}).get(RATIO_KEY)
        stats = getattr(bench, "stats", None)
        if not tag or stats is None or not getattr(stats, "data", None):
            continue
        out.setdefault(tag["method"], {})[tag["impl"]] = stats.median
    return out


def ratio_table(benchmarks) -> list[dict]:
    """Rows ``{method, ratio, rounds...}``: median(generic) / median(specialized)."""
    rows = []
    for method, med in _medians(benchmarks).items():
        if "generic" in med and "specialized" in med:
            rows.append(dict(method=method, ratio=med["generic"] / med["specialized"]))
    return rows


def pytest_benchmark_update_json(config, benchmarks, output_json):
    rows = ratio_table(benchmarks)
    if rows:
        output_json[RATIO_KEY] = dict(goal=GOAL, ratios=rows)


@pytest.hookimpl(trylast=True)  # after pytest-benchmark's own tables
def pytest_terminal_summary(terminalreporter, exitstatus, config):
    session = getattr(config, "_benchmarksession", None)
    rows = ratio_table(getattr(session, "benchmarks", []) or [])
    if not rows:
        return
    tr = terminalreporter
    tr.write_sep("-", "fastvi: generic cfunc kernel / hand-specialized yardstick (ratio of medians)")
    tr.write_line(f"{'method':<10} {'generic/specialized':>20}   goal <= {GOAL}")
    for row in rows:
        verdict = "met" if row["ratio"] <= GOAL else "MISSED"
        tr.write_line(f"{row['method']:<10} {row['ratio']:>20.3f}   {verdict}")
