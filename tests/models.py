"""Small models used only by the tests (module-level functions, as numba needs).

``polar_pendulum``: a point mass in polar coordinates q = (r, φ), φ from the downward
vertical, so the mass matrix diag(m, m r²) depends on q; with ``spring`` the radius is a
spring (unconstrained, m = 0), otherwise the constraint r − l = 0 makes it a pendulum.
params = (m, g, l_or_r0, k).
"""

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
# model a user would write, and the scene's callbacks take the time (its driven variant).
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
