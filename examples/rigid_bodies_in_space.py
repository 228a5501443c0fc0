"""Rigid bodies in space: the heavy top and Bricard's linkage
===========================================================

Two mechanisms from :mod:`fastvi.bodies`, each built as an ordinary :class:`fastvi.Model`
whose coordinates are every body's centre of mass and its three directors.

* **The heavy top** of Brüls, Cardona & Arnold: a lamina (its principal moments satisfy
  ``J₂ = J₁ + J₃``, so one director carries no inertia and the mass matrix is singular),
  spinning at 150 rad/s about its symmetry axis while it precesses about the vertical
  through its fixed point. The constraints hold at round-off, the energy error stays
  bounded.
* **Bricard's linkage** (IFToMM A04): five rods closed into a loop by six revolute joints.
  Grübler's count gives no mobility, yet it moves with one degree of freedom: its 60
  constraint equations have rank 59. The set-up finds the redundant row and drops it.

Each run is animated with :meth:`fastvi.Result.animate`: the bodies' centres, the joints
(pivots on the ground drawn as triangles) and each rigid body's frame.

Run ``python examples/rigid_bodies_in_space.py [--out DIR]``; the default writes
``heavy_top.gif`` and ``bricard.gif`` into ``docs/figures/``. With ``FASTVI_QUICK=1``:
shorter runs and animations, written to a temporary directory.

.. image:: /figures/heavy_top.gif
   :alt: the heavy top precessing

.. image:: /figures/bricard.gif
   :alt: Bricard's linkage moving under gravity
"""

# sphinx_gallery_thumbnail_path = "figures/heavy_top.gif"

from pathlib import Path

import numpy as np

import fastvi
from fastvi.bodies import outputs, scenes
from _cli import QUICK, out_dir


def heavy_top(out: Path) -> None:
    model = scenes.heavy_top()  # the lamina: model.mass_singular is True
    q0, v0 = model.initial_state()
    t_end = 0.2 if QUICK else 2.0
    run = fastvi.integrate(model, q0, v0, h=2.5e-4, t_end=t_end, method="P3L-Q4G", save_every=20)
    print(run.summary())
    L = outputs.angular_momentum(model, run)[:, 2]  # about the vertical through the fixed point
    print(f"heavy top: singular mass {model.mass_singular}, max |g| {run.constraint_residual.max():.1e}, "
          f"angular momentum about the vertical kept to {np.ptp(L) / abs(L[0]):.1e} (relative)")
    gif = run.animate(out / "heavy_top.gif", fps=10 if QUICK else 20, duration=1 if QUICK else 6,
                      dpi=70)
    print(f"animation: {gif}")


def bricard(out: Path) -> None:
    model = scenes.bricard()
    print(model.dof)  # 60 equations of rank 59: one redundant row, dropped
    q0, v0 = model.initial_state()
    t_end = 0.5 if QUICK else 5.0
    run = fastvi.integrate(model, q0, v0, h=0.01, t_end=t_end, method="P2L-Q3G", save_every=2)
    print(run.summary())
    gif = run.animate(out / "bricard.gif", fps=10 if QUICK else 20, duration=1 if QUICK else 5,
                      dpi=70)
    print(f"animation: {gif}")


def main(argv=None):
    out = out_dir(__doc__, "the GIFs", argv)
    heavy_top(out)
    bricard(out)


if __name__ == "__main__":
    main()
