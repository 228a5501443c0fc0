"""Structure: bounded energy error without drift, symplecticity of the one-step map."""

import numpy as np
import pytest

import fastvi
from tests.kernel_helpers import one_step
from fastvi.studies.convergence import drift_slope

from . import models


@pytest.mark.parametrize("name", ["P2L-Q3G", "P3L-Q4G"])
def test_energy_error_does_not_drift_over_1e5_steps(double_pendulum, name):
    q0, v0 = double_pendulum.initial_state(np.pi / 2, np.pi / 2)
    r = fastvi.integrate(double_pendulum, q0, v0, h=0.01, n_steps=100_000, method=name, save_every=10)
    err = r.energy_error
    slope, window_max = drift_slope(r.t, err)
    growth = abs(slope) * r.t[-1]
    # A drifting method (RK4) grows by about its whole error over the run (growth/max ~ 1);
    # here the window maxima only fluctuate with the chaotic motion. Measured growth/max:
    # P2 0.014, P3 0.19 (0.03 over 4·10^5 steps, so the 0.19 is fluctuation, not a trend).
    assert growth <= 0.5 * np.abs(err).max(), (growth, window_max)
    assert np.abs(err).max() < {"P2L-Q3G": 1e-3, "P3L-Q4G": 1e-5}[name]  # measured 6e-5, 3e-7


def _one_step(model, meth, h, q, p):
    v = np.linalg.solve(model.mass_matrix(q), p)
    st, q1, p1, _, _, _ = one_step(model, meth, h, q, p, v, tol=1e-15, max_iter=50)
    assert st == 0
    return q1, p1


@pytest.mark.parametrize("label,model,q,v", [
    ("constant mass", models.quartic(), np.array([0.8, -0.3]), np.array([0.2, 0.5])),
    ("q-dependent mass", models.polar_pendulum(spring=50.0), np.array([1.1, 0.7]), np.array([0.4, 1.3])),
])
@pytest.mark.parametrize("name", ["P1L-Q2G", "P2L-Q3G", "P3L-Q3L"])
def test_one_step_map_is_symplectic_unconstrained(label, model, q, v, name):
    """DΦᵀ J DΦ = J for the map (q, p) → (q', p'), DΦ by central differences."""
    meth = fastvi.method(name)
    h = 0.1
    p = model.mass_matrix(q) @ v
    n = model.n
    z = np.concatenate([q, p])
    D = np.zeros((2 * n, 2 * n))
    d = 1e-5
    for k in range(2 * n):
        zp, zm = z.copy(), z.copy()
        zp[k] += d
        zm[k] -= d
        fp = np.concatenate(_one_step(model, meth, h, zp[:n], zp[n:]))
        fm = np.concatenate(_one_step(model, meth, h, zm[:n], zm[n:]))
        D[:, k] = (fp - fm) / (2 * d)
    J = np.block([[np.zeros((n, n)), np.eye(n)], [-np.eye(n), np.zeros((n, n))]])
    assert np.abs(D.T @ J @ D - J).max() < 1e-8  # measured ≤ 2e-10 (finite-difference error)


def test_loop_action_is_preserved_on_the_constrained_phase_space(double_pendulum):
    """∮ p·dq over a closed loop of consistent initial states is invariant under the flow
    of a symplectic map on the constraint manifold (measured with a spectrally accurate
    trapezoid rule on the periodic loop)."""
    K = 128  # 64 points left a 1e-8 quadrature error on the deformed loop
    alpha = 2 * np.pi * np.arange(K) / K
    starts = [double_pendulum.initial_state(1.0 + 0.3 * np.cos(a), -0.5, 0.2, 0.4 + 1.5 * np.sin(a)) for a in alpha]

    def action(qs, ps):
        dq = np.fft.ifft(1j * np.fft.fftfreq(K, 1.0 / K)[:, None] * np.fft.fft(qs, axis=0), axis=0).real
        return np.sum(ps * dq) * (2 * np.pi / K)

    q0 = np.array([s[0] for s in starts])
    p0 = np.array([double_pendulum.mass_matrix(s[0]) @ s[1] for s in starts])
    finals = [fastvi.integrate(double_pendulum, *s, h=0.05, n_steps=40, method="P2L-Q3G") for s in starts]
    q1 = np.array([r.q[-1] for r in finals])
    p1 = np.array([r.p[-1] for r in finals])
    a0, a1 = action(q0, p0), action(q1, p1)
    assert abs(a0) > 0.05  # a loop with real area (measured 0.099)
    assert abs(a1 - a0) < 1e-12 * abs(a0)  # measured 2e-15 relative
