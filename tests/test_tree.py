"""The tree scene (``fastvi.scenes.tree``): a hub with branches, the non-banded pattern of the
sparse-solve benchmarks (issue 12)."""

import pickle

import numpy as np
import pytest

import fastvi
from fastvi import structure
from fastvi.scenes import chain, tree
from fastvi.scenes.tree import parents

P2 = fastvi.method("P2L-Q3G")


def _angles(N):
    return 0.3 + 0.6 * np.sin(np.arange(N)), 0.5 * np.cos(np.arange(N))


def test_initial_state_is_consistent_and_the_model_checks():
    model = tree(3, 2, m=np.linspace(1.0, 2.0, 7), l=np.linspace(0.5, 1.1, 7))
    th, om = _angles(7)
    q0, v0 = model.initial_state(th, om)
    assert np.abs(model.constraint_value(q0)).max() < 1e-14
    assert np.abs(model.constraint_jacobian_value(q0) @ v0).max() < 1e-14
    assert np.allclose(model.angles(q0), th, rtol=0, atol=1e-14)
    # finite differences of every callback, and the declared pattern of G
    assert model.check(q0, v0).ok


def test_parents_and_pattern():
    assert parents(2, 3).tolist() == [-1, 0, 1, 2, 0, 4, 5]
    G = tree(2, 3).constraint_jacobian_value(np.arange(14.0) + 1.0)
    hub_rows = np.flatnonzero(G[:, 0:2].any(axis=1))
    assert hub_rows.tolist() == [0, 1, 4]  # the hub's link and the first link of each branch


def test_one_branch_is_a_chain():
    N = 5
    t, c = tree(1, N - 1), chain(N)
    th, om = _angles(N)
    q0, v0 = c.initial_state(th, om)
    qt, vt = t.initial_state(th, om)
    assert np.allclose(q0, qt, atol=1e-15) and np.allclose(v0, vt, atol=1e-15)
    a = fastvi.integrate(t, q0, v0, h=0.01, n_steps=50)
    b = fastvi.integrate(c, q0, v0, h=0.01, n_steps=50)
    assert np.abs(a.q - b.q).max() < 1e-13  # the same equations (measured 0: the same arithmetic)


def test_a_large_tree_goes_sparse_and_conserves_energy():
    model = tree(8, 4)  # N = 33 bodies: the hub's 9 constraints form a clique
    p = structure.plan(model, P2)
    assert p.solvers == dict(newton="banded", schur="sparse", projection="sparse")
    assert min(p.bandwidths["projection"]) >= 8  # no band narrower than the hub's clique
    th, om = _angles(33)
    q0, v0 = model.initial_state(th, om)
    runs = {s: fastvi.integrate(model, q0, v0, h=0.005, n_steps=300, method="P3L-Q4G",
                                solver=s, save_every=10)
            for s in ("auto", "dense", "banded")}
    r = runs["auto"]
    E0 = abs(r.energy[0])
    # measured: 1.1e-13 relative energy error, constraints 1.1e-15, hidden constraints 9e-16
    assert np.abs(r.energy_error).max() < 1e-8 * E0
    assert r.constraint_residual.max() < 1e-13
    assert r.velocity_residual.max() < 1e-12
    for s in ("dense", "banded"):  # measured 6e-15 and 4e-15 after 300 steps
        assert np.abs(runs[s].q - r.q).max() < 1e-11


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="`branches` must be >= 1"):
        tree(0, 2)
    with pytest.raises(TypeError, match="`links` must be an integer"):
        tree(2, 1.5)
    with pytest.raises(ValueError, match="`m` must be a number or have N = 7 entries"):
        tree(3, 2, m=[1.0, 2.0])
    with pytest.raises(ValueError, match="`thetas` must have N = 7 entries"):
        tree(3, 2).initial_state(np.zeros(6))


def test_pickles_as_its_recipe():
    model = tree(2, 2, damping=0.1)
    back = pickle.loads(pickle.dumps(model))
    assert back.name == model.name == "tree2x2-damped"
    th, om = _angles(5)
    q0, v0 = model.initial_state(th, om)
    a = fastvi.integrate(model, q0, v0, h=0.01, n_steps=20)
    b = fastvi.integrate(back, q0, v0, h=0.01, n_steps=20)
    assert np.array_equal(a.q, b.q)
