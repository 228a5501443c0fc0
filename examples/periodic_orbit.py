"""Nonlinear normal modes of the double pendulum and their Floquet multipliers
============================================================================

A small oscillation of the double pendulum (unit masses and rods, g = 9.81) is a mix of two
linear normal modes: the in-phase one (θ2 = √2 θ1, period 2.62 s) and the anti-phase one
(θ2 = −√2 θ1, period 1.09 s). At larger amplitudes each continues as a family of periodic
orbits, the *nonlinear normal modes*, whose period grows with the energy (the pendulum
softens). :func:`fastvi.periodic_orbit` finds them on the integrator's own discrete flow:
Newton's method on ``Φ^N(x0) = x0`` in coordinates of the tangent space of the constrained
phase space (the model is the Cartesian one, n = 4 with m = 2 rod constraints), with the
exact derivatives of :func:`fastvi.sensitivity`, and a phase condition that starts the
orbit at a turning point (``v0[0] = 0``).

The periods are stepped from just above the linear one upwards, each orbit the guess of the
next (natural continuation). For each, the script prints the amplitude, the energy and the
Floquet multipliers: the eigenvalues of the monodromy matrix, which come in reciprocal
pairs because the discrete map is symplectic. Two are the trivial pair ≈ 1 (along the flow
and across the energies); the other pair ``e^{±iθ}`` on the unit circle means the mode is
linearly stable, and it leaves the circle through −1 (a period doubling) or +1 where it
turns unstable.

Run ``python examples/periodic_orbit.py [--out DIR]``; it prints the table and writes
``periodic_orbit.png`` (the modes as curves in the angles, the paths of both bobs on the
largest in-phase one, and the stability index of the multipliers against the energy)
into ``docs/figures/``. With ``FASTVI_QUICK=1``: the first six orbits, written to a temporary
directory.

.. image:: /figures/periodic_orbit.png
   :alt: nonlinear normal modes of the double pendulum and their multipliers
"""

# sphinx_gallery_thumbnail_path = "figures/periodic_orbit.png"

import numpy as np

import fastvi
from _cli import QUICK, figure, out_dir, save

G = 9.81
#: the linear modes of the unit double pendulum: ω², the shape θ2 / θ1, and a guess of θ1
#: for the first period of the branch (the anti-phase mode softens faster)
MODES = {"in-phase": (G * (2 - np.sqrt(2)), np.sqrt(2), 0.2),
         "anti-phase": (G * (2 + np.sqrt(2)), -np.sqrt(2), 0.05)}


def branch(model, name, stretches, n_steps):
    """The orbits of the mode ``name`` with periods ``stretch`` × the linear one, each
    started from the previous."""
    w2, ratio, theta1 = MODES[name]
    q0, v0 = model.initial_state(theta1, theta1 * ratio)
    orbits = []
    for s in stretches:
        orbit = fastvi.periodic_orbit(model, q0, v0, period=s * 2 * np.pi / np.sqrt(w2),
                                      n_steps=n_steps, phase=("v", 0))
        orbits.append(orbit)
        q0, v0 = orbit.q0, orbit.v0
    return orbits


def stability_index(orbit):
    """``(λ + 1/λ)/2`` of the nontrivial pair: ``cos θ`` for ``λ = e^{±iθ}`` on the unit
    circle (stable), real beyond ±1 off it (unstable)."""
    lam = orbit.multipliers[0]
    return float(np.real(lam + 1 / lam) / 2)


def main(argv=None):
    out = out_dir(__doc__, "the figure", argv)
    model = fastvi.scenes.double_pendulum()
    stretches = np.linspace(1.005, 1.08, 31)[:6 if QUICK else None]  # steps small enough to follow
    branches = {name: branch(model, name, stretches, 200) for name in MODES}

    print(f"{'mode':<11} {'T/T_lin':>7} {'θ1 (rad)':>9} {'θ2 (rad)':>9} {'energy':>9} "
          f"{'residual':>9} {'index':>8}  multipliers (nontrivial pair; |trivial pair − 1|)")
    for name, orbits in branches.items():
        for s, o in list(zip(stretches, orbits))[::1 if QUICK else 3]:
            th1, th2 = model.angles(o.q0)
            lam = o.multipliers
            print(f"{name:<11} {s:7.3f} {th1:9.4f} {th2:9.4f} {model.energy(o.q0, o.v0):9.4f} "
                  f"{o.residual:9.1e} {stability_index(o):8.5f}  {lam[0]:.5f}, {lam[1]:.5f}; "
                  f"{np.abs(lam[2:] - 1).max():.0e}")

    fig = figure(figsize=(12, 4))
    axes = fig.subplots(1, 3)
    for name, orbits in branches.items():  # the modes are curves in configuration space
        shown = orbits[::max(1, len(orbits) // 4)]
        for i, o in enumerate(shown):
            th1, th2 = model.angles(o.result.q)
            axes[0].plot(th1, th2, color="C0" if name == "in-phase" else "C1", lw=1.2,
                         alpha=0.4 + 0.6 * i / max(1, len(shown) - 1), label=name if i == 0 else None)
    axes[0].set_aspect("equal")
    axes[0].set_title("the modes in angles, T/T_lin = 1.005 … 1.08", fontsize=10)
    axes[0].set_xlabel("θ1 (rad)")
    axes[0].set_ylabel("θ2 (rad)")
    axes[0].legend(fontsize=7)
    o = branches["in-phase"][-1]
    q = o.result.q
    axes[1].plot(q[:, 0], q[:, 1], color="C0", lw=1.5, label="bob 1")
    axes[1].plot(q[:, 2], q[:, 3], color="C3", lw=1.5, label="bob 2")
    for k in range(0, o.n_steps // 2 + 1, o.n_steps // 10):  # half a period: there and back
        axes[1].plot([0, q[k, 0], q[k, 2]], [0, q[k, 1], q[k, 3]], "o-", color="0.5", lw=0.8, ms=3)
    axes[1].set_aspect("equal")
    axes[1].set_title(f"in-phase mode, T = {o.period:.3f} s", fontsize=10)
    axes[1].set_xlabel("x (m)")
    axes[1].set_ylabel("y (m)")
    axes[1].legend(fontsize=7)
    for name, orbits in branches.items():
        energy = [model.energy(o.q0, o.v0) for o in orbits]
        axes[2].plot(energy, [stability_index(o) for o in orbits], "o-", ms=3, label=name)
    axes[2].axhline(-1.0, color="0.5", lw=0.8, ls="--")
    axes[2].set_title("stability index (λ + 1/λ)/2: stable in (−1, 1)", fontsize=10)
    axes[2].set_xlabel("energy (J)")
    axes[2].legend(fontsize=7)
    save(fig, out / "periodic_orbit.png", dpi=100)


if __name__ == "__main__":
    main()
