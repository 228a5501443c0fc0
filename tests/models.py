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
