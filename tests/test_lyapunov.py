"""Lyapunov exponents of the discrete flow against theory and an independent reference.

References: Benettin's QR method on the angle equations of the double pendulum and their
variational equations, SciPy DOP853 at rtol = 1e-12 (``studies/lyapunov.py``, no fastvi
kernel involved); theory: the step is symplectic on the constrained phase space, so the
exponents pair up and the sum of all of them is a boundary term; a quasi-periodic motion
has λ = 0.
"""

import numpy as np
import pytest

import fastvi
from fastvi.scenes.double_pendulum import state_from_angles
from studies.lyapunov import CHAOTIC, cartesian_directions, chaotic_stats, ensemble, reference_spectrum

from . import models

Y0 = np.array([np.pi / 2, np.pi / 2, 0.0, 0.0])  # released at rest from θ1 = θ2 = π/2


def test_spectrum_matches_the_scipy_reference_and_converges_at_order_four(double_pendulum):
    """Same start, same start vectors (the angle unit vectors, mapped to Cartesian), same
    segments and norm: over T = 10 s, before the two trajectories part, the running
    estimates of all four exponents agree to the method's error (measured 1.7e-6 at
    h = 0.01, 1.1e-7 at h = 0.005: order 4)."""
    ref = np.cumsum(reference_spectrum(Y0, np.eye(4), t_end=10.0), axis=0)[-1] / 10.0
    start = cartesian_directions(Y0)  # (δq, δp) = (δq, δv): unit masses
    err = []
    for h in (0.01, 0.005):
        spec = fastvi.lyapunov_spectrum(double_pendulum, *state_from_angles(*Y0), h=h,
                                        t_end=10.0, start=start)
        assert spec.t[-1] == 10.0 and spec.dimension == 4
        err.append(np.abs(spec.exponents - ref).max())
    assert ref[0] > 0.5  # the chaotic start
    assert err[0] < 1e-5 and err[1] < 1e-6
    assert err[0] / err[1] > 8  # ≈ 2^4


def test_sum_of_exponents_is_the_symplectic_boundary_term(double_pendulum, dp_start):
    """The step preserves YᵀJY on the tangent space, so T Σλ_i = ½ log det(Z₀ᵀJZ₀) −
    ½ log det(Z_TᵀJZ_T), Z orthonormal bases of the tangent space (fastvi.tangent_space):
    exact at every T; the pairs λ_1 + λ_4 and λ_2 + λ_3 vanish like 1/T."""
    dp = double_pendulum
    q0, v0 = dp_start
    J = np.block([[np.zeros((4, 4)), np.eye(4)], [-np.eye(4), np.zeros((4, 4))]])

    def half_logdet(q, v):
        Z = fastvi.tangent_space(dp, q, v)
        return 0.5 * np.log(abs(np.linalg.det(Z.T @ J @ Z)))

    T = 20.0  # short: the end state of one integrate run parts from the segmented run's
    spec = fastvi.lyapunov_spectrum(dp, q0, v0, h=0.01, t_end=T)
    end = fastvi.integrate(dp, q0, v0, h=0.01, n_steps=2000, save_every=2000)
    boundary = half_logdet(end.q[0], end.v[0]) - half_logdet(end.q[-1], end.v[-1])
    assert abs(boundary) > 0.1  # the identity is not trivially 0 = 0
    assert abs(T * spec.exponents.sum() - boundary) < 1e-8
    lam = fastvi.lyapunov_spectrum(dp, q0, v0, h=0.01, t_end=100.0).exponents
    assert lam[0] > 0.5 and np.all(np.diff(lam) < 0)
    assert abs(lam[0] + lam[3]) < 0.05 and abs(lam[1]) < 0.1 and abs(lam[2]) < 0.1


def test_largest_lyapunov_exponent_separates_regular_from_chaotic_motion(double_pendulum):
    """Theory: a quasi-periodic motion (small oscillations) has λ = 0, the finite-time
    estimate decaying like log T / T; the double pendulum released at rest from
    θ1 = θ2 = π/2 is chaotic, λ > 0, and its estimate agrees at two step sizes within the
    spread of the finite-time values (docs/sensitivities.md: 0.93 ± 0.02 over the 14
    chaotic of 16 starts on its energy surface at T = 2000 s)."""
    dp = double_pendulum
    regular = fastvi.largest_lyapunov(dp, *dp.initial_state(0.1, 0.1), h=0.01, t_end=100.0)
    assert abs(regular[-1]) < 0.02 and abs(regular[-1]) < abs(regular[4]) + 0.01
    q0, v0 = dp.initial_state(np.pi / 2, np.pi / 2)
    coarse = fastvi.largest_lyapunov(dp, q0, v0, h=0.01, t_end=100.0)
    fine = fastvi.largest_lyapunov(dp, q0, v0, h=0.005, t_end=100.0)
    assert 0.5 < coarse[-1] < 1.5 and 0.5 < fine[-1] < 1.5
    assert abs(coarse[-1] - fine[-1]) < 0.2


def test_errors_name_the_bad_argument(double_pendulum, dp_start):
    q0, v0 = dp_start
    with pytest.raises(ValueError, match="`segment`"):
        fastvi.largest_lyapunov(double_pendulum, q0, v0, h=0.03, t_end=10.0, segment=1.0)
    with pytest.raises(ValueError, match="`t_end`"):
        fastvi.lyapunov_spectrum(double_pendulum, q0, v0, h=0.01, t_end=2.5)
    with pytest.raises(ValueError, match="`count`"):
        fastvi.lyapunov_spectrum(double_pendulum, q0, v0, h=0.01, t_end=1.0, count=5)
    with pytest.raises(ValueError, match="`start`"):
        fastvi.lyapunov_spectrum(double_pendulum, q0, v0, h=0.01, t_end=1.0, start=np.ones((8, 3)))
    with pytest.raises(ValueError, match="dependent"):
        fastvi.lyapunov_spectrum(double_pendulum, q0, v0, h=0.01, t_end=1.0, count=2,
                                 start=np.ones((8, 2)))
    # before any run: each names its argument rather than failing in a conversion
    kw = dict(h=0.01, t_end=1.0, segment=0.5)
    for bad, match in ((dict(segment=np.nan), "`segment` must be positive and finite"),
                       (dict(t_end=np.inf), "`t_end` must be positive and finite"),
                       (dict(segment="1"), "`segment` must be a float"),
                       (dict(count=2.7), "`count` must be an integer"),
                       (dict(count=True), "`count` must be an integer"),
                       (dict(seed="a"), "`seed` must be an integer")):
        with pytest.raises((TypeError, ValueError), match=match):
            fastvi.lyapunov_spectrum(double_pendulum, q0, v0, **{**kw, **bad})
    with pytest.raises(TypeError, match="`model` must be a fastvi.Model"):
        fastvi.lyapunov_spectrum("dp", q0, v0, **kw)


@pytest.mark.slow
def test_ensemble_on_the_energy_surface_agrees_with_the_scipy_reference():
    """16 starts at rest on the energy surface of θ1 = θ2 = π/2: over the chaotic ones, the
    means of λ_1 from fastvi (h = 0.01 and 0.005) and from the SciPy reference agree at
    T = 200 s within three combined standard errors (√(s₁² + s₂²)/√count: after some 20 s
    the runs follow different trajectories, independent samples), the same starts are
    regular in both, and fastvi's means at h = 0.01 and 0.005 agree likewise at
    T = 1000 s (``python -m fastvi lyapunov``: the table; measured 1.4 and 1.2 combined
    standard errors)."""
    runs = ensemble(16, 1000.0, 200.0)
    ref_mean, ref_std, ref_count = chaotic_stats(runs["ref"], 200.0)
    assert ref_count >= 12 and ref_mean > 0.5
    for h in (0.01, 0.005):
        assert np.array_equal(runs[h][:, -1] > CHAOTIC, runs["ref"][:, -1] > CHAOTIC)
        mean, std, count = chaotic_stats(runs[h], 200.0)
        assert abs(mean - ref_mean) < 3 * np.hypot(std, ref_std) / np.sqrt(count)
    coarse, fine = (chaotic_stats(runs[h], 1000.0) for h in (0.01, 0.005))
    assert abs(coarse[0] - fine[0]) < 3 * np.hypot(coarse[1], fine[1]) / np.sqrt(fine[2])


def _half_logdet(model, q, v, t):
    """½ log |det(Zᵀ J Z)|, Z an orthonormal basis of the tangent space at ``(q, v)``, ``t``."""
    d = model.n
    J = np.block([[np.zeros((d, d)), np.eye(d)], [-np.eye(d), np.zeros((d, d))]])
    Z = fastvi.tangent_space(model, q, v, t=t)
    return 0.5 * np.log(abs(np.linalg.det(Z.T @ J @ Z)))


def _boundary(model, q0, v0, h, T, t0):
    end = fastvi.integrate(model, q0, v0, h=h, n_steps=int(round(T / h)),
                           save_every=int(round(T / h)), t0=t0)
    return (_half_logdet(model, end.q[0], end.v[0], end.t[0])
            - _half_logdet(model, end.q[-1], end.v[-1], end.t[-1]))


def test_a_forced_models_exponents_follow_its_drive_across_segments():
    """A segment starts where the last one ended, at ``t0 + j · segment``: the estimates do
    not depend on ``segment`` (the QR method's products are the same), and their sum is the
    symplectic boundary term, exactly for Kapitza's pendulum (a driven constraint, conservative)
    and up to Liouville's ``−c T / m`` at order 4 for the pendulum driven by a force with a
    dashpot. Restarting the drive at 0 in every segment broke all three."""
    kp = fastvi.scenes.kapitza_pendulum()
    q0, v0 = kp.initial_state(2.0, t0=0.3)
    runs = [fastvi.lyapunov_spectrum(kp, q0, v0, h=0.002, t_end=2.0, segment=seg, t0=0.3)
            for seg in (0.5, 0.25)]
    assert np.allclose(runs[0].t, [0.8, 1.3, 1.8, 2.3], rtol=0, atol=1e-12)
    assert np.abs(runs[0].exponents - runs[1].exponents).max() < 1e-11
    assert runs[0].exponents[0] > 1.0  # the tumbling start, not a trivial 0 = 0
    boundary = _boundary(kp, q0, v0, 0.002, 2.0, 0.3)
    assert abs(boundary) > 0.1 and abs(2.0 * runs[0].exponents.sum() - boundary) < 1e-10

    driven, c = models.driven_pendulum(), models.DRIVEN_PARAMS[3]  # m = 1
    q0, v0 = np.array([np.sin(0.2), -np.cos(0.2)]), np.zeros(2)
    T, errors = 8.0, []
    for h in (0.02, 0.01):
        spec = [fastvi.lyapunov_spectrum(driven, q0, v0, h=h, t_end=T, segment=seg, t0=0.3)
                for seg in (1.0, 4.0)]
        assert np.abs(spec[0].exponents - spec[1].exponents).max() < 1e-12
        errors.append(abs(T * spec[0].exponents.sum() - _boundary(driven, q0, v0, h, T, 0.3) + c * T))
    # measured 6.9e-9 → 4.3e-10 (and 2.6e-11 at h = 0.005): order 4
    assert errors[1] < 1e-8 and 13 < errors[0] / errors[1] < 19, errors
