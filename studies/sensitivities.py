r"""``python -m fastvi sensitivities``: the cost, order and structure of the derivatives of
the discrete flow, and a parameter fit → the tables of ``docs/sensitivities.md``.

Measurements on the double pendulum (Cartesian, n = 4, m = 2), and on chains of links:

* **cost**: the compiled loop's time of :func:`fastvi.sensitivity` for 1, 2n and 2n + k
  directions and of :func:`fastvi.adjoint`, against a plain :func:`fastvi.integrate` and
  against the 2n + k (forward) or 2(2n + k) (central) runs of finite differences, on the
  damped pendulum (k = 6 parameters), ``--repeat`` rounds that call each computation in
  turn, in one process (medians, and ratios as the median of each round's ratio);
* **order**: the error of ``∂(q, v)(1)/∂(θ0, ω0)`` from θ1 = θ2 = π/2 at rest against
  five-point differences of SciPy DOP853 runs in angles (rtol = atol = 1e-13), and its
  log–log slope;
* **symplecticity**: ``max |Yᵀ J Y − Zᵀ J Z|`` for a basis ``Z`` of the tangent space at
  the start and its image ``Y`` after ``--steps`` steps, over ``|Y|²``;
* **adjoint memory**: the peak memory and time of the adjoint of the damped pendulum under
  ``⌈√N⌉`` checkpoints and with every step kept, and of a damped chain of 256 links under
  the default schedule for two memory budgets (``segments_table``);
* **by the number of parameters**: the adjoint by the initial state, and by it and every
  parameter, of damped chains of 2 to 128 links against a plain run (``parameters_table``);
* **fit**: the damping and the outer rod length of the damped pendulum fitted to its two
  angles with noise (σ = 0.01 rad, 101 samples over 5 s) by ``scipy.optimize.least_squares``
  with the exact Jacobian and with SciPy's finite differences, and by BFGS with the
  adjoint gradient.

Writes ``./fastvi-study-sensitivities/sensitivities.md`` (``--out`` elsewhere).
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

from fastvi.studies.cli import default_out, study_parser
from fastvi.studies.convergence import observed_order
from fastvi.studies.reference import chain_cartesian, chain_pendulum_reference

FD_POINTS = ((2.0, -1.0), (1.0, 8.0), (-1.0, -8.0), (-2.0, 1.0))


def _in_turn(fns, repeat: int) -> np.ndarray:
    """The times of ``fns`` over ``repeat`` rounds, ``(repeat, len(fns))``: each round calls
    every function once, the order turned by one each round, after one untimed call of each
    (which may compile). On a shared machine whose speed drifts over seconds, the times of
    one round are comparable where those of separate blocks of calls are not: a ratio is
    the median of the rounds' ratios."""
    for fn in fns:
        fn()
    times = np.empty((repeat, len(fns)))
    for r in range(repeat):
        for j in np.roll(np.arange(len(fns)), r):
            times[r, j] = fns[j]()
    return times


def _ratio(times: np.ndarray, j: int, base: int = 0) -> float:
    """The median over the rounds of column ``j`` over column ``base``."""
    return float(np.median(times[:, j] / times[:, base]))


def cost_table(steps: int, repeat: int, h: float = 0.01, method: str = "P2L-Q3G") -> str:
    import fastvi

    dp = fastvi.scenes.double_pendulum(damping=0.3)
    q0, v0 = dp.initial_state(1.0, 0.5)
    n, k = dp.n, dp.params.size
    run = dict(h=h, n_steps=steps, method=method, save_every=steps)

    def plain(specialize=None):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return fastvi.integrate(dp, q0, v0, specialize=specialize,
                                    **run).stats["integration_time"]

    def sens(wrt, specialize=None):
        return lambda: fastvi.sensitivity(dp, q0, v0, wrt=wrt, specialize=specialize,
                                          **run).result.stats["integration_time"]

    def adj(param_index=None, specialize=None):
        def timed():
            A = fastvi.adjoint(dp, q0, v0, lambda r: (np.ones((len(r.t), n)), None),
                               param_index=param_index, specialize=specialize, **run)
            return A.result.stats["integration_time"] + A.stats["backward_time"]
        return timed

    one = np.zeros((2 * n + k, 1))
    one[0, 0] = 1.0
    timed = [("integrate (no derivatives)", plain, 1),
             ("integrate, generic stages (`specialize=False`)", lambda: plain(False), 1),
             ("sensitivity, 1 direction (q0[0])", sens(one), 1),
             (f"sensitivity, 2n = {2 * n} directions (q0, v0)", sens(("q0", "v0")), 2 * n),
             (f"sensitivity, 2n + k = {2 * n + k} directions (q0, v0, params)",
              sens(("q0", "v0", "params")), 2 * n + k),
             ("adjoint: gradient by q0 and v0", adj([]), 2 * n),
             (f"adjoint: gradient by q0, v0 and the k = {k} params", adj(), 2 * n + k),
             ("sensitivity, 1 direction, generic kernels (`specialize=False`)",
              sens(one, False), 1),
             (f"adjoint by q0, v0 and the {k} params, generic kernels (`specialize=False`)",
              adj(None, False), 2 * n + k)]
    times = _in_turn([fn for _, fn, _ in timed], repeat)
    t_plain = float(np.median(times[:, 0]))
    rows = [(name, float(np.median(times[:, j])), d, _ratio(times, j))
            for j, (name, _, d) in enumerate(timed)]
    for runs, d in ((2 * n + k + 1, "forward"), (2 * (2 * n + k), "central")):
        rows.append((f"finite differences, {d}: {runs} runs", runs * t_plain, 2 * n + k, runs))
    out = [f"Damped double pendulum (c = 0.3), `{method}`, h = {h}, {steps} steps, the "
           f"compiled loop's time, median of {repeat} rounds run in turn (a ratio is the "
           "median of the rounds' ratios).", "",
           "| computation | directions | time (s) | × integrate |", "|---|---|---|---|"]
    for name, t, d, ratio in rows:
        out.append(f"| {name} | {d} | {t:.3f} | {ratio:.1f} |")
    return "\n".join(out)


def reference_jacobian(a0, T: float, lengths) -> np.ndarray:
    """``∂(q, v)(T)/∂(θ0, ω0)`` (2n, n) of a planar chain of unit masses started at the
    angles and angular velocities ``a0``: five-point differences (step 1e-3) of SciPy DOP853
    runs in angles (rtol = atol = 1e-13), in Cartesian coordinates."""
    N = len(lengths)

    def end(a):
        th, om = chain_pendulum_reference(a[:N], a[N:], [T], [1.0] * N, lengths, tol=1e-13)
        q, v = chain_cartesian(th, om, lengths)
        return np.concatenate([q[0], v[0]])

    d = 1e-3
    ref = np.zeros((4 * N, 2 * N))
    for j in range(2 * N):
        for sgn, w in FD_POINTS:
            e = np.zeros(2 * N)
            e[j] = sgn * d
            ref[:, j] += w * end(np.asarray(a0, float) + e)
    return ref / (12 * d)


def angle_directions(a0, lengths, k: int) -> np.ndarray:
    """``∂(q0, v0)/∂(θ0, ω0)`` of a planar chain by complex steps (exact), as the raw
    directions ``(δq0, δv0, δθ)`` (4N + k, 2N) of :func:`fastvi.sensitivity`'s ``wrt``."""
    N = len(lengths)
    D = np.zeros((4 * N + k, 2 * N))
    for j in range(2 * N):
        a = np.asarray(a0, complex).copy()
        a[j] += 1e-30j
        q, v = chain_cartesian(a[None, :N], a[None, N:], lengths)
        D[:4 * N, j] = np.concatenate([q[0], v[0]]).imag / 1e-30
    return D


def order_table() -> str:
    import fastvi

    dp = fastvi.scenes.double_pendulum()
    a0, T, L = np.array([np.pi / 2, np.pi / 2, 0.0, 0.0]), 1.0, [1.0, 1.0]
    ref = reference_jacobian(a0, T, L)
    D = angle_directions(a0, L, dp.params.size)
    q0, v0 = dp.initial_state(np.pi / 2, np.pi / 2)
    out = ["| method | h | max error of ∂(q, v)(1)/∂(θ0, ω0) | observed order |", "|---|---|---|---|"]
    for name, hs in [("P1L-Q2G", [0.05, 0.025, 0.0125, 0.00625]),
                     ("P2L-Q3G", [0.1, 0.05, 0.025, 0.0125]),
                     ("P3L-Q4G", [0.1, 0.05, 0.025, 0.0125])]:
        errs = []
        for h in hs:
            S = fastvi.sensitivity(dp, q0, v0, h=h, t_end=T, wrt=D, method=name,
                                   save_every=10**6)
            errs.append(float(np.abs(np.vstack([S.dq[-1], S.dv[-1]]) - ref).max()))
        slope, _ = observed_order(hs, errs)
        out.append(f"| `{name}` | {hs[0]:g} … {hs[-1]:g} | {errs[0]:.1e} … {errs[-1]:.1e} | "
                   f"{slope:.2f} |")
    return "\n".join(out)


def symplectic_table(steps: int) -> str:
    import fastvi

    dp = fastvi.scenes.double_pendulum()
    J = np.block([[np.zeros((4, 4)), np.eye(4)], [-np.eye(4), np.zeros((4, 4))]])
    out = ["| start (θ1, θ2) | method | steps | max\\|Y\\| | max\\|YᵀJY − ZᵀJZ\\| / max\\|Y\\|² |",
           "|---|---|---|---|---|"]
    for ang in [(0.3, 0.2), (1.0, 0.5)]:
        q0, v0 = dp.initial_state(*ang)
        Z = fastvi.tangent_space(dp, q0, v0)
        D = np.vstack([Z[:4], np.linalg.solve(dp.mass_matrix(q0), Z[4:]), np.zeros((5, 4))])
        for name in ["P1L-Q2G", "P2L-Q3G", "P3L-Q4G"]:
            S = fastvi.sensitivity(dp, q0, v0, h=0.01, n_steps=steps, wrt=D, method=name,
                                   save_every=steps)
            Y = np.vstack([S.dq[-1], S.dp[-1]])
            size = np.abs(Y).max()
            err = np.abs(Y.T @ J @ Y - Z.T @ J @ Z).max() / size ** 2
            out.append(f"| ({ang[0]}, {ang[1]}) | `{name}` | {steps} | {size:.1e} | {err:.1e} |")
    return "\n".join(out)


def _angles(t, q, v):
    from fastvi.scenes.double_pendulum import angles

    return np.stack(angles(q), axis=-1)


def _start(prm):
    from fastvi.scenes.double_pendulum import state_from_angles

    return state_from_angles(1.0, 0.5, 0.0, 0.0, prm[2], prm[3])


def fit_table() -> str:
    from scipy.optimize import least_squares, minimize

    import fastvi

    dp = fastvi.scenes.double_pendulum(damping=0.3)
    true = dp.params.copy()
    true[3] = 0.8
    h, N, every = 0.01, 500, 5
    r = fastvi.integrate(dp, *_start(true), h=h, n_steps=N, save_every=every, params=true)
    data = _angles(r.t, r.q, r.v) + 0.01 * np.random.default_rng(0).normal(size=(len(r.t), 2))
    x0 = np.array([0.1, 1.0])
    out = ["Fit of (c, l2) = (0.3, 0.8) from (0.1, 1.0): 101 noisy samples of both angles.", "",
           "| solver | Jacobian or gradient | (c, l2) found | cost | iterations | runs | time (s) |",
           "|---|---|---|---|---|---|---|"]
    for label, jac in [("exact (fastvi.sensitivity)", "exact"), ("SciPy 2-point", "2-point"),
                       ("SciPy 3-point", "3-point")]:
        fit = fastvi.TrajectoryFit(dp, data, _angles, param_index=[5, 3], initial_state=_start,
                                   h=h, n_steps=N, save_every=every)
        t = time.perf_counter()
        sol = least_squares(fit.residuals, x0, jac=fit.jacobian if jac == "exact" else jac)
        t = time.perf_counter() - t
        runs = f"{fit.nfev} + {fit.njev} sensitivity" if fit.njev else f"{fit.nfev}"
        out.append(f"| least_squares | {label} | ({sol.x[0]:.4f}, {sol.x[1]:.4f}) | {sol.cost:.6e} | "
                   f"{sol.njev} | {runs} | {t:.2f} |")
    fit = fastvi.TrajectoryFit(dp, data, _angles, param_index=[5, 3], initial_state=_start, h=h,
                               n_steps=N, save_every=every)
    t = time.perf_counter()
    sol = minimize(fit.cost, x0, jac=True, method="BFGS")
    t = time.perf_counter() - t
    out.append(f"| minimize (BFGS) | adjoint (fastvi.adjoint) | ({sol.x[0]:.4f}, {sol.x[1]:.4f}) | "
               f"{sol.fun:.6e} | {sol.nit} | {sol.nfev} adjoint | {t:.2f} |")
    return "\n".join(out)


def _adjoint_runs(model, q0, v0, h, method):
    """``took(N, **schedule)``: the compiled loops' time of one gradient by q0 and v0 of
    ``model`` from ``(q0, v0)`` over ``N`` steps (one sample saved at each end, keywords
    of :func:`fastvi.adjoint` choosing the schedule); ``peak(N, **schedule)``: that
    gradient and the peak of ``tracemalloc`` while it ran; ``plain(N)``: the time of the
    same plain run."""
    import tracemalloc

    import fastvi

    def gradient(N, **schedule):
        return fastvi.adjoint(model, q0, v0, lambda r: (np.ones((len(r.t), model.n)), None),
                              h=h, n_steps=N, save_every=N, method=method, param_index=[],
                              **schedule)

    def took(N, **schedule):
        A = gradient(N, **schedule)
        return A.result.stats["integration_time"] + A.stats["backward_time"]

    def peak(N, **schedule):
        tracemalloc.start()
        try:
            return gradient(N, **schedule), tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    def plain(N):
        return fastvi.integrate(model, q0, v0, h=h, n_steps=N, save_every=N,
                                method=method).stats["integration_time"]

    return took, peak, plain


def memory_table(sizes=(1_000, 10_000, 100_000), h: float = 0.01,
                 method: str = "P2L-Q3G") -> str:
    """Peak memory (``tracemalloc``: the NumPy arrays, checkpoints and records included) and
    time of :func:`fastvi.adjoint` with ``⌈√N⌉`` checkpoints and with every step kept
    (``checkpoint_every = N``, the default within ``fastvi.adjoint.KEEP_ALL_BYTES``), one
    sample saved at each end; times relative to :func:`fastvi.integrate` (sized stages)."""
    import math

    import fastvi

    dp = fastvi.scenes.double_pendulum(damping=0.3)
    q0, v0 = dp.initial_state(1.0, 0.5)
    fastvi.integrate(dp, q0, v0, h=h, n_steps=10, method=method, specialize=True)
    took, peak, plain = _adjoint_runs(dp, q0, v0, h, method)

    out = [f"Damped double pendulum, `{method}`, h = {h}: peak memory of one adjoint gradient "
           "by q0 and v0 (`tracemalloc`), and its time over a plain run's (the compiled "
           "loops, median of 3 rounds run in turn).", "",
           "| steps N | checkpoints × segment | peak (KiB) | × integrate | every step kept (KiB) "
           "| × integrate |", "|---|---|---|---|---|---|"]
    for N in sizes:
        C = math.isqrt(N - 1) + 1
        times = _in_turn([lambda: plain(N), lambda: took(N, checkpoint_every=C),
                          lambda: took(N, checkpoint_every=N)], 3)
        A, size = peak(N, checkpoint_every=C)
        nck, seg = A.stats["checkpoints"], A.stats["segment"]
        out.append(f"| {N} | {nck} × {seg} | {size / 1024:.0f} | {_ratio(times, 1):.1f} | "
                   f"{peak(N, checkpoint_every=N)[1] / 1024:.0f} | {_ratio(times, 2):.1f} |")
    return "\n".join(out)


def ensemble_table(members: int = 16, steps: int = 2_000, h: float = 0.01,
                   method: str = "P2L-Q3G") -> str:
    """:func:`fastvi.sensitivity_ensemble` against one :func:`fastvi.sensitivity` per member,
    2n directions each: wall time, and whether the members agree bit for bit."""
    import fastvi

    dp = fastvi.scenes.double_pendulum(damping=0.3)
    starts = [dp.initial_state(a, 0.5) for a in np.linspace(0.2, 2.0, members)]
    Q0 = np.array([q for q, _ in starts])
    V0 = np.array([v for _, v in starts])
    run = dict(h=h, n_steps=steps, method=method, save_every=steps)
    times = _in_turn([
        lambda: fastvi.sensitivity_ensemble(dp, Q0, V0, **run).stats["integration_time"],
        lambda: sum(fastvi.sensitivity(dp, Q0[i], V0[i], **run).result.stats["integration_time"]
                    for i in range(members))], 3)
    ens = fastvi.sensitivity_ensemble(dp, Q0, V0, **run)
    one = [fastvi.sensitivity(dp, Q0[i], V0[i], **run) for i in range(members)]
    same = all(np.array_equal(o.dq, ens.dq[i]) for i, o in enumerate(one))
    t_ens, serial = np.median(times, axis=0)
    return (f"{members} members of the damped double pendulum, `{method}`, h = {h}, {steps} "
            f"steps, 2n = {2 * dp.n} directions each, {ens.stats['threads']} threads; the "
            "compiled loops' time, median of 3 rounds run in turn:\n\n"
            "| computation | time (s) |\n|---|---|\n"
            f"| `sensitivity_ensemble` (one parallel loop) | {t_ens:.3f} |\n"
            f"| `sensitivity`, member by member | {serial:.3f} |\n\n"
            f"Speed-up {_ratio(times, 1, 0):.2f}; members equal bit for bit: {same}.")


def segments_table(links: int = 256, sizes=(1_000, 4_000, 8_000, 16_000),
                   budgets=(64 * 2**20, None), h: float = 0.01, method: str = "P2L-Q3G",
                   repeat: int = 3) -> str:
    """The adjoint's default schedule on a model that records much a step: the gradient by
    q0 and v0 of a damped chain of ``links`` links, for each memory budget (``None``: the
    default, ``fastvi.adjoint.KEEP_ALL_BYTES``), its segment, the steps retaken, the peak
    memory (``tracemalloc``) and the time over a plain run's (the compiled loops,
    ``repeat`` rounds in turn)."""
    import fastvi

    default = sys.modules["fastvi.adjoint"].KEEP_ALL_BYTES  # the module, not the function
    ch = fastvi.scenes.chain(links, damping=0.3)
    took, peak, plain = _adjoint_runs(ch, *chain_start(links), h, method)
    out = [f"Damped chain of {links} links (n = {ch.n}, m = {ch.m}), `{method}`, h = {h}: "
           "one adjoint gradient by q0 and v0 under the default schedule for each memory "
           f"budget; peak memory by `tracemalloc`, time over a plain run's (median of {repeat} "
           "rounds run in turn).",
           "", "| steps N | budget (MiB) | segment × checkpoints | steps retaken | peak (MiB) "
           "| × integrate |", "|---|---|---|---|---|---|"]
    for N in sizes:
        times = _in_turn([lambda: plain(N)] + [lambda b=b: took(N, max_memory=b)
                                               for b in budgets], repeat)
        for j, budget in enumerate(budgets, start=1):
            A, size = peak(N, max_memory=budget)
            C, nck = A.stats["segment"], A.stats["checkpoints"]
            mib = (default if budget is None else budget) / 2**20
            out.append(f"| {N} | {mib:.0f} | {C} × {nck} | {N - C} | {size / 2**20:.0f} | "
                       f"{_ratio(times, j):.2f} |")
    return "\n".join(out)


def chain_start(links: int, angle: float = 0.3):
    """A planar chain of ``links`` unit links hanging at ``angle`` from the vertical, at
    rest: ``(q0, v0)`` in Cartesian coordinates."""
    a = np.full(links, angle)
    q0 = np.zeros(2 * links)
    q0[0::2], q0[1::2] = np.cumsum(np.sin(a)), -np.cumsum(np.cos(a))
    return q0, np.zeros(2 * links)


def scaling_table(links=(8, 16, 32, 64, 128), steps: int = 200, h: float = 0.01,
                  method: str = "P2L-Q3G", repeat: int = 3) -> str:
    """One forward direction and one adjoint gradient (by q0 and v0) of planar chains of
    growing length, against a plain run: the compiled loops' time, ``repeat`` rounds in turn."""
    import fastvi

    out = [f"Planar chains of N links (n = 2N, m = N), `{method}`, h = {h}, {steps} steps: "
           f"the compiled loops' time, median of {repeat} rounds run in turn.", "",
           "| links N | Newton matrix | plain step (µs) | sensitivity, 1 direction | "
           "adjoint by q0, v0 |", "|---|---|---|---|---|"]
    for N in links:
        ch = fastvi.scenes.chain(N)
        q0, v0 = chain_start(N)
        run = dict(h=h, n_steps=steps, save_every=steps, method=method)
        D = np.zeros((4 * N + ch.params.size, 1))
        D[2 * N, 0] = 1.0

        def plain():
            return fastvi.integrate(ch, q0, v0, **run).stats["integration_time"]

        def sens():
            return fastvi.sensitivity(ch, q0, v0, wrt=D, **run).result.stats["integration_time"]

        def adj():
            A = fastvi.adjoint(ch, q0, v0, lambda r: (np.ones((len(r.t), 2 * N)), None),
                               param_index=[], **run)
            return A.result.stats["integration_time"] + A.stats["backward_time"]

        times = _in_turn([plain, sens, adj], repeat)
        solver = fastvi.structure.plan(ch, fastvi.tables.method(method)).solvers["newton"]
        out.append(f"| {N} | {solver} | {np.median(times[:, 0]) / steps * 1e6:.1f} | "
                   f"{_ratio(times, 1):.1f} | {_ratio(times, 2):.1f} |")
    return "\n".join(out)


def parameters_table(links=(2, 4, 8, 16, 32, 64, 128), steps: int = 2_000, h: float = 0.01,
                     method: str = "P2L-Q3G", repeat: int = 5) -> str:
    """The adjoint's gradient by the initial state, and by the initial state and every
    parameter (k = 2N + 2: masses, lengths, g, c), of damped chains of N links, over a plain
    run: the compiled loops' time, ``repeat`` rounds in turn, everything compiled for the model's
    sizes first (``specialize=True``)."""
    import fastvi

    out = [f"Damped chains (c = 0.3) of N links, `{method}`, h = {h}, {steps} steps, the "
           f"compiled loops' time over a plain run, median of {repeat} rounds run in turn:", "",
           "| links N | n | k | plain step (µs) | adjoint by q0, v0 | by q0, v0 and θ | "
           "a parameter, a step |", "|---|---|---|---|---|---|---|"]
    for N in links:
        ch = fastvi.scenes.chain(N, damping=0.3)
        q0, v0 = chain_start(N)
        run = dict(h=h, n_steps=steps, save_every=steps, method=method, specialize=True)
        k = ch.params.size

        def plain():
            return fastvi.integrate(ch, q0, v0, **run).stats["integration_time"]

        def adj(pidx):
            def timed():
                A = fastvi.adjoint(ch, q0, v0, lambda r: (np.ones((len(r.t), 2 * N)), None),
                                   param_index=pidx, **run)
                return A.result.stats["integration_time"] + A.stats["backward_time"]
            return timed

        times = _in_turn([plain, adj([]), adj(None)], repeat)
        # a parameter's cost: the rounds' median of the difference of the two gradients
        by_param = np.median(times[:, 2] - times[:, 1]) / steps / k
        solver = fastvi.structure.plan(ch, fastvi.tables.method(method)).solvers["newton"]
        label = f"{N} (banded)" if solver == "banded" else f"{N}"
        out.append(f"| {label} | {2 * N} | {k} | {np.median(times[:, 0]) / steps * 1e6:.1f} | "
                   f"{_ratio(times, 1):.2f} | {_ratio(times, 2):.2f} | {by_param * 1e6:.2f} µs |")
    return "\n".join(out)


def main(argv=None) -> int:
    parser = study_parser("python -m fastvi sensitivities", __doc__)
    parser.add_argument("--steps", type=int, default=10_000, help="steps of the cost and symplecticity runs")
    parser.add_argument("--repeat", type=int, default=3, help="timings: rounds of calls in turn (medians)")
    parser.add_argument("--out", default=f"{default_out('sensitivities')}/sensitivities.md",
                        help="where to write the tables")
    args = parser.parse_args(argv)
    import fastvi

    dp = fastvi.scenes.double_pendulum(damping=0.3)  # compile everything first: not timed
    fastvi.integrate(dp, *dp.initial_state(1.0, 0.5), h=0.01, n_steps=2, specialize=True)
    for specialize in (False, True):  # the sized linearised step, which the default then takes
        fastvi.sensitivity(dp, *dp.initial_state(1.0, 0.5), h=0.01, n_steps=2, wrt=("params",),
                           specialize=specialize)
        fastvi.adjoint(dp, *dp.initial_state(1.0, 0.5),
                       lambda r: (np.ones((len(r.t), 4)), None), h=0.01, n_steps=2,
                       specialize=specialize)
    parts = [("Cost", cost_table(args.steps, args.repeat)), ("Adjoint memory", memory_table()),
             ("Large mechanisms", scaling_table()),
             ("Adjoint memory of a large mechanism", segments_table(repeat=args.repeat)),
             ("By the number of parameters", parameters_table(repeat=args.repeat)),
             ("Ensembles", ensemble_table()), ("Order", order_table()),
             ("Symplecticity", symplectic_table(args.steps)), ("Fit", fit_table())]
    text = "\n\n".join(f"## {title}\n\n{body}" for title, body in parts) + "\n"
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    sys.stdout.write(text)
    return 0
