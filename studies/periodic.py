r"""``python -m studies.periodic``: periodic orbits of the double pendulum by
:func:`fastvi.periodic_orbit` against an independent reference → the numbers of
``docs/sensitivities.md`` ("Periodic orbits and Floquet multipliers").

The reference never touches fastvi's kernels: the same nonlinear normal mode in minimal
coordinates (the two angles), found as a *brake orbit* — released at rest, at rest again
after half a period, hence periodic by time reversibility — by Newton on
``ω(T/2; θ0) = 0`` with SciPy's DOP853 (rtol = atol = 1e-12) integrating the equations of
motion together with their variational equations; the monodromy matrix is the
variational equations' solution over one period, its eigenvalues the multipliers.

For each number of steps per period it prints the closing residual, the reciprocal-pair
and determinant errors, the distance of the trivial pair from 1, and the distance of the
nontrivial multipliers and of the initial angles from the reference's.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from fastvi.studies.reference import chain_pendulum_rhs

#: the double pendulum of fastvi.scenes.double_pendulum() (unit masses and rods)
MASSES, LENGTHS, GRAVITY = (1.0, 1.0), (1.0, 1.0), 9.81
TOL = 1e-12


def linear_modes(g: float = GRAVITY):
    r"""The linear normal modes of the unit double pendulum: ``(ω², θ2/θ1)`` of the in-phase
    mode ``ω² = g (2 − √2)``, ``θ2 = √2 θ1`` and of the anti-phase one ``ω² = g (2 + √2)``,
    ``θ2 = −√2 θ1`` (``M = [[2, 1], [1, 1]]``, ``K = g diag(2, 1)``)."""
    r = np.sqrt(2.0)
    return {"in-phase": (g * (2 - r), r), "anti-phase": (g * (2 + r), -r)}


def _variational_rhs(masses, lengths, g):
    """The equations of motion in angles with their variational equations ``Φ' = J Φ``;
    ``J`` by complex steps of the right-hand side (exact to round-off)."""
    f = chain_pendulum_rhs(masses, lengths, g)
    N = 2 * len(masses)

    def rhs(t, y):
        x, Phi = y[:N], y[N:].reshape(N, N)
        J = np.empty((N, N))
        for j in range(N):
            xc = x.astype(complex)
            xc[j] += 1e-30j
            J[:, j] = f(t, xc).imag / 1e-30
        return np.concatenate([f(t, x), (J @ Phi).ravel()])

    return rhs


def flow_with_tangent(x0, t: float, masses=MASSES, lengths=LENGTHS, g=GRAVITY):
    """``(x(t), ∂x(t)/∂x0)`` of the angle equations from ``x0 = (θ, ω)`` (DOP853)."""
    N = 2 * len(masses)
    y0 = np.concatenate([np.asarray(x0, float), np.eye(N).ravel()])
    sol = solve_ivp(_variational_rhs(masses, lengths, g), (0.0, t), y0, method="DOP853",
                    rtol=TOL, atol=TOL)
    if not sol.success:  # pragma: no cover
        raise RuntimeError(sol.message)
    y = sol.y[:, -1]
    return y[:N], y[N:].reshape(N, N)


def brake_orbit(theta_guess, period: float, masses=MASSES, lengths=LENGTHS, g=GRAVITY,
                max_iter: int = 20) -> np.ndarray:
    """The angles ``θ0`` of the brake orbit of ``period`` near ``theta_guess``: released at
    rest, at rest after ``period / 2``. Newton on ``ω(T/2; θ0) = 0``."""
    L = len(masses)
    theta = np.asarray(theta_guess, float).copy()
    for _ in range(max_iter):
        x, Phi = flow_with_tangent(np.concatenate([theta, np.zeros(L)]), period / 2, masses,
                                   lengths, g)
        step = np.linalg.solve(Phi[L:, :L], -x[L:])
        theta += step
        if np.abs(step).max() < 1e-13:
            return theta
    raise RuntimeError(f"brake_orbit did not converge (last step {np.abs(step).max():.1e})")


def reference_multipliers(theta0, period: float, masses=MASSES, lengths=LENGTHS, g=GRAVITY):
    """Eigenvalues of the monodromy matrix of the orbit from rest at ``theta0``, farthest
    from 1 first."""
    x0 = np.concatenate([np.asarray(theta0, float), np.zeros(len(masses))])
    _, Phi = flow_with_tangent(x0, period, masses, lengths, g)
    lam = np.linalg.eigvals(Phi)
    return lam[np.argsort(-np.abs(lam - 1.0), kind="stable")]


def pair_errors(lam) -> tuple[float, float, float]:
    """For multipliers ordered as :attr:`fastvi.PeriodicOrbit.multipliers` of a 2-degree-of-
    freedom system: ``|λ1 λ2 − 1|`` (the nontrivial pair), ``|det − 1|``, and the largest
    distance of the trivial pair from 1."""
    return (abs(lam[0] * lam[1] - 1), abs(np.prod(lam) - 1), float(np.abs(lam[2:] - 1).max()))


@dataclass
class Row:
    """One orbit of :func:`measure` against the reference."""

    steps: int
    h: float
    iterations: int
    residual: float
    pair: float
    det: float
    trivial: float
    multipliers: float  # max |λ − λ_ref| over the nontrivial pair
    angles: float  # max |θ0 − θ0_ref|


def measure(mode: str = "in-phase", amplitude: float = 0.3, stretch: float = 1.01,
            steps=(50, 100, 200, 400), method: str = "P2L-Q3G"):
    """The mode scaled to ``θ1 = amplitude``, with the period ``stretch`` times the linear
    one, found at each number of steps per period and compared with the reference:
    ``(T, θ0_ref, λ_ref, rows)``."""
    import fastvi

    w2, ratio = linear_modes()[mode]
    T = stretch * 2 * np.pi / np.sqrt(w2)
    guess = np.array([amplitude, ratio * amplitude])
    theta_ref = brake_orbit(guess, T)
    lam_ref = reference_multipliers(theta_ref, T)
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(*guess)
    rows = []
    for N in steps:
        o = fastvi.periodic_orbit(dp, q0, v0, period=T, n_steps=N, method=method,
                                  phase=("v", 0), tol=1e-13)
        lam = o.multipliers
        dlam = np.abs(np.sort_complex(lam[:2]) - np.sort_complex(lam_ref[:2])).max()
        dth = np.abs(np.array(dp.angles(o.q0)) - theta_ref).max()
        rows.append(Row(N, o.h, o.iterations, o.residual, *pair_errors(lam), dlam, dth))
    return T, theta_ref, lam_ref, rows


def table(mode: str = "in-phase", amplitude: float = 0.3, stretch: float = 1.01,
          method: str = "P2L-Q3G") -> str:
    """:func:`measure` as a Markdown table."""
    T, theta_ref, lam_ref, rows = measure(mode, amplitude, stretch, method=method)
    out = [f"{mode} mode, T = {T:.6f} s ({stretch:g} × linear), reference θ0 = "
           f"({theta_ref[0]:.6f}, {theta_ref[1]:.6f}), multipliers {lam_ref[0]:.6f}, "
           f"{lam_ref[1]:.6f}, trivial pair off 1 by {np.abs(lam_ref[2:] - 1).max():.1e}", "",
           "| steps per period | h | iterations | closing residual | \\|λ1λ2 − 1\\| | \\|det − 1\\| "
           "| trivial \\|λ − 1\\| | \\|λ − λ_ref\\| | \\|θ0 − θ0_ref\\| |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r.steps} | {r.h:.4g} | {r.iterations} | {r.residual:.1e} | {r.pair:.1e} "
                   f"| {r.det:.1e} | {r.trivial:.1e} | {r.multipliers:.2e} | {r.angles:.2e} |")
    return "\n".join(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m studies.periodic",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="P2L-Q3G")
    args = parser.parse_args(argv)
    parts = [table("in-phase", 0.3, 1.01, method=args.method),
             table("anti-phase", 0.1, 1.01, method=args.method)]
    sys.stdout.write("\n\n".join(parts) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
