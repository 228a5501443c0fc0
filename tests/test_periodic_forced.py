"""Periodic orbits of forced models (fastvi.periodic_orbit without a phase condition).

References are independent of the code under test: SciPy's DOP853 at rtol 1e-13 on the
models' equations in the angle, with their variational equations (the monodromy matrix over
one period of the drive) and, for the damped response, SciPy's own shooting (``fsolve``).
Theory: Liouville's formula (``det`` of a damped pendulum's monodromy is ``exp(−c T / m)``),
symplecticity of the conservative drive's map (multipliers in reciprocal pairs), and the
exact inverted orbit of Kapitza's pendulum (``x = 0`` by symmetry).
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import fsolve

import fastvi

from . import models

L, GRAV, AMP = 1.0, 9.81, 0.05  # Kapitza's pendulum (the scene's defaults but ω)


def _kapitza_monodromy(omega):
    """SciPy's monodromy of ``θ̈ = −(g + ÿ_p(t)) sin θ / l`` at ``θ ≡ π`` over ``2π/ω``."""
    def rhs(t, y):
        k = -(GRAV - AMP * omega**2 * np.cos(omega * t)) / L
        return np.concatenate([[y[1], k * np.sin(y[0])],
                               (np.array([[0.0, 1.0], [k * np.cos(y[0]), 0.0]])
                                @ y[2:].reshape(2, 2)).ravel()])
    s = solve_ivp(rhs, (0.0, 2 * np.pi / omega), np.concatenate([[np.pi, 0.0], np.eye(2).ravel()]),
                  method="DOP853", rtol=1e-13, atol=1e-14)
    return s.y[2:, -1].reshape(2, 2)


def _inverted(omega, n_steps, periods=1, t0=0.0):
    """Kapitza's pendulum from 0.05 rad off the top at ``t0``, over ``periods`` of the drive."""
    kp = fastvi.scenes.kapitza_pendulum(omega=omega)
    q0, v0 = kp.initial_state(np.pi + 0.05, t0=t0)
    return kp, fastvi.periodic_orbit(kp, q0, v0, period=periods * 2 * np.pi / omega,
                                     n_steps=n_steps, t0=t0)


@pytest.mark.parametrize("omega,stable", [(150.0, True), (30.0, False)])
def test_kapitzas_inverted_position_has_scipys_multipliers_at_order_four(omega, stable):
    """``a² ω² = 56 > 2 g l`` keeps the inverted pendulum up (multipliers on the unit
    circle); ``a² ω² = 2.25`` does not (a real pair ``λ, 1/λ``, ``λ > 1``)."""
    ref = np.sort_complex(np.linalg.eigvals(_kapitza_monodromy(omega)))
    errors = []
    for n_steps in (20, 40):
        kp, up = _inverted(omega, n_steps)
        assert up.forced and up.t0 == 0.0 and up.residual < 1e-12
        # the orbit is the inverted position itself, the bob above the moving pivot
        assert np.abs(up.q0 - [0.0, kp.pivot(0.0) + L]).max() < 1e-12
        assert np.abs(up.v0).max() < 1e-12
        lam = np.sort_complex(up.multipliers)
        assert abs(np.prod(lam) - 1.0) < 1e-13  # symplectic: a reciprocal pair
        if stable:
            assert np.abs(np.abs(lam) - 1.0).max() < 1e-12 and abs(lam[0].imag) > 0.1
        else:
            assert np.abs(lam.imag).max() == 0.0 and lam[-1].real > 1.8
        errors.append(np.abs(lam - ref).max())
    # measured 9.3e-7 → 5.8e-8 (stable) and 4.8e-7 → 3.0e-8 (unstable): order 4.0
    assert errors[1] < 1e-7 and 13 < errors[0] / errors[1] < 19, errors


def test_a_later_start_and_a_double_period_give_the_same_multipliers():
    """The monodromy from ``t0 = 10 h`` is the same maps composed in another order, a similar
    matrix: its multipliers are those from ``t0 = 0`` to round-off. Over two periods of the
    drive the map is the one-period map squared, and so are its multipliers."""
    kp, up = _inverted(150.0, 40)
    h = up.h
    _, later = _inverted(150.0, 40, t0=10 * h)
    assert later.t0 == 10 * h and later.result.t[0] == 10 * h
    assert np.abs(later.q0 - [0.0, kp.pivot(10 * h) + L]).max() < 1e-12
    lam = np.sort_complex(up.multipliers)
    assert np.abs(np.sort_complex(later.multipliers) - lam).max() < 1e-13
    _, twice = _inverted(150.0, 80, periods=2)
    assert np.abs(np.sort_complex(twice.multipliers) - np.sort_complex(lam**2)).max() < 1e-13


# the damped pendulum driven by a horizontal force on its bob (tests/models.py)
M, LD, GD, C, FORCE, OMEGA = models.DRIVEN_PARAMS
PERIOD = 2 * np.pi / OMEGA


def _driven_reference():
    """SciPy's periodic response ``(θ, θ̇)(0)`` (shooting with ``fsolve``) and its monodromy,
    of ``m l² θ̈ = −m g l sin θ − c l² θ̇ + F l cos(ω t) cos θ``."""
    def rhs(t, y):
        th, om = y[0], y[1]
        acc = (-M * GD * LD * np.sin(th) - C * LD * LD * om
               + FORCE * LD * np.cos(OMEGA * t) * np.cos(th)) / (M * LD * LD)
        J = np.array([[0.0, 1.0], [(-M * GD * LD * np.cos(th)
                                    - FORCE * LD * np.cos(OMEGA * t) * np.sin(th)) / (M * LD * LD),
                                   -C / M]])
        return np.concatenate([[om, acc], (J @ y[2:].reshape(2, 2)).ravel()])

    def flow(y0):
        s = solve_ivp(rhs, (0.0, PERIOD), np.concatenate([y0, np.eye(2).ravel()]),
                      method="DOP853", rtol=1e-13, atol=1e-14)
        return s.y[:2, -1], s.y[2:, -1].reshape(2, 2)

    y0 = fsolve(lambda y: flow(y)[0] - y, [0.3, 0.0], xtol=1e-14)
    end, mono = flow(y0)
    assert np.abs(end - y0).max() < 1e-12
    return y0, mono


def test_the_response_of_a_driven_damped_pendulum_converges_to_scipys_at_order_four():
    model = models.driven_pendulum()
    assert not model.time_dependent  # forced through its force alone
    y0, mono = _driven_reference()
    ref = np.sort_complex(np.linalg.eigvals(mono))
    volume = np.exp(-C * PERIOD / M)  # Liouville: the trace of the angle equation's matrix is −c/m
    assert abs(np.linalg.det(mono) - volume) < 1e-12  # (the reference agrees with theory)
    q0 = np.array([np.sin(0.2), -np.cos(0.2)]) * LD
    state, lam, det = [], [], []
    for n_steps in (25, 50):
        o = fastvi.periodic_orbit(model, q0, np.zeros(2), period=PERIOD, n_steps=n_steps)
        assert o.forced and o.residual < 1e-12
        th = np.arctan2(o.q0[0], -o.q0[1])
        rate = (o.v0[0] * np.cos(th) + o.v0[1] * np.sin(th)) / LD
        state.append(max(abs(th - y0[0]), abs(rate - y0[1])))
        lam.append(np.abs(np.sort_complex(o.multipliers) - ref).max())
        det.append(abs(np.prod(o.multipliers).real - volume))
    # measured: state 2.7e-5 → 1.7e-6, multipliers 5.2e-5 → 3.2e-6, det 3.8e-7 → 2.4e-8
    for errors in (state, lam, det):
        assert errors[1] < 1e-5 and 13 < errors[0] / errors[1] < 19, (state, lam, det)


def test_forced_models_name_a_wrong_period_and_a_phase_condition(double_pendulum):
    kp = fastvi.scenes.kapitza_pendulum()
    q0, v0 = kp.initial_state(np.pi + 0.05)
    T = 2 * np.pi / 150.0
    with pytest.raises(ValueError, match=r"not a period of the model's time dependence.*`constraint`"):
        fastvi.periodic_orbit(kp, q0, v0, period=1.1 * T, n_steps=40)
    with pytest.raises(ValueError, match=r"not a period.*`force`"):
        fastvi.periodic_orbit(models.driven_pendulum(), q0, v0, period=0.7 * PERIOD, n_steps=40)
    with pytest.raises(ValueError, match=r"`phase` = 'section'.*forced.*`phase=None`"):
        fastvi.periodic_orbit(kp, q0, v0, period=T, n_steps=40, phase="section")
    with pytest.raises(ValueError, match=r"`phase` = None is for a forced model"):
        fastvi.periodic_orbit(double_pendulum, *double_pendulum.initial_state(0.3, 0.4),
                              period=2.0, n_steps=40, phase=None)
    with pytest.raises(TypeError, match="`t0` must be a float"):
        fastvi.periodic_orbit(kp, q0, v0, period=T, n_steps=40, t0="0")
