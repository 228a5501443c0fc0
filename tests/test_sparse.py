"""Structured linear solves (issue 12): the banded LU, pattern detection, the choice of
solver, and agreement of the dense and banded paths on every scene."""

import numpy as np
import pytest

import fastvi
from fastvi import structure
from fastvi.kernels import layout as lay
from fastvi.kernels.banded import band_factor, band_ld, band_solve
from fastvi.kernels.step import assemble_at, fd_constraint_hessian, fd_constraint_hessian_grouped
from fastvi.scenes import chain, double_pendulum
from fastvi.scenes.chain import (constraint as _g, constraint_hessian as _ddg,
                                 constraint_jacobian as _G, pattern, potential as _V,
                                 potential_grad as _dV)

P2 = fastvi.method("P2L-Q3G")


def _to_band(A, kl, ku):
    N = A.shape[0]
    ld = band_ld(kl, ku)
    ab = np.zeros(ld * N)
    for j in range(N):
        for i in range(max(0, j - ku), min(N, j + kl + 1)):
            ab[ld * j + kl + ku + i - j] = A[i, j]
    return ab


@pytest.mark.parametrize("kl,ku", [(0, 0), (1, 2), (3, 1), (5, 5)])
def test_banded_lu_solves_like_numpy_with_pivoting(kl, ku):
    rng = np.random.default_rng(kl * 10 + ku)
    N = 40
    A = rng.standard_normal((N, N))
    A[np.triu_indices(N, ku + 1)] = 0.0
    A[np.tril_indices(N, -kl - 1)] = 0.0
    if kl > 0:
        A[np.diag_indices(N)] *= 1e-3  # small diagonal: partial pivoting must swap rows
    b = rng.standard_normal(N)
    ab = _to_band(A, kl, ku)
    piv = np.zeros(N, dtype=np.int64)
    assert band_factor(ab, piv, N, kl, ku) == 0
    if kl > 0:
        assert np.any(piv != np.arange(N))  # rows were interchanged
    x = b.copy()
    band_solve(ab, piv, x, N, kl, ku)
    ref = np.linalg.solve(A, b)
    # measured ≤ 3e-13 relative (condition numbers up to ~1e4)
    assert np.max(np.abs(x - ref)) <= 1e-10 * np.max(np.abs(ref))


def test_banded_lu_reports_a_singular_matrix():
    N, kl, ku = 10, 1, 1
    A = np.diag(np.arange(1.0, N + 1)) + np.diag(np.ones(N - 1), 1) + np.diag(np.ones(N - 1), -1)
    A[4, :] = 0.0
    ab = _to_band(A, kl, ku)
    assert band_factor(ab, np.zeros(N, dtype=np.int64), N, kl, ku) != 0


def test_detected_pattern_of_a_chain_is_its_structure():
    model = chain(6)
    pats = structure.detect_pattern(model, P2)
    G = pats["G"]
    expected = np.zeros((6, 12), dtype=bool)
    for i in range(6):
        expected[i, 2 * i:2 * i + 2] = True
        if i:
            expected[i, 2 * i - 2:2 * i] = True
    assert np.array_equal(G, expected)
    # the Newton matrix at another random state has no non-zero outside the pattern
    rng = np.random.default_rng(99)
    ws = lay.make_workspace(12, 6, P2.s, P2.r, P2.J)
    md = model.kernel_data()
    ws.X[:] = rng.standard_normal(ws.X.size)
    q = rng.standard_normal(12)
    ws.G[0] = model.constraint_jacobian_value(q)
    assemble_at(md, P2.kernel_tables, 0.02, q, rng.standard_normal(12), ws, True)
    assert not np.any((ws.A != 0.0) & ~pats["newton"])
    assert pats["newton"].sum() < 0.3 * pats["newton"].size  # sparse: measured 17 %


def _bodies():
    from fastvi.bodies import scenes
    return scenes


#: (model, method) by case, built in the test rather than at collection (as _SCENE_CASES)
_PATTERN_CASES = {
    "damped_chain12": lambda: (chain(12, damping=0.3), P2),
    "closed_chain14": lambda: (fastvi.scenes.closed_chain(14), fastvi.method("P3L-Q4G")),
    "tree": lambda: (fastvi.scenes.tree(), P2),
    "kapitza_pendulum": lambda: (fastvi.scenes.kapitza_pendulum(), P2),  # rheonomic
    # a rotation's exact constraint Hessian, with entries at round-off of an analytic zero
    "spatial_slider_crank": lambda: (_bodies().spatial_slider_crank(), P2),
    "flyball_governor": lambda: (_bodies().flyball_governor(), P2),  # forces
}


@pytest.mark.parametrize("case", list(_PATTERN_CASES))
def test_detected_pattern_is_what_the_assembled_newton_matrix_writes(case, monkeypatch):
    """The Newton matrix's pattern is detected from the residual's dependence on each
    unknown (and G's blocks and the constraint Hessian's, which carry round-off entries),
    without compiling the matrix: at the states it draws it equals the non-zeros of the
    matrix the step kernel assembles there, exactly."""
    from fastvi.kernels import step

    model, meth = _PATTERN_CASES[case]()
    seen = []
    real = step.residual_dependence

    def spy(md, tabs, h, qk, pk, ws, dx, R0, P):
        seen.append((qk.copy(), pk.copy(), ws.X.copy(), ws.G[0].copy()))
        return real(md, tabs, h, qk, pk, ws, dx, R0, P)

    monkeypatch.setattr(step, "residual_dependence", spy)
    pats = structure.detect_pattern(model, meth)
    assert len(seen) == structure.PATTERN_STATES
    n, m = model.n, model.m
    N = meth.s * n + meth.J * m
    md = model.kernel_data()
    union = np.zeros((N, N), dtype=bool)
    for q, p, X, G0 in seen:
        ws = lay.make_workspace(n, m, meth.s, meth.r, meth.J)
        ws.X[:] = X
        ws.G[0] = G0
        assert assemble_at(md, meth.kernel_tables, 0.01, q, p, ws, True) == lay.OK
        union |= ws.A[:N, :N] != 0.0
    assert np.array_equal(pats["newton"], union)


def test_small_models_keep_the_dense_path():
    for model in (double_pendulum(), chain(3)):
        p = structure.plan(model, P2)
        assert set(p.solvers.values()) == {"dense"}
        assert p.patterns == {}  # not even analysed
        ws = structure.workspace(model, P2)
        assert not np.any(ws.si)


def _field_offsets(ty):
    """The byte offset of every field of the numba tuple type ``ty`` in memory, by LLVM's
    rule for a struct that is not packed (each field at the next multiple of its alignment)."""
    from numba.core.registry import cpu_target
    ctx = cpu_target.target_context
    offsets, at = [], 0
    for t in ty.types:
        llty = ctx.get_data_type(t)
        align = ctx.get_abi_alignment(llty)
        at = -(-at // align) * align
        offsets.append(at)
        at += ctx.get_abi_sizeof(llty)
    return offsets


def test_a_structured_workspace_lays_out_its_fields_as_its_loop_view():
    # the step and the time loops are compiled for the loop view; the structured stages
    # they call read the same memory as a structured workspace (layout.loop_view)
    import numba
    ws = structure.workspace(chain(16), P2)
    assert ws.structured
    view = lay.loop_view(ws)
    assert view.structured is None and view.si is ws.si and view.sb is ws.sb
    t_ws, t_view = numba.typeof(ws), numba.typeof(view)
    assert t_ws != t_view
    assert _field_offsets(t_ws) == _field_offsets(t_view)


def test_a_structured_plan_steps_with_the_compiled_step_of_a_dense_one():
    from fastvi.kernels import step as step_mod
    model = chain(16)
    md, tabs = model.kernel_data(), P2.kernel_tables
    opts = lay.NewtonOptions(1e-14, 30, lay.NEWTON_AUTO)
    banded = structure.workspace(model, P2)
    dense = structure.workspace(model, P2, solver="dense")
    step_b, stages_b = step_mod.step_kernel(md, tabs, opts, banded, full=True)
    step_d, stages_d = step_mod.step_kernel(md, tabs, opts, dense, full=True)
    assert step_b is step_d
    for name in ("newton_mech", "newton_full", "end_momentum"):
        assert isinstance(getattr(stages_b, name), step_mod._TwinStage), name
        assert not isinstance(getattr(stages_d, name), step_mod._TwinStage), name


def test_chain_chooses_banded_solves_by_size():
    assert structure.plan(chain(6), P2).solvers == dict(newton="banded", schur="dense",
                                                        projection="dense")
    p = structure.plan(chain(16), P2)
    assert p.solvers == dict(newton="banded", schur="banded", projection="banded")
    # RCM finds the chain's band: 6N rows, bandwidth independent of N
    assert p.bandwidths["newton"] == structure.plan(chain(24), P2).bandwidths["newton"]
    assert max(p.bandwidths["newton"]) <= 8 and max(p.bandwidths["projection"]) <= 1


def _coupled_chain(N):
    """chain(N) with a tridiagonal (non-diagonal) constant mass: no Schur/projection on the
    pattern of G (M⁻¹ is dense), the full Newton matrix still banded."""
    M = np.eye(2 * N) * 2.0 + np.diag(np.full(2 * N - 2, 0.3), 2) + np.diag(np.full(2 * N - 2, 0.3), -2)
    prm = (*([1.0] * N), *([1.0] * N), 9.81)
    return fastvi.Model(2 * N, N, params=prm, mass=M, potential=_V, potential_grad=_dV,
                        potential_hessian=0, constraint=_g, constraint_jacobian=_G,
                        constraint_hessian=_ddg, constraint_jacobian_pattern=pattern(N),
                        name=f"coupled{N}")


def test_non_diagonal_mass_keeps_dense_schur_and_projection():
    p = structure.plan(_coupled_chain(10), P2)
    assert p.solvers == dict(newton="banded", schur="dense", projection="dense")


#: (model, the arguments of its initial_state) by case; built in the test, not at collection
#: (a model compiles its callbacks: a dozen at import cost every test process seconds)
_SCENE_CASES = {
    "pendulum": lambda: (fastvi.scenes.pendulum(), (0.9,)),
    "double_pendulum": lambda: (double_pendulum(), (np.pi / 2, np.pi / 2)),
    "triple_pendulum": lambda: (fastvi.scenes.triple_pendulum(), (0.5, 1.0, 1.5)),
    "four_bar": lambda: (fastvi.scenes.four_bar(), (0.4, 2.0)),
    "spherical_pendulum": lambda: (fastvi.scenes.spherical_pendulum(), (1.0, 0.0, 0.0, 2.0)),
    "rotary_rod_slider": lambda: (fastvi.scenes.rotary_rod_slider(), (0.3,)),
    "chain12": lambda: (chain(12), (np.linspace(0.2, 1.4, 12),)),
    "coupled_chain10": lambda: (_coupled_chain(10), None),
    "closed_chain14": lambda: (fastvi.scenes.closed_chain(14), ()),
    "damped_chain12": lambda: (chain(12, damping=0.3), (np.linspace(0.2, 1.4, 12),)),  # forces
    "kapitza_pendulum": lambda: (fastvi.scenes.kapitza_pendulum(), (2.5,)),  # rheonomic constraint
    "slider_crank": lambda: (fastvi.scenes.slider_crank(), (0.3,)),
}


@pytest.mark.parametrize("newton", ["auto", "full"])
@pytest.mark.parametrize("name", list(_SCENE_CASES))
def test_dense_banded_and_sparse_trajectories_agree(name, newton):
    model, args = _SCENE_CASES[name]()
    if args is None:
        q0, v0 = chain(10).initial_state(np.linspace(0.2, 1.0, 10))
    else:
        q0, v0 = model.initial_state(*args)
    run = {}
    for solver in ("dense", "banded", "sparse"):
        run[solver] = fastvi.integrate(model, q0, v0, h=0.01, n_steps=40, newton=newton,
                                       solver=solver)
    scale = max(1.0, np.max(np.abs(run["dense"].q)))
    pscale = max(1.0, np.max(np.abs(run["dense"].p)))
    for solver in ("banded", "sparse"):
        # measured ≤ 1.1e-14 (q) and ≤ 1.4e-13 (p, chain12) after 40 steps
        assert np.max(np.abs(run["dense"].q - run[solver].q)) < 1e-12 * scale, (name, solver)
        assert np.max(np.abs(run["dense"].p - run[solver].p)) < 1e-11 * pscale, (name, solver)
        assert np.max(run[solver].constraint_residual) < 1e-12 * scale


def test_auto_path_of_a_small_model_is_the_dense_one_bit_for_bit():
    model = double_pendulum()
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    a = fastvi.integrate(model, q0, v0, h=0.01, n_steps=200)
    d = fastvi.integrate(model, q0, v0, h=0.01, n_steps=200, solver="dense")
    assert np.array_equal(a.q, d.q) and np.array_equal(a.p, d.p)


def test_rejects_an_unknown_solver():
    model = double_pendulum()
    q0, v0 = model.initial_state(0.1, 0.2)
    with pytest.raises(ValueError, match="`solver` must be one of 'auto', 'dense', 'banded', 'sparse'"):
        fastvi.integrate(model, q0, v0, h=0.01, n_steps=2, solver="superlu")


def test_closed_chain_is_banded_and_holds_its_constraints():
    model = fastvi.scenes.closed_chain(40, d=30.0)
    q0, v0 = model.initial_state()
    assert np.max(np.abs(model.constraint_value(q0))) < 1e-12
    p = structure.plan(model, P2)
    assert p.solvers == dict(newton="banded", schur="banded", projection="banded")
    assert max(p.bandwidths["schur"]) <= 4
    res = fastvi.integrate(model, q0, v0, h=0.01, n_steps=100, save_every=10)
    # measured 4e-15 and 2e-14 relative energy error
    assert np.max(res.constraint_residual) < 1e-12
    assert np.max(np.abs(res.energy_error)) < 1e-8 * max(1.0, abs(res.energy[0]))


def test_chain_256_holds_constraints_and_energy():
    N = 256
    model = chain(N)
    q0, v0 = model.initial_state(0.5 * np.sin(np.linspace(0.0, np.pi, N)))
    assert structure.plan(model, P2).solvers["schur"] == "banded"
    # check=False: Model.check of n = 512 takes ≈ 10 s (finite differences, O(n³))
    res = fastvi.integrate(model, q0, v0, h=0.01, n_steps=60, save_every=5, check=False)
    assert res.success
    # measured 4.9e-14 (|q| up to ~250) and 1.1e-15 relative energy error
    assert np.max(res.constraint_residual) < 1e-12
    assert np.max(res.velocity_residual) < 1e-10
    assert np.max(np.abs(res.energy_error)) < 1e-8 * max(1.0, abs(res.energy[0]))


def test_a_diagonal_mass_given_as_a_vector_is_the_matrix():
    N = 5
    prm = (*np.linspace(1.0, 2.0, N), *([1.0] * N), 9.81)
    kw = dict(params=prm, potential=_V, potential_grad=_dV, potential_hessian=0, constraint=_g,
              constraint_jacobian=_G, constraint_hessian=_ddg, constraint_jacobian_pattern=pattern(N))
    masses = np.repeat(prm[:N], 2)
    vec = fastvi.Model(2 * N, N, mass=masses, **kw)
    mat = fastvi.Model(2 * N, N, mass=np.diag(masses), **kw)
    assert np.array_equal(vec.mass_matrix(np.zeros(2 * N)), np.diag(masses))
    q0, v0 = chain(N).initial_state(np.linspace(0.3, 0.9, N))
    a = fastvi.integrate(vec, q0, v0, h=0.01, n_steps=30)
    b = fastvi.integrate(mat, q0, v0, h=0.01, n_steps=30)
    assert np.array_equal(a.q, b.q) and np.array_equal(a.p, b.p)
    with pytest.raises(ValueError, match=r"`mass` must be an \(10, 10\) array, its diagonal \(10,\)"):
        fastvi.Model(2 * N, N, mass=np.ones(2 * N + 1), **kw)
    with pytest.raises(ValueError, match="`mass` must be"):
        fastvi.Model(2 * N, N, mass=-masses, **kw)


def _chain_without_constraint_hessian(N, damping=None):
    """A chain whose full Newton differences G for its constraint Hessian; with ``damping``,
    a dashpot on every mass (the last parameter) whose ∂F/∂v it differences too."""
    from fastvi.scenes import damping as dashpot
    prm = (*([1.0] * N), *([1.0] * N), 9.81, *(() if damping is None else (damping,)))
    force = {} if damping is None else dict(force=dashpot.force, force_jacobian_q=0)
    return fastvi.Model(2 * N, N, params=prm, mass=np.ones(2 * N), potential=_V,
                        potential_grad=_dV, potential_hessian=0, constraint=_g,
                        constraint_jacobian=_G, constraint_jacobian_pattern=pattern(N),
                        name=f"nohess{N}" + ("" if damping is None else "-damped"), **force)


def test_grouped_differences_of_the_constraint_hessian_are_the_column_by_column_ones():
    """The two difference kernels of the Newton matrix, called as the step calls them (its
    trajectory with them: the test below)."""
    N = 24
    n, m = 2 * N, N
    model = _chain_without_constraint_hessian(N)
    ws = structure.workspace(model, P2)
    ng = ws.si[lay.SI_HC_NG]
    assert 0 < ng <= 6  # a chain: 6 groups whatever N (distance-2 colouring of its bodies)
    rng = np.random.default_rng(5)
    md = model.kernel_data()
    fjac = md.fns[lay.CJAC]
    q = rng.standard_normal(n)
    eta = rng.standard_normal(m)
    grouped, plain, exact = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
    qa, d, Gp, Gm = np.zeros(n), np.zeros(n), np.zeros((m, n)), np.zeros((m, n))
    fd_constraint_hessian_grouped(fjac, q, eta, md.prm, grouped, qa, d, Gp, Gm, ws.si, n, m)
    fd_constraint_hessian(fjac, q, eta, md.prm, plain, qa, Gp, Gm, n, m)  # n pairs of calls
    _ddg(q, eta, md.prm, exact)
    # the same floating-point operations: equal bit for bit
    assert np.array_equal(grouped, plain)
    # and the Hessian they difference is the exact one (the chain's), to the differences'
    # error (measured 2e-11 of max|H| at this random state)
    assert np.abs(grouped - exact).max() < 1e-8 * np.abs(exact).max()
    assert np.abs(grouped - exact).max() > 0.0  # differences, not the exact Hessian


def test_grouped_differences_give_the_exact_hessians_trajectory():
    N = 32
    fd, exact = _chain_without_constraint_hessian(N), chain(N)
    q0, v0 = exact.initial_state(np.linspace(0.2, 1.0, N))
    a = fastvi.integrate(fd, q0, v0, h=0.01, n_steps=40, newton="full", check=False)
    b = fastvi.integrate(exact, q0, v0, h=0.01, n_steps=40, newton="full", check=False)
    # measured 1e-14: central differences of a quadratic constraint are exact up to round-off
    assert np.abs(a.q - b.q).max() < 1e-11


@pytest.mark.parametrize("case", ["damped", "grouped-hessians"])
def test_the_banded_plans_assembly_over_spans_is_the_dense_one_bit_for_bit(case, monkeypatch):
    """A banded plan assembles the exact Newton matrix over each row's span of the
    coordinates' coupling and of G, and zeroes only those spans: every entry must be the
    dense assembly's, at several states in a row (nothing stale is left outside the spans).
    So must the band of the assembly straight into band storage (the map of a long chain,
    its threshold lowered here), in the plan's banded ordering."""
    model = chain(16, damping=0.3) if case == "damped" else _chain_without_constraint_hessian(24)
    ws = structure.workspace(model, P2)
    assert ws.si[lay.SI_A] == lay.SOLVE_BANDED and ws.si[lay.SI_BSPAN] and ws.si[lay.SI_GSPAN]
    si = ws.si.copy()
    si[lay.SI_BSPAN] = si[lay.SI_GSPAN] = 0  # the same plan, assembled densely
    dense = lay.make_workspace(model.n, model.m, P2.s, P2.r, P2.J)._replace(
        si=si, sb=ws.sb.copy(), structured=True)
    monkeypatch.setattr(lay, "BAND_ASSEMBLY_BYTES", 0)
    mapped = structure.workspace(model, P2)
    N, kl, ku = ws.A.shape[0], int(ws.si[lay.SI_A_KL]), int(ws.si[lay.SI_A_KU])
    perm = ws.si[ws.si[lay.SI_A_PERM]:][:N]
    assert mapped.A.shape[0] == 1 and mapped.A.size < N * N / 2
    md = model.kernel_data()
    rng = np.random.default_rng(3)
    n = model.n
    for _ in range(3):
        q, p = rng.standard_normal(n), rng.standard_normal(n)
        X = 0.1 * rng.standard_normal(ws.X.size)
        for w in (ws, dense, mapped):
            w.X[:] = X
            w.G[0] = model.constraint_jacobian_value(q)
            assert assemble_at(md, P2.kernel_tables, 0.02, q, p, w, True) == lay.OK
        assert np.array_equal(ws.A, dense.A)
        assert np.count_nonzero(ws.A) > 3 * ws.A.shape[0]  # something was assembled
        band = _to_band(dense.A[perm][:, perm], kl, ku)
        assert np.array_equal(mapped.A[0, :band.size], band)


def test_a_workspace_allocates_the_full_newtons_fields_only_with_its_stage():
    """A run's workspace leaves empty what its step never reads (``layout.unused_fields``):
    for a chain (constant diagonal mass, banded Schur complement and projection) the fields
    of a mass function, of M̄'s factors, the dense Schur complement and projection and,
    until the step takes the full Newton, that Newton's matrix, blocks and scratch. ``step_kernel`` allocates
    those in place when it returns the full Newton: every tuple holding them sees them."""
    from fastvi.kernels import step as step_mod
    model = chain(16)
    n, N = model.n, P2.s * model.n + P2.J * model.m
    ws = structure.workspace(model, P2, newton=False)
    view = lay.loop_view(ws)
    assert {f for f in lay.Workspace._fields[:-4] if getattr(ws, f).size == 0} == {
        *lay.NEWTON_FIELDS, "Mi", "Mb", "Sc", "S"}
    opts = lay.NewtonOptions(1e-14, 30, lay.NEWTON_AUTO)
    step_mod.step_kernel(model.kernel_data(), P2.kernel_tables, opts, ws, full=True)
    assert ws.A.shape == (N, N) and view.A is ws.A and not ws.A.any()
    assert view.Aq.shape == view.Hc.shape == (n, n)
    # a constant mass, no force, the constraint Hessian given: no ∂(Mv)/∂q, no ∂F/∂v, no
    # differences of G or of M, whose blocks and scratch the full Newton never reads
    assert all(getattr(view, f).size == 0 for f in ("Cq", "Fv", "Ma", "Gp", "Gm"))
    damped = chain(16, damping=0.3)
    ws = structure.workspace(damped, P2, newton=False)
    step_mod.step_kernel(damped.kernel_data(), P2.kernel_tables, opts, ws, full=True)
    assert ws.Fv.shape == (n, n) and ws.Cq.size == ws.Ma.size == 0
    fd = _chain_without_constraint_hessian(16)
    ws = structure.workspace(fd, P2, newton=False)
    step_mod.step_kernel(fd.kernel_data(), P2.kernel_tables, opts, ws, full=True)
    assert ws.Gp.shape == ws.Gm.shape == (fd.m, n)
    assert ws.Mb.size == ws.Sc.size == ws.S.size == 0  # still never read
    # a small model's dense Schur complement and projection keep theirs
    small = structure.workspace(double_pendulum(), P2, newton=False)
    assert small.Sc.shape == (P2.J * 2, P2.J * 2) and small.Ma.shape == (4, 4)
    assert small.S.shape == (2, 2) and small.Gp.shape == (2, 4) and small.Gm.size == 0
    # the work of time over a step reads ∂g/∂t into Gp, whatever the projection's solve
    flags, si = model.kernel_data().flags.copy(), ws.si.copy()
    assert si[lay.SI_S] != lay.SOLVE_DENSE and "Gp" in lay.unused_fields(flags, si, False)
    flags[lay.F_TIME] = 1
    assert "Gp" not in lay.unused_fields(flags, si, False)


@pytest.mark.parametrize("name", ["damped_chain12", "coupled_chain10"])
def test_the_full_newton_assembled_into_band_storage_gives_the_same_run(name, monkeypatch):
    """A long chain's full Newton assembles its matrix straight into the band storage that
    its LU factors, through a map of each entry's place (``layout.assembly_into_band``),
    instead of a dense N² matrix packed into that storage afterwards: the same trajectory
    bit for bit, from storage that grows like N. The threshold is lowered so that a small
    chain takes that path."""
    model, args = _SCENE_CASES[name]()
    q0, v0 = (chain(10).initial_state(np.linspace(0.2, 1.0, 10)) if args is None
              else model.initial_state(*args))
    N = P2.s * model.n + P2.J * model.m
    dense = fastvi.integrate(model, q0, v0, h=0.01, n_steps=40, newton="full", check=False)
    assert structure.workspace(model, P2).A.shape == (N, N)
    monkeypatch.setattr(lay, "BAND_ASSEMBLY_BYTES", 0)
    ws = structure.workspace(model, P2, newton=False)
    assert ws.si[lay.SI_XMAP] != 0 and ws.A.size == 0
    lay.fit_newton_fields(ws, model.kernel_data().flags)  # what the full Newton's first need does
    assert ws.A.shape[0] == 1 and ws.A.size < N * N / 2
    band = fastvi.integrate(model, q0, v0, h=0.01, n_steps=40, newton="full", check=False)
    assert np.array_equal(band.q, dense.q) and np.array_equal(band.p, dense.p)


@pytest.mark.slow
def test_an_ensembles_members_assemble_into_band_storage_as_the_single_run(monkeypatch):
    """An ensemble's members allocate their workspaces as the single run's
    (``layout.field_shapes``), the map and the band-shaped matrix with it: the same final
    states, bit for bit, as the run assembled densely (slow: it compiles the members of a
    structured plan, about 20 s)."""
    model, args = _SCENE_CASES["damped_chain12"]()
    q0, v0 = model.initial_state(*args)
    dense = fastvi.integrate(model, q0, v0, h=0.01, n_steps=40, newton="full", check=False)
    monkeypatch.setattr(lay, "BAND_ASSEMBLY_BYTES", 0)
    ws = structure.workspace(model, P2)
    shapes = lay.field_shapes(ws)
    assert ws.A.shape[0] == 1 and tuple(shapes[lay.Workspace._fields.index("A")]) == (
        1, ws.A.size, 0)
    ens = fastvi.integrate_ensemble(model, np.stack([q0, q0]), np.stack([v0, v0]), h=0.01,
                                    n_steps=40, newton="full", threads=1)
    assert np.array_equal(ens.q[1], dense.q[-1])  # the final states


@pytest.mark.parametrize("newton", ["auto", "full"])
@pytest.mark.parametrize("name", ["chain12", "coupled_chain10", "damped_chain12",
                                  "differenced_chain12", "rotary_rod_slider",
                                  "kapitza_pendulum"])
def test_a_workspace_without_its_unread_fields_gives_the_same_run(name, newton, monkeypatch):
    """The same trajectory, bit for bit, as with every field allocated: whether the full
    Newton is taken from the start or on a step's first need."""
    if name == "differenced_chain12":  # the full Newton's differences of G and of ∂F/∂v
        model = _chain_without_constraint_hessian(12, damping=0.3)
        q0, v0 = chain(12).initial_state(np.linspace(0.2, 1.4, 12))
    else:
        model, args = _SCENE_CASES[name]()
        q0, v0 = (chain(10).initial_state(np.linspace(0.2, 1.0, 10)) if args is None
                  else model.initial_state(*args))
    lean = fastvi.integrate(model, q0, v0, h=0.01, n_steps=40, newton=newton)
    monkeypatch.setattr(lay, "unused_fields", lambda flags, si, newton: frozenset())
    every = fastvi.integrate(model, q0, v0, h=0.01, n_steps=40, newton=newton)
    assert np.array_equal(lean.q, every.q) and np.array_equal(lean.p, every.p)
    assert np.array_equal(lean.newton_iterations, every.newton_iterations)


def test_a_plain_run_of_a_large_mechanism_holds_no_dense_newton_matrix():
    """A 128-link chain's run (its model checked, its plan made, its kernels compiled by a
    first run) allocates less than its dense Newton matrix alone, 8 N² bytes with
    N = s n + J m = 768: measured 2.6 MiB, where the workspace with every field took
    11.7 MiB."""
    import tracemalloc
    model = chain(128)
    q0, v0 = model.initial_state(np.linspace(0.2, 1.4, 128))
    fastvi.integrate(model, q0, v0, h=0.01, n_steps=2)
    tracemalloc.start()
    try:
        fastvi.integrate(model, q0, v0, h=0.01, n_steps=10, save_every=10)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    N = P2.s * model.n + P2.J * model.m
    assert peak < 8 * N * N, peak


@pytest.mark.parametrize("case", ["damped_chain12", "closed_chain14", "coupled_chain10"])
def test_pattern_detection_over_gs_declared_pattern_finds_the_dense_residuals_pattern(
        case, monkeypatch):
    """With G's pattern declared, the residuals of the pattern detection form Gᵀη over it
    (``structure._g_pattern_plan``), as a structured step does: the same patterns as the
    residuals that form it densely."""
    model = _SCENE_CASES[case]()[0]
    assert model.constraint_jacobian_pattern is not None
    over_pattern = structure.detect_pattern(model, P2)
    monkeypatch.setattr(structure, "_g_pattern_plan",
                        lambda PG: np.zeros(lay.SI_HEADER, dtype=np.int64))
    dense = structure.detect_pattern(model, P2)
    for name in ("G", "newton"):
        assert np.array_equal(over_pattern[name], dense[name]), name
    assert over_pattern["newton"].sum() < 0.2 * over_pattern["newton"].size
