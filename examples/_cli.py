"""What the example scripts share: their quick mode, where they write, how they save a figure.

Not an example itself: sphinx-gallery (``docs/conf.py``) and ``tests/test_examples.py`` skip
the files of ``examples/`` whose name starts with ``_``. A script imports it from its own
directory (``from _cli import ...``), which Python puts first on the path when it runs
``python examples/<name>.py``, from whatever directory.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

#: ``FASTVI_QUICK=1`` (the test suite sets it): shortened runs, files in a temporary directory
QUICK = os.environ.get("FASTVI_QUICK") == "1"

#: the checkout's figures, the ones the documentation shows
FIGURES = Path(__file__).resolve().parents[1] / "docs" / "figures"


def default_dir() -> Path:
    """Where a script writes unless told otherwise: ``docs/figures``, or a new temporary
    directory in quick mode (never into the checkout)."""
    return Path(tempfile.mkdtemp(prefix="fastvi-example-")) if QUICK else FIGURES


def out_dir(doc: str, what: str, argv=None) -> Path:
    """The directory given as ``--out DIR`` on the command line, else :func:`default_dir`.

    ``doc`` (the script's docstring) gives ``--help`` its description (the first line),
    ``what`` says what the directory receives (``"the figure"``).
    """
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help=f"directory of {what}")
    out = parser.parse_args(argv).out
    return default_dir() if out is None else out


def figure_path(name: str, argv=None) -> str:
    """The figure's path given as the first command-line argument, else ``name`` in the
    current directory (in a temporary directory in quick mode)."""
    argv = sys.argv[1:] if argv is None else argv
    if argv:
        return argv[0]
    return os.path.join(tempfile.mkdtemp(prefix="fastvi-example-"), name) if QUICK else name


def figure(**kwargs):
    """A matplotlib ``Figure(**kwargs)`` drawn off screen (Agg): no window, no pyplot state."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def save(fig, path, dpi: int) -> None:
    """Lay ``fig`` out, write it to ``path`` and say where."""
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    print(f"figure: {path}")
