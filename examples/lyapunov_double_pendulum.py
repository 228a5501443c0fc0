"""The largest Lyapunov exponent of the double pendulum from the tangent flow
==========================================================================

The largest Lyapunov exponent measures how fast two nearby motions separate:
``|δx(t)| ~ e^{λ t} |δx(0)|``. It is computed here by Benettin's method on the *exact
tangent flow of the discrete map*: :func:`fastvi.sensitivity` carries one tangent vector
along a segment of the run (one solve a step with the step's own Newton matrix), the vector
is renormalised at the end of each segment, and λ is the mean of the logarithms of the
growth factors (:func:`fastvi.largest_lyapunov`). Because the tangent map of a variational
integrator is symplectic, the exponents come in ± pairs and a regular (quasi-periodic)
motion gives λ → 0 like log T / T.

Two energies of the double pendulum (unit masses and rods, g = 9.81): released at rest from
θ1 = θ2 = π/2 (chaotic), and from θ1 = θ2 = 0.1 rad (regular). For the chaotic energy the
exponent is averaged over an ensemble of starts a millionth of a radian apart, at two step
sizes, to show it converged in h and in T.

Run ``python examples/lyapunov_double_pendulum.py [--out DIR]``; it prints the table and
writes ``lyapunov.png`` (the running estimate against T) into ``docs/figures/``. With
``FASTVI_QUICK=1``: a short run, written to a temporary directory.

.. image:: /figures/lyapunov.png
   :alt: running estimates of the largest Lyapunov exponent
"""

# sphinx_gallery_thumbnail_path = "figures/lyapunov.png"

import argparse
import os
import tempfile
from pathlib import Path

import numpy as np

import fastvi

QUICK = os.environ.get("FASTVI_QUICK") == "1"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help="directory of the figure")
    args = parser.parse_args(argv)
    if args.out is None:
        args.out = (Path(tempfile.mkdtemp()) if QUICK else Path(__file__).resolve().parents[1]
                    / "docs" / "figures")
    T, members = (20.0, 2) if QUICK else (1000.0, 8)
    model = fastvi.scenes.double_pendulum()
    curves = {}
    for h in (0.01, 0.005):
        runs = []
        for i in range(members):
            q0, v0 = model.initial_state(np.pi / 2 + 1e-6 * i, np.pi / 2)
            runs.append(fastvi.largest_lyapunov(model, q0, v0, h=h, t_end=T, seed=i))
        curves[f"chaotic, h = {h:g}"] = np.array(runs)
    q0, v0 = model.initial_state(0.1, 0.1)
    curves["regular, h = 0.01"] = fastvi.largest_lyapunov(model, q0, v0, h=0.01, t_end=T)[None, :]
    t = np.arange(1, curves["regular, h = 0.01"].shape[1] + 1) * 1.0
    print(f"{'motion':<20} " + " ".join(f"{'λ(T=' + format(x, 'g') + ')':>12}" for x in (T / 10, T / 2, T)))
    for label, runs in curves.items():
        mean = runs.mean(axis=0)
        cols = [mean[int(x) - 1] for x in (T / 10, T / 2, T)]
        spread = f"  (± {runs[:, -1].std():.3f} over {runs.shape[0]} starts)" if runs.shape[0] > 1 else ""
        print(f"{label:<20} " + " ".join(f"{c:12.4f}" for c in cols) + spread)

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.5, 4))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for label, runs in curves.items():
        ax.plot(t, runs.mean(axis=0), label=label)
    ax.set_xscale("log")
    ax.set_xlabel("T (s)")
    ax.set_ylabel("λ estimate (1/s)")
    ax.set_title("Largest Lyapunov exponent of the double pendulum, P2L-Q3G")
    ax.legend()
    fig.tight_layout()
    path = args.out / "lyapunov.png"
    fig.savefig(path, dpi=100)
    print(f"figure: {path}")


if __name__ == "__main__":
    main()
