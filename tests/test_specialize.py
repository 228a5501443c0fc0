"""Size-specialized stages (``integrate(..., specialize=True)``, or chosen with ``None``): the
sizes become compile-time constants, the arithmetic and its order do not change — so the
trajectory must equal the generic kernel's bit for bit, not merely to round-off."""

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


# compiles the sized stages for the double pendulum's sizes (≈ 8 s on an empty cache)
def test_specialized_double_pendulum_is_the_generic_trajectory_bit_for_bit():
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(np.pi / 2, np.pi / 2)
    kw = dict(h=0.01, n_steps=3000, method="P2L-Q3G", save_every=7)
    gen = fastvi.integrate(dp, q0, v0, specialize=False, **kw)
    sized = fastvi.integrate(dp, q0, v0, specialize=True, **kw)
    _same(gen, sized)
    _same(gen, fastvi.integrate(dp, q0, v0, **kw))  # None: the sized stages, compiled now
    # and the run is a real one: energy bounded, constraints at round-off
    assert np.max(np.abs(sized.energy - sized.energy[0])) < 1e-3
    assert np.max(sized.constraint_residual) < 1e-13
    # adaptive steps: the sized step inlines the predictor of a changing step length
    ka = dict(h=0.05, t_end=30.0, method="P2L-Q3G", save_every=3, adaptive=3.0)
    _same(fastvi.integrate(dp, q0, v0, specialize=False, **ka),
          fastvi.integrate(dp, q0, v0, specialize=True, **ka))


@pytest.mark.slow
def test_specialized_full_newton_is_the_generic_trajectory_bit_for_bit():
    """The full Newton goes through the same specialized kernel (its sized assembly is a
    compile of its own, some 12 s: ``make test-slow``)."""
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(np.pi / 2, np.pi / 2)
    kw = dict(h=0.01, n_steps=3000, method="P2L-Q3G", save_every=7, newton="full")
    _same(fastvi.integrate(dp, q0, v0, specialize=False, **kw),
          fastvi.integrate(dp, q0, v0, specialize=True, **kw))


def test_none_uses_the_sized_stages_where_they_are_compiled_or_pay():
    from fastvi.structure import SIZED_MAX_N, SIZED_MIN_STEPS, sizing

    assert sizing(True, 1000, 1) is True and sizing(False, 4, 10**9) is False
    assert sizing(None, 4, SIZED_MIN_STEPS) is True
    assert sizing(None, 4, SIZED_MIN_STEPS - 1) == "cached"
    assert sizing(None, SIZED_MAX_N + 1, 10**9) is False


def test_specialize_is_a_flag_or_none():
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(0.1, 0.2)
    with pytest.raises(TypeError, match="`specialize` must be None, True or False"):
        fastvi.integrate(dp, q0, v0, h=0.01, n_steps=2, specialize="yes")
    with pytest.raises(TypeError, match="`specialize` must be None, True or False"):
        fastvi.integrate(dp, q0, v0, h=0.01, n_steps=2, specialize=1)


# the stiff rod–slider takes the full Newton on nearly every step (the mechanics iteration fails there and
# falls back), the fallback's retries from lower-degree guesses included; compiles the
# slider's sizes
@pytest.mark.slow
def test_specialized_stiff_fallback_is_the_generic_trajectory_bit_for_bit():
    from studies import peers

    k = 1e8
    model = fastvi.scenes.rotary_rod_slider(k=k)
    q0, v0 = model.initial_state(0.0, peers.SLIDER_R0 + peers.slider_stretch(k))
    kw = dict(h=0.01, n_steps=1000, method="P2L-Q2G")
    gen = fastvi.integrate(model, q0, v0, specialize=False, **kw)
    sized = fastvi.integrate(model, q0, v0, specialize=True, **kw)
    assert gen.stats["full_newton_steps"] > 10  # the fallback was taken, and taken again
    for key in ("newton_iterations", "full_newton_steps"):
        assert sized.stats[key] == gen.stats[key], key
    _same(gen, sized)


def test_none_takes_the_sized_stages_once_they_are_compiled_after_a_miss(monkeypatch):
    """A disk-cache miss is remembered for the process (a lookup costs milliseconds), but
    stages compiled since then in this process are taken."""
    from fastvi import structure
    from fastvi.kernels import step as step_mod

    class EveryKeyMissed(set):
        def __contains__(self, key):
            return True

    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(0.3, 0.2)
    fastvi.integrate(dp, q0, v0, h=0.01, n_steps=5, specialize=True)  # compiled (or loaded)
    monkeypatch.setattr(step_mod, "_NOT_CACHED", EveryKeyMissed())
    meth = fastvi.method("P2L-Q3G")
    opts = lay.NewtonOptions(1e-14, 30, lay.NEWTON_MODES["auto"])
    _, stages = step_mod.step_kernel(dp.kernel_data(), meth.kernel_tables, opts,
                                     structure.workspace(dp, meth), sized="cached")
    assert isinstance(stages.newton_mech, step_mod._TwinStage)


def test_an_adaptive_run_is_sized_by_its_span_not_by_its_step_cap(monkeypatch):
    """An adaptive run has no step count; its stages are sized by the steps of ε over its span
    (a short adaptive run of a new model compiled ≈ 10 s of sized stages before)."""
    from fastvi import structure

    asked = []
    sizing = structure.sizing
    monkeypatch.setattr(structure, "sizing", lambda sp, n, steps: asked.append(steps) or sizing(sp, n, steps))
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(0.5, 0.5)
    fastvi.integrate(dp, q0, v0, h=0.05, t_end=2.0, adaptive=2.0)
    assert asked == [40] and sizing(None, dp.n, asked[0]) == "cached"
