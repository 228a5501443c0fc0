"""Every ``examples/*.py`` runs to completion (quick mode), so the examples cannot rot.

Each example is run as its own process, as a user would run it, with ``FASTVI_QUICK=1``:
examples must honour it by shortening their runs and writing files to a temporary
directory (never into the checkout). The working directory is a fresh temporary one, so a
stray relative output path does not touch the repository either.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# examples/_*.py: what the scripts share, not scripts (examples/_cli.py)
EXAMPLES = sorted(p for p in (ROOT / "examples").glob("*.py") if not p.name.startswith("_"))
TIMEOUT = 300  # s; quick mode takes 10-20 s (mostly compiling the model callbacks)


def _checkout_pngs():
    """PNG files of the checkout (not of .venv or caches, which other processes may change)."""
    found = {}
    for top, dirs, files in os.walk(ROOT):
        dirs[:] = [d for d in dirs if not d.startswith(".") and d != "__pycache__"]
        for name in files:
            if name.endswith(".png"):
                path = Path(top) / name
                found[path] = path.stat().st_mtime
    return found


def test_there_are_examples():
    assert EXAMPLES, "examples/ has no scripts"


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs_in_quick_mode(path, tmp_path):
    env = dict(os.environ, FASTVI_QUICK="1", MPLBACKEND="Agg")
    before = _checkout_pngs()
    proc = subprocess.run([sys.executable, str(path)], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=TIMEOUT)
    assert proc.returncode == 0, f"{path.name} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    after = _checkout_pngs()
    assert after == before, f"{path.name} wrote figures into the checkout in quick mode"
