"""How the page writes numbers and saves figures: shared by its sections."""

from __future__ import annotations

import os

import numpy as np


def fmt(x: float, spec: str = ".3g") -> str:
    """``x`` in ``spec``, or "—" where it is not finite (a level a contender never reached)."""
    return format(x, spec) if np.isfinite(x) else "—"


def pyplot(outdir: str, log=None):
    """matplotlib's pyplot with the file backend and ``outdir/figures`` made, or None (with a
    note to ``log``) where matplotlib is not installed."""
    try:
        import matplotlib
    except ImportError:
        if log is not None:
            log("matplotlib is not installed (pip install fastvi[plot]): no figures")
        return None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(os.path.join(outdir, "figures"), exist_ok=True)
    return plt


def save(plt, fig, outdir: str, name: str, dpi: int = 110) -> str:
    """Save ``fig`` as ``outdir/figures/name``, close it and return its path relative to
    ``outdir`` (as the page links it)."""
    rel = f"figures/{name}"
    fig.tight_layout()
    fig.savefig(os.path.join(outdir, rel), dpi=dpi)
    plt.close(fig)
    return rel
