"""Kapitza's pendulum: an inverted pendulum held up by shaking its pivot
=====================================================================

A pendulum whose pivot moves vertically, ``y_p(t) = a cos(ω t)``, is a rheonomic
(time-dependent) constraint: ``fastvi.scenes.kapitza_pendulum`` writes it as
``g(t, q) = ½(x² + (y − y_p(t))² − l²)`` with ``time_dependent=True``. When
``a² ω² > 2 g l`` the upside-down position is stable: started 0.3 rad from the top, the
rod wobbles around it instead of falling. With the pivot at rest the same start falls.

The script integrates both, checks the run against SciPy's DOP853 on the angle equation
``θ̈ = −(g − a ω² cos ω t) sin θ / l``, prints the energy balance (the drive pumps energy
in and out; ``H − H0 − W`` stays at the integrator's error) and draws the angle. Then it
measures the top's linear stability: ``fastvi.periodic_orbit`` of the forced model gives
the Floquet multipliers of the inverted position over one period of the drive (on the unit
circle: stable), and bisecting on them finds the pivot frequency above which the top is
stable, beside Kapitza's estimate ``√(2 g l) / a``.

Run ``python examples/kapitza_pendulum.py [figure.png]`` (default ``kapitza_pendulum.png``).
With ``FASTVI_QUICK=1`` the run is shorter and the figure goes to a temporary directory.

.. image:: /figures/kapitza_pendulum.png
   :alt: the figure this script draws
"""

# sphinx_gallery_thumbnail_path = "figures/kapitza_pendulum.png"

import numpy as np
from scipy.integrate import solve_ivp

import fastvi
from _cli import QUICK, figure, figure_path, save

T = 2.0 if QUICK else 10.0
H = 1e-3  # ω h = 0.15: the drive is resolved


def main(path):
    shaken = fastvi.scenes.kapitza_pendulum(a=0.05, omega=150.0)
    m, l, g, a, w = shaken.params
    theta0 = np.pi - 0.3  # 0.3 rad from the top, at rest
    q0, v0 = shaken.initial_state(theta0)
    run = fastvi.integrate(shaken, q0, v0, h=H, t_end=T, save_every=5)
    theta = np.unwrap(shaken.angle(run.q, run.t))
    print(run.summary())

    # independent reference: the angle equation in minimal coordinates
    ref = solve_ivp(lambda t, y: [y[1], -(g - a * w * w * np.cos(w * t)) * np.sin(y[0]) / l],
                    (0.0, T), [theta0, 0.0], method="DOP853", rtol=1e-12, atol=1e-12, t_eval=run.t)
    print(f"max |θ − θ_scipy| = {np.max(np.abs(theta - ref.y[0])):.2e} rad")
    print(f"farthest from the top: {np.max(np.abs(theta - np.pi)):.3f} rad (started 0.300)")
    print(f"energy balance: max |H − H0 − W| = {np.max(np.abs(run.energy_balance)):.2e} J, "
          f"while H − H0 swings by {np.ptp(run.energy_error):.2f} J")

    still = fastvi.scenes.kapitza_pendulum(a=1e-9, omega=150.0)  # pivot (practically) at rest
    fall = fastvi.integrate(still, *still.initial_state(theta0), h=H, t_end=T, save_every=5)
    fall_theta = np.unwrap(still.angle(fall.q, fall.t))

    fig = figure(figsize=(7, 4))
    ax = fig.subplots()
    ax.plot(run.t, theta, lw=0.8, label=f"pivot shaken: a = {a:g} m, ω = {w:g} rad/s")
    ax.plot(fall.t, fall_theta, lw=0.8, label="pivot at rest")
    ax.axhline(np.pi, color="k", lw=0.5, ls=":")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("θ (rad from the downward vertical)")
    ax.set_title("Kapitza's pendulum, fastvi P2L-Q3G, h = 1 ms")
    ax.legend(fontsize="small")
    save(fig, path, dpi=120)

    up = _top(a, w)
    print(f"Floquet multipliers of the top at ω = {w:g}: {np.round(up.multipliers, 5)}, "
          f"max ||λ| − 1| = {np.abs(np.abs(up.multipliers) - 1).max():.1e} (stable)")
    lo, hi = 60.0, 120.0  # unstable, stable
    for _ in range(12 if QUICK else 30):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if _stable(_top(a, mid)) else (mid, hi)
    print(f"the top is stable above ω = {0.5 * (lo + hi):.4f} rad/s for a = {a:g} m "
          f"(Kapitza's estimate √(2 g l)/a = {np.sqrt(2 * g * l) / a:.4f})")


def _top(a, w):
    """The inverted position as a periodic orbit over one period of the drive, 40 steps."""
    model = fastvi.scenes.kapitza_pendulum(a=a, omega=w)
    return fastvi.periodic_orbit(model, *model.initial_state(np.pi), period=2 * np.pi / w,
                                 n_steps=40)


def _stable(orbit):
    """A conservative period map's multipliers are λ, 1/λ: on the unit circle, or real."""
    return abs(orbit.multipliers.sum().real) < 2.0


if __name__ == "__main__":
    main(figure_path("kapitza_pendulum.png"))
