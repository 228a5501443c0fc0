"""How far the predictor's guess is from the converged step: polynomials of 1, 2, 3 steps, Hermite.

    .venv/bin/python bench/predictor_errors.py

The guess for step k's control points is the polynomial through the control points of the
last 1, 2 or 3 steps (degree s, 2s, 3s) evaluated at step k's nodes; the error is the
max-norm against the control points step k converged to (double pendulum from π/2 at rest,
3000 steps, dense output). Its size sets the Newton iterations a step needs: the mechanics
iteration contracts by a fixed factor per iteration and stops at ``tol`` (docs/benchmarks.md,
"Goals of issue 11"). The last column is the kernel's two-step guess since 2026-11-26
(``fastvi.tables.hermite_predictor``: degree s + 2 through the last step's points, the
nearest earlier one and the slope ``v_k``). Prints the median, the 90th percentile and the
maximum over the steps.
"""

import numpy as np

import fastvi
from fastvi.tables import hermite_predictor, lagrange_basis

CASES = (("P2L-Q3G", 0.01), ("P3L-Q4G", 0.01), ("P2L-Q3G", 0.02), ("P3L-Q4G", 0.025),
         ("P4L-Q4G", 0.025))


def guess_errors(points, tau, history):
    """Max-norm error of the ``history``-step extrapolation at every step it applies to."""
    s = len(tau) - 1
    errors = []
    for k in range(3, points.shape[0]):
        nodes, values = [], []
        for back in range(history, 0, -1):  # step k − back, in step k − 1's local time
            for mu in range(s + 1 if back == 1 else s):  # a step's end is the next one's start
                nodes.append(tau[mu] - (back - 1))
                values.append(points[k - back, mu])
        basis, _ = lagrange_basis(np.array(nodes), 1.0 + tau[1:])
        errors.append(np.abs(basis.T @ np.array(values) - points[k, 1:]).max())
    return np.array(errors)


def hermite_errors(points, tau, v, h):
    """Max-norm error of the Hermite guess (the kernel's two-step one) at every step."""
    s = len(tau) - 1
    EH = hermite_predictor(tau)
    errors = []
    for k in range(3, points.shape[0]):
        inputs = np.vstack([points[k - 2, s - 1], points[k - 1], h * v[k]])
        errors.append(np.abs((EH.T @ inputs)[1:] - points[k, 1:]).max())
    return np.array(errors)


def _stats(e):
    return f"{np.median(e):.1e} (p90 {np.percentile(e, 90):.1e}, max {e.max():.1e})"


def main():
    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    for method, h in CASES:
        res = fastvi.integrate(model, q0, v0, h=h, n_steps=3000, method=method, dense_output=True)
        cols = []
        for history in (1, 2, 3):
            e = guess_errors(res.sol.points, res.sol.tau, history)
            cols.append(f"{history} step{'s' if history > 1 else ' '}: {_stats(e)}")
        cols.append(f"Hermite: {_stats(hermite_errors(res.sol.points, res.sol.tau, res.v, h))}")
        print(f"{method} h = {h:g}:  " + ",  ".join(cols))


if __name__ == "__main__":
    main()
