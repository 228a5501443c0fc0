"""Lyapunov exponents of the double pendulum from the tangent flow
================================================================

The Lyapunov exponents measure how fast nearby motions separate: ``|δx(t)| ~ e^{λ t}
|δx(0)|`` along the most unstable direction, and likewise for areas and volumes. They are
computed here by the QR method of Shimada–Nagashima and Benettin et al. on the *exact
tangent flow of the discrete map*: :func:`fastvi.lyapunov_spectrum` carries four tangent
vectors along each one-second segment of the run with :func:`fastvi.sensitivity` (one
solve a vector and step with the step's own Newton matrix), re-orthonormalises them at the
segment's end, and averages the logarithms of the diagonal of the triangular factor.

The constrained phase space of the double pendulum has dimension 2(n − m) = 4. Its step is
symplectic, so the exponents come in ± pairs, two of them zero: λ_1 > 0 = λ_2 = λ_3 >
λ_4 = −λ_1 for a chaotic motion, all four zero for a regular one.

Three runs of the double pendulum (unit masses and rods, g = 9.81, ``P2L-Q3G``,
h = 0.01): the spectrum of the release at rest from θ1 = θ2 = π/2 (energy E = 0, the
pivot's height the zero of the potential), the largest exponent of small oscillations
from θ1 = θ2 = 0.1 rad (regular), and λ_1 over eight starts at rest on the energy surface
E = 0. ``docs/sensitivities.md`` tabulates λ_1 over sixteen such starts up to T = 2000 s
at two step sizes, against an independent SciPy computation of the same exponent
(``python -m fastvi lyapunov``).

Run ``python examples/lyapunov_double_pendulum.py [--out DIR]``; it prints the table and
writes ``lyapunov.png`` (the running estimates against T) into ``docs/figures/``. With
``FASTVI_QUICK=1``: a short run, written to a temporary directory.

.. image:: /figures/lyapunov.png
   :alt: running estimates of the Lyapunov exponents of the double pendulum
"""

# sphinx_gallery_thumbnail_path = "figures/lyapunov.png"

import numpy as np

import fastvi
from fastvi.scenes.double_pendulum import state_from_angles
from _cli import QUICK, figure, out_dir, save


def main(argv=None):
    out = out_dir(__doc__, "the figure", argv)
    T, T_ens, members = (20.0, 20.0, 2) if QUICK else (1000.0, 500.0, 8)
    model = fastvi.scenes.double_pendulum()
    chaotic = fastvi.lyapunov_spectrum(model, *state_from_angles(np.pi / 2, np.pi / 2), h=0.01,
                                       t_end=T)
    regular = fastvi.largest_lyapunov(model, *state_from_angles(0.1, 0.1), h=0.01, t_end=T)
    print(f"{'T (s)':>8} {'λ_1':>8} {'λ_2':>8} {'λ_3':>8} {'λ_4':>8} {'λ_1 + λ_4':>10}"
          f" {'regular λ_1':>12}")
    for x in (T / 100, T / 10, T):
        lam = chaotic.running[int(x) - 1]
        print(f"{x:8g} " + " ".join(f"{v:8.4f}" for v in lam) + f" {lam[0] + lam[3]:10.1e}"
              f" {regular[int(x) - 1]:12.4f}")

    # starts at rest on the energy surface E = 0: 2 cos θ1 + cos θ2 = 0
    th1 = np.pi / 2 + 0.45 * np.linspace(-1.0, 1.0, members)
    ensemble = np.array([
        fastvi.largest_lyapunov(model, *state_from_angles(a, np.arccos(-2 * np.cos(a))),
                                h=0.01, t_end=T_ens) for a in th1])
    final = ensemble[:, -1]
    print(f"λ_1 over {members} starts at rest on E = 0, T = {T_ens:g} s: "
          f"{final.mean():.3f} ± {final.std(ddof=1):.3f} 1/s (mean ± standard deviation)")

    fig = figure(figsize=(9, 4))
    ax, bx = fig.subplots(1, 2)
    for i in range(chaotic.dimension):
        ax.plot(chaotic.t, chaotic.running[:, i], label=f"λ_{i + 1}, θ1 = θ2 = π/2")
    ax.plot(chaotic.t, regular, "k--", label="λ_1, θ1 = θ2 = 0.1 (regular)")
    ax.axhline(0.0, color="0.7", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("T (s)")
    ax.set_ylabel("running estimate (1/s)")
    ax.set_title("Spectrum, P2L-Q3G, h = 0.01")
    ax.legend(fontsize=7)
    t = np.arange(1, ensemble.shape[1] + 1) * 1.0
    for curve in ensemble:
        bx.plot(t, curve, color="tab:blue", lw=0.6, alpha=0.6)
    bx.plot(t, ensemble.mean(axis=0), color="k", label="mean")
    bx.set_xscale("log")
    bx.set_xlabel("T (s)")
    bx.set_ylabel("λ_1 estimate (1/s)")
    bx.set_title(f"λ_1, {members} starts at rest on E = 0")
    bx.legend(fontsize=7)
    save(fig, out / "lyapunov.png", dpi=100)


if __name__ == "__main__":
    main()
