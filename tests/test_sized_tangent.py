"""The linearised step compiled for a model's sizes (``specialize=True`` of the derivatives,
or chosen with ``None``): the sizes become compile-time constants and nothing else changes,
so the derivatives must equal the generic kernels' bit for bit.

The sized code takes the generic :class:`TangentWork` by pointer (the time loops are
compiled once for both): that holds only while the two types lay out every field but the
sizes alike, which the first test checks without compiling a kernel."""

import numba
import numpy as np
import pytest
from numba.core.registry import cpu_target

import fastvi
from fastvi.kernels import layout as lay
from fastvi.kernels.tangent import TangentWork, make_tangent_work, sized_twin
from fastvi.structure import SIZED_MAX_N, SIZED_TANGENT_MIN_STEPS, sizing


def _offsets(value):
    ctx = cpu_target.target_context
    t = ctx.get_data_type(numba.typeof(value))
    return [t.get_element_offset(ctx.target_data, i) for i in range(len(t.elements))]


@pytest.mark.parametrize("dims", [(4, 2, 2, 3, 2), (2, 0, 1, 2, 1), (7, 3, 4, 5, 4)])
def test_the_sized_tangent_work_lays_out_every_field_but_the_sizes_as_the_generic(dims):
    n, m, s, r, J = dims
    tw = make_tangent_work(n, m, s, r, J, 3, [0, 2],
                           fastvi.scenes.double_pendulum().param_derivative_data(), 6)
    twin = sized_twin(tw)
    assert TangentWork._fields[-1] == "ws" and lay.Workspace._fields[-1] == "dims"
    assert twin.ws.dims == lay.size_markers(tw.ws.dims)
    assert _offsets(twin) == _offsets(tw)  # every field of the TangentWork, ws last
    assert _offsets(twin.ws)[:-1] == _offsets(tw.ws)[:-1]  # the sizes alone differ
    assert all(a is b for a, b in zip(twin[:-1], tw[:-1]))  # the same arrays


def test_none_sizes_the_linearised_step_where_it_is_compiled_or_pays():
    assert sizing(None, 4, SIZED_TANGENT_MIN_STEPS, SIZED_TANGENT_MIN_STEPS) is True
    assert sizing(None, 4, SIZED_TANGENT_MIN_STEPS - 1, SIZED_TANGENT_MIN_STEPS) == "cached"
    assert sizing(None, SIZED_MAX_N + 1, 10**12, SIZED_TANGENT_MIN_STEPS) is False
    assert sizing(False, 4, 10**12, SIZED_TANGENT_MIN_STEPS) is False


def test_specialize_of_the_derivatives_is_named_in_its_error(double_pendulum):
    q0, v0 = double_pendulum.initial_state(0.5, 0.3)
    for call in (lambda **k: fastvi.sensitivity(double_pendulum, q0, v0, **k),
                 lambda **k: fastvi.adjoint(double_pendulum, q0, v0,
                                            lambda r: (np.ones_like(r.q), None), **k)):
        with pytest.raises(TypeError, match="`specialize` must be None, True or False"):
            call(h=0.01, n_steps=3, specialize="yes")


# compiles the sized linearised step for the damped double pendulum (≈ 40–70 s of CPU on an
# empty cache)
@pytest.mark.slow
def test_sized_derivatives_are_the_generic_ones_bit_for_bit():
    dp = fastvi.scenes.double_pendulum(damping=0.3)
    q0, v0 = dp.initial_state(1.0, 0.5)
    kw = dict(h=0.01, n_steps=400, save_every=7)
    wrt = ("q0", "v0", "params")
    gen = fastvi.sensitivity(dp, q0, v0, wrt=wrt, specialize=False, **kw)
    sized = fastvi.sensitivity(dp, q0, v0, wrt=wrt, specialize=True, **kw)
    for f in ("dq", "dv", "dp"):
        assert np.array_equal(getattr(gen, f), getattr(sized, f)), f
    assert np.array_equal(gen.result.q, sized.result.q)
    # None takes the sized step now that it is compiled: the same numbers again
    assert np.array_equal(fastvi.sensitivity(dp, q0, v0, wrt=wrt, **kw).dq, gen.dq)

    def cost(res):
        return np.sin(res.q), res.v ** 2

    a_gen = fastvi.adjoint(dp, q0, v0, cost, specialize=False, **kw)
    a_sized = fastvi.adjoint(dp, q0, v0, cost, specialize=True, **kw)
    assert np.array_equal(a_gen.gradient, a_sized.gradient)
    # checkpointed: the retaken segments go through the same sized sweep
    a_ck = fastvi.adjoint(dp, q0, v0, cost, specialize=True, checkpoint_every=37, **kw)
    assert np.array_equal(a_ck.gradient, a_gen.gradient)
    # the ensemble's members read their own generic tangent work through the sized hook
    Q0, V0 = np.stack([q0, q0]), np.stack([v0, v0])
    e_gen = fastvi.sensitivity_ensemble(dp, Q0, V0, specialize=False, **kw)
    e_sized = fastvi.sensitivity_ensemble(dp, Q0, V0, specialize=True, **kw)
    assert np.array_equal(e_gen.dq, e_sized.dq) and np.array_equal(e_gen.dp, e_sized.dp)
