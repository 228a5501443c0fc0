"""A scene's compiled derivatives against central differences (the scene tests share it)."""

import numpy as np

from fastvi.model import SLOTS, call_callback


def fd_jacobian(f, q, eps=1e-6):
    """Central differences of a vector function of ``q``: column ``b`` is ``∂f/∂q_b``."""
    return np.array([(f(q + eps * e) - f(q - eps * e)) / (2 * eps) for e in np.eye(len(q))]).T


def slot_value(model, slot, q, v, shape):
    """The compiled callback ``slot`` of ``model`` at ``(q, v)`` (``v`` is η for
    ``constraint_hessian``), written into a new array of ``shape``."""
    fns, _, _ = model.kernel_arguments()
    out = np.zeros(shape)
    call_callback(fns[SLOTS.index(slot)], np.ascontiguousarray(q, float),
                  np.ascontiguousarray(v, float), np.asarray(model.params, float), out)
    return out


def constraint_derivative_errors(model, q, eta):
    """``(max|G − G_fd|, max|H − H_fd|, H)`` at ``q``: the Jacobian against central
    differences of ``g``, and the compiled ``H = Σ η_a ∇²g_a = ∂(Gᵀη)/∂q`` against central
    differences of ``Gᵀη``."""
    G = model.constraint_jacobian_value(q)
    G_err = np.max(np.abs(G - fd_jacobian(model.constraint_value, q)))
    H = slot_value(model, "constraint_hessian", q, eta, (model.n, model.n))
    H_fd = fd_jacobian(lambda x: model.constraint_jacobian_value(x).T @ eta, q)
    return G_err, np.max(np.abs(H - H_fd)), H
