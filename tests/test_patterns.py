"""Declared sparsity patterns of G (issue 12) and a large closed-loop mechanism through its
singular positions."""

import numpy as np
import pytest

import fastvi
from fastvi import structure
from fastvi.check import ModelCheckError
from fastvi.scenes import chain as chain_scene
from fastvi.scenes import ladder
from fastvi.scenes.chain import (constraint as _g, constraint_hessian as _ddg,
                                 constraint_jacobian as _G, pattern, potential as _V,
                                 potential_grad as _dV)
from fastvi._numba import njit

N = 5
P3 = fastvi.method("P3L-Q4G")


def _state():
    return chain_scene(N).initial_state(np.linspace(0.2, 0.9, N), np.linspace(0.3, -0.4, N))


def _model(jacobian=_G, declared=None):
    prm = (*([1.0] * N), *([1.0] * N), 9.81)
    return fastvi.Model(2 * N, N, params=prm, mass=np.eye(2 * N), potential=_V, potential_grad=_dV,
                        constraint=_g, constraint_jacobian=jacobian,
                        constraint_jacobian_pattern=pattern(N) if declared is None else declared)


def _without(k):
    rows, cols = pattern(N)
    keep = np.arange(rows.size) != k
    return rows[keep], cols[keep]


def test_declared_pattern_passes_check_and_replaces_detection():
    model = _model()
    q0, v0 = _state()
    assert model.check(q0, v0).ok
    p = structure.detect_pattern(model, P3)
    rows, cols = pattern(N)
    expected = np.zeros((N, 2 * N), dtype=bool)
    expected[rows, cols] = True
    assert np.array_equal(p["G"], expected)
    # the same pattern as detection from a callback that writes every entry
    dense = fastvi.Model(2 * N, N, params=model.params, mass=np.eye(2 * N), potential=_V,
                         potential_grad=_dV, constraint=_g, constraint_jacobian=_dense_G)
    assert dense.check(q0, v0).ok
    assert np.array_equal(structure.detect_pattern(dense, P3)["G"], expected)


_G_nb = njit(_G)
chain_hessian = njit(_ddg)


def _dense_G(q, p, out):
    out[:, :] = 0.0
    _G_nb(q, p, out)


def _G_skipping_1_3(q, p, out):
    _G_nb(q, p, out)
    out[1, 3] = 0.0  # follows a pattern that wrongly leaves (1, 3) out


def test_a_nonzero_written_outside_the_declared_pattern_is_caught_by_check():
    rows, cols = pattern(N)
    k = int(np.flatnonzero((rows == 1) & (cols == 3))[0])
    model = _model(declared=_without(k))  # the callback still writes (1, 3)
    q0, v0 = _state()
    with pytest.raises(ModelCheckError, match=r"non-zeros at \[1, 3\], outside .*constraint_jacobian_pattern"):
        model.check(q0, v0)
    with pytest.raises(ModelCheckError, match="outside"):  # and by integrate's own check
        fastvi.integrate(model, q0, v0, h=0.01, n_steps=2)


def test_a_pattern_missing_a_true_nonzero_is_caught_against_finite_differences():
    rows, cols = pattern(N)
    k = int(np.flatnonzero((rows == 1) & (cols == 3))[0])
    model = _model(jacobian=_G_skipping_1_3, declared=_without(k))
    q0, v0 = _state()
    with pytest.raises(ModelCheckError, match=r"entry \[1, 3\] is outside the declared .*misses a non-zero"):
        model.check(q0, v0)


def test_an_unset_entry_of_the_pattern_is_named():
    rows, cols = pattern(N)
    extra = (np.append(rows, 0), np.append(cols, 2 * N - 1))  # declared, never written
    model = _model(declared=extra)
    q0, v0 = _state()
    with pytest.raises(ModelCheckError, match=r"never wrote entry \[0, %d\]" % (2 * N - 1)):
        model.check(q0, v0)


def test_the_constraint_hessian_pattern_is_the_pairs_that_share_a_constraint():
    assert fastvi.scenes.double_pendulum().constraint_hessian_pattern is None  # no G pattern
    H = chain_scene(N).constraint_hessian_pattern
    # link i joins bodies i − 1 and i: their four coordinates, x and y crossed included
    bodies = np.repeat(np.arange(N), 2)
    assert np.array_equal(H, np.abs(bodies[:, None] - bodies[None, :]) <= 1)


def _hessian_beside_its_pattern(q, eta, p, out):
    chain_hessian(q, eta, p, out)
    out[0, 2 * N - 1] = 1.0  # body 0 and body N − 1 share no link


def test_the_constraint_hessian_is_handed_zeros_and_named_outside_its_pattern():
    q0, v0 = _state()
    model = chain_scene(N)  # its Hessian writes the non-zeros alone
    assert model.check(q0, v0).ok
    tree = fastvi.scenes.tree(2, 2)  # and the tree's adds into them (+=)
    assert tree.check(*tree.initial_state(np.full(tree.n // 2, 0.3))).ok
    bad = fastvi.Model(2 * N, N, params=model.params, mass=np.eye(2 * N), potential=_V,
                       potential_grad=_dV, constraint=_g, constraint_jacobian=_G,
                       constraint_hessian=_hessian_beside_its_pattern,
                       constraint_jacobian_pattern=pattern(N))
    with pytest.raises(ModelCheckError, match=r"constraint_hessian` wrote non-zeros at \[0, %d\], "
                       r"outside the pairs of coordinates that share a constraint" % (2 * N - 1)):
        bad.check(q0, v0)


@pytest.mark.parametrize("bad, match", [
    (np.ones((N, 2 * N + 1), dtype=bool), "boolean array"),
    (np.ones((N, 2 * N)), "boolean array"),
    ((np.array([0, N]), np.array([0, 1])), "outside the shape"),
    ((np.array([0.0]), np.array([1.0])), "integer arrays"),
])
def test_bad_pattern_arguments_are_named(bad, match):
    with pytest.raises(ValueError, match="constraint_jacobian_pattern.*" + match):
        _model(declared=bad)


def test_pattern_without_constraints_is_refused():
    with pytest.raises(ValueError, match="m = 0"):
        fastvi.Model(2, params=(1.0,), mass=np.eye(2), potential=lambda q, p: 0.0,
                     potential_grad=_dV, constraint_jacobian_pattern=np.ones((1, 2), dtype=bool))


def test_a_model_with_a_pattern_pickles_with_it():
    import pickle

    model = ladder(3)
    back = pickle.loads(pickle.dumps(model))
    assert np.array_equal(back.constraint_jacobian_pattern, model.constraint_jacobian_pattern)


def test_ladder_is_a_consistent_model():
    lad = ladder(4)
    q0, v0 = lad.initial_state(np.linspace(0.2, 0.7, 4), np.linspace(0.5, -0.5, 4))
    assert lad.check(q0, v0).ok
    assert np.abs(lad.constraint_value(q0)).max() < 1e-14
    assert np.abs(lad.constraint_jacobian_value(q0) @ v0).max() < 1e-14
    assert np.abs(lad.rung_tilts(q0)).max() == 0.0


def test_large_ladder_passes_its_singular_positions():
    """32 parallelogram cells (n = 128, m = 96; the Schur complement and the projection by the
    sparse LU, the full Newton matrix banded), released at rest with the rails
    0.3 rad above the horizontal: every cell swings down through its singular position (rails
    aligned with the rungs: G loses rank), with energy, constraints and the parallelogram
    branch kept, and the structured and dense solves agree through the crossing."""
    cells = 32
    lad = ladder(cells)
    q0, v0 = lad.initial_state(np.full(cells, 0.3))
    assert structure.plan(lad, P3).solvers == dict(newton="banded", schur="sparse",
                                                   projection="sparse")
    r = fastvi.integrate(lad, q0, v0, h=0.005, n_steps=600, method="P3L-Q4G")
    sines = lad.rail_sines(r.q)
    crossings = (np.diff(np.sign(sines), axis=0) != 0).sum(axis=0)
    assert crossings.min() >= 1  # measured: every cell crosses once or twice in 3 s
    sv = np.array([np.linalg.svd(lad.constraint_jacobian_value(q), compute_uv=False) for q in r.q])
    assert (sv[:, -1] / sv[:, 0]).min() < 1e-3  # measured 2.5e-5: G nearly singular at a sample
    E0 = abs(lad.energy(q0, v0))
    assert np.abs(r.energy_error).max() < 1e-7 * E0  # measured 1.7e-8 relative (5.3e-5 J of 3.1e3)
    assert r.constraint_residual.max() < 1e-13  # measured 6e-15
    assert r.velocity_residual.max() < 1e-12  # measured 2e-14
    assert np.abs(lad.rung_tilts(r.q)).max() < 1e-11  # parallelogram branch (measured 2e-13)
    first = int(np.argmax(crossings > 0))
    k = int(np.argmax(np.diff(np.sign(sines[:, first])) != 0)) + 2  # just past the first crossing
    dense = fastvi.integrate(lad, q0, v0, h=0.005, n_steps=k, method="P3L-Q4G", solver="dense")
    assert np.abs(dense.q - r.q[:k + 1]).max() < 1e-10  # measured 1.2e-14 over 52 steps
