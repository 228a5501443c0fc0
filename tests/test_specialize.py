"""Size-specialized kernels (``integrate(..., specialize=True)``): the sizes become
compile-time constants, the arithmetic and its order do not change — so the trajectory must
equal the generic kernel's bit for bit, not merely to round-off."""

import numpy as np
import pytest

import fastvi
from fastvi.kernels import layout as lay

FIELDS = ("t", "q", "v", "p", "energy", "constraint_residual", "velocity_residual",
          "newton_iterations")


def _same(a, b):
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert np.array_equal(x, y), f"{f} differs: max |Δ| = {np.max(np.abs(x - y)):.3e}"


def test_markers_and_sizes():
    assert lay.size_markers((4, 2, 2, 3, 2)) == ((None,) * 4, (None,) * 2, (None,) * 2,
                                                 (None,) * 3, (None,) * 2)
    assert lay.size_markers((3, 0, 1, 2, 1))[1] == ()
    assert [lay.dim(k) for k in lay.size_markers((4, 0, 3))] == [4, 0, 3]
    ws = lay.specialize(lay.make_workspace(4, 2, 2, 3, 2))
    assert ws.dims == lay.size_markers((4, 2, 2, 3, 2))
    assert ws.X.shape == (12,)


def test_parallel_markers_carry_the_sizes_into_a_compiled_body():
    """Ensembles pass sizes to their parallel loop as empty arrays of that many dimensions
    (numba's prange takes no nested tuples); the body turns them back into the size markers
    of integrate(..., specialize=True). Sizes above 64 stay integers."""
    dims = (4, 2, 0, 3, 70)
    pm = lay.parallel_markers(dims)
    assert [type(x) for x in pm] == [np.ndarray] * 4 + [int]
    assert [lay.dim(x) for x in pm] == list(dims)
    assert lay.member_sizes(pm) == lay.size_markers(dims[:4]) + (70,)
    assert lay.member_sizes(dims) == dims  # the generic kernels' integers pass unchanged


# compiles the time loop for the double pendulum's sizes (≈ 90 s on an empty cache): over
# the 8-minute budget of `make test` together with the rest; `make test-slow` and `make bench`
# (which asserts the same equality on every method it times) run it
@pytest.mark.slow
def test_specialized_double_pendulum_is_the_generic_trajectory_bit_for_bit():
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(np.pi / 2, np.pi / 2)
    kw = dict(h=0.01, n_steps=3000, method="P2L-Q3G", save_every=7)
    gen = fastvi.integrate(dp, q0, v0, **kw)
    sized = fastvi.integrate(dp, q0, v0, specialize=True, **kw)
    _same(gen, sized)
    # and the run is a real one: energy bounded, constraints at round-off
    assert np.max(np.abs(sized.energy - sized.energy[0])) < 1e-3
    assert np.max(sized.constraint_residual) < 1e-13
    # the full Newton variant goes through the same specialized kernel
    full = fastvi.integrate(dp, q0, v0, newton="full", specialize=True, **kw)
    _same(fastvi.integrate(dp, q0, v0, newton="full", **kw), full)
    # adaptive steps: the sized step inlines the predictor of a changing step length
    ka = dict(h=0.05, t_end=30.0, method="P2L-Q3G", save_every=3, adaptive=3.0)
    _same(fastvi.integrate(dp, q0, v0, **ka), fastvi.integrate(dp, q0, v0, specialize=True, **ka))


def test_specialize_is_a_flag():
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(0.1, 0.2)
    with pytest.raises(TypeError, match="`specialize` must be True or False"):
        fastvi.integrate(dp, q0, v0, h=0.01, n_steps=2, specialize="yes")
    with pytest.raises(TypeError, match="`specialize` must be True or False"):
        fastvi.integrate(dp, q0, v0, h=0.01, n_steps=2, specialize=1)


# the stiff rod–slider takes the full Newton on nearly every step (the mechanics iteration fails there and
# falls back), the fallback's retries from lower-degree guesses included; compiles the
# slider's sizes (≈ 100 s on an empty cache)
@pytest.mark.slow
def test_specialized_stiff_fallback_is_the_generic_trajectory_bit_for_bit():
    from studies import peers

    k = 1e8
    model = fastvi.scenes.rotary_rod_slider(k=k)
    q0, v0 = model.initial_state(0.0, peers.SLIDER_R0 + peers.slider_stretch(k))
    kw = dict(h=0.01, n_steps=1000, method="P2L-Q2G")
    gen = fastvi.integrate(model, q0, v0, **kw)
    sized = fastvi.integrate(model, q0, v0, specialize=True, **kw)
    assert gen.stats["full_newton_steps"] > 10  # the fallback was taken, and taken again
    for key in ("newton_iterations", "full_newton_steps"):
        assert sized.stats[key] == gen.stats[key], key
    _same(gen, sized)
