"""The paper-B study (``python -m fastvi paper-b``): it runs, writes what the docs show, and its
verdicts follow the numbers rather than being fixed text."""

import os
import time

import numpy as np
import pytest

from studies import paper_b


def _rows(dH, growth=None, rk_growth=1.0, rk_dH=1e-9):
    """Synthetic table rows: ``dH[(kind, base)]`` per method, the same for every system and h."""
    rows = []
    for system in ("double_pendulum", "rotary_rod_slider"):
        for h in (0.01, 0.001):
            for (kind, base), e in dH.items():
                label = base + (paper_b.PAPER_VARIANT if kind == "paper" else "")
                rows.append(paper_b.Row(system, h, label, kind, base, e, 1e-16, 1e-16,
                                        (growth or {}).get((kind, base), 1.0), 0.1, 2.0,
                                        np.zeros(2), np.zeros(2)))
            for kind, label in (("rk4", "RK4"), ("rk4proj", "RK4 + projection")):
                rows.append(paper_b.Row(system, h, label, kind, "RK4", rk_dH, 1e-6, 1e-6, rk_growth,
                                        0.1, np.nan, np.zeros(2), np.zeros(2)))
    return rows


SYSTEMS = {"double_pendulum": (None, None, "double pendulum (x)"),
           "rotary_rod_slider": (None, None, "rotary rod–slider (x)")}


def _all(value_by_base):
    return {(kind, base): value_by_base[base] for kind in ("paper", "default")
            for base in paper_b.PAPER_METHODS}


def test_claim_verdicts_agree_when_the_numbers_support_the_claims():
    rows = _rows(_all({"P1L-Q2G": 1e-2, "P2L-Q2G": 1.5e-5, "P2L-Q3G": 1e-5}), rk_growth=50.0, rk_dH=1.0)
    text = " ".join(paper_b.claims(rows, SYSTEMS))
    assert text.count("**agrees**") == 4  # claim 1 in both variants, claims 2 and 3
    assert "disagrees" not in text and "partly" not in text


def test_claim_verdicts_disagree_when_the_numbers_contradict_the_claims():
    rows = _rows(_all({"P1L-Q2G": 1e-3, "P2L-Q2G": 1e-1, "P2L-Q3G": 1e-3}), rk_growth=1.1, rk_dH=1e-9)
    text = " ".join(paper_b.claims(rows, SYSTEMS))
    assert text.count("**disagrees**") == 4
    assert "**agrees**" not in text


def test_growth_is_one_for_bounded_and_ten_for_linear_drift():
    t = np.linspace(0.0, 100.0, 100_001)
    assert paper_b._growth(np.sin(7 * t)) == pytest.approx(1.0, abs=1e-6)
    # the first tenth's peak falls a little short of t = 10, hence not exactly 10
    assert paper_b._growth(1e-3 * t * np.abs(np.sin(7 * t))) == pytest.approx(10.0, rel=0.05)  # 10.3


@pytest.mark.slow  # its RK4 rows compile the RK4 kernel (tests/test_baselines.py)
def test_quick_study_writes_tables_figures_and_page(tmp_path, capsys):
    assert paper_b.main(["--quick", "--quiet", "--out", str(tmp_path)]) == 0
    page = (tmp_path / "paper-b.md").read_text(encoding="utf-8")
    assert "Quick mode" in page
    for heading in ("## Table 3: h = 0.01", "## Table 4: h = 0.001", "## CPU time of the slider run",
                    "## Paper B's claims against these numbers", "## Why"):
        assert heading in page
    # 2 systems × 2 step sizes × (3 methods × 2 variants + 2 RK4 rows)
    assert page.count("(paper B) |") == 12 and page.count("(fastvi default) |") == 12
    assert page.count("| RK4 + projection |") == 4 + 1  # and a row of the order table
    figs = sorted(os.listdir(tmp_path / "figures"))
    assert len(figs) == 6 and all(f.startswith("paper-b-") and f.endswith(".png") for f in figs)
    for f in figs:
        assert f"](figures/{f})" in page
    out = capsys.readouterr().out
    assert "## Table 3" in out and "## Table 4" in out
    # every variational run of the quick study holds the constraints at round-off
    g_col = [float(line.split("|")[3]) for line in page.splitlines() if "(paper B) |" in line
             or "(fastvi default) |" in line]
    assert max(g_col) < 1e-14  # measured 4.4e-16


@pytest.mark.slow
def test_full_study_meets_the_acceptance_times(tmp_path):
    """Acceptance: the whole study under 5 minutes; the paper's slider run well under 1 s."""
    t0 = time.perf_counter()
    assert paper_b.main(["--quiet", "--out", str(tmp_path)]) == 0
    assert time.perf_counter() - t0 < 300.0  # measured 38-70 s on 2 shared, busy cores
    median, _, res = paper_b.time_slider()
    assert res.stats["steps"] == 10_000
    assert median < 1.0  # measured 0.08-0.13 s
