"""The linearised step of a large mechanism uses its structure: the step's banded ordering
for the exact Newton matrix, groups of constraints that share no coordinate for the
projection's second derivatives, and the pattern of G for ``G M⁻¹ Gᵀ``. References: the
same derivatives with every system dense (``solver="dense"``, whose linearised step the
other tests check against differences of whole runs), the adjoint identity, and the
definition of the groups. They compile the step and the linearised step for a structured
model (minutes): they run in ``make test-slow``."""

import numpy as np
import pytest

import fastvi
from fastvi.kernels.tangent import make_sparsity

LINKS = 8  # n = 16, m = 8: the plan solves the step's Newton matrix banded


def _chain_start(links, angle=0.4, spin=0.7):
    q0, v0 = np.zeros(2 * links), np.zeros(2 * links)
    x = y = vx = vy = 0.0
    for i in range(links):
        a = angle + 0.1 * i
        w = spin * (-1) ** i
        x, y = x + np.sin(a), y - np.cos(a)
        vx, vy = vx + w * np.cos(a), vy + w * np.sin(a)
        q0[2 * i:2 * i + 2], v0[2 * i:2 * i + 2] = (x, y), (vx, vy)
    return q0, v0


@pytest.fixture(scope="module")
def chain():
    return fastvi.scenes.chain(LINKS, damping=0.2)


@pytest.mark.slow  # compiles the step of a structured model
def test_chain_is_linearised_with_its_structure(chain):
    q0, _ = _chain_start(LINKS)
    run = fastvi._discrete.prepare(chain, q0, np.zeros_like(q0), h=0.01, t_end=None, n_steps=1,
                                   t0=0.0, t_span=None, method="P2L-Q3G", save_every=1,
                                   tol=1e-12, max_iter=20, newton="auto", params=None,
                                   solver="auto", check=False, monitor=False, what="a test")
    sp = run.sparsity
    N = 2 * chain.n + 2 * chain.m
    assert sorted(sp.perm) == list(range(N)) and 0 < sp.kl < N // 2
    # the groups partition the constraints, and no two constraints of a group share a
    # coordinate: the chain's links alternate, so two groups suffice
    PG = np.zeros((chain.m, chain.n), dtype=bool)
    for c in range(chain.m):
        PG[c, sp.gcol[sp.gptr[c]:sp.gptr[c + 1]]] = True
    assert sorted(sp.grow) == list(range(chain.m)) and len(sp.gsta) - 1 == 2
    for k in range(len(sp.gsta) - 1):
        rows = sp.grow[sp.gsta[k]:sp.gsta[k + 1]]
        assert PG[rows].sum(axis=0).max() == 1
    dense = make_sparsity()
    assert dense.perm.size == 0 and dense.gsta.size == 0


@pytest.mark.slow  # compiles the linearised step for a structured model: minutes
def test_structured_derivatives_equal_the_dense_ones(chain):
    q0, v0 = _chain_start(LINKS)
    rng = np.random.default_rng(3)
    D = rng.normal(size=(4 * LINKS + chain.params.size, 3))
    run = dict(h=0.01, n_steps=150, save_every=50, wrt=D)
    S = fastvi.sensitivity(chain, q0, v0, **run)
    R = fastvi.sensitivity(chain, q0, v0, solver="dense", **run)
    scale = np.abs(R.dq).max()
    # the two trajectories differ by round-off (other solves: 3e-15), and so do the
    # derivatives, the parameters' five-point differences dividing it by their step:
    # measured 1.1e-12 of the largest entry
    assert np.abs(S.dq - R.dq).max() < 1e-10 * scale
    assert np.abs(S.dv - R.dv).max() < 1e-10 * np.abs(R.dv).max()


@pytest.mark.slow
def test_structured_adjoint_is_the_transpose_of_the_structured_forward(chain):
    q0, v0 = _chain_start(LINKS)
    rng = np.random.default_rng(4)
    N, every = 120, 40
    K = N // every + 1
    Lq, Lv = rng.normal(size=(K, chain.n)), rng.normal(size=(K, chain.n))
    A = fastvi.adjoint(chain, q0, v0, lambda r: (Lq, Lv), h=0.01, n_steps=N, save_every=every)
    D = rng.normal(size=(2 * chain.n + chain.params.size, 2))
    S = fastvi.sensitivity(chain, q0, v0, h=0.01, n_steps=N, save_every=every, wrt=D)
    forward = np.einsum("kn,knd->d", Lq, S.dq) + np.einsum("kn,knd->d", Lv, S.dv)
    grad = np.concatenate([A.grad_q0, A.grad_v0, A.grad_params])
    assert np.allclose(grad @ D, forward, rtol=1e-12, atol=0)  # measured 7.7e-15


@pytest.mark.slow
def test_structured_ensemble_members_are_the_single_runs(chain):
    # the members build their linearised step in the parallel loop, with the plan and the
    # structure the single run gets in Python
    starts = [_chain_start(LINKS, angle=a) for a in (0.3, 0.6)]
    Q0, V0 = np.array([q for q, _ in starts]), np.array([v for _, v in starts])
    run = dict(h=0.01, n_steps=60, save_every=20, wrt=("q0",))
    E = fastvi.sensitivity_ensemble(chain, Q0, V0, **run)
    for i in range(2):
        S = fastvi.sensitivity(chain, Q0[i], V0[i], **run)
        assert np.array_equal(E.dq[i], S.dq) and np.array_equal(E.dv[i], S.dv)



@pytest.mark.slow
def test_the_spans_change_no_bit(monkeypatch):
    """A banded plan assembles the extended Newton matrix, and forms the projection's
    products, over each row's span of non-zeros (``ws.si[SI_BSPAN]``, ``Sparsity.bspan``):
    the same derivatives, bit for bit, as the same plan without the spans."""
    from fastvi import structure
    from fastvi.kernels import layout as lay

    q0, v0 = _chain_start(LINKS)
    rng = np.random.default_rng(5)
    N, every = 90, 30
    K = N // every + 1
    Lq, Lv = rng.normal(size=(K, 2 * LINKS)), rng.normal(size=(K, 2 * LINKS))

    def derivatives():
        model = fastvi.scenes.chain(LINKS, damping=0.2)  # a model of its own: its own plan
        S = fastvi.sensitivity(model, q0, v0, h=0.01, n_steps=N, save_every=every,
                               wrt=("q0", "params"))
        A = fastvi.adjoint(model, q0, v0, lambda r: (Lq, Lv), h=0.01, n_steps=N,
                           save_every=every, checkpoint_every=7)
        return S.dq, S.dv, A.grad_q0, A.grad_v0, A.grad_params

    spans = derivatives()
    workspace, patterns = structure.workspace, structure.linearisation_patterns

    def without_spans(*a, **k):
        ws = workspace(*a, **k)
        assert ws.si[lay.SI_BSPAN] and ws.si[lay.SI_GSPAN]
        si = ws.si.copy()
        si[lay.SI_BSPAN] = si[lay.SI_GSPAN] = 0
        return ws._replace(si=si)

    monkeypatch.setattr(structure, "workspace", without_spans)
    monkeypatch.setattr(structure, "linearisation_patterns",
                        lambda PG, PA, s, J, diagonal_mass=False: patterns(PG, PA, s, J))
    for a, b in zip(spans, derivatives()):
        assert np.array_equal(a, b)


@pytest.mark.slow
def test_the_band_assembly_changes_no_bit(monkeypatch):
    """A large mechanism's linearised step assembles the extended Newton matrix straight
    into the band storage that its LU factors, through a map of each entry's place, instead
    of a dense (N + n)² matrix packed into that storage afterwards: the same derivatives,
    bit for bit, from storage that grows like N, not N²; and so does each member of an
    ensemble, whose workspaces are the single run's."""
    from fastvi import _discrete as disc
    from fastvi.kernels import layout

    q0, v0 = _chain_start(LINKS)
    rng = np.random.default_rng(6)
    N, every = 90, 30
    K = N // every + 1
    Lq, Lv = rng.normal(size=(K, 2 * LINKS)), rng.normal(size=(K, 2 * LINKS))
    model = fastvi.scenes.chain(LINKS, damping=0.2)

    def derivatives(limit):
        monkeypatch.setattr(layout, "BAND_ASSEMBLY_BYTES", limit)
        run = disc.prepare(model, q0, v0, h=0.01, t_end=None, n_steps=2, t0=0.0, t_span=None,
                           method="P2L-Q3G", save_every=1, tol=1e-14, max_iter=50,
                           newton="auto", params=None, solver="auto", check=False,
                           monitor=True, what="x")
        size = disc.tangent_work(run, 1, np.arange(0)).ws.A.size
        rows = (run.meth.s + 1) * model.n + run.meth.J * model.m  # of the extended matrix
        S = fastvi.sensitivity(model, q0, v0, h=0.01, n_steps=N, save_every=every,
                               wrt=("q0", "v0", "params"))
        A = fastvi.adjoint(model, q0, v0, lambda r: (Lq, Lv), h=0.01, n_steps=N,
                           save_every=every, checkpoint_every=7)
        return size, rows, (S.dq, S.dv, A.grad_q0, A.grad_v0, A.grad_params)

    dense_size, rows, dense = derivatives(1 << 62)
    band_size, _, band = derivatives(0)
    assert dense_size == rows ** 2 and band_size < dense_size / 2
    assert np.abs(dense[0]).max() > 0.0 and np.abs(dense[4]).max() > 0.0
    for a, b in zip(dense, band):
        assert np.array_equal(a, b)
    # an ensemble's members allocate the single run's workspaces again, maps included
    E = fastvi.sensitivity_ensemble(model, np.stack([q0, q0]), np.stack([v0, v0]), h=0.01,
                                    n_steps=N, save_every=every, wrt=("q0", "v0", "params"))
    assert np.array_equal(E.dq[1], dense[0]) and np.array_equal(E.dv[1], dense[1])
