"""Pareto fronts of the speed study and what is read off them: cost at equal error, ratios,
crossovers.

A contender's front is the set of its runs that no cheaper run of it beats in error; the cost
at an error level between two front runs is interpolated log–log (a method's cost grows as a
power of its error). Nothing is extrapolated: outside a front the cost is NaN.
"""

from __future__ import annotations

import numpy as np

from .config import ADAPTIVE, BEST_OF, PEER_LEVELS


#: which runs a metric is read from
_PANEL = {"err_q": "error", "dH": "long", "g": "long"}


def pareto(points, metric: str, cost: str = "wall"):
    """(error, cost) of the runs that no cheaper run of the same set beats in error.

    Returns two arrays, by increasing cost (so decreasing error)."""
    pts = sorted((p for p in points if p.ok and np.isfinite(getattr(p, metric))
                  and getattr(p, metric) > 0), key=lambda p: getattr(p, cost))
    errs, costs = [], []
    for p in pts:
        e = getattr(p, metric)
        if not errs or e < errs[-1]:
            errs.append(e)
            costs.append(getattr(p, cost))
    return np.array(errs), np.array(costs)


def cost_at(points, metric: str, E, cost: str = "wall"):
    """Cost to reach error ``E``: log–log interpolation on the Pareto front, NaN outside it."""
    errs, costs = pareto(points, metric, cost)
    E = np.atleast_1d(np.asarray(E, float))
    out = np.full(E.shape, np.nan)
    if len(errs) < 2:
        return out
    le, lc = np.log(errs[::-1]), np.log(costs[::-1])  # increasing error
    inside = (E >= errs.min()) & (E <= errs.max())
    out[inside] = np.exp(np.interp(np.log(E[inside]), le, lc))
    return out


def select(points, metric, label=None, labels=None):
    """The runs of the panel that ``metric`` is read from, of one contender or several."""
    panel = _PANEL[metric]
    return [p for p in points if p.panel == panel and (label is None or p.label == label)
            and (labels is None or p.label in labels)]


def best_fastvi(points, metric, E, cost: str = "wall"):
    """(cost, method) of the cheapest of :data:`BEST_OF` at each error level ``E``."""
    E = np.atleast_1d(E)
    costs = np.array([cost_at(select(points, metric, m), metric, E, cost) for m in BEST_OF])
    best = np.full(E.shape, np.nan)
    which = np.full(E.shape, "", dtype=object)
    for k in range(len(E)):
        col = costs[:, k]
        if np.any(np.isfinite(col)):
            j = int(np.nanargmin(col))
            best[k], which[k] = col[j], BEST_OF[j]
    return best, which


def _grid(lo, hi, per_decade):
    return np.logspace(np.log10(hi), np.log10(lo), max(2, int(per_decade * np.log10(hi / lo)) + 1))


def compare(points, metric: str, rival: str, cost: str = "wall", per_decade: int = 40):
    """Speed-up of the best fastvi method over ``rival`` at equal error (a fine error grid).

    Returns ``(E, ratio, method)`` over the error range both Pareto fronts cover (empty if
    they do not overlap), ``E`` decreasing."""
    e1, _ = pareto(select(points, metric, rival), metric, cost)
    fronts = [pareto(select(points, metric, m), metric, cost)[0] for m in BEST_OF]
    e2 = np.concatenate([f for f in fronts if len(f) >= 2] or [np.array([])])
    empty = (np.array([]), np.array([]), np.array([]))
    if len(e1) < 2 or len(e2) < 2:
        return empty
    lo, hi = max(e1.min(), e2.min()), min(e1.max(), e2.max())
    if not lo < hi:
        return empty
    E = _grid(lo, hi, per_decade)
    fw, which = best_fastvi(points, metric, E, cost)
    ratio = cost_at(select(points, metric, rival), metric, E, cost) / fw
    keep = np.isfinite(ratio)
    return E[keep], ratio[keep], which[keep]


def crossings(E, ratio, target: float) -> list[float]:
    """Error levels where ``ratio`` crosses ``target`` (log-linear interpolation)."""
    out = []
    d = np.log(ratio) - np.log(target)
    for k in range(len(E) - 1):
        if d[k] == 0.0:
            out.append(float(E[k]))
        elif d[k] * d[k + 1] < 0:
            f = d[k] / (d[k] - d[k + 1])
            out.append(float(np.exp(np.log(E[k]) + f * (np.log(E[k + 1]) - np.log(E[k])))))
    return out


def method_crossovers(points, metric: str, per_decade: int = 40):
    """Error ranges where each of :data:`BEST_OF` is the cheapest: [(method, E_hi, E_lo)]."""
    fronts = [pareto(select(points, metric, m), metric)[0] for m in BEST_OF]
    errs = np.concatenate([f for f in fronts if len(f) >= 2] or [np.array([])])
    if len(errs) < 2:
        return []
    E = _grid(errs.min(), errs.max(), per_decade)
    _, which = best_fastvi(points, metric, E)
    spans = []
    for e, w in zip(E, which):
        if not w:
            continue
        if spans and spans[-1][0] == w:
            spans[-1][2] = e
        else:
            spans.append([w, e, e])
    # a method cheapest at a single grid point only is interpolation noise between two others
    return [tuple(s) for s in spans if s[1] != s[2] or len(spans) == 1]


def step_costs(points, T) -> dict:
    """Median CPU time per step (s) of each contender of the pendulum panel at ``T``."""
    per = {}
    for p in points:
        if p.panel == "pendulum" and p.T == T and p.ok and p.work:
            per.setdefault(p.label, []).append(p.cpu / p.work)
    return {lab: float(np.median(v)) for lab, v in per.items()}


def front_at(points, E, bound: bool = True):
    """(CPU time, steps) to reach max|ΔH| = E on these runs' Pareto front in (max|ΔH|, CPU),
    each interpolated log–log between the two front runs around E (steps NaN where a run
    did not count them).

    With ``bound``, at an E looser than the whole front where a run of the set is that
    loose but costs more than the front's cheapest run (so the front dropped it: a longer
    step that needs more iterations, or the machine's load between two close settings): the
    cheapest front run's, which reaches E, so its CPU time bounds the cost there (as the
    stiff table's "≤" cells). NaN otherwise outside the front."""
    ok = [p for p in points if p.ok]
    errs, cpus = pareto(ok, "dH", cost="cpu")
    work = {(p.dH, p.cpu): p.work for p in ok}
    if bound and len(errs) and E > errs.max() and any(p.dH >= E for p in ok):
        return float(cpus[0]), float(work[(errs[0], cpus[0])])
    if len(errs) < 2 or not errs.min() <= E <= errs.max():
        return np.nan, np.nan
    steps = np.array([work[(e, c)] for e, c in zip(errs, cpus)], float)
    le = np.log(errs[::-1])  # increasing error
    x = np.log(E)
    cpu = float(np.exp(np.interp(x, le, np.log(cpus[::-1]))))
    if not (steps > 0).all():  # runs that did not count their steps
        return cpu, np.nan
    return cpu, float(np.exp(np.interp(x, le, np.log(steps[::-1]))))


def peer_split(points, T, rival, levels=PEER_LEVELS):
    """Where each ratio of :func:`peer_ratios` comes from: ``[(E, method, steps ratio, cost
    per step ratio)]``, fastvi's cheapest method at ``E`` against ``rival``, each contender's
    steps and CPU time read off its own front at ``E`` (the product of the two ratios is the
    CPU ratio). NaN where either front does not reach ``E``."""
    rows = []
    riv = [p for p in points if p.label == rival and p.T == T and p.panel == "pendulum"]
    for E, _, which, _, _ in peer_ratios(points, T, rival, levels):
        mine = [p for p in points if p.label == which and p.T == T and p.panel == "pendulum"]
        (cf, sf), (cr, sr) = front_at(mine, E), front_at(riv, E)
        rows.append((E, which, sf / sr, (cf / sf) / (cr / sr)))
    return rows


def peer_ratios(points, T, rival, levels=PEER_LEVELS, fixed_only=False):
    """[(E, fastvi-best CPU, method, rival CPU, fastvi / rival)] at each level ``E``;
    ``fixed_only``: the best of the fixed-step (symplectic) contenders."""
    rows = []
    riv = [p for p in points if p.label == rival and p.T == T and p.panel == "pendulum"]
    methods = sorted({p.label for p in points if p.is_fastvi and p.T == T and p.panel == "pendulum"
                      and not (fixed_only and p.label.endswith(ADAPTIVE))})
    for E in levels:
        best, which = np.nan, ""
        for m in methods:
            c = front_at([p for p in points if p.label == m and p.T == T and p.panel == "pendulum"], E)[0]
            if np.isfinite(c) and not (c >= best):
                best, which = c, m
        r = front_at(riv, E)[0]
        rows.append((E, best, which, r, best / r if np.isfinite(best) and np.isfinite(r) else np.nan))
    return rows
