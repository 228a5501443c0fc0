"""Patterns of the derivatives by θ (``Model(param_patterns=...)``): the kernels read only
their entries, so a derivative may write only those.

The chain's derivatives write their patterns only. The same chain with derivatives that
write every entry (dense twins below, no pattern) is an independent computation of the
same sensitivities and gradient, which must agree bit for bit: a non-zero the pattern
loses, or a stale entry it reads, changes them.
"""

import importlib
import pickle

import numpy as np
import pytest

import fastvi
from tests.models import chain_constraint_hessian_dense as dense_constraint_hessian
from tests.models import td_potential, td_potential_grad
from fastvi.check import ModelCheckError
from fastvi.model import PATTERN_MIN_ENTRIES

CH = importlib.import_module("fastvi.scenes.chain")
DAMPING = importlib.import_module("fastvi.scenes.damping")


# ----------------------------------------------------------------------------- dense twins
def dense_potential_grad_by_params(q, p, out):
    nb = q.shape[0] // 2
    out[:, :] = 0.0
    for i in range(nb):
        out[i, 2 * i + 1] = p[2 * nb]
        out[2 * nb, 2 * i + 1] = p[i]


def dense_constraint_by_params(q, p, out):
    nb = q.shape[0] // 2
    out[:, :] = 0.0
    for i in range(nb):
        out[nb + i, i] = -p[nb + i]


def dense_force_by_params(t, q, v, p, out):
    out[:, :] = 0.0
    for a in range(q.shape[0]):
        out[p.shape[0] - 1, a] = -v[a]


def dense_chain(N, c):
    """``chain(N, damping=c)`` with derivatives by θ, and a constraint Hessian, that write
    every entry (the chain's Hessian writes those of coordinates that share a link alone)."""
    ms = np.ones(N)
    return fastvi.Model(
        2 * N, N, params=(*ms, *np.ones(N), 9.81, c), mass=np.repeat(ms, 2),
        potential=CH.potential, potential_grad=CH.potential_grad, potential_hessian=0,
        constraint=CH.constraint, constraint_jacobian=CH.constraint_jacobian,
        constraint_hessian=dense_constraint_hessian, constraint_jacobian_pattern=CH.pattern(N),
        param_derivatives=dict(potential_grad=dense_potential_grad_by_params,
                               constraint=dense_constraint_by_params, constraint_jacobian=0,
                               force=dense_force_by_params),
        **DAMPING.options(c, 2 * N), name=f"dense-chain{N}")


@pytest.mark.parametrize("N, read", [
    (3, "dense"),
    (3, "patterns"),  # the threshold lowered: a small model read over its patterns
    pytest.param(12, "patterns", marks=pytest.mark.slow),  # compiles a structured model's derivatives
])
def test_derivatives_over_the_patterns_are_the_dense_ones_bit_for_bit(N, read, monkeypatch):
    if read == "patterns" and N * (2 * N + 2) * 2 < PATTERN_MIN_ENTRIES:
        monkeypatch.setattr(fastvi.model, "PATTERN_MIN_ENTRIES", 0)
    patterned, dense = fastvi.scenes.chain(N, damping=0.3), dense_chain(N, 0.3)
    assert patterned.param_patterns and not dense.param_patterns
    assert (patterned.param_derivative_data().fptr.size > 0) == (read == "patterns")
    assert np.array_equal(patterned.params, dense.params)
    q0, v0 = patterned.initial_state(np.linspace(0.3, 0.9, N))
    run = dict(h=0.01, n_steps=60, save_every=20)
    S = [fastvi.sensitivity(model, q0, v0, wrt=("params",), **run) for model in (patterned, dense)]
    assert np.abs(S[0].dq).max() > 0.0  # the parameters move the motion
    assert np.array_equal(S[0].dq, S[1].dq) and np.array_equal(S[0].dp, S[1].dp)

    def loss(result):
        return np.ones((len(result.t), 2 * N)), np.ones((len(result.t), 2 * N))

    A = [fastvi.adjoint(model, q0, v0, loss, checkpoint_every=7, **run)
         for model in (patterned, dense)]
    assert np.abs(A[0].grad_params).max() > 0.0
    assert np.array_equal(A[0].grad_params, A[1].grad_params)
    assert np.array_equal(A[0].grad_q0, A[1].grad_q0)
    # every step kept (the default here): the retaken segments, their checkpoints of G(q_k)
    # over its pattern, changed no bit
    kept = fastvi.adjoint(patterned, q0, v0, loss, **run)
    assert kept.stats["segment"] == 60 and np.array_equal(kept.gradient, A[0].gradient)


def test_the_patterns_read_by_the_kernels_are_the_union_of_the_slots():
    N = 12
    model = fastvi.scenes.chain(N, damping=0.3)
    data = model.param_derivative_data()
    k, n = model.params.size, model.n
    assert k * n >= PATTERN_MIN_ENTRIES
    expected = model.param_patterns["potential_grad"] | model.param_patterns["force"]
    rows = [set(data.fidx[data.fptr[l]:data.fptr[l + 1]]) for l in range(k)]
    assert rows == [set(np.flatnonzero(expected[l])) for l in range(k)]
    assert rows[k - 1] == set(range(n)) and rows[N] == set()  # c moves every force; l_1 none
    crow = [set(data.cidx[data.cptr[l]:data.cptr[l + 1]]) for l in range(k)]
    assert crow == [set()] * N + [{i} for i in range(N)] + [set()] * 2
    # small outputs are read densely (the kernels zero what they read before each call)
    small = fastvi.scenes.chain(3, damping=0.3).param_derivative_data()
    assert small.fptr.size == 0 and small.cptr.size == 0
    assert fastvi.scenes.spherical_pendulum().param_derivative_data().fptr.size == 0


# ----------------------------------------------------------------------------- the check
def td_potential_grad_by_params(t, q, p, out):
    out[0, 0] = q[0]
    out[1, 1] = q[1] - p[2] * np.sin(t)
    out[2, 1] = -p[1] * np.sin(t)


PATTERN = (np.array([0, 1, 2]), np.array([0, 1, 1]))


def td_model(pattern=PATTERN, **kwargs):
    return fastvi.Model(2, params=(2.0, 3.0, 0.5), mass=[1.0, 2.0], potential=td_potential,
                        potential_grad=td_potential_grad, time_dependent=True,
                        param_derivatives=dict(potential_grad=td_potential_grad_by_params),
                        param_patterns=dict(potential_grad=pattern), name="td", **kwargs)


def test_a_derivative_that_writes_its_pattern_only_passes_the_check_and_pickles():
    model = td_model()
    q = np.array([0.4, -0.3])
    model.check(q)
    assert model.param_derivatives_checked
    value = model.param_derivative_value("potential_grad", q, t=1.1)
    assert value[2, 1] == pytest.approx(-3.0 * np.sin(1.1), rel=1e-14) and value[2, 0] == 0.0
    back = pickle.loads(pickle.dumps(model))
    assert np.array_equal(back.param_patterns["potential_grad"], model.param_patterns["potential_grad"])


def test_the_check_names_a_non_zero_outside_the_pattern_and_an_entry_never_written():
    q = np.array([0.4, -0.3])
    with pytest.raises(ModelCheckError, match=r"outside the model's `param_patterns\['potential_grad'\]`"):
        td_model(pattern=(np.array([0, 1]), np.array([0, 1]))).check(q, t=1.1)
    with pytest.raises(ModelCheckError, match=r"never wrote entry \[1, 0\]"):
        td_model(pattern=(np.array([0, 1, 2, 1]), np.array([0, 1, 1, 0]))).check(q)


@pytest.mark.parametrize("patterns, error, match", [
    (dict(mass=np.ones((3, 2, 2), dtype=bool)), ValueError, "a pattern is for"),
    (dict(force=np.ones((3, 2), dtype=bool)), ValueError, "no function for 'force'"),
    (dict(potential_grad=np.ones((3, 3), dtype=bool)), ValueError, r"\(3, 2\) boolean array"),
    (dict(potential_grad=(np.array([3]), np.array([0]))), ValueError, "outside the shape"),
    ([("potential_grad", None)], TypeError, "mapping"),
])
def test_bad_param_patterns_are_rejected_by_name(patterns, error, match):
    with pytest.raises(error, match=r"param_patterns.*" + match):
        fastvi.Model(2, params=(2.0, 3.0, 0.5), mass=[1.0, 2.0], potential=td_potential,
                     potential_grad=td_potential_grad, time_dependent=True,
                     param_derivatives=dict(potential_grad=td_potential_grad_by_params),
                     param_patterns=patterns)
