r"""The reliability monitor of :func:`fastvi.integrate`: no wrong answer reported as a success.

Every step of a run can converge and the trajectory still be wrong: a step beyond a
method's stability limit, a Newton solution on the wrong branch of the discrete equations,
substeps of a recovered step (``recover=``) that do not compose into a step of the same
motion. None of these shows in a Newton residual. They show in what a variational
integrator keeps: its energy error is bounded, of the size ``C (ωh)^{2s}`` of the energy of
the motion, for as long as the run lasts; the constraints hold to the Newton tolerance at
every step; a step moves ``q`` by what its velocities allow. After every run the monitor
reads the saved samples (no kernel change, no cost per step) and checks

=================  ===================================================  ====================
indicator          value at sample k                                    limit
=================  ===================================================  ====================
energy             ``|H_k − H_0 − W_k|`` (the energy balance; ``W = 0``  ``ENERGY_TOL`` (0.1)
                   for a conservative model) over ``E_k``, the largest  times ``E_k``, plus
                   kinetic energy ``½ vᵀp`` (or ``|W|``) seen up to k    round-off
constraints        ``max |g(q_k)|`` over ``max(1, |q|)²``                ``CONSTRAINT_TOL``
                                                                        (1e-6, or 10⁴·tol)
hidden             ``max |G v_k + g_t|`` over ``max(1,|q|) max(1,|v|)``  ``CONSTRAINT_TOL``
constraints
displacement       ``|q_{k+1} − q_k|`` over ``(t_{k+1} − t_k)               ``DISPLACEMENT_TOL``
                   max(|v_k|, |v_{k+1}|)`` (max norms; samples one      (4)
                   step apart only)
=================  ===================================================  ====================

and a run that breaks a limit ends with ``Status.UNRELIABLE``: its result keeps the samples
up to the last one that met every limit, and the message says at which sample (time, steps)
which indicator broke and by how much. :func:`fastvi.integrate` raises
:class:`fastvi.IntegrationError` with that partial result (or returns it, with
``on_failure="return"``). ``monitor=False`` turns the monitor off.

Why these limits
----------------
*Energy.* The energy error of a symplectic step is the difference between ``H`` and the
modified energy the step conserves exactly; both follow the same motion, so the error is
a fraction ``O((ωh)^{2s})`` of the energy that moves (the kinetic energy), and it does not
grow. A tenth of the largest kinetic energy is beyond what any step that resolves the
motion leaves (the runs of the test suite at steps that resolve the motion
stay below 5 %, 99 % of them below 1.6 %; the slider–crank of ``tests/test_reliability.py``
at h = 0.1 reaches 13 % at its fourth step and 86 % at step 20): at that
level the step is at or beyond the edge where Newton fails, and an error that grows from
there (orders of magnitude, exponentially beyond a stability limit) is no longer an
approximation of the motion. The kinetic energy is the scale because it is what the
motion exchanges: it does not depend on where the potential's zero is, and for a driven
or damped model the work ``W`` the forces do is the scale as well.

*Constraints.* The constraints are solved to the Newton tolerance at every step and the
hidden constraint is projected to round-off; ``CONSTRAINT_TOL`` is the tolerance initial
data must meet (:data:`fastvi._validate.CONSISTENCY_TOL`), so a sample that would be
refused as a start is not accepted as a result.

*Displacement.* Over one step ``q_{k+1} − q_k = ∫ v dt``, which a step that resolves the
motion keeps within ``h max|v|`` up to ``O((ωh)²)``: the runs of the test suite stay below
1.4, the broken slider–crank steps reach 12–23 (a jump to another branch of the crank).

What the monitor cannot see: an error that keeps the energy, the constraints and the
displacement plausible, e.g. a phase error (a step too large for an accurate position but
within the method's stability), or a wrong model. It flags a broken run, not an
inaccurate one: compare with a run at ``h/2`` for that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._validate import CONSISTENCY_TOL

__all__ = ["Verdict", "assess", "ENERGY_TOL", "CONSTRAINT_TOL", "DISPLACEMENT_TOL"]

#: largest energy error (balance, for a forced or driven model) relative to the largest
#: kinetic energy (or work) seen so far; see the module docstring for why
ENERGY_TOL = 0.1
#: largest constraint residual relative to max(1, |q|)² (the hidden constraint: to
#: max(1, |q|) max(1, |v|)): the tolerance initial data must meet
CONSTRAINT_TOL = CONSISTENCY_TOL
#: constraint limit relative to the Newton tolerance of the run (a loose ``tol`` leaves
#: residuals of about tol·|q|²)
CONSTRAINT_PER_TOL = 1e4
#: largest one-step displacement relative to the step times the larger end velocity
DISPLACEMENT_TOL = 4.0
#: round-off floor of the energy test, relative to the sizes of the energies summed
_ROUNDOFF = 1e-10


@dataclass(frozen=True)
class Verdict:
    """What the monitor found: the worst value of each indicator and the first breach.

    Attributes
    ----------
    indicators : dict
        ``{"energy": …, "constraint": …, "hidden_constraint": …, "displacement": …}``:
        each indicator's largest value over the run, as a fraction of its limit (below 1:
        met). The displacement is NaN when no two samples are one step apart.
    sample : int or None
        Index of the first sample that broke a limit (None: the run is reliable).
    indicator : str
        Which indicator broke first ("" when none).
    reason : str
        The sentence for the error message.
    """

    indicators: dict
    sample: int | None = None
    indicator: str = ""
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.sample is None


def _first(bad: np.ndarray) -> int | None:
    """The first bad sample after the start (sample 0 is the initial state, which
    :func:`fastvi._validate.initial_state` has checked and projected)."""
    idx = np.flatnonzero(bad[1:]) + 1
    return int(idx[0]) if idx.size else None


def _ratio(value: np.ndarray, limit: np.ndarray) -> float:
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(value > 0, value / limit, 0.0)
    r = r[~np.isnan(r)]
    return float(r.max()) if r.size else 0.0


def assess(t, q, v, p, energy, work, g, gv, *, one_step: bool, newton_tol: float) -> Verdict:
    """Check a run's samples against the limits of the module docstring.

    Parameters
    ----------
    t, q, v, p, energy, work, g, gv : ndarray
        The samples of a :class:`fastvi.Result` (``work`` None for a conservative model;
        ``g``, ``gv`` the constraint residuals, zeros without constraints).
    one_step : bool
        Consecutive samples are one step apart (``save_every=1``): the displacement test
        applies. Otherwise it is skipped (the velocities at the ends of a stretch of many
        steps do not bound its displacement).
    newton_tol : float
        The run's Newton tolerance (a looser one widens the constraint limits).

    Returns
    -------
    Verdict
    """
    K = t.shape[0]
    ind = {"energy": 0.0, "constraint": 0.0, "hidden_constraint": 0.0, "displacement": float("nan")}
    if K < 2:
        return Verdict(ind)
    found = []  # (sample, indicator, reason)

    # energy balance against the largest kinetic energy (or work) seen so far
    ke = 0.5 * np.einsum("ij,ij->i", v, p)
    w = np.zeros(K) if work is None else np.asarray(work)
    err = np.abs(energy - energy[0] - w)
    scale = np.maximum.accumulate(np.maximum(np.abs(ke), np.abs(w)))
    size = np.maximum.accumulate(np.abs(energy) + np.abs(ke) + np.abs(w))
    limit = ENERGY_TOL * scale + _ROUNDOFF * size
    bad = ~(err <= limit)  # NaN breaks it too
    ind["energy"] = _ratio(err, limit)
    k = _first(bad)
    if k is not None:
        what = "energy balance |H − H(t0) − W|" if work is not None else "energy error |H − H(t0)|"
        found.append((k, "energy", f"the {what} = {err[k]:.3g} is {err[k] / max(scale[k], 1e-300):.3g} "
                      f"of the largest kinetic energy{' or work' if work is not None else ''} so far "
                      f"({scale[k]:.3g}); a variational step that resolves the motion keeps it "
                      f"below {ENERGY_TOL:g} of it"))

    qscale = np.maximum.accumulate(np.maximum(1.0, np.max(np.abs(q), axis=1)))
    vscale = np.maximum.accumulate(np.maximum(1.0, np.max(np.abs(v), axis=1)))
    ctol = max(CONSTRAINT_TOL, CONSTRAINT_PER_TOL * newton_tol)
    for name, res, lim, words in (
            ("constraint", g, ctol * qscale**2, "constraint residual max|g|"),
            ("hidden_constraint", gv, CONSTRAINT_TOL * qscale * vscale, "velocity residual max|G v + g_t|")):
        res = np.asarray(res)
        ind[name] = _ratio(res, lim)
        k = _first(~(res <= lim))
        if k is not None:
            found.append((k, name, f"the {words} = {res[k]:.3g} exceeds {lim[k]:.3g}, the tolerance "
                          "initial data must meet"))

    if one_step and K > 2:
        dt = np.diff(t)
        dq = np.max(np.abs(np.diff(q, axis=0)), axis=1)
        vmax = np.maximum(np.max(np.abs(v[1:]), axis=1), np.max(np.abs(v[:-1]), axis=1))
        lim = DISPLACEMENT_TOL * dt * vmax + 1e-12 * qscale[1:]
        ind["displacement"] = _ratio(dq, lim)
        k = _first(~(dq <= lim))
        if k is not None:
            found.append((k + 1, "displacement",
                          f"the step moved q by {dq[k]:.3g}, {dq[k] / max(dt[k] * vmax[k], 1e-300):.3g} "
                          f"times its length times its largest end velocity ({dt[k]:.3g} × "
                          f"{vmax[k]:.3g}): the step left the motion (a jump to another solution "
                          "of the step's equations)"))
    if not found:
        return Verdict(ind)
    k, name, reason = min(found, key=lambda f: f[0])
    return Verdict(ind, k, name, reason)


def stats(verdict: Verdict) -> dict:
    """The indicators as flat ``Result.stats`` entries (``monitor_energy``, …: the largest
    value over the run as a fraction of its limit), which :meth:`Result.save` can write."""
    return {f"monitor_{name}": float(value) for name, value in verdict.indicators.items()}


def step_of_sample(j: int, every: int, steps: int) -> int:
    """Steps done at sample ``j`` (every ``every``-th step is saved, and the last)."""
    return min(j * every, steps)


def judge(result, *, every: int, newton_tol: float) -> Verdict:
    """:func:`assess` on a :class:`fastvi.Result`."""
    m = result.constraint_residual
    verdict = assess(result.t, result.q, result.v, result.p, result.energy, result.work, m,
                     result.velocity_residual, one_step=every == 1,
                     newton_tol=newton_tol)
    return verdict


def cut(result, verdict: Verdict, *, every: int, later: str | None = None):
    """The result up to the last sample before the breach, with ``Status.UNRELIABLE``.

    Returns ``(result, failed_step, failed_time, detail)``: the step from which the
    trajectory is not to be trusted (the first step after the last good sample), the time
    at its start, and the sentence for :class:`fastvi.IntegrationError`.
    """
    from dataclasses import replace

    from .status import Status

    j = verdict.sample  # first bad sample, >= 1 (sample 0 is the projected initial state)
    steps = int(result.stats["steps"])
    good = step_of_sample(j - 1, every, steps)
    bad = step_of_sample(j, every, steps)
    t_good, t_bad = float(result.t[j - 1]), float(result.t[j])
    span = (f"step {bad - 1} (t = {t_good:.6g} → {t_bad:.6g})" if bad - good == 1 else
            f"steps {good}–{bad - 1} (t = {t_good:.6g} → {t_bad:.6g})")
    retaken = [k for k, _ in result.stats.get("recovered_steps", []) if k < bad]
    extra = (f"; {len(retaken)} step(s) up to it were retaken in substeps (`recover`), which "
             "cannot mend a step too large for the motion" if retaken else "")
    extra += f"; the run went on until {later}" if later else ""
    detail = (f"the reliability monitor stopped trusting the trajectory at {span}: {verdict.reason}"
              f"{extra}. The result keeps the samples up to t = {t_good:.6g}; use a smaller `h` "
              "(see fastvi.monitor; `monitor=False` turns this check off)")
    stats = dict(result.stats, steps=good, monitor_breach=verdict.indicator, monitor_breach_time=t_bad,
                 recovered_steps=[x for x in result.stats.get("recovered_steps", []) if x[0] < good])
    arrays = {name: getattr(result, name)[:j] for name in
              ("t", "q", "v", "p", "energy", "constraint_residual", "velocity_residual",
               "newton_iterations")}
    for name in ("work", "work_forces"):
        if getattr(result, name) is not None:
            arrays[name] = getattr(result, name)[:j]
    extra = {}
    if result.t_events is not None:
        keep = [te <= t_good for te in result.t_events]
        extra = dict(t_events=[te[k] for te, k in zip(result.t_events, keep)],
                     q_events=[qe[k] for qe, k in zip(result.q_events, keep)],
                     v_events=[ve[k] for ve, k in zip(result.v_events, keep)])
    if result.sol:  # a DenseSolution (without dense output: a falsy NoDenseOutput)
        from .events import DenseSolution

        sol = result.sol
        extra["sol"] = DenseSolution(sol.t0, sol.h, sol.tau, sol.points[:good])
    out = replace(result, **arrays, **extra, stats=stats, status=Status.UNRELIABLE, failed_step=good)
    return out, good, t_good, detail
