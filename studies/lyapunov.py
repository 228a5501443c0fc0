r"""``python -m fastvi lyapunov``: Lyapunov exponents of the double pendulum, converged in T
and h over an ensemble of starts on one energy surface, against an independent SciPy
reference → the table of ``docs/sensitivities.md``.

The double pendulum of unit masses and rods, g = 9.81, at the energy of the release at rest
from θ1 = θ2 = π/2 (E = 0, the pivot's height the zero of the potential): ``--members``
starts at rest on that surface (``cos θ2 = −2 cos θ1``, θ1 spread over ``π/2 ± 0.45``).
fastvi: :func:`fastvi.lyapunov_spectrum` (``P2L-Q3G``, segments of 1 s) at two step sizes,
λ_1 at several T, and the whole spectrum. Reference: Benettin's method on the angle
equations and their variational equations (complex-step derivatives, exact to round-off),
SciPy DOP853 at rtol = atol = 1e-12, the same starts, segments and norm — independent of
fastvi's kernels.

Writes ``./fastvi-study-lyapunov/lyapunov.md`` (``--out`` elsewhere).
"""

from __future__ import annotations

import time

import numpy as np
from scipy.integrate import solve_ivp

from fastvi.studies.cli import default_out, study_parser, write_sections

G = 9.81
STEP = 1e-30  # complex step: derivatives exact to round-off


def _rhs(y, masses, lengths, g):
    """The angle equations of a planar double pendulum of point masses, ``y = (θ1, θ2, ω1,
    ω2)`` (4, ...), broadcasting over trailing axes and analytic (complex steps)."""
    m1, m2 = masses
    l1, l2 = lengths
    th1, th2, om1, om2 = y
    d = th1 - th2
    a11, a12, a22 = (m1 + m2) * l1 * l1, m2 * l1 * l2 * np.cos(d), m2 * l2 * l2
    b1 = -m2 * l1 * l2 * np.sin(d) * om2 * om2 - (m1 + m2) * g * l1 * np.sin(th1)
    b2 = m2 * l1 * l2 * np.sin(d) * om1 * om1 - m2 * g * l2 * np.sin(th2)
    det = a11 * a22 - a12 * a12
    return np.stack([om1, om2, (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det])


def cartesian_directions(y, masses=(1.0, 1.0), lengths=(1.0, 1.0)) -> np.ndarray:
    """``∂(q, p)/∂(θ, ω)`` (8, 4) at ``y = (θ1, θ2, ω1, ω2)``: Cartesian ``q = (x1, y1, x2,
    y2)`` and momenta ``p = M v`` of the point masses (complex steps)."""
    l1, l2 = lengths
    m = np.array([masses[0], masses[0], masses[1], masses[1]])
    out = np.zeros((8, 4))
    for j in range(4):
        z = np.asarray(y, complex).copy()
        z[j] += STEP * 1j
        s1, c1, s2, c2 = np.sin(z[0]), np.cos(z[0]), np.sin(z[1]), np.cos(z[1])
        q = np.array([l1 * s1, -l1 * c1, l1 * s1 + l2 * s2, -l1 * c1 - l2 * c2])
        v = np.array([l1 * c1 * z[2], l1 * s1 * z[2], l1 * c1 * z[2] + l2 * c2 * z[3],
                      l1 * s1 * z[2] + l2 * s2 * z[3]])
        out[:, j] = np.concatenate([q, m * v]).imag / STEP
    return out


def reference_spectrum(y0, start, *, t_end: float, segment: float = 1.0,
                       masses=(1.0, 1.0), lengths=(1.0, 1.0), g: float = G,
                       rtol: float = 1e-12):
    r"""Benettin's QR method on the angle equations of the double pendulum.

    The state ``y = (θ1, θ2, ω1, ω2)`` and the tangent vectors ``U`` (4, d) — columns of
    ``start`` at ``y0`` — follow ``ẏ = f(y)``, ``U̇ = Df(y) U`` (``Df U`` by complex steps)
    with SciPy DOP853 at ``rtol = atol = rtol``, in segments of ``segment`` seconds; at
    each segment's end ``C U = Q R`` with ``C = ∂(q, p)/∂(θ, ω)``, the Cartesian
    coordinates and momenta, and ``U ← U R⁻¹``. Returns the logarithms ``log |R_ii|``
    (J, d) of the segments (those of the start's own QR subtracted from the first).
    """
    y = np.array(y0, dtype=float)
    U = np.array(start, dtype=float).reshape(4, -1)
    d = U.shape[1]
    segments = int(round(t_end / segment))
    growth = np.empty((segments, d))

    def rhs(t, z):
        Y = z[:4, None] + STEP * 1j * np.hstack([np.zeros((4, 1)), z[4:].reshape(4, d)])
        F = _rhs(Y, masses, lengths, g)
        return np.concatenate([F[:, 0].real, (F[:, 1:].imag / STEP).ravel()])

    r_prev = np.linalg.qr(cartesian_directions(y, masses, lengths) @ U, mode="r")
    for j in range(segments):
        sol = solve_ivp(rhs, (0.0, segment), np.concatenate([y, U.ravel()]), method="DOP853",
                        rtol=rtol, atol=rtol)
        if not sol.success:  # pragma: no cover
            raise RuntimeError(sol.message)
        y, U = sol.y[:4, -1], sol.y[4:, -1].reshape(4, d)
        r = np.linalg.qr(cartesian_directions(y, masses, lengths) @ U, mode="r")
        growth[j] = np.log(np.abs(np.diag(r))) - np.log(np.abs(np.diag(r_prev)))
        U = np.linalg.solve(r.T, U.T).T
        r_prev = np.eye(d)
    return growth


def energy_surface_starts(members: int) -> np.ndarray:
    """``members`` starts ``(θ1, θ2, 0, 0)`` at rest on the energy surface of the release from
    θ1 = θ2 = π/2 (unit masses and rods: ``2 cos θ1 + cos θ2 = 0``)."""
    th1 = np.pi / 2 + 0.45 * np.linspace(-1.0, 1.0, members)
    th2 = np.arccos(-2.0 * np.cos(th1))
    return np.stack([th1, th2, np.zeros(members), np.zeros(members)], axis=1)


def fastvi_running(y0, h: float, t_end: float, count: int = 1, method: str = "P2L-Q3G"):
    """:func:`fastvi.lyapunov_spectrum` from the angles ``y0``: the record."""
    import fastvi
    from fastvi.scenes.double_pendulum import state_from_angles

    dp = fastvi.scenes.double_pendulum()
    q0, v0 = state_from_angles(*y0)
    return fastvi.lyapunov_spectrum(dp, q0, v0, h=h, t_end=t_end, count=count, method=method)


#: a start is counted chaotic when its λ_1 estimate at the longest T exceeds this (1/s): the
#: regular ones (KAM tori) sit near 0.003 at T = 2000 s, the chaotic ones near 0.9
CHAOTIC = 0.1


def ensemble(members: int, t_end: float, t_ref: float, hs=(0.01, 0.005)) -> dict:
    """λ_1(T) (members, T) of the starts of :func:`energy_surface_starts`: fastvi at each
    ``h`` up to ``t_end`` and the SciPy reference up to ``t_ref``, segments of 1 s, and the
    seconds each took."""
    starts = energy_surface_starts(members)
    runs, secs = {"starts": starts}, {}
    for h in hs:
        t = time.perf_counter()
        runs[h] = np.array([fastvi_running(y, h, t_end).running[:, 0] for y in starts])
        secs[h] = time.perf_counter() - t
    t = time.perf_counter()
    runs["ref"] = np.array([np.cumsum(reference_spectrum(y, np.eye(4)[:, :1], t_end=t_ref)[:, 0])
                            / np.arange(1.0, t_ref + 1) for y in starts])
    secs["ref"] = time.perf_counter() - t
    runs["seconds"] = secs
    return runs


def chaotic_stats(lam, T: float):
    """``(mean, standard deviation, chaotic count)`` of λ_1(T) over the starts whose estimate
    at their longest span exceeds :data:`CHAOTIC`."""
    keep = lam[:, -1] > CHAOTIC
    values = lam[keep, int(T) - 1]
    return values.mean(), values.std(ddof=1), int(keep.sum())


def ensemble_table(members: int, t_end: float, t_ref: float, hs=(0.01, 0.005)) -> str:
    runs = ensemble(members, t_end, t_ref, hs)
    Ts = [T for T in (50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0) if T <= t_end]
    rows = [(f"fastvi `P2L-Q3G`, h = {h:g}", runs[h], runs["seconds"][h]) for h in hs]
    rows.append(("SciPy DOP853 rtol = 1e-12, angles", runs["ref"], runs["seconds"]["ref"]))
    out = [f"Largest exponent λ_1 (1/s) over {members} starts at rest on the energy surface E = 0 "
           "(unit masses and rods, g = 9.81), segments of 1 s: mean ± standard deviation over the "
           f"chaotic starts (λ_1 > {CHAOTIC:g} at the longest T; the others are regular, λ_1 → 0).", "",
           "| computation | chaotic / regular | " + " | ".join(f"T = {T:g} s" for T in Ts)
           + " | time (s) |", "|---|---|" + "---|" * (len(Ts) + 1)]
    for label, lam, sec in rows:
        cells = []
        for T in Ts:
            if T <= lam.shape[1]:
                mean, std, count = chaotic_stats(lam, T)
                cells.append(f"{mean:.3f} ± {std:.3f}")
            else:
                cells.append("")
        out.append(f"| {label} | {count} / {members - count} | " + " | ".join(cells)
                   + f" | {sec:.0f} |")
    last = runs[hs[-1]][:, -1]
    out += ["", f"Per start, λ_1 at T = {t_end:g} s, h = {hs[-1]:g} (θ1 of the start at rest, "
            "θ2 = arccos(−2 cos θ1)): "
            + ", ".join(f"{y[0]:.3f}: {lam:.3f}" for y, lam in zip(runs["starts"], last))]
    return "\n".join(out)


def spectrum_table(t_end: float, h: float = 0.01) -> str:
    y0 = (np.pi / 2, np.pi / 2, 0.0, 0.0)
    out = ["Whole spectrum from θ1 = θ2 = π/2 at rest, "
           f"`P2L-Q3G`, h = {h:g}:", "",
           "| T (s) | λ_1 | λ_2 | λ_3 | λ_4 | λ_1 + λ_4 | λ_2 + λ_3 |", "|---|---|---|---|---|---|---|"]
    spec = fastvi_running(y0, h, t_end, count=4)
    for T in (10.0, 100.0, 1000.0, 10000.0):
        if T <= t_end:
            lam = spec.running[int(T) - 1]
            out.append(f"| {T:g} | " + " | ".join(f"{x:.4f}" for x in lam)
                       + f" | {lam[0] + lam[3]:.1e} | {lam[1] + lam[2]:.1e} |")
    return "\n".join(out)


def main(argv=None) -> int:
    parser = study_parser("python -m fastvi lyapunov", __doc__)
    parser.add_argument("--members", type=int, default=16, help="starts on the energy surface")
    parser.add_argument("--t-end", type=float, default=2000.0, help="longest span T (s)")
    parser.add_argument("--t-ref", type=float, default=200.0, help="span of the SciPy reference (s)")
    parser.add_argument("--out", default=f"{default_out('lyapunov')}/lyapunov.md",
                        help="where to write the tables")
    args = parser.parse_args(argv)
    parts = [("Ensemble", ensemble_table(args.members, args.t_end, args.t_ref)),
             ("Spectrum", spectrum_table(args.t_end))]
    write_sections(args.out, parts)
    return 0
