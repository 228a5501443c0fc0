"""Fitting a damping and a rod length to noisy angles of a double pendulum
=========================================================================

Synthetic data: the damped double pendulum (``damping=c``) with ``c = 0.3`` and an outer
rod of ``l2 = 0.8``, released from θ1 = 1, θ2 = 0.5 at rest; both angles sampled every
0.05 s for 5 s, with noise of 0.01 rad. ``fastvi.TrajectoryFit`` gives
``scipy.optimize.least_squares`` the residuals and their exact Jacobian (forward
sensitivities of the discrete flow), starting from ``c = 0.1``, ``l2 = 1``. The initial
state depends on ``l2`` (the angles are what is known), so it is given as
``initial_state(params)``. The script prints the fit against SciPy's own finite
differences and plots the data with the first guess and the fitted trajectory.

Run ``python examples/parameter_fit.py [figure.png]`` (default ``parameter_fit.png``).
With ``FASTVI_QUICK=1`` the run is shorter and the figure goes to a temporary directory.

.. image:: /figures/parameter_fit.png
   :alt: the figure this script draws
"""

# sphinx_gallery_thumbnail_path = "figures/parameter_fit.png"

import time

import numpy as np
from scipy.optimize import least_squares

import fastvi
from fastvi.scenes.double_pendulum import angles, state_from_angles
from _cli import QUICK, figure, figure_path, save

C, L2 = 5, 3  # indices of the damping and the outer rod length in the parameters


def observe(t, q, v):
    """The two angles at every sample: (K, 2)."""
    return np.stack(angles(q), axis=-1)


def start(params):
    """θ1 = 1, θ2 = 0.5 at rest, for the rod lengths in ``params``."""
    return state_from_angles(1.0, 0.5, 0.0, 0.0, params[2], params[3])


def main(path):
    model = fastvi.scenes.double_pendulum(damping=0.3)
    true = model.params.copy()
    true[L2] = 0.8
    h, every = 0.01, 5
    steps = 100 if QUICK else 500
    run = fastvi.integrate(model, *start(true), h=h, n_steps=steps, save_every=every,
                           params=true)
    data = observe(run.t, run.q, run.v)
    data = data + 0.01 * np.random.default_rng(0).normal(size=data.shape)

    guess = np.array([0.1, 1.0])
    for label, jac in [("exact Jacobian", "exact"), ("SciPy 2-point", "2-point")]:
        fit = fastvi.TrajectoryFit(model, data, observe, param_index=[C, L2],
                                   initial_state=start, h=h, n_steps=steps, save_every=every)
        t = time.perf_counter()
        sol = least_squares(fit.residuals, guess, jac=fit.jacobian if jac == "exact" else jac)
        t = time.perf_counter() - t
        print(f"{label:15s}: c = {sol.x[0]:.4f}, l2 = {sol.x[1]:.4f} (true 0.3, 0.8), "
              f"cost {sol.cost:.4e}, {sol.njev} iterations, {t:.2f} s")
    best = fit.trajectory(sol.x)
    first = fit.trajectory(guess)

    fig = figure(figsize=(7, 5))
    axes = fig.subplots(2, 1, sharex=True)
    for i, ax in enumerate(axes):
        ax.plot(run.t, data[:, i], ".", ms=3, color="0.4", label="noisy data")
        ax.plot(first.t, observe(first.t, first.q, first.v)[:, i], lw=0.8, ls="--",
                label="first guess (c, l2) = (0.1, 1)")
        ax.plot(best.t, observe(best.t, best.q, best.v)[:, i], lw=1.2,
                label=f"fit (c, l2) = ({sol.x[0]:.3f}, {sol.x[1]:.3f})")
        ax.set_ylabel(f"θ{i + 1} (rad)")
    axes[0].legend(fontsize=8, loc="upper right")
    axes[1].set_xlabel("t (s)")
    fig.suptitle("Damped double pendulum: damping and rod length from noisy angles")
    save(fig, path, dpi=110)


if __name__ == "__main__":
    main(figure_path("parameter_fit.png"))
