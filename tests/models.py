"""Small models used only by the tests (module-level functions, as numba needs).

``polar_pendulum``: a point mass in polar coordinates q = (r, φ), φ from the downward
vertical, so the mass matrix diag(m, m r²) depends on q; with ``spring`` the radius is a
spring (unconstrained, m = 0), otherwise the constraint r − l = 0 makes it a pendulum.
params = (m, g, l_or_r0, k).

``driven_pendulum``: the scenes' pendulum with a dashpot, driven by a horizontal force on its
bob: a forced model whose constraint and potential do not depend on time.
"""

import importlib

import numba
import numpy as np

import fastvi


def mass(q, p, out):
    out[0, 0] = p[0]
    out[0, 1] = 0.0
    out[1, 0] = 0.0
    out[1, 1] = p[0] * q[0] * q[0]


def kinetic_grad(q, v, p, out):
    out[0] = p[0] * q[0] * v[1] * v[1]
    out[1] = 0.0


def kinetic_hessian(q, v, p, out):
    out[:, :] = 0.0
    out[0, 0] = p[0] * v[1] * v[1]


def momentum_jacobian(q, v, p, out):
    out[:, :] = 0.0
    out[1, 0] = 2.0 * p[0] * q[0] * v[1]


def potential(q, p):
    return -p[0] * p[1] * q[0] * np.cos(q[1]) + 0.5 * p[3] * (q[0] - p[2]) ** 2


def potential_grad(q, p, out):
    out[0] = -p[0] * p[1] * np.cos(q[1]) + p[3] * (q[0] - p[2])
    out[1] = p[0] * p[1] * q[0] * np.sin(q[1])


def potential_hessian(q, p, out):
    out[0, 0] = p[3]
    out[0, 1] = p[0] * p[1] * np.sin(q[1])
    out[1, 0] = out[0, 1]
    out[1, 1] = p[0] * p[1] * q[0] * np.cos(q[1])


def constraint(q, p, out):
    out[0] = q[0] - p[2]


def constraint_jacobian(q, p, out):
    out[0, 0] = 1.0
    out[0, 1] = 0.0


def constraint_hessian(q, eta, p, out):
    out[:, :] = 0.0


def polar_pendulum(m=1.0, g=9.81, l=1.0, exact=True, spring=None):
    """Pendulum (or, with ``spring=k``, a spring pendulum) in polar coordinates."""
    second = dict(kinetic_hessian=kinetic_hessian, momentum_jacobian=momentum_jacobian,
                  potential_hessian=potential_hessian) if exact else {}
    if spring is None:
        cons = dict(constraint=constraint, constraint_jacobian=constraint_jacobian)
        if exact:
            cons["constraint_hessian"] = constraint_hessian
        return fastvi.Model(2, 1, params=(m, g, l, 0.0), mass=mass, potential=potential,
                            potential_grad=potential_grad, kinetic_grad=kinetic_grad,
                            name="polar_pendulum", **cons, **second)
    return fastvi.Model(2, 0, params=(m, g, l, spring), mass=mass, potential=potential,
                        potential_grad=potential_grad, kinetic_grad=kinetic_grad,
                        name="spring_pendulum", **second)


# a plain unconstrained anharmonic oscillator with constant mass (the m = 0, constant-M path)
def quartic_V(q, p):
    return 0.5 * q[0] ** 2 + 0.25 * p[0] * q[0] ** 4 + 0.5 * q[1] ** 2 + 0.1 * q[0] * q[1]


def quartic_dV(q, p, out):
    out[0] = q[0] + p[0] * q[0] ** 3 + 0.1 * q[1]
    out[1] = q[1] + 0.1 * q[0]


def quartic(eps=1.0):
    return fastvi.Model(2, 0, params=(eps,), mass=np.array([[1.0, 0.2], [0.2, 2.0]]),
                        potential=quartic_V, potential_grad=quartic_dV, name="quartic")


# ----------------------------------------------------------------------------- slider–crank
# Crank pin A on a circle of radius r about the origin, slider B on the x axis, a rod of
# length L from A to B with its mass at its midpoint C, in redundant Cartesian coordinates
# q = (xa, ya, xc, yc, xb, yb); five constraints leave one degree of freedom.
# params = (r, L, ma, mc, mb, g). The same mechanism as fastvi.scenes.slider_crank, written
# here as an autonomous user model (callbacks without t): the consistent-state tests need a
# model a user would write, independent of the scene's own callbacks.
def sc_V(q, p):
    return p[5] * (p[2] * q[1] + p[3] * q[3] + p[4] * q[5])


def sc_dV(q, p, out):
    out[0] = 0.0
    out[1] = p[5] * p[2]
    out[2] = 0.0
    out[3] = p[5] * p[3]
    out[4] = 0.0
    out[5] = p[5] * p[4]


def sc_ddV(q, p, out):
    out[:, :] = 0.0


def sc_g(q, p, out):
    dx, dy = q[4] - q[0], q[5] - q[1]
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] - p[0] * p[0])
    out[1] = 0.5 * (dx * dx + dy * dy - p[1] * p[1])
    out[2] = q[2] - 0.5 * (q[0] + q[4])
    out[3] = q[3] - 0.5 * (q[1] + q[5])
    out[4] = q[5]


def sc_G(q, p, out):
    dx, dy = q[4] - q[0], q[5] - q[1]
    out[:, :] = 0.0
    out[0, 0] = q[0]
    out[0, 1] = q[1]
    out[1, 0] = -dx
    out[1, 1] = -dy
    out[1, 4] = dx
    out[1, 5] = dy
    out[2, 0] = -0.5
    out[2, 2] = 1.0
    out[2, 4] = -0.5
    out[3, 1] = -0.5
    out[3, 3] = 1.0
    out[3, 5] = -0.5
    out[4, 5] = 1.0


def sc_ddg(q, eta, p, out):
    out[:, :] = 0.0
    for a in (0, 1):  # η0 ∇²g0 on (xa, ya); η1 ∇²g1 couples A and B
        out[a, a] = eta[0] + eta[1]
        out[a + 4, a + 4] = eta[1]
        out[a, a + 4] = -eta[1]
        out[a + 4, a] = -eta[1]


SLIDER_CRANK_PARAMS = (0.3, 1.0, 0.5, 1.0, 2.0, 9.81)


def slider_crank():
    """Slider–crank (n = 6, m = 5) with exact second derivatives."""
    ma, mc, mb = SLIDER_CRANK_PARAMS[2:5]
    return fastvi.Model(6, 5, params=SLIDER_CRANK_PARAMS, mass=np.diag([ma, ma, mc, mc, mb, mb]),
                        potential=sc_V, potential_grad=sc_dV, potential_hessian=sc_ddV,
                        constraint=sc_g, constraint_jacobian=sc_G, constraint_hessian=sc_ddg,
                        name="slider_crank")


def slider_crank_state(phi, omega):
    """The exact ``(q, v)`` for crank angle ``phi`` and crank speed ``omega`` (slider to the right)."""
    from fastvi.scenes.slider_crank import state

    return state(phi, omega, *SLIDER_CRANK_PARAMS[:2])


# ----------------------------------------------------------------------------- bar slider–crank
# The slider–crank of the reliability monitor's case, in 8 body coordinates: the crank and the
# rod as uniform bars given by centre and angle (inertia m L²/12), the slider a point on the x
# axis, q = (x1, y1, θ1, x2, y2, θ2, x3, y3). Seven constraints: the crank's end pinned at the
# origin, crank tip = rod start, rod end = slider, slider on y = 0. Gravity and a spring k
# pulling the slider to x = x_rest. params = (a, L, m1, m2, m3, g, k, x_rest).
BAR_SC_PARAMS = (0.3, 1.0, 1.0, 2.0, 1.0, 9.81, 100.0, 0.8)


def bsc_V(q, p):
    return p[5] * (p[2] * q[1] + p[3] * q[4] + p[4] * q[7]) + 0.5 * p[6] * (q[6] - p[7]) ** 2


def bsc_dV(q, p, out):
    out[:] = 0.0
    out[1] = p[5] * p[2]
    out[4] = p[5] * p[3]
    out[6] = p[6] * (q[6] - p[7])
    out[7] = p[5] * p[4]


def bsc_ddV(q, p, out):
    out[:, :] = 0.0
    out[6, 6] = p[6]


def bsc_g(q, p, out):
    ha, hl = 0.5 * p[0], 0.5 * p[1]
    c1, s1, c2, s2 = np.cos(q[2]), np.sin(q[2]), np.cos(q[5]), np.sin(q[5])
    out[0] = q[0] - ha * c1
    out[1] = q[1] - ha * s1
    out[2] = q[0] + ha * c1 - q[3] + hl * c2
    out[3] = q[1] + ha * s1 - q[4] + hl * s2
    out[4] = q[3] + hl * c2 - q[6]
    out[5] = q[4] + hl * s2 - q[7]
    out[6] = q[7]


def bsc_G(q, p, out):
    ha, hl = 0.5 * p[0], 0.5 * p[1]
    c1, s1, c2, s2 = np.cos(q[2]), np.sin(q[2]), np.cos(q[5]), np.sin(q[5])
    out[:, :] = 0.0
    out[0, 0], out[0, 2] = 1.0, ha * s1
    out[1, 1], out[1, 2] = 1.0, -ha * c1
    out[2, 0], out[2, 2], out[2, 3], out[2, 5] = 1.0, -ha * s1, -1.0, -hl * s2
    out[3, 1], out[3, 2], out[3, 4], out[3, 5] = 1.0, ha * c1, -1.0, hl * c2
    out[4, 3], out[4, 5], out[4, 6] = 1.0, -hl * s2, -1.0
    out[5, 4], out[5, 5], out[5, 7] = 1.0, hl * c2, -1.0
    out[6, 7] = 1.0


def bsc_ddg(q, eta, p, out):
    ha, hl = 0.5 * p[0], 0.5 * p[1]
    c1, s1, c2, s2 = np.cos(q[2]), np.sin(q[2]), np.cos(q[5]), np.sin(q[5])
    out[:, :] = 0.0
    out[2, 2] = ha * (c1 * (eta[0] - eta[2]) + s1 * (eta[1] - eta[3]))
    out[5, 5] = -hl * (c2 * (eta[2] + eta[4]) + s2 * (eta[3] + eta[5]))


def bar_slider_crank(**overrides):
    """The bar slider–crank (n = 8, m = 7) with exact second derivatives."""
    a, L, m1, m2, m3 = BAR_SC_PARAMS[:5]
    mass = np.diag([m1, m1, m1 * a * a / 12, m2, m2, m2 * L * L / 12, m3, m3])
    funcs = dict(potential=bsc_V, potential_grad=bsc_dV, potential_hessian=bsc_ddV,
                 constraint=bsc_g, constraint_jacobian=bsc_G, constraint_hessian=bsc_ddg)
    funcs.update(overrides)
    return fastvi.Model(8, 7, params=BAR_SC_PARAMS, mass=mass, name="bar_slider_crank", **funcs)


def bar_slider_crank_state(phi=0.3, omega=5.0):
    """The exact ``(q, v)`` at crank angle ``phi`` and crank speed ``omega`` (slider right)."""
    a, L = BAR_SC_PARAMS[:2]
    A, dA = a * np.array([np.cos(phi), np.sin(phi)]), a * omega * np.array([-np.sin(phi), np.cos(phi)])
    th2 = -np.arcsin(A[1] / L)
    dth2 = -dA[1] / (L * np.cos(th2))
    e2, de2 = np.array([np.cos(th2), np.sin(th2)]), np.array([-np.sin(th2), np.cos(th2)])
    C2, dC2 = A + 0.5 * L * e2, dA + 0.5 * L * dth2 * de2
    B, dB = A + L * e2, dA + L * dth2 * de2
    q = np.array([A[0] / 2, A[1] / 2, phi, C2[0], C2[1], th2, B[0], B[1]])
    v = np.array([dA[0] / 2, dA[1] / 2, omega, dC2[0], dC2[1], dth2, dB[0], dB[1]])
    return q, v


def damped_double_pendulum_by_differences(damping=0.3):
    """The damped double pendulum (a 2-link :func:`fastvi.scenes.chain`, unit masses and
    rods) without its derivatives by the parameters: the linearised step then differences
    the whole step in θ, the reference of the exact derivatives by θ."""
    import importlib

    # the module, which the package's function `chain` shadows as an attribute
    chain = importlib.import_module("fastvi.scenes.chain")
    damping_ = importlib.import_module("fastvi.scenes.damping")

    return fastvi.Model(
        4, 2, params=(1.0, 1.0, 1.0, 1.0, 9.81, damping), mass=np.ones(4),
        potential=chain.potential, potential_grad=chain.potential_grad, potential_hessian=0,
        constraint=chain.constraint, constraint_jacobian=chain.constraint_jacobian,
        constraint_hessian=chain.constraint_hessian, constraint_jacobian_pattern=chain.pattern(2),
        name="double_pendulum-by-differences",
        **damping_.options(damping, 4))


# a pendulum (Cartesian) with dashpot c, driven by a horizontal force F cos(ω t) on its bob:
# forced through its force alone; the scene's pendulum otherwise. params = (m, l, g, c, F, ω)
pendulum_scene = importlib.import_module("fastvi.scenes.pendulum")  # the module: the name is the scene
DRIVEN_PARAMS = (1.0, 1.0, 9.81, 0.5, 2.0, 2.5)


def driven_force(t, q, v, p, out):
    out[0] = -p[3] * v[0] + p[4] * np.cos(p[5] * t)
    out[1] = -p[3] * v[1]


def driven_force_v(t, q, v, p, out):
    out[:, :] = 0.0
    out[0, 0] = -p[3]
    out[1, 1] = -p[3]


def driven_pendulum():
    """The pendulum of :data:`DRIVEN_PARAMS`: time enters through its force alone."""
    return fastvi.Model(2, 1, params=DRIVEN_PARAMS, mass=DRIVEN_PARAMS[0] * np.eye(2),
                        potential=pendulum_scene._V, potential_grad=pendulum_scene._dV,
                        potential_hessian=0, constraint=pendulum_scene._g,
                        constraint_jacobian=pendulum_scene._G,
                        constraint_hessian=pendulum_scene._ddg, force=driven_force,
                        force_jacobian_q=0, force_jacobian_v=driven_force_v, name="driven_pendulum")


# time-dependent spring: V = ½ k1 x² + ½ k2 (y − a sin t)², params = (k1, k2, a, …)
def td_potential(t, q, p):
    return 0.5 * p[0] * q[0] ** 2 + 0.5 * p[1] * (q[1] - p[2] * np.sin(t)) ** 2


def td_potential_grad(t, q, p, out):
    out[0] = p[0] * q[0]
    out[1] = p[1] * (q[1] - p[2] * np.sin(t))


@numba.njit
def chain_constraint_hessian_dense(q, eta, p, out):
    """``fastvi.scenes.chain``'s ``Σ_i η_i ∇²g_i``, every entry written (the scene's writes
    those of coordinates that share a link alone); jitted, so that other callbacks can call it."""
    nb = q.shape[0] // 2
    out[:, :] = 0.0
    for i in range(nb):
        d = eta[i] + (eta[i + 1] if i + 1 < nb else 0.0)
        out[2 * i, 2 * i] = d
        out[2 * i + 1, 2 * i + 1] = d
        if i + 1 < nb:
            for a in range(2):
                out[2 * i + a, 2 * i + 2 + a] = -eta[i + 1]
                out[2 * i + 2 + a, 2 * i + a] = -eta[i + 1]
