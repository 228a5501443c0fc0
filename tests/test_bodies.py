"""fastvi.bodies set-up: principal frames, exact derivatives and patterns, the rank analysis,
initial data from joint coordinates, outputs on exact states, errors. (No long runs here:
the dynamics are in test_bodies_dynamics.py.)"""

import pickle

import numpy as np
import pytest

import fastvi
from fastvi import bodies
from fastvi.bodies import outputs as out
from fastvi.bodies import scenes
from fastvi.bodies.rigid import expm_so3, principal


def _random_rotation(seed):
    return expm_so3(np.random.default_rng(seed).standard_normal(3))


# ----------------------------------------------------------------------------- bodies
def test_principal_axes_diagonalise_a_full_tensor_and_keep_a_diagonal_one():
    P0 = _random_rotation(1)
    moments = np.array([2.0, 3.0, 4.0])
    J = P0 @ np.diag(moments) @ P0.T
    Jp, P = principal(J)
    assert np.allclose(P.T @ J @ P, np.diag(Jp), atol=1e-14) and np.isclose(np.linalg.det(P), 1.0)
    assert np.allclose(np.sort(Jp), moments)
    Jd, Pd = principal((1.0, 2.0, 2.5))
    assert np.array_equal(Pd, np.eye(3)) and np.array_equal(Jd, [1.0, 2.0, 2.5])


def test_a_body_with_a_full_tensor_moves_like_its_principal_twin():
    """The same body given in a rotated user frame (full J) and in its principal frame: the
    same mass matrix up to ordering, the same outputs in each user frame."""
    P0 = _random_rotation(2)
    moments = np.array([0.2, 0.3, 0.4])
    w = np.array([0.3, -1.0, 2.0])

    def top(J, R):
        mech = bodies.Mechanism(gravity=(0, 0, -9.81))
        x = np.array([0.1, 0.2, 0.3])
        b = mech.body("b", mass=2.0, inertia=J, position=x, rotation=R, omega=w, velocity=np.cross(w, x))
        mech.spherical("ground", b, point=(0.0, 0.0, 0.0))
        return mech.build()

    m1 = top(np.diag(moments), np.eye(3))
    m2 = top(P0.T @ np.diag(moments) @ P0, P0)  # the user's axes are P0's columns: J_user = P0ᵀ J P0
    q1, v1 = m1.initial_state()
    q2, v2 = m2.initial_state()
    assert np.allclose(out.rotation(m1, q1, "b") @ P0, out.rotation(m2, q2, "b"), atol=1e-14)
    assert np.allclose(out.angular_velocity(m1, q1, "b", v=v1), out.angular_velocity(m2, q2, "b", v=v2),
                       atol=1e-13)
    assert np.isclose(out.kinetic_energy(m1, q1, v1), out.kinetic_energy(m2, q2, v2), rtol=1e-13)


def test_kinetic_energy_and_momentum_of_a_free_body_match_rigid_body_formulas():
    J = np.array([[0.5, 0.1, 0.0], [0.1, 0.6, 0.05], [0.0, 0.05, 0.7]])
    R = _random_rotation(3)
    w, vc = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.1, -0.2])
    mech = bodies.Mechanism()
    b = mech.body("b", mass=3.0, inertia=J, position=(1.0, 2.0, 3.0), rotation=R, velocity=vc, omega=w)
    mech.point_mass("p", mass=0.5, position=(0, 0, 1), velocity=(1, 0, 0))
    model = mech.build()
    q, v = model.initial_state()
    Jw = R @ J @ R.T  # world inertia
    T = 0.5 * 3.0 * vc @ vc + 0.5 * w @ Jw @ w + 0.5 * 0.5 * 1.0
    assert np.isclose(out.kinetic_energy(model, q, v), T, rtol=1e-14)
    L = 3.0 * np.cross(b.position, vc) + Jw @ w + 0.5 * np.cross([0, 0, 1], [1, 0, 0])
    assert np.allclose(out.angular_momentum(model, q, v), L, rtol=1e-14)
    assert np.allclose(out.linear_momentum(model, q, v), 3.0 * vc + [0.5, 0, 0])
    assert np.allclose(out.angular_velocity(model, q, "b", v=v, frame="body"), R.T @ w, atol=1e-15)
    assert model.dof.dof == 6 + 3


# ----------------------------------------------------------------------------- derivatives
def _kitchen_sink():
    """Every joint and load kind on one mechanism (time-dependent: a driven joint)."""
    mech = bodies.Mechanism(gravity=(0.1, -0.2, -9.81), name="sink")
    R = _random_rotation(4)
    a = mech.body("a", mass=1.0, inertia=(0.1, 0.2, 0.25), position=(0, 0, 1), rotation=R)
    b = mech.body("b", mass=2.0, inertia=[[0.3, 0.01, 0], [0.01, 0.2, 0.02], [0, 0.02, 0.25]],
                  position=(0.5, 0, 1))
    c = mech.body("c", mass=1.5, inertia=(0.1, 0.1, 0.15), position=(1, 0.5, 1))
    d = mech.body("d", mass=1.0, inertia=(0.1, 0.12, 0.15), position=(1, 1, 1))
    e = mech.body("e", mass=1.0, inertia=(0.1, 0.12, 0.15), position=(0, 1, 2))
    f = mech.body("f", mass=1.0, inertia=(0.1, 0.12, 0.15), position=(0, 2, 2))
    p = mech.point_mass("p", mass=0.3, position=(2, 0, 0))
    hinge = mech.revolute("ground", a, point=(0, 0, 0.5), axis=(0, 1, 1))
    mech.universal(a, b, point=(0.25, 0, 1), axis_a=R.T @ [0, 0, 1], axis_b=(0, 1, 0))
    mech.cylindrical(b, c, point=(0.75, 0.25, 1), axis=(1, 1, 0))
    mech.prismatic(c, d, point=(1, 0.75, 1), axis=(0, 1, 0.3))
    mech.fixed(d, e, point=(0.5, 1, 1.5))
    mech.driven_revolute(e, f, bodies.Profile(rate=0.7, amplitude=0.2, frequency=3.0), point=(0, 1.5, 2),
                         axis=(1, 0, 0))
    mech.distance(f, p, point_a=(0.1, 0, 0))
    mech.spring(a, c, stiffness=50.0, damping=0.3, point_a=(0.1, 0.2, 0), point_b=(0, 0.1, 0.1))
    mech.spring("ground", p, stiffness=20.0, damping=0.5, length=0.0, point_a=(2, 0, -1))
    mech.rotary_spring(hinge, stiffness=3.0, damping=0.2, angle=0.3)
    mech.torque(b, (0.1, 0.2, -0.3), profile=bodies.Profile(value=1.0, amplitude=0.5, frequency=2.0))
    mech.force(c, (1.0, 0.0, 0.5), point=(0.1, 0.0, 0.0))
    return mech.build(t0=0.0)


def test_every_joint_and_load_has_exact_derivatives_and_a_correct_pattern():
    model = _kitchen_sink()
    assert model.time_dependent and model.has_force and not model.linear_potential
    exact = model.has_exact_second_derivatives  # the kinetic ones are zero: M is constant
    assert exact["potential_hessian"] and exact["constraint_hessian"] and model.mass_matrix_constant is not None
    rng = np.random.default_rng(5)
    q0, _ = model.initial_state()
    q = q0 + 0.05 * rng.standard_normal(model.n)  # off the constraints: the derivatives hold anywhere
    v = rng.standard_normal(model.n)
    report = model.check(q, v, t=0.37, rtol=1e-7)
    assert report.ok, report


def test_driven_prismatic_and_rates_have_exact_time_derivatives():
    mech = bodies.Mechanism()
    s = mech.body("s", mass=1.0, inertia=(0.1, 0.1, 0.1), position=(0, 0, 0))
    mech.driven_prismatic("ground", s, bodies.Profile(rate=0.3, amplitude=0.1, frequency=2.0),
                          point=(0, 0, 0), axis=(1, 1, 0))
    model = mech.build()
    assert model.dof.dof == 0 and model.m == 12  # the drive takes the joint's freedom
    rng = np.random.default_rng(6)
    q0, v0 = model.initial_state(t=0.4)
    assert model.check(q0 + 0.01 * rng.standard_normal(12), v0, t=0.4).ok
    # the drive holds at t: the body is at s(t) along the axis and moves with s'(t)
    prof = bodies.Profile(rate=0.3, amplitude=0.1, frequency=2.0)
    assert np.allclose(out.position(model, q0, "s"), prof(0.4) * np.array([1, 1, 0]) / np.sqrt(2))
    assert np.allclose(v0[:3], prof.derivative(0.4) * np.array([1, 1, 0]) / np.sqrt(2), atol=1e-14)


def test_same_sizes_compile_nothing_new():
    """Two different mechanisms with n = 12, m = 9: the same compiled callbacks."""
    top = scenes.lagrange_top()
    other = scenes.heavy_top(inertia=(0.2, 0.3, 0.25))
    cf1, cf2 = top.kernel_arguments()[0], other.kernel_arguments()[0]
    assert all(a is b for a, b in zip(cf1, cf2))
    assert top.params.shape == other.params.shape and not np.array_equal(top.params, other.params)


# ----------------------------------------------------------------------------- redundancy
def test_bricard_has_one_redundant_row_and_one_degree_of_freedom():
    model = scenes.bricard()
    dof = model.dof
    assert (dof.coordinates, dof.equations, dof.rank, dof.dof) == (60, 60, 59, 1)
    assert len(dof.redundant) == 1 and model.m == 59
    assert dof.sigma_min > 1e-2  # the kept rows are far from dependent
    kept = scenes.bricard(redundant="keep")
    assert kept.m == 60
    G = kept.constraint_jacobian_value(kept.initial_state()[0])
    assert np.linalg.matrix_rank(G, tol=1e-10) == 59  # what the QR reported, by SVD
    with pytest.raises(ValueError, match="1 redundant"):
        scenes.bricard(redundant="raise")


def test_degrees_of_freedom_of_each_joint():
    expected = dict(spherical=3, revolute=1, universal=2, cylindrical=2, prismatic=1, fixed=0)
    for kind, dof in expected.items():
        mech = bodies.Mechanism()
        b = mech.body("b", mass=1.0, inertia=(0.1, 0.2, 0.25), position=(0.2, 0.1, 0.0))
        geometry = dict(point=(0, 0, 0))
        if kind in ("revolute", "cylindrical", "prismatic"):
            geometry["axis"] = (1, 2, 3)
        if kind == "universal":
            geometry.update(axis_a=(1, 0, 0), axis_b=(0, 1, 0))
        getattr(mech, kind)("ground", b, **geometry)
        model = mech.build()
        assert model.dof.dof == dof, kind
        assert not model.dof.redundant


def test_a_doubled_joint_is_redundant_and_dropped():
    mech = bodies.Mechanism()
    b = mech.body("b", mass=1.0, inertia=(0.1, 0.2, 0.25), position=(1, 0, 0))
    mech.revolute("ground", b, point=(0, 0, 0), axis=(0, 0, 1))
    mech.spherical("ground", b, point=(0, 0, 0))
    model = mech.build()
    assert model.dof.dof == 1 and len(model.dof.redundant) == 3 and model.m == 6 + 5


def test_recheck_follows_the_kept_rows():
    model = scenes.bricard()
    q0, v0 = model.initial_state()
    res = fastvi.integrate(model, q0, v0, h=0.02, t_end=1.0)
    rc = bodies.recheck(model, res, every=5)
    assert rc.ok and rc.sigma_min.min() > 0.5 * model.dof.sigma_min
    with pytest.warns(RuntimeWarning, match="approach dependence"):
        bodies.recheck(model, res, every=5, threshold=2.0)


# ----------------------------------------------------------------------------- initial data
def test_joint_coordinates_place_an_open_chain_exactly():
    """A double pendulum of rods on hinges: joint angles and rates against the planar formula."""
    mech = bodies.Mechanism(gravity=(0, 0, -9.81))
    r1 = mech.body("r1", mass=1.0, inertia=(0.01, 0.1, 0.1), position=(0.5, 0, 0))
    r2 = mech.body("r2", mass=1.0, inertia=(0.01, 0.1, 0.1), position=(1.5, 0, 0))
    mech.revolute("ground", r1, point=(0, 0, 0), axis=(0, -1, 0), name="h1")
    mech.revolute(r1, r2, point=(1, 0, 0), axis=(0, -1, 0), name="h2")
    model = mech.build()
    th, om = (0.3, -0.8), (1.2, 0.5)
    q, v = model.initial_state({"h1": th[0], "h2": th[1]}, {"h1": om[0], "h2": om[1]})
    assert np.abs(model.constraint_value(q)).max() < 1e-15
    assert np.abs(model.constraint_jacobian_value(q) @ v).max() < 1e-14
    # about −y, a positive angle lifts the x axis towards +z
    e = lambda a: np.array([np.cos(a), 0.0, np.sin(a)])  # noqa: E731
    de = lambda a: np.array([-np.sin(a), 0.0, np.cos(a)])  # noqa: E731
    a2 = th[0] + th[1]
    assert np.allclose(out.position(model, q, "r2"), e(th[0]) + 0.5 * e(a2), atol=1e-15)
    assert np.allclose(v[12:15], om[0] * de(th[0]) + 0.5 * (om[0] + om[1]) * de(a2), atol=1e-14)
    assert np.allclose(out.joint_coordinate(model, q, "h2"), th[1], atol=1e-15)


def test_joint_rates_drive_a_loop():
    model = scenes.spatial_slider_crank()
    q, v = model.initial_state(angle=0.4, speed=6.0)
    assert np.abs(model.constraint_value(q)).max() < 1e-14
    assert np.abs(model.constraint_jacobian_value(q) @ v).max() < 1e-13
    assert np.isclose(out.joint_coordinate(model, q, "crank"), 0.4, atol=1e-14)
    assert np.allclose(out.angular_velocity(model, q, "crank", v=v), [6.0, 0, 0], atol=1e-13)
    # the slider on the x axis at the loop's closure: |C − B| = 0.3
    A = np.array([0.0, 0.1, 0.12])
    B = A + 0.08 * np.array([0, -np.sin(0.4), np.cos(0.4)])
    C = out.position(model, q, "slider")
    assert abs(np.linalg.norm(C - B) - 0.3) < 1e-14 and abs(C[1]) + abs(C[2]) < 1e-14


def test_loop_values_are_refused_and_inconsistent_velocities_warned():
    model = scenes.spatial_slider_crank()
    with pytest.raises(ValueError, match="closes a loop"):
        fastvi.bodies.initial_state(model, {"slide": 0.1})
    mech = bodies.Mechanism()
    b = mech.body("b", mass=1.0, inertia=(0.1, 0.1, 0.1), position=(1, 0, 0), omega=(0, 0, 1.0))
    mech.spherical("ground", b, point=(0, 0, 0))
    with pytest.warns(RuntimeWarning, match="velocities do not satisfy"):
        mech.build().initial_state()


# ----------------------------------------------------------------------------- outputs
def test_reactions_of_a_precessing_top_balance_its_centre_of_mass():
    """On the exact steady precession the ball joint carries m (a − g), and no torque."""
    model = scenes.lagrange_top()
    t = np.linspace(0.0, 0.5, 6)
    q, v = model.exact(t)
    F, T = out.reactions(model, q, "pivot", v=v)
    phi = q[:, :3]
    wp = 3.0
    acc = -wp * wp * (phi - phi[:, 2:3] * np.array([0, 0, 1.0]))  # uniform circle about e_z
    assert np.allclose(F, 1.0 * (acc - np.array([0, 0, -9.81])), atol=1e-12)
    assert np.abs(T).max() < 1e-12


def test_reactions_of_a_driven_hinge_give_the_motor_torque():
    """A disc spun up at a constant angular acceleration α about a vertical driven hinge:
    the hinge's torque about its axis is J α."""
    alpha = 2.0
    mech = bodies.Mechanism(gravity=(0, 0, -9.81))
    disc = mech.body("disc", mass=3.0, inertia=(0.2, 0.2, 0.3), position=(0, 0, 0))
    mech.driven_revolute("ground", disc, bodies.Profile(acceleration=alpha), point=(0, 0, 0),
                         axis=(0, 0, 1), name="motor")
    model = mech.build()
    q0, v0 = model.initial_state(t=0.5)
    F, T = out.reactions(model, q0[None], "motor", v=v0[None], t=0.5)
    assert np.isclose(T[0, 2], 0.3 * alpha, rtol=1e-12) and np.allclose(F[0], [0, 0, 3.0 * 9.81])
    assert np.isclose(out.joint_coordinate(model, q0, "motor"), 0.5 * alpha * 0.25, atol=1e-15)


# ----------------------------------------------------------------------------- errors
@pytest.mark.parametrize("inertia, match", [
    ((1.0, 1.0, 3.0), r"triangle inequality J1 \+ J2 >= J3"),
    ((-1.0, 1.0, 1.0), "principal moment <= 0"),
    ([[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], "symmetric"),
])
def test_non_physical_inertia_is_refused_naming_the_body(inertia, match):
    mech = bodies.Mechanism()
    with pytest.raises(ValueError, match=f"body 'wheel'.*{match}"):
        mech.body("wheel", mass=1.0, inertia=inertia)


def test_bad_joint_arguments_are_named():
    mech = bodies.Mechanism()
    b = mech.body("b", mass=1.0, inertia=(1, 1, 1))
    with pytest.raises(ValueError, match="revolute joint 'h'.*`axis` has zero length"):
        mech.revolute("ground", b, point=(0, 0, 0), axis=(0, 0, 0), name="h")
    with pytest.raises(ValueError, match="spherical joint 's'.*argument `b` = 7 is not a body"):
        mech.spherical("ground", 7, point=(0, 0, 0), name="s")
    with pytest.raises(ValueError, match="argument `a` = 'wheel' is not a body"):
        mech.spherical("wheel", b, point=(0, 0, 0))
    p = mech.point_mass("p", mass=1.0, position=(1, 0, 0))
    with pytest.raises(ValueError, match="point mass 'p' has no axes"):
        mech.revolute(b, p, point=(1, 0, 0), axis=(0, 0, 1))
    with pytest.raises(ValueError, match="perpendicular"):
        mech.universal("ground", b, point=(0, 0, 0), axis_a=(1, 0, 0), axis_b=(1, 1, 0))
    with pytest.raises(ValueError, match="name 'b' is taken"):
        mech.body("b", mass=1.0, inertia=(1, 1, 1))
    with pytest.raises(ValueError, match="the same body"):
        mech.spherical(b, "b", point=(0, 0, 0))


def test_body_scenes_pickle_by_recipe():
    model = scenes.spatial_slider_crank(speed=4.0)
    clone = pickle.loads(pickle.dumps(model))
    assert clone.name == model.name and np.array_equal(clone.params, model.params)
    q, v = clone.initial_state()
    assert np.allclose(out.angular_velocity(clone, q, "crank", v=v), [4.0, 0, 0])
