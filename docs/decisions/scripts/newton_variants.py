"""How many iterations a step needs with other Newton matrices and stopping rules (a twin).

    .venv/bin/python docs/decisions/scripts/newton_variants.py [METHOD H [STEPS]]   (default: the four below)

Replays the double pendulum from θ1 = θ2 = π/2 at rest with the step kernel, and at every
step (from the fourth) restarts the step's equations in NumPy from the kernel's own
predictor, with the kernel's own residual and exact Newton matrix
(``fastvi.kernels.step.assemble``), iterating ``X ← X − K⁻¹ R(X)`` with

* ``mech``: the mechanics matrix at the predictor — the exact matrix with the impulses set
  to zero, i.e. without the constraint Hessian ``Σ η_i ∇²g_i`` (gravity has none of its
  own): what ``newton="auto"`` iterates with, up to its Schur complement's ``G_j``;
* ``broyden``: the same start, improved by Broyden's ("good") rank-one updates;
* ``frozen``: the exact matrix at the predictor, kept for the step (a simplified Newton
  with the constraint Hessian of the predicted impulses);
* ``newton``: the exact matrix at every iterate.

For each: iterations a step with the kernel's stopping rule for the mechanics iteration
(increment ≤ tol = 1e-14, relative to max(1, |q_k|)), and with the full Newton's early exit
(``θ/(1−θ)·|δ| ≤ tol``, θ the ratio of the last two increments) together with the error
that exit leaves (max-norm distance of the control points from the step's converged ones,
relative): an exit that leaves more than round-off lets conserved momenta drift
(``docs/decisions/0001-mechanics-newton.md. The first line is the kernel's own count.
"""

import sys

import numpy as np

import fastvi
from fastvi.kernels import layout as lay
from fastvi.kernels.step import assemble, linear_force, predict, step

CASES = (("P2L-Q3G", 0.01), ("P2L-Q3G", 0.02), ("P3L-Q4G", 0.0125), ("P3L-Q4G", 0.025))
KINDS = ("mech", "broyden", "frozen", "newton")
TOL = 1e-14


def _copy(ws, dims):
    out = lay.make_workspace(*dims)
    for name in ws._fields:
        a = getattr(ws, name)
        if isinstance(a, np.ndarray):
            getattr(out, name)[...] = a
    return out


def _solve_step(residual_jac, X0, sn, qscale, kind):
    """Increments (scaled, of the control points) and iterates of one variant."""
    X = X0.copy()
    if kind in ("mech", "broyden"):
        Xz = X0.copy()
        Xz[sn:] = 0.0
        K0 = residual_jac(Xz)[1]
    else:
        K0 = residual_jac(X0)[1]
    H = np.linalg.inv(K0)  # Broyden's inverse update: H ← H + (d − H y) dᵀH / (dᵀ H y)
    R = residual_jac(X)[0]
    incs, iterates = [], []
    for _ in range(12):
        K = residual_jac(X)[1] if kind == "newton" else None
        d = -np.linalg.solve(K, R) if kind == "newton" else -H @ R
        X = X + d
        incs.append(np.abs(d[:sn]).max() / qscale)
        iterates.append(X.copy())
        if incs[-1] <= TOL:
            break
        Rn = residual_jac(X)[0]
        if kind == "broyden":
            Hy = H @ (Rn - R)
            H = H + np.outer(d - Hy, d @ H) / (d @ Hy)
        R = Rn
    return incs, iterates


def _early_exit(incs):
    for i in range(1, len(incs)):
        th = incs[i] / incs[i - 1]
        if incs[i] <= TOL or (th < 1.0 and th / (1.0 - th) * incs[i] <= TOL):
            return i + 1
    return len(incs)


def study(method, h, n_steps):
    model = fastvi.scenes.double_pendulum()
    meth = fastvi.method(method)
    n, m, s, J = model.n, model.m, meth.s, meth.J
    dims = (n, m, s, meth.r, J)
    sn = s * n
    md, tabs = model.kernel_data(), meth.kernel_tables
    opts = lay.NewtonOptions(TOL, 30, lay.NEWTON_MODES["auto"])
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    state = np.zeros((6, n))
    state[0], state[1], state[2] = q0, model.mass_matrix(q0) @ v0, v0
    ws = lay.make_workspace(*dims)
    out = np.zeros(lay.STEP_OUT_SIZE)
    kernel_iters = []
    rows = {k: [] for k in KINDS}
    for k in range(n_steps):
        qk, pk, vk = state[0].copy(), state[1].copy(), state[2].copy()
        if k:
            guess = _copy(ws, dims)
            predict(tabs, n, m, h, vk, guess, guess.hold[lay.H_HIST])
            X0, G0 = guess.X.copy(), ws.G[0].copy()
        st = step(md, tabs, opts, h, state, ws, k == 0, out)
        if st != 0:
            raise RuntimeError(f"step {k} failed with status {st}")
        for a in range(3):
            state[a] = state[a + 3]
        if k < 3:
            continue
        kernel_iters.append(out[lay.S_ITERS])

        def residual_jac(X, qk=qk, pk=pk, G0=G0):
            w = lay.make_workspace(*dims)
            w.X[:] = X
            w.G[0][:, :] = G0
            linear_force(md, w, qk)  # −∇V of gravity: assemble reads it from the workspace
            if assemble(md, tabs, h, qk, pk, w, True) != 0:
                raise RuntimeError("assembly failed")
            return w.R.copy(), w.A.copy()

        Xs = ws.X.copy()
        for _ in range(3):  # the step's solution, polished with the exact Newton
            R, K = residual_jac(Xs)
            Xs -= np.linalg.solve(K, R)
        qscale = max(1.0, np.abs(qk).max())
        for kind in KINDS:
            incs, iterates = _solve_step(residual_jac, X0, sn, qscale, kind)
            e = _early_exit(incs)
            left = np.abs(iterates[e - 1][:sn] - Xs[:sn]).max() / qscale
            rows[kind].append((len(incs), e, left))
    print(f"{method}, h = {h:g}, {len(kernel_iters)} steps: the kernel {np.mean(kernel_iters):.2f} "
          "iterations a step")
    for kind in KINDS:
        a = np.array(rows[kind])
        print(f"  {kind:8s} increment ≤ tol: {a[:, 0].mean():.2f} it/step   early exit: "
              f"{a[:, 1].mean():.2f} it/step, error left median {np.median(a[:, 2]):.1e} "
              f"max {a[:, 2].max():.1e}")


def main(argv):
    if argv:
        cases = [(argv[0], float(argv[1]))]
        n_steps = int(argv[2]) if len(argv) > 2 else 300
    else:
        cases, n_steps = CASES, 300
    for method, h in cases:
        study(method, h, n_steps)


if __name__ == "__main__":
    main(sys.argv[1:])
