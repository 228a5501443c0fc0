"""Fuzzing: any method name, step size and consistent start gives finite output or a
documented exception."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fastvi
from fastvi import IntegrationError

names = st.builds(
    lambda s, r, q, nodes, cons, k: f"P{s}L-Q{r}{q}{nodes}{cons.replace('#', str(k))}",
    st.integers(1, 4), st.integers(1, 5), st.sampled_from("GL"),
    st.sampled_from(["", "-NE", "-NL", "-NC"]),
    st.sampled_from(["", "-CE", "-CN", "-CL#", "-CG#"]), st.integers(1, 4),
)
angles = st.floats(-3.1, 3.1)
rates = st.floats(-12.0, 12.0)


def _run(model, q0, v0, name, h):
    try:
        r = fastvi.integrate(model, q0, v0, h=h, n_steps=25, method=name, max_iter=20)
    except ValueError as err:  # a name outside the family (e.g. Q1L, CL1) is refused by name
        assert "method" in str(err) or "C" in str(err) or "quadrature" in str(err)
        return
    except IntegrationError as err:
        assert err.status < 0 and np.all(np.isfinite(err.result.q))
        return
    for arr in (r.q, r.v, r.p, r.energy, r.constraint_residual, r.velocity_residual):
        assert np.all(np.isfinite(arr))
    assert r.constraint_residual.max() < 1e-9


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(name=names, h=st.floats(1e-3, 0.5), t1=angles, t2=angles, w1=rates, w2=rates)
def test_double_pendulum_fuzz(double_pendulum, name, h, t1, t2, w1, w2):
    _run(double_pendulum, *double_pendulum.initial_state(t1, t2, w1, w2), name, h)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(name=names, h=st.floats(1e-3, 1.0), t=angles, w=rates)
def test_pendulum_fuzz(pendulum, name, h, t, w):
    _run(pendulum, *pendulum.initial_state(t, w), name, h)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_inputs_are_refused(double_pendulum, dp_start, bad):
    q0, v0 = dp_start
    with pytest.raises(ValueError, match="`q0` must be finite"):
        fastvi.integrate(double_pendulum, np.r_[q0[:3], bad], v0, h=0.01, n_steps=1)
    with pytest.raises(ValueError, match="`h` must be positive and finite"):
        fastvi.integrate(double_pendulum, q0, v0, h=bad, n_steps=1)
    with pytest.raises(ValueError, match="`params` must be finite"):
        fastvi.integrate(double_pendulum, q0, v0, h=0.01, n_steps=1, params=[1, 1, 1, 1, bad])
