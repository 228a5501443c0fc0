"""The documentation site builds without a warning (``make docs``), when Sphinx is installed.

``-W`` turns every warning into an error: a page missing from the table of contents, a
docstring numpydoc cannot parse, an autosummary entry that does not import, a Markdown link
to a heading that does not exist. The examples are rendered but not executed
(``docs/conf.py``), so the build takes seconds, not the minutes of a kernel compile.
"""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

for _mod in ("sphinx", "myst_parser", "numpydoc", "sphinx_gallery", "furo"):
    pytest.importorskip(_mod, reason="the docs extra is not installed (pip install -e '.[docs]')")


def test_docs_build_without_warnings(tmp_path):
    # Build from a copy: autosummary and sphinx-gallery write their pages (and the gallery's
    # thumbnails) into the source tree, which must not change under the other tests
    # (tests/test_examples.py watches the checkout's PNG files).
    src = tmp_path / "src"
    shutil.copytree(ROOT / "docs", src / "docs",
                    ignore=shutil.ignore_patterns("_build", "generated", "auto_examples"))
    shutil.copytree(ROOT / "examples", src / "examples")
    out = tmp_path / "html"
    proc = subprocess.run(
        [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q",
         "-d", str(tmp_path / "doctrees"), str(src / "docs"), str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"sphinx failed:\n{proc.stderr[-5000:]}"
    # the three kinds of page a reader opens first
    assert (out / "index.html").exists()
    assert (out / "generated" / "fastvi.integrate.html").exists()
    gallery = (out / "auto_examples" / "index.html").read_text(encoding="utf-8")
    assert "Kapitza" in gallery
