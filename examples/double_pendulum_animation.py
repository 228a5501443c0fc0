"""Watching the double pendulum: an animated GIF and the paths of its masses
=========================================================================

The double pendulum (unit masses and rods, g = 9.81) released from θ1 = 2.2 rad,
θ2 = 2.6 rad at rest is chaotic: the outer rod flips over the top within a few seconds.
The run keeps its dense output (``dense_output=True``), so each frame of the animation is
the trajectory at exactly its own time, not the nearest saved step. The scene carries its
drawing (``model.drawing``: the pivot, the two masses, the two rods), so
:meth:`fastvi.Result.animate` needs nothing else; :meth:`fastvi.Result.plot_trajectory`
draws the paths of both masses over the whole run.

Run ``python examples/double_pendulum_animation.py [--out DIR]``; the default writes
``double_pendulum.gif`` (8 s of motion in real time at 25 frames per second, ≈ 1 MB) and
``double_pendulum_paths.png`` into ``docs/figures/``. With ``FASTVI_QUICK=1``: 1 s at 10
frames per second, written to a temporary directory.

.. image:: /figures/double_pendulum.gif
   :alt: the animation this script writes

.. image:: /figures/double_pendulum_paths.png
   :alt: the paths of the two masses
"""

# sphinx_gallery_thumbnail_path = "figures/double_pendulum_paths.png"

import fastvi
from _cli import QUICK, out_dir


def main(argv=None):
    out = out_dir(__doc__, "the GIF and the PNG", argv)
    t_end, fps = (1.0, 10) if QUICK else (8.0, 25)

    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(2.2, 2.6)
    run = fastvi.integrate(model, q0, v0, h=0.005, t_end=t_end, save_every=4, dense_output=True)
    print(run.summary())

    gif = run.animate(out / "double_pendulum.gif", fps=fps, trail=1.5, dpi=70)
    print(f"animation: {gif} ({gif.stat().st_size / 1e6:.2f} MB)")
    paths = out / "double_pendulum_paths.png"
    run.plot_trajectory(path=paths)
    print(f"paths: {paths}")


if __name__ == "__main__":
    main()
