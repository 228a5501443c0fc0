"""Derivatives at a start that ``integrate`` projects onto the constraints.

A start off the constraints by less than ``1e-6`` is moved, with a warning, to the nearest
point of ``g = 0`` in the metric of ``M`` at the given ``q0`` and the nearest velocity with
``G v + g_t = 0``; the derivatives by ``(q0, v0, θ)`` differentiate that projection. The
reference is central differences of whole ``integrate`` runs from the perturbed raw
starts (each projected by ``integrate`` itself), at the start and after a few steps, on
models with a constant mass, a configuration-dependent mass, and a singular constant mass;
the adjoint's gradient is checked against the forward derivatives (``⟨λ, δx⟩``).
"""

import warnings

import numpy as np
import pytest

import fastvi

from .test_sensitivity import adjoint_gap
from .test_singular_mass import _follower, _state

#: the violation of the given start, ``max |g(q0)|`` and ``max |G v0 + g_t|``: large
#: enough that the terms of the projection's derivative its move scales (about this size)
#: stand out of the differences' noise, small enough that the differences' starts stay
#: within the 1e-6 that ``integrate`` projects
OFFSET = 4e-7
EPS = 5e-8  # the differences' step


def _scenes():
    dp = fastvi.scenes.double_pendulum(damping=0.3)
    rr = fastvi.scenes.rotary_rod_slider()
    return {
        "constant mass": (dp, dp.initial_state(0.9, -0.4, 0.3, 1.1), dict(h=0.05, n_steps=4)),
        "mass function": (rr, rr.initial_state(0.3, 1.1, 0.5, 0.2), dict(h=0.01, n_steps=4)),
        "singular mass": (_follower(), _state(1.1, 0.4), dict(h=0.05, n_steps=4)),
    }


def _off(model, q, v, seed):
    """``(q, v)`` moved along random directions until each violation is :data:`OFFSET`."""
    rng = np.random.default_rng(seed)
    prm = model.params
    dq, dv = rng.standard_normal(model.n), rng.standard_normal(model.n)
    G = model.constraint_jacobian_value(q, prm, 0.0)
    return (q + OFFSET * dq / np.abs(G @ dq).max(), v + OFFSET * dv / np.abs(G @ dv).max())


def _runs(model, x, kw):
    n = model.n
    with warnings.catch_warnings():  # every start is projected: that is the point
        warnings.simplefilter("ignore")
        r = fastvi.integrate(model, x[:n], x[n:2 * n], params=x[2 * n:], **kw)
    return np.concatenate([r.q, r.v], axis=1)


def _differences(model, q0, v0, kw):
    """(K, 2n, 2n + k): central differences of every sample of ``(q, v)``."""
    x = np.concatenate([q0, v0, model.params])
    cols = []
    for j in range(x.size):
        e = np.zeros(x.size)
        e[j] = EPS * max(1.0, abs(x[j])) if j >= 2 * model.n else EPS
        cols.append((_runs(model, x + e, kw) - _runs(model, x - e, kw)) / (2 * e[j]))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("scene", ["constant mass", "mass function", "singular mass"])
def test_derivatives_at_a_projected_start_are_those_of_the_projected_runs(scene):
    model, (q, v), kw = _scenes()[scene]
    q0, v0 = _off(model, q, v, seed=3)
    with pytest.warns(UserWarning, match="projected"):
        S = fastvi.sensitivity(model, q0, v0, wrt=("q0", "v0", "params"), **kw)
    F = _differences(model, q0, v0, kw)
    A = np.concatenate([S.dq, S.dv], axis=1)
    for k in (0, -1):  # the projection alone, and after the steps
        err = np.abs(A[k] - F[k]).max() / max(1.0, np.abs(F[k]).max())
        # the differences' noise is 1e-9–7e-9 here; the projection linearised at the
        # projected start, without the terms the move scales, is off by 5e-8–4e-7
        assert err < 2e-8, (scene, k, err)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert adjoint_gap(model, q0, v0, **kw) < 1e-13


def test_the_projected_start_is_the_nearest_point_in_the_metric_of_the_given_start():
    """``M(q0) (q* − q0) + G(q*)ᵀ μ = 0`` for some ``μ``, and ``g(q*) = 0``: the
    definition the derivative differentiates, not merely a point on the constraints."""
    model, (q, v), kw = _scenes()["constant mass"]  # constraints that curve
    q0, v0 = _off(model, q, v, seed=4)
    with pytest.warns(UserWarning, match="projected"):
        r = fastvi.integrate(model, q0, v0, **kw)
    qs, prm = r.q[0], model.params
    w = model.mass_matrix(q0, prm) @ (qs - q0)
    Gs = model.constraint_jacobian_value(qs, prm, 0.0)
    mu = np.linalg.lstsq(Gs.T, -w, rcond=None)[0]
    # relative to the move: q*'s round-off is 3e-10 of it; a projection that took G at the
    # given q0 instead (the Gauss–Newton step) is off by 1.5e-7
    assert np.abs(w + Gs.T @ mu).max() < 1e-8 * np.abs(w).max()
    assert np.abs(model.constraint_value(qs, prm, 0.0)).max() < 1e-15
