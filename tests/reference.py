"""A plain-NumPy twin of the step residual, written from docs/method.md in absolute form.

It shares nothing with the kernels but the model callbacks (evaluated one by one from
Python) and the raw Lagrange basis (no exactness corrections, no increments).
"""

import numpy as np

from fastvi.tables import gauss_legendre, gauss_lobatto, lagrange_basis


def residual(model, meth, h, qk, pk, X, params=None):
    n, m, s, J = model.n, model.m, meth.s, meth.J
    prm = model.params if params is None else params
    Q = np.vstack([qk, qk + X[: s * n].reshape(s, n)])  # absolute control points
    eta = X[s * n:].reshape(J, m) if m else np.zeros((J, 0))
    c, b = (gauss_legendre if meth.quadrature == "gauss" else gauss_lobatto)(meth.r)
    ell, dell = lagrange_basis(meth.tau, c)
    ellc, _ = lagrange_basis(meth.tau, meth.d)
    D = np.zeros((s + 1, n))
    for i in range(meth.r):
        qi = ell[:, i] @ Q
        vi = dell[:, i] @ Q / h
        F = -model.callback_value("potential_grad", qi, params=prm)
        if model.mass_matrix_constant is None:
            F = F + model.callback_value("kinetic_grad", qi, vi, params=prm)
        Mv = model.mass_matrix(qi, prm) @ vi
        for nu in range(s + 1):
            D[nu] += h * b[i] * (ell[nu, i] * F + dell[nu, i] * Mv / h)
    R = [pk + D[0]] + [D[nu] for nu in range(1, s)]
    R = np.concatenate(R)
    C = []
    for j in range(J + 1):
        qd = ellc[:, j] @ Q
        if m and j < J:
            G = model.constraint_jacobian_value(qd, prm)
            for nu in range(s):
                R[nu * n:(nu + 1) * n] -= ellc[nu, j] * G.T @ eta[j]
        if m and j > 0:
            C.append(model.constraint_value(qd, prm))
    return np.concatenate([R] + C) if C else R
