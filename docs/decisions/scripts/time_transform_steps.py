"""How many steps a time-transformed (Sundman) variational step saves at equal energy error.

    .venv/bin/python docs/decisions/scripts/time_transform_steps.py [--starts=8] [--T=1000] [--quick]
    PYTHONPATH=TREE .venv/bin/python docs/decisions/scripts/time_transform_steps.py cost KIND METHOD H

The speed study's gap to DOP853 at max|ΔH| = 1e-2 J is the number of steps (fastvi's fixed
step against an adaptive one; docs/benchmarks.md). This measures what an adaptive step that
stays variational would buy, *before* any kernel is built: the Poincaré time transformation
written as a model, integrated by the existing kernels (the configuration-dependent mass
path) with a fixed step Δτ in a fictive time τ, dt/dτ = σ(q). With the energy E0 fixed by
the start, the extended Hamiltonian K = σ(q) (H(q, p) − E0) (K = 0 on the solution) has the
Lagrangian

    L̃(q, q') = q'ᵀ M q' / (2 σ(q)) − σ(q) (V(q) − E0),       q' = dq/dτ = σ v,

a configuration-dependent mass M/σ(q) and potential σ (V − E0), with the same holonomic
constraints; its conjugate momentum M q'/σ is the physical one. A symplectic step of L̃
keeps K near 0, so |H − E0| stays bounded, as for the fixed step. On the energy shell the
kinetic energy is KE(q) = E0 − V(q), so the step can follow the speed through q alone:

    σ(q) = (1 + KE(q)/K_r)^(−1/2)       (σ ≈ 1 where the pendulum is slow,
                                          ≈ sqrt(K_r/KE) ∝ 1/|v| where it whips).

Physical time is t(τ) = ∫ σ(q(τ)) dτ (trapezoid over the steps, enough to count steps up to
T). For each method the script sweeps h (fixed step) and (K_r, Δτ) (transformed), counts
the steps to reach t = T, reads max|ΔH| over every step (the median over ``--starts``
starts 1e-12 rad apart, `studies.wpd.peer_runs.peer_starts`: the motion is chaotic), and
prints the steps each needs at the study's levels (log–log along each front) and their
ratio. Then the cost a step of each (generic kernels, no saving): the model-level
transform runs through the general mass path, so the ratio says how cheap a dedicated
kernel path (a scalar factor on a constant mass) would have to be to pay
(docs/decisions/0002-adaptive-step.md).

``cost`` measures that dedicated path: ``docs/decisions/scripts/time_transform_kernel.patch`` is a prototype
of it (double pendulum only: linear potential, diagonal constant mass; the mass part of the
residual by quadrature with the factor 1/σ(q_i), the mechanics matrix with M̄ = M/σ(q_k),
the end velocity scaled by σ(q_{k+1}); no full-Newton fallback, no time output). Apply it to
a worktree (``git worktree add --detach /tmp/wt-tt 5fa7114 && git -C /tmp/wt-tt apply
$PWD/docs/decisions/scripts/time_transform_kernel.patch``) and run ``cost prototype METHOD Δτ`` with
``PYTHONPATH=/tmp/wt-tt``, and ``cost plain METHOD h`` with this tree: µs a step (process
CPU, best of 7 runs of 40 000 steps, ``specialize=True``) and Newton iterations a step. The
prototype integrates the model-level transform's discrete Lagrangian (the same quadrature):
``cost prototype`` first prints its steps and max|ΔH| over 20 s, which ``run_transformed``
in an unpatched tree reproduces.
"""

import importlib
import sys
import time

import numba
import numpy as np

import fastvi
from studies.wpd.peer_runs import peer_starts

#: the scene's module (its name is shadowed by the function in fastvi.scenes): its callbacks
_dp = importlib.import_module("fastvi.scenes.double_pendulum")
G_ACC = 9.81
LEVELS = (1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6)
# params = (m1, m2, l1, l2, g, E0, K_r): the double pendulum's, then the shell and the scale


@numba.njit
def _ke(q, p):
    return p[5] - p[4] * (p[0] * q[1] + p[1] * q[3])


def mass(q, p, out):
    f = np.sqrt(1.0 + _ke(q, p) / p[6])  # 1/σ
    out[:, :] = 0.0
    out[0, 0] = p[0] * f
    out[1, 1] = p[0] * f
    out[2, 2] = p[1] * f
    out[3, 3] = p[1] * f


def kinetic_grad(q, v, p, out):
    # ½ q'ᵀ M q' ∂(1/σ)/∂q with ∂(1/σ)/∂q = σ/2 · ∂(KE/K_r)/∂q = −σ ∇V / (2 K_r)
    f = np.sqrt(1.0 + _ke(q, p) / p[6])
    t = 0.5 * (p[0] * (v[0] * v[0] + v[1] * v[1]) + p[1] * (v[2] * v[2] + v[3] * v[3]))
    c = -t * p[4] / (2.0 * f * p[6])
    out[0] = 0.0
    out[1] = c * p[0]
    out[2] = 0.0
    out[3] = c * p[1]


def potential(q, p):
    ke = _ke(q, p)
    return -ke / np.sqrt(1.0 + ke / p[6])  # σ (V − E0) = −σ KE


def potential_grad(q, p, out):
    # d(−KE (1 + x)^(−1/2))/dKE with x = KE/K_r, and dKE/dq = −∇V
    x = _ke(q, p) / p[6]
    d = -(1.0 + x) ** -0.5 + 0.5 * x * (1.0 + x) ** -1.5
    out[0] = 0.0
    out[1] = -d * p[4] * p[0]
    out[2] = 0.0
    out[3] = -d * p[4] * p[1]


def sigma(q, p):
    """dt/dτ at the configurations ``q`` (..., 4)."""
    return 1.0 / np.sqrt(1.0 + _ke.py_func(np.moveaxis(q, -1, 0), p) / p[6])


def transformed(E0: float, Kr: float) -> fastvi.Model:
    """The double pendulum (unit masses and rods) in fictive time, as a fastvi Model."""
    return fastvi.Model(4, 2, params=(1.0, 1.0, 1.0, 1.0, G_ACC, E0, Kr), mass=mass,
                        kinetic_grad=kinetic_grad, potential=potential,
                        potential_grad=potential_grad, constraint=_dp._g,
                        constraint_jacobian=_dp._G, constraint_hessian=_dp._ddg,
                        name="double_pendulum-sundman")


def prototype_model(E0: float, Kr: float) -> fastvi.Model:
    """The plain double pendulum with (E0, K_r) appended to its parameters: what the
    prototype kernel of ``docs/decisions/scripts/time_transform_kernel.patch`` transforms by itself."""
    return fastvi.Model(4, 2, params=(1.0, 1.0, 1.0, 1.0, G_ACC, E0, Kr), mass=np.eye(4),
                        potential=_dp.potential, potential_grad=_dp.potential_grad, potential_hessian=0,
                        constraint=_dp._g, constraint_jacobian=_dp._G,
                        constraint_hessian=_dp._ddg, name="double_pendulum-prototype")


def cost(kind, method, h, Kr=3.0, steps=40000, repeats=7):
    """µs a step and iterations a step of ``kind`` ("plain": the double pendulum at step h;
    "prototype": the patched kernel on :func:`prototype_model` at Δτ = h)."""
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(np.pi / 2, np.pi / 2)
    md = dp
    if kind == "prototype":
        E0 = float(dp.energy(q0, v0))
        md = prototype_model(E0, Kr)
        res = fastvi.integrate(md, q0, v0, h=h, n_steps=2000, method=method,
                               specialize=True)
        # the same numbers as run_transformed(method, Kr, h, THETA, 20.0) in an unpatched tree
        k, dH = _to_physical_time(res, np.array(md.params), h, 20.0)
        print(f"prototype over 20 s: {k} steps, max|ΔH| {dH:.6e}")
    us, stats = step_cost(md, q0, v0, method, h, steps, repeats, specialize=True)
    print(f"{kind} {method} {'Δτ' if kind == 'prototype' else 'h'} = {h:g}: "
          f"{us:.3f} µs a step, {stats['newton_iterations'] / steps:.2f} Newton iterations "
          f"a step, full-Newton steps {stats.get('full_newton_steps', 0)}")


def run_fixed(method, h, theta, T):
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(*theta)
    res = fastvi.integrate(dp, q0, v0, h=h, t_end=T, method=method, on_failure="return")
    dH = np.max(np.abs(res.energy - res.energy[0])) if res.success else np.inf
    return len(res.t) - 1, float(dH)


def run_transformed(method, Kr, dtau, theta, T):
    """(steps to reach t = T, max|H − E0| over them) of the fictive-time integration."""
    dp = fastvi.scenes.double_pendulum()
    q0, v0 = dp.initial_state(*theta)
    E0 = float(dp.energy(q0, v0))
    md = transformed(E0, Kr)
    p = np.array(md.params)
    s0 = sigma(q0, p)
    # σ ≥ (1 + KE_max/K_r)^(−1/2) with KE_max ≤ 3 g for these rods (the bobs 1 m and 2 m
    # below the pivot at most): enough fictive steps to reach t = T
    n = int(np.ceil(T / (dtau / np.sqrt(1.0 + (E0 + 3.0 * G_ACC) / Kr))))
    res = fastvi.integrate(md, q0, v0 * s0, h=dtau, n_steps=n, method=method,
                           on_failure="return")
    k, dH = _to_physical_time(res, p, dtau, T)
    if k < len(res.q):  # the energy formula against the scene's own, once
        vp = res.v[k] / sigma(res.q[k], p)
        H = 0.5 * np.sum(res.p[k] ** 2) + G_ACC * (res.q[k, 1] + res.q[k, 3])
        assert abs(H - dp.energy(res.q[k], vp)) <= 1e-12 * (1.0 + abs(H))
    return k, dH


def _to_physical_time(res, p, dtau, T):
    """(steps of a fictive-time run to reach t = T, max|H − E0| over them; inf if it stops
    short). t = ∫σ dτ by the trapezoid; H from the momenta, the physical ones (M q'/σ) for
    the model-level transform and the prototype alike, with unit masses:
    H = ½ |p|² + g (y1 + y2)."""
    sg = sigma(res.q, p)
    t = np.concatenate([[0.0], np.cumsum(0.5 * (sg[1:] + sg[:-1]) * dtau)])
    k = int(np.searchsorted(t, T))
    if k >= len(t):
        return k, np.inf
    H = 0.5 * np.sum(res.p[: k + 1] ** 2, axis=1) + G_ACC * (res.q[: k + 1, 1]
                                                             + res.q[: k + 1, 3])
    return k, float(np.max(np.abs(H - p[5])))


def median_over_starts(run, starts):
    out = [run(th) for th in starts]
    return out[0][0], float(np.median([o[1] for o in out]))


def steps_at(front, E):
    """Steps at max|ΔH| = E, log–log between the two runs around E (NaN outside)."""
    pts = sorted((dH, k) for k, dH in front if np.isfinite(dH))
    for (e0, k0), (e1, k1) in zip(pts, pts[1:]):
        if e0 <= E <= e1 and k0 >= k1:
            w = np.log(E / e0) / np.log(e1 / e0)
            return float(np.exp((1 - w) * np.log(k0) + w * np.log(k1)))
    return np.nan


def step_cost(model, q0, v0, method, h, steps=20000, repeats=5, specialize=False):
    """(process CPU µs a step, the last run's stats): nothing saved but the ends, best of
    ``repeats`` runs of ``steps`` steps."""
    fastvi.integrate(model, q0, v0, h=h, n_steps=10, method=method, specialize=specialize)
    best = np.inf
    for _ in range(repeats):
        c0 = time.process_time()
        res = fastvi.integrate(model, q0, v0, h=h, n_steps=steps, method=method,
                               save_every=steps, specialize=specialize)
        best = min(best, time.process_time() - c0)
    return best / steps * 1e6, res.stats


CASES = {
    "P2L-Q3G": dict(fixed=(0.01, 0.0125, 0.0166666666666666667, 0.02, 0.025, 0.03125),
                    transformed={3.0: (0.04, 0.05, 0.0625, 0.08, 0.1),
                                 10.0: (0.03, 0.04, 0.05, 0.0625)}),
    "P3L-Q4G": dict(fixed=(0.0125, 0.0166666666666666667, 0.02, 0.025, 0.03125, 0.04),
                    transformed={3.0: (0.04, 0.05, 0.0625, 0.08, 0.1),
                                 10.0: (0.03, 0.04, 0.05, 0.0625)}),
    "P4L-Q4G": dict(fixed=(0.0125, 0.0166666666666666667, 0.02, 0.025),
                    transformed={3.0: (0.04, 0.05, 0.0625, 0.08),
                                 10.0: (0.025, 0.03, 0.04, 0.05)}),
}
QUICK = {"P2L-Q3G": dict(fixed=(0.02, 0.025), transformed={10.0: (0.04, 0.05)})}


def main(argv):
    if argv[:1] == ["cost"]:
        cost(argv[1], argv[2], float(argv[3]))
        return
    opts = dict(a.lstrip("-").split("=") if "=" in a else (a.lstrip("-"), "1") for a in argv)
    T = float(opts.get("T", 1000.0))
    starts = peer_starts(int(opts.get("starts", 8)))
    cases = QUICK if "quick" in opts else CASES
    print(f"double pendulum from π/2, π/2 at rest, T = {T:g} s, max|ΔH| over every step, "
          f"median over {len(starts)} starts")
    for method, cfg in cases.items():
        fronts = {"fixed": []}
        for h in cfg["fixed"]:
            k, dH = median_over_starts(lambda th: run_fixed(method, h, th, T), starts)
            fronts["fixed"].append((k, dH))
            print(f"{method} fixed h = {h:.5g}: {k} steps, max|ΔH| {dH:.3e}", flush=True)
        for Kr, dtaus in cfg["transformed"].items():
            key = f"K_r = {Kr:g}"
            fronts[key] = []
            for dtau in dtaus:
                k, dH = median_over_starts(lambda th: run_transformed(method, Kr, dtau, th, T),
                                           starts)
                fronts[key].append((k, dH))
                print(f"{method} {key} Δτ = {dtau:g}: {k} steps, max|ΔH| {dH:.3e}", flush=True)
        print(f"\n{method}: steps to reach max|ΔH| over T = {T:g} s (— outside a front)")
        print("| max\\|ΔH\\| (J) | fixed h | " + " | ".join(k for k in fronts if k != "fixed")
              + " | fixed / best transformed |")
        print("|---" * (len(fronts) + 2) + "|")
        for E in LEVELS:
            kf = steps_at(fronts["fixed"], E)
            kt = [steps_at(fr, E) for key, fr in fronts.items() if key != "fixed"]
            best = np.nanmin(kt) if np.any(np.isfinite(kt)) else np.nan
            cells = " | ".join("—" if not np.isfinite(x) else f"{x:.0f}" for x in [kf] + kt)
            ratio = f"{kf / best:.2f}" if np.isfinite(kf / best) else "—"
            print(f"| {E:.0e} | {cells} | {ratio} |")
        dp = fastvi.scenes.double_pendulum()
        q0, v0 = dp.initial_state(np.pi / 2, np.pi / 2)
        E0 = float(dp.energy(q0, v0))
        md = transformed(E0, 10.0)
        cf = step_cost(dp, q0, v0, method, 0.02)[0]
        ct = step_cost(md, q0, v0 * sigma(q0, np.array(md.params)), method, 0.04)[0]
        print(f"{method}: a step costs {cf:.2f} µs fixed, {ct:.2f} µs transformed through the "
              f"mass path (generic kernels): {ct / cf:.2f}×\n", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
