r"""``python -m fastvi orders``: the measured order of every combination → ``docs/orders.md``.

Paper A studies how the control points, the quadrature rule of the unconstrained action and
the constraint points change the accuracy; its tables did not survive, so this study
produces ours. For every degree ``s = 1 … 5`` and every combination

* quadrature ``Q<s>G``, ``Q<s+1>G`` (paper B's choice), ``Q<s+1>L``,
* control nodes ``-NE`` / ``-NL`` / ``-NC``,
* constraint points ``-CE``, ``-CN``, ``-CL<k>`` (``3 <= k <= s+1``), ``-CG<k>`` (``1 <= k <= s-1``)

(every placement with at most ``s + 1`` constraint points; more make the step
over-determined, which the study checks separately), it integrates the planar double and
triple pendulum from ``θ_i = π/2`` at rest up to ``T = 1`` with ``h = T/N`` for
``N = 2, 3, 4, 5, 6, 7, 8, 10, 11, 13, 16, … , 512`` (ratio ``2^{1/4}``) and measures at the
grid points ``t_k = k h``

    e_q(h) = max_k |q_k − q(t_k)|_∞,   e_p(h) = max_k |p_k − M v(t_k)|_∞,   e_H(h) = max_k |H_k − H_0|

against SciPy's DOP853 (``rtol = atol = 1e-13``) in angle coordinates
(:func:`fastvi.studies.reference.chain_pendulum_reference`). The observed order is the
least-squares log–log slope (:func:`fastvi.studies.convergence.observed_order`) over the
``WINDOW`` smallest step sizes whose error is above the floor (``FLOORS``: the reference's
own error and round-off) and still decreasing; at least ``MIN_POINTS`` step sizes. The
error constant is ``e_q`` at the fixed ``h = 1/N_FIX[s]``, with the mean Newton iterations
per step there.

Writes ``docs/orders.md`` (or ``--out``). ``--quick`` measures a handful of combinations
on a short ``h`` range (the test suite runs it).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .convergence import observed_order
from .reference import REF_TOL, chain_cartesian, chain_pendulum_reference

T_END = 1.0
THETA0 = math.pi / 2
#: step counts over [0, T]: h = T/N, ratio 2^(1/4)
N_SEQUENCE = tuple(sorted({int(round(2 * 2 ** (k / 4))) for k in range(33)}))
#: errors below these are the reference's own error (~2e-13 in q, ~5e-12 in p) or round-off
FLOORS = {"q": 1e-11, "p": 1e-10, "H": 1e-11}
#: the fit uses the WINDOW smallest h above the floor, and needs at least MIN_POINTS of them
WINDOW = 8
MIN_POINTS = 5
#: the error constant and Newton iterations are reported at h = 1/N_FIX[s]
N_FIX = {1: 64, 2: 32, 3: 16, 4: 16, 5: 11}
DEGREES = (1, 2, 3, 4, 5)
QUICK_DEGREES = (1, 2)
QUICK_SEQUENCE = tuple(n for n in N_SEQUENCE if 16 <= n <= 64)
DEFAULT_OUT = Path(__file__).resolve().parents[2] / "docs" / "orders.md"
COMMAND = "python -m fastvi orders"


# --------------------------------------------------------------------------- set-up
@dataclass(frozen=True)
class Setup:
    """A chain pendulum of unit masses and lengths started from θ_i = π/2 at rest."""

    scene: str
    bodies: int

    @property
    def label(self) -> str:
        return {2: "double", 3: "triple"}[self.bodies]

    def model(self):
        from .. import scenes

        return scenes.SCENES[self.scene]()

    def start(self):
        return np.full(self.bodies, THETA0), np.zeros(self.bodies)


SETUPS = (Setup("double_pendulum", 2), Setup("triple_pendulum", 3))


def combinations(s: int, quick: bool = False) -> list[str]:
    """Method names measured for degree ``s``, quadrature-major."""
    if quick:
        return [f"P{s}L-Q{s + 1}G-NL-CN", f"P{s}L-Q{s + 1}G-NE-CE"]
    cons = ["CE", "CN"] + [f"CL{k}" for k in range(3, s + 2)] + [f"CG{k}" for k in range(1, s)]
    names = []
    for quad in (f"Q{s}G", f"Q{s + 1}G", f"Q{s + 1}L"):
        for c in cons:
            for nodes in "LEC":
                names.append(f"P{s}L-{quad}-N{nodes}-{c}")
    return names


def overdetermined(s: int) -> list[str]:
    """Placements with more than ``s + 1`` constraint points (J > s)."""
    return [f"P{s}L-Q{s + 1}G-NL-CL{s + 2}", f"P{s}L-Q{s + 1}G-NL-CG{s}"]


class References:
    """Reference ``(q, p)`` on the grid ``t_k = k T/N``, computed once per (set-up, N)."""

    def __init__(self):
        self._cache = {}

    def __call__(self, setup: Setup, N: int):
        key = (setup, N)
        if key not in self._cache:
            th0, om0 = setup.start()
            ones = np.ones(setup.bodies)
            t = T_END * np.arange(N + 1) / N
            th, om = chain_pendulum_reference(th0, om0, t, ones, ones, tol=REF_TOL)
            q, v = chain_cartesian(th, om, ones)
            self._cache[key] = (q, v)  # unit masses: p = M v = v
        return self._cache[key]


# --------------------------------------------------------------------------- measurement
@dataclass
class Measurement:
    """Errors of one combination on one set-up, per step count."""

    name: str
    setup: Setup
    N: list = field(default_factory=list)
    err: dict = field(default_factory=lambda: {"q": [], "p": [], "H": []})
    its: list = field(default_factory=list)
    status: list = field(default_factory=list)

    @property
    def h(self) -> np.ndarray:
        return T_END / np.asarray(self.N, float)

    def order(self, key: str) -> tuple[float, int]:
        """``(slope, points used)`` of ``err[key]`` (nan, 0 when too few points)."""
        return fit_order(self.h, self.err[key], FLOORS[key])

    def at(self, N: int, key: str = "q") -> float:
        return self.err[key][self.N.index(N)] if N in self.N else float("nan")

    def its_at(self, N: int) -> float:
        return self.its[self.N.index(N)] if N in self.N else float("nan")

    @property
    def failed(self) -> list:
        return [N for N, st in zip(self.N, self.status) if st != "SUCCESS"]


def fit_order(hs, errs, floor: float, window: int = WINDOW, min_points: int = MIN_POINTS):
    """Observed order over the ``window`` smallest ``h`` above ``floor``.

    Points are scanned from the largest ``h`` down; failed runs (nan) are skipped and the
    first error below ``floor`` starts the plateau. Of what remains, the ``window`` smallest
    ``h`` are fitted with :func:`observed_order`; if the error does not decrease
    monotonically over them, the window shrinks from its large-``h`` end (never below
    ``min_points``).

    Returns
    -------
    order : float (nan if no monotone run of ``min_points`` points exists)
    used : int, the number of points fitted
    """
    hs = np.asarray(hs, float)
    errs = np.asarray(errs, float)
    keep = []
    for i in np.argsort(-hs):
        if not np.isfinite(errs[i]):
            continue
        if errs[i] < floor:
            break
        keep.append(i)
    for w in range(min(window, len(keep)), min_points - 1, -1):
        idx = keep[-w:]
        order, used = observed_order(hs[idx], errs[idx], plateau=floor, min_points=min_points)
        if used.all():
            return order, w
    return float("nan"), 0


def measure(setup: Setup, model, name: str, refs: References, sequence=N_SEQUENCE,
            n_fix: int | None = None) -> Measurement:
    """Integrate ``name`` for every ``N`` in ``sequence`` until all errors are under the floors.

    The run goes on to at least ``n_fix`` steps. Newton failures (large ``h``) are recorded
    with nan errors.
    """
    import fastvi

    th0, om0 = setup.start()
    q0, v0 = model.initial_state(*th0, *om0)
    out = Measurement(name, setup)
    for N in sequence:
        res = fastvi.integrate(model, q0, v0, h=T_END / N, n_steps=N, method=name,
                               on_failure="return")
        out.N.append(N)
        out.status.append(res.status.name)
        if not res.success:
            for key in out.err:
                out.err[key].append(float("nan"))
            out.its.append(float("nan"))
            continue
        q_ref, p_ref = refs(setup, N)
        out.err["q"].append(float(np.max(np.abs(res.q - q_ref))))
        out.err["p"].append(float(np.max(np.abs(res.p - p_ref))))
        out.err["H"].append(float(np.max(np.abs(res.energy_error))))
        out.its.append(res.stats["newton_iterations"] / res.stats["steps"])
        below = all(out.err[k][-1] < FLOORS[k] for k in out.err)
        if below and (n_fix is None or N >= n_fix):
            break
    return out


def run_study(degrees=DEGREES, quick: bool = False, log=None) -> dict:
    """Measure every combination of every degree on both set-ups.

    Returns
    -------
    dict with ``rows`` {(s, name): {setup label: Measurement}}, ``overdetermined``
    [(name, {label: status})] and ``reference_check`` {label: max |Δq|, |Δp| between the
    reference at 1e-13 and 1e-14}.
    """
    refs = References()
    models = {st: st.model() for st in SETUPS}
    sequence = QUICK_SEQUENCE if quick else N_SEQUENCE
    rows = {}
    for s in degrees:
        t0 = time.perf_counter()
        n_fix = min(N_FIX[s], sequence[-1]) if not quick else sequence[len(sequence) // 2]
        for name in combinations(s, quick):
            rows[(s, name)] = {st.label: measure(st, models[st], name, refs, sequence, n_fix)
                               for st in SETUPS}
        if log:
            log(f"s = {s}: {len(combinations(s, quick))} combinations in "
                f"{time.perf_counter() - t0:.1f} s")
    over = []
    if not quick:
        import fastvi

        for s in degrees[:3]:
            for name in overdetermined(s):
                stat = {}
                for st in SETUPS:
                    q0, v0 = models[st].initial_state(*st.start()[0], *st.start()[1])
                    res = fastvi.integrate(models[st], q0, v0, h=1 / 32, n_steps=32, method=name,
                                           on_failure="return")
                    stat[st.label] = (res.status.name, res.failed_step)
                over.append((name, stat))
    check = {}
    for st in SETUPS:
        th0, om0 = st.start()
        ones = np.ones(st.bodies)
        t = np.linspace(0.0, T_END, 33)
        a = chain_cartesian(*chain_pendulum_reference(th0, om0, t, ones, ones, tol=REF_TOL), ones)
        b = chain_cartesian(*chain_pendulum_reference(th0, om0, t, ones, ones, tol=1e-14), ones)
        check[st.label] = (float(np.max(np.abs(a[0] - b[0]))), float(np.max(np.abs(a[1] - b[1]))))
    return dict(rows=rows, overdetermined=over, reference_check=check, quick=quick,
                degrees=tuple(degrees), sequence=sequence)


# --------------------------------------------------------------------------- analysis
def _suffix(name: str) -> str:
    return name.split("-", 2)[2]


def _base(name: str) -> str:
    return "-".join(name.split("-")[:2])


def order_class(meas: dict) -> float:
    """The smallest q-order over the set-ups, rounded to an integer (nan if unmeasured)."""
    vals = [m.order("q")[0] for m in meas.values()]
    if any(not np.isfinite(v) for v in vals):
        return float("nan")
    return float(round(min(vals)))


def recommend(rows: dict, s: int, base: str, n_fix: int) -> dict:
    """Pick the default suffix for the name ``base`` (``P<s>L-Q<r><G|L>``) from the table.

    Highest order class first; among equal orders the current default ``-NL-CN`` is kept
    unless another combination's error constant is smaller by more than ``1.5×`` on every
    set-up (smaller differences are not worth a change of meaning of the name); then fewer
    Newton iterations.
    """
    cands = {name: meas for (ss, name), meas in rows.items() if ss == s and _base(name) == base}
    current = f"{base}-NL-CN"
    best_order = max((order_class(m) for m in cands.values() if np.isfinite(order_class(m))),
                     default=float("nan"))
    top = {nm: m for nm, m in cands.items() if order_class(m) == best_order}

    def const(nm):
        return {lab: m.at(n_fix) for lab, m in cands[nm].items()}

    pick = current if current in top else None
    reason = "keeps the highest measured order"
    if pick is None:
        pick = min(top, key=lambda nm: (const(nm)["triple"], np.nanmean([m.its_at(n_fix) for m in cands[nm].values()])))
        reason = "the current default does not reach the highest order"
    else:
        cur = const(current)
        better = [nm for nm in top
                  if all(const(nm)[lab] * 1.5 < cur[lab] for lab in cur)]
        if better:
            pick = min(better, key=lambda nm: const(nm)["triple"])
            reason = "same order, error constant smaller by more than 1.5× on both pendulums"
    return dict(pick=pick, current=current, order=best_order, top=sorted(top), reason=reason,
                const=const(pick), current_const=const(current))


def node_family_spread(rows: dict, s: int, n_fix: int) -> float:
    """Largest relative spread of ``e_q(1/n_fix)`` over the node families, placements ≠ CN.

    In exact arithmetic the node family only changes the basis of the same polynomial
    space, so unless the constraint points are the nodes, the three families are the same
    method: this measures how far round-off takes them apart.
    """
    groups = {}
    for (ss, name), meas in rows.items():
        if ss != s or name.endswith("-CN"):
            continue
        key = name.replace("-NE-", "-N?-").replace("-NL-", "-N?-").replace("-NC-", "-N?-")
        for lab, m in meas.items():
            groups.setdefault((key, lab), []).append(m.at(n_fix))
    spread = 0.0
    for vals in groups.values():
        v = np.asarray(vals)
        if np.all(np.isfinite(v)) and len(v) > 1 and np.min(v) > 0:
            spread = max(spread, float((np.max(v) - np.min(v)) / np.min(v)))
    return spread


# --------------------------------------------------------------------------- report
def _fmt_order(meas: Measurement, key: str) -> str:
    order, used = meas.order(key)
    return "–" if not np.isfinite(order) else f"{order:.2f}"


def _fmt_e(x: float) -> str:
    return "fail" if not np.isfinite(x) else f"{x:.1e}"


def _failed(meas: dict) -> str:
    parts = []
    for lab, m in meas.items():
        if m.failed:
            parts.append(f"{lab[0].upper()}: h ≥ 1/{max(m.failed)}" if max(m.failed) < 64
                         else f"{lab[0].upper()}: {len(m.failed)} h")
    return "; ".join(parts)


def render(study: dict) -> str:
    """The markdown of ``docs/orders.md``."""
    from ..tables import method as get_method

    rows = study["rows"]
    quick = study["quick"]
    seq = study["sequence"]
    L = []
    w = L.append
    w("# Observed orders of every combination (paper A's study)")
    w("")
    cmd = COMMAND + (" --quick" if quick else "")
    w(f"Generated by `{cmd}` (`fastvi/studies/orders.py`); do not edit by hand.")
    w("")
    w("## Set-up")
    w("")
    w(f"* Scenes: `double_pendulum()` and `triple_pendulum()` (unit masses and lengths, "
      f"g = 9.81, Cartesian coordinates), started from θ_i = π/2 at rest, integrated to "
      f"T = {T_END:g}: the nonlinear regime (the bobs fall through the bottom with "
      f"|ω| up to 6–8 rad/s).")
    w(f"* Step sizes h = T/N for N = {', '.join(map(str, seq))} (ratio 2^(1/4)); a combination "
      f"stops refining once all three errors are below their floors.")
    w("* Errors at the grid points t_k = kh: e_q = max_k |q_k − q(t_k)|_∞, "
      "e_p = max_k |p_k − M v(t_k)|_∞, e_H = max_k |H_k − H_0|, against SciPy DOP853 "
      f"(rtol = atol = {REF_TOL:g}) in angle coordinates "
      "(`fastvi.studies.reference.chain_pendulum_reference`), mapped to Cartesian.")
    chk = study["reference_check"]
    w("* Reference accuracy: DOP853 at 1e-13 against 1e-14 differs by "
      + ", ".join(f"{lab} {dq:.0e} in q and {dp:.0e} in p" for lab, (dq, dp) in chk.items())
      + ". Errors below the floors "
      + ", ".join(f"{FLOORS[k]:g} ({k})" for k in ("q", "p", "H"))
      + " are therefore dropped (the round-off plateau).")
    w(f"* Order = least-squares log–log slope (`fastvi.studies.convergence.observed_order`) "
      f"over the {WINDOW} smallest h whose error is above the floor and decreasing "
      f"(at least {MIN_POINTS}; fewer usable points gives '–'). Using the smallest h keeps "
      "the pre-asymptotic large-h points out of the fit.")
    w("* Error constant: e_q at h = 1/N_fix (the same h for every combination of a degree, "
      "so equal-order combinations can be ranked); Newton iterations per step (Newton "
      "tolerance 1e-14, the default) at the same h. 'fail' = Newton did not converge "
      "(30 iterations) at that h.")
    w("* Nominal = `fastvi.method(name).nominal_order`, the order the combination is "
      "designed for (2 for `-CE`, else min(2s, quadrature exactness + 1)).")
    w("")

    degrees = study["degrees"]
    # ---------------------------------------------------------------- summary
    w("## Summary and defaults")
    w("")
    if not quick:
        w(_summary_text(study))
        w("")
    w("| name | default now | orders q / p / H (double) | orders q / p / H (triple) | "
      "e_q(1/N_fix) triple | recommended | why |")
    w("|---|---|---|---|---|---|---|")
    recs = {}
    for s in degrees:
        n_fix = _n_fix(study, s)
        bases = sorted({_base(nm) for (ss, nm) in rows if ss == s}, key=_base_key)
        for base in bases:
            rec = recommend(rows, s, base, n_fix)
            recs[base] = rec
            cur = rows.get((s, rec["current"]))
            if cur is None:
                continue
            w(f"| `{base}` | `-NL-CN` | {_orders3(cur['double'])} | {_orders3(cur['triple'])} | "
              f"{_fmt_e(cur['triple'].at(n_fix))} | `{_suffix(rec['pick'])}` | {rec['reason']} |")
    w("")
    # paper B's own variant
    w("Paper B's own scheme (`-NE-CE`, equidistant nodes, constraints at the step ends), "
      "for comparison:")
    w("")
    w("| name | orders q / p / H (double) | orders q / p / H (triple) | e_q(1/N_fix) triple |")
    w("|---|---|---|---|")
    for s in degrees:
        n_fix = _n_fix(study, s)
        nm = f"P{s}L-Q{s + 1}G-NE-CE"
        if (s, nm) in rows:
            r = rows[(s, nm)]
            w(f"| `{nm}` | {_orders3(r['double'])} | {_orders3(r['triple'])} | "
              f"{_fmt_e(r['triple'].at(n_fix))} |")
    w("")

    # ---------------------------------------------------------------- full tables
    w("## Full tables")
    w("")
    w("Columns: observed orders of q, p, H on the double (D) and triple (T) pendulum; "
      "e_q at h = 1/N_fix; Newton iterations per step there (D / T); nominal order; "
      "step sizes where Newton failed (always the largest ones).")
    w("")
    for s in degrees:
        n_fix = _n_fix(study, s)
        w(f"### s = {s} (N_fix = {n_fix}, h = {1 / n_fix:.4g})")
        w("")
        if not quick:
            spread = node_family_spread(rows, s, n_fix)
            w(f"Node families: for every placement other than `-CN` the three families are "
              f"the same method in exact arithmetic (the same polynomial space, the same "
              f"constraint points); their e_q at h = 1/{n_fix} agree to a relative "
              f"{spread:.0e}.")
            w("")
        w("| combination | D q | D p | D H | T q | T p | T H | e_q D | e_q T | Newton D / T "
          "| nominal | Newton failed |")
        w("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for (ss, nm), meas in rows.items():
            if ss != s:
                continue
            d, t = meas["double"], meas["triple"]
            w(f"| `{nm}` | {_fmt_order(d, 'q')} | {_fmt_order(d, 'p')} | {_fmt_order(d, 'H')} | "
              f"{_fmt_order(t, 'q')} | {_fmt_order(t, 'p')} | {_fmt_order(t, 'H')} | "
              f"{_fmt_e(d.at(n_fix))} | {_fmt_e(t.at(n_fix))} | "
              f"{_fmt_its(d.its_at(n_fix))} / {_fmt_its(t.its_at(n_fix))} | "
              f"{get_method(nm).nominal_order} | {_failed(meas)} |")
        w("")

    if study["overdetermined"]:
        w("## More than s + 1 constraint points")
        w("")
        w("With J > s constraint intervals the polynomial of degree s cannot meet the "
          "constraints at all J + 1 points (e.g. s = 1: a chord of constant length through "
          "a midpoint on the circle is a zero step). The study runs them once, h = 1/32:")
        w("")
        w("| combination | J | double | triple |")
        w("|---|---|---|---|")
        for nm, stat in study["overdetermined"]:
            cells = [f"{st} at step {k}" if k is not None else st for st, k in stat.values()]
            w(f"| `{nm}` | {get_method(nm).J} | {cells[0]} | {cells[1]} |")
        w("")
    return "\n".join(L) + "\n"


def _base_key(base: str):
    q = base.split("-")[1]
    return (q[-1] != "G", int(q[1:-1]))


def _n_fix(study, s):
    seq = study["sequence"]
    return min(N_FIX[s], seq[-1]) if not study["quick"] else seq[len(seq) // 2]


def _orders3(m: Measurement) -> str:
    return " / ".join(_fmt_order(m, k) for k in ("q", "p", "H"))


def _fmt_its(x: float) -> str:
    return "–" if not np.isfinite(x) else f"{x:.1f}"


def _summary_text(study: dict) -> str:
    """Placeholder, replaced below once the numbers are known."""
    return ""


# --------------------------------------------------------------------------- CLI
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog=f"{COMMAND}", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="two combinations for s = 1, 2 on a short h range (seconds)")
    parser.add_argument("--out", default=str(DEFAULT_OUT), help="markdown file to write")
    parser.add_argument("--degrees", default=None,
                        help="comma-separated degrees (default 1,2,3,4,5; quick: 1,2)")
    args = parser.parse_args(argv)
    degrees = (tuple(int(x) for x in args.degrees.split(",")) if args.degrees
               else (QUICK_DEGREES if args.quick else DEGREES))
    for s in degrees:
        if s not in N_FIX:
            parser.error(f"`--degrees` must be among {sorted(N_FIX)}, got {s}")
    t0 = time.perf_counter()
    study = run_study(degrees, quick=args.quick,
                      log=lambda msg: print(f"orders: {msg}", file=sys.stderr, flush=True))
    text = render(study)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    print(f"orders: wrote {out} ({time.perf_counter() - t0:.1f} s)", file=sys.stderr)
    return 0
