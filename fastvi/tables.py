"""Quadrature rules, control nodes, Lagrange basis tables and method names.

Everything here is plain NumPy, computed once per method and memoised. The kernels only
ever see the arrays of a :class:`Method`.

Method names
------------
A name has the form ``P<s>L-Q<r><G|L>[-N<E|L|C>][-C<spec>]``:

``P<s>L``
    Lagrange polynomial of degree ``s`` on ``s + 1`` control points per step (paper B).
``Q<r>G`` / ``Q<r>L``
    ``r``-point Gauss–Legendre (``G``) or Gauss–Lobatto (``L``) quadrature of the
    unconstrained action.
``-NE`` / ``-NL`` / ``-NC``
    control-node family: equidistant, Gauss–Lobatto (default), Chebyshev–Gauss–Lobatto.
``-CE`` / ``-CN`` / ``-CL<k>`` / ``-CG<k>``
    constraint points: step ends only (paper B), every control node (default), ``k``
    Gauss–Lobatto points, or ``k`` Gauss points plus the two step ends (paper A).

Paper B's names (``P1L-Q2G``, ``P2L-Q3G``, ...) are accepted as they are and mean fastvi's
default combination for that degree and quadrature: Gauss–Lobatto control nodes with the
constraint enforced at every control node (``-NL-CN``), which reaches order ``2s`` when
``r >= s``. Paper B's own scheme, equidistant nodes with the constraint at the step ends
only, is ``P<s>L-Q<r>G-NE-CE``; it is order 2 whatever ``s`` (see ``docs/method.md``).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from fractions import Fraction
from functools import cached_property, lru_cache

import numpy as np

__all__ = [
    "Method",
    "method",
    "gauss_legendre",
    "gauss_lobatto",
    "control_nodes",
    "lagrange_basis",
    "NODE_FAMILIES",
    "CONSTRAINT_PLACEMENTS",
]

#: Control-node families by their one-letter code in a method name.
NODE_FAMILIES = {"E": "equidistant", "L": "lobatto", "C": "chebyshev"}
#: Constraint placements by their code in a method name (``L``/``G`` take a count).
CONSTRAINT_PLACEMENTS = {"E": "ends", "N": "nodes", "L": "lobatto", "G": "gauss"}

_MAX_POINTS = 40  # the root finders below are accurate well beyond the 12 promised

_NAME_RE = re.compile(
    r"^P(?P<s>\d+)L-Q(?P<r>\d+)(?P<q>[GL])(?:-N(?P<nodes>[ELC]))?(?:-C(?P<cons>[ENLG])(?P<k>\d+)?)?$"
)


# --------------------------------------------------------------------------- quadrature
def _legendre_and_derivative(k: int, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P_k(x) and P_k'(x) on [-1, 1] by the three-term recurrence."""
    p0 = np.ones_like(x)
    if k == 0:
        return p0, np.zeros_like(x)
    p1 = x.copy()
    for j in range(2, k + 1):
        p0, p1 = p1, ((2 * j - 1) * x * p1 - (j - 1) * p0) / j
    with np.errstate(divide="ignore", invalid="ignore"):  # P' is unused at x = ±1
        dp = k * (x * p1 - p0) / (x * x - 1.0)
    return p1, dp


def _check_count(r: int, least: int, what: str) -> int:
    if not isinstance(r, (int, np.integer)) or isinstance(r, bool):
        raise TypeError(f"`{what}` must be an integer, got {r!r}")
    if not least <= r <= _MAX_POINTS:
        raise ValueError(f"`{what}` must be between {least} and {_MAX_POINTS}, got {r}")
    return int(r)


@lru_cache(maxsize=None)
def _gauss_legendre(r: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(r)
    # one Newton polish of the roots in the recurrence keeps them at round-off for large r
    p, dp = _legendre_and_derivative(r, x)
    x = x - p / dp
    _, dp = _legendre_and_derivative(r, x)
    w = 2.0 / ((1.0 - x * x) * dp * dp)
    c, b = _symmetric(0.5 * (x + 1.0), 0.5 * w)
    c.setflags(write=False)
    b.setflags(write=False)
    return c, b


def _symmetric(c: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Make a rule on [0, 1] symmetric in floating point: c[-1-i] = 1 − c[i], b[-1-i] = b[i]."""
    k = len(c)
    c = c.copy()
    b = 0.5 * (b + b[::-1])
    for i in range(k // 2):
        c[k - 1 - i] = 1.0 - c[i]
    if k % 2:
        c[k // 2] = 0.5
    return c, b / math.fsum(b)


def gauss_legendre(r: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre rule with ``r`` points on [0, 1].

    Exact for polynomials of degree ``2r - 1``:
    ``∫_0^1 f(t) dt ≈ Σ_i b_i f(c_i)``.

    Returns
    -------
    c, b : ndarray, shape (r,)
        Nodes (increasing, interior) and positive weights summing to 1. Read-only.
    """
    return _gauss_legendre(_check_count(r, 1, "r"))


@lru_cache(maxsize=None)
def _gauss_lobatto(r: int) -> tuple[np.ndarray, np.ndarray]:
    if r == 2:
        x = np.array([-1.0, 1.0])
    else:
        # interior nodes: roots of P'_{r-1}, started from Chebyshev–Gauss–Lobatto points
        k = r - 1
        x = -np.cos(np.pi * np.arange(r) / k)
        inner = x[1:-1].copy()
        for _ in range(100):
            p, dp = _legendre_and_derivative(k, inner)
            # P'' from the Legendre ODE: (1 - x^2) P'' = 2x P' - k(k+1) P
            d2p = (2 * inner * dp - k * (k + 1) * p) / (1 - inner * inner)
            step = dp / d2p
            inner = inner - step
            if np.max(np.abs(step)) < 1e-16:
                break
        x = np.concatenate(([-1.0], np.sort(inner), [1.0]))
        # symmetric by construction in exact arithmetic: enforce it in floating point
        x = 0.5 * (x - x[::-1])
    p, _ = _legendre_and_derivative(r - 1, x)
    w = 2.0 / (r * (r - 1) * p * p)
    c, b = _symmetric(0.5 * (x + 1.0), 0.5 * w)
    c[0], c[-1] = 0.0, 1.0
    c.setflags(write=False)
    b.setflags(write=False)
    return c, b


def gauss_lobatto(r: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Lobatto rule with ``r >= 2`` points on [0, 1], both ends included.

    Exact for polynomials of degree ``2r - 3``.

    Returns
    -------
    c, b : ndarray, shape (r,)
        Nodes with ``c[0] = 0``, ``c[-1] = 1``, and positive weights summing to 1. Read-only.
    """
    return _gauss_lobatto(_check_count(r, 2, "r"))


def control_nodes(s: int, family: str = "lobatto") -> np.ndarray:
    """The ``s + 1`` control points ``0 = τ_0 < … < τ_s = 1`` of a degree-``s`` step.

    Parameters
    ----------
    s : int
        Polynomial degree, ``s >= 1``.
    family : {"equidistant", "lobatto", "chebyshev"}
        Equidistant (paper B), Gauss–Lobatto, or Chebyshev–Gauss–Lobatto points.
    """
    s = _check_count(s, 1, "s")
    if family == "equidistant":
        tau = np.arange(s + 1) / s
    elif family == "lobatto":
        tau = np.array(gauss_lobatto(s + 1)[0])
    elif family == "chebyshev":
        tau = 0.5 * (1.0 - np.cos(np.pi * np.arange(s + 1) / s))
        tau = 0.5 * (tau + (1.0 - tau[::-1]))  # exact symmetry
    else:
        raise ValueError(
            f"`family` must be one of {sorted(NODE_FAMILIES.values())}, got {family!r}"
        )
    tau[0], tau[-1] = 0.0, 1.0
    return tau


# --------------------------------------------------------------------------- Lagrange basis
def lagrange_basis(tau: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values and derivatives of the Lagrange basis on nodes ``tau`` at points ``x``.

    ``ℓ_ν(x) = Π_{μ≠ν} (x − τ_μ)/(τ_ν − τ_μ)`` and its derivative, evaluated by products
    (no division by ``x − τ``) in extended precision, then rounded once. Where ``x``
    coincides with a node the values are exactly ``δ``.

    Returns
    -------
    ell, dell : ndarray, shape (len(tau), len(x))
        ``ell[ν, i] = ℓ_ν(x_i)``, ``dell[ν, i] = ℓ'_ν(x_i)``.
    """
    t = np.asarray(tau, dtype=np.longdouble)
    xs = np.asarray(x, dtype=np.longdouble)
    k = len(t)
    ell = np.zeros((k, len(xs)), dtype=np.longdouble)
    dell = np.zeros_like(ell)
    for nu in range(k):
        others = [mu for mu in range(k) if mu != nu]
        denom = np.prod([t[nu] - t[mu] for mu in others]) if others else np.longdouble(1)
        val = np.ones(len(xs), dtype=np.longdouble)
        for mu in others:
            val = val * (xs - t[mu])
        ell[nu] = val / denom
        der = np.zeros(len(xs), dtype=np.longdouble)
        for a in others:
            term = np.ones(len(xs), dtype=np.longdouble)
            for mu in others:
                if mu != a:
                    term = term * (xs - t[mu])
            der = der + term
        dell[nu] = der / denom
    ell = ell.astype(np.float64)
    dell = dell.astype(np.float64)
    for i, xi in enumerate(np.asarray(x, dtype=np.float64)):
        hit = np.nonzero(np.asarray(tau, dtype=np.float64) == xi)[0]
        if hit.size:
            ell[:, i] = 0.0
            ell[hit[0], i] = 1.0
    return ell, dell


def _exact_sum(col: np.ndarray, target: float) -> None:
    """Adjust ``col`` in place by at most an ulp or two so that its exact sum is ``target``.

    First ``col[0]`` is recomputed from the others with a correctly rounded sum; if the
    exact (rational) sum still misses, the entry with the finest ulp absorbs the rest:
    every other term is a multiple of that ulp, so the corrected entry is representable.
    """
    target = Fraction(target)  # float − Fraction would be a float
    col[0] = float(target - sum(Fraction(x) for x in col[1:]))
    if sum(Fraction(x) for x in col) == target:
        return
    nonzero = [i for i in range(len(col)) if col[i] != 0.0]
    k = min(nonzero, key=lambda i: np.spacing(abs(col[i])))
    col[k] = float(target - sum(Fraction(x) for i, x in enumerate(col) if i != k))
    if sum(Fraction(x) for x in col) != target:  # pragma: no cover - not seen for s <= 12
        raise ArithmeticError("could not make a basis table consistent in floating point")


def _consistent(ell: np.ndarray, dell: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Make every column a partition of unity with derivatives summing to zero, exactly.

    The step works with increments from ``q_k``; that silently assumes these identities.
    Off by a few ulps, the scheme stops being exactly variational and energy drifts
    linearly (``docs/method.md``, section 9), so the tables are corrected until the exact
    sum of every column of values is 1 and of derivatives is 0.
    """
    ell = ell.copy()
    dell = dell.copy()
    for i in range(ell.shape[1]):
        _exact_sum(ell[:, i], 1.0)
        _exact_sum(dell[:, i], 0.0)
    return ell, dell


# --------------------------------------------------------------------------- Method
@dataclass(frozen=True, eq=False)
class Method:
    """A Galerkin variational integrator, as the tables the kernels need.

    Attributes
    ----------
    name : str
        Canonical name, ``P<s>L-Q<r><G|L>-N<x>-C<y>``.
    s, r, J : int
        Degree, quadrature points, number of constraint intervals (``J + 1`` constraint
        points including both step ends).
    quadrature, nodes, constraints : str
        ``"gauss"``/``"lobatto"``; control-node family; constraint placement.
    tau : (s+1,) control points. c, b : (r,) quadrature nodes and weights.
    d : (J+1,) constraint points, ``d[0] = 0``, ``d[J] = 1``.
    L, Ld : (s+1, r) ``ℓ_ν(c_i)`` and ``ℓ'_ν(c_i)``.
    Lc : (s+1, J+1) ``ℓ_ν(d_j)``.
    E : (s+1, s+1) ``ℓ_μ(1 + τ_ν)``, the predictor that extrapolates the previous
        step's polynomial onto this step's control points.
    nominal_order : int or None
        The order this combination is known to reach (2 for step-end constraints, ``2s``
        for constraints at the ``s + 1`` Lobatto points, capped by the quadrature), or None
        where the order table (``docs/orders.md``) shows no general rule.
    """

    name: str
    s: int
    r: int
    J: int
    quadrature: str
    nodes: str
    constraints: str
    tau: np.ndarray = field(repr=False)
    c: np.ndarray = field(repr=False)
    b: np.ndarray = field(repr=False)
    d: np.ndarray = field(repr=False)
    L: np.ndarray = field(repr=False)
    Ld: np.ndarray = field(repr=False)
    Lc: np.ndarray = field(repr=False)
    E: np.ndarray = field(repr=False)
    nominal_order: int | None = 2

    @cached_property
    def kernel_tables(self):
        """The arrays the step kernel reads, as a :class:`fastvi.kernels.layout.Tables`.

        Besides ``b, L, Ld, Lc, E, tau`` it holds the tables of the mechanics Newton matrix
        (``docs/method.md`` §10): with ``A[ν, μ−1] = Σ_i b_i ℓ'_ν(c_i) ℓ'_μ(c_i)``
        (ν = 0…s−1, μ = 1…s; the mass block of the step equations is ``(1/h) A ⊗ M``),
        ``Ainv = A⁻¹``, the impulse coupling ``W = Lc_C A⁻¹ Lc_B`` of the Schur complement
        ``S_{jj'} = h W[j−1, j'] G_j M⁻¹ G_{j'}ᵀ``, and the mass block ``Am`` of the rows
        ν = 1…s, exactly symmetric (:func:`_mass_block`; its last row is the mass part of
        ``∂P/∂Q^μ``).
        """
        from .kernels.layout import Tables

        s, J = self.s, self.J
        A = np.einsum("i,vi,ui->vu", self.b, self.Ld[:s], self.Ld[1:])
        invertible = bool(np.linalg.cond(A) < 1e12)  # r < s Gauss points make A singular
        Ainv = np.linalg.inv(A) if invertible else np.zeros((s, s))
        # s = 1 too: for a linear potential and a constant mass its mechanics iteration is
        # Newton's method at a fraction of the full Newton's cost
        # (docs/decisions/0001-mechanics-newton.md)
        mech = invertible
        W = self.Lc[1:, 1:].T @ Ainv @ self.Lc[:s, :J]
        E2 = hermite_predictor(self.tau)
        return Tables(self.b, self.L, self.Ld, self.Lc, self.E, self.tau,
                      np.ascontiguousarray(Ainv), np.ascontiguousarray(W), mech,
                      np.ascontiguousarray(self.c), np.ascontiguousarray(self.d),
                      np.ascontiguousarray(E2), _mass_block(self.b, self.Ld),
                      np.ascontiguousarray(self.L @ self.b), _basis_at_end(self.tau))


def hermite_predictor(tau: np.ndarray) -> np.ndarray:
    """Weights of the predictor from the last two steps, ``(s + 3, s + 1)``.

    The polynomial of degree s + 2 through the last step's control points (local time
    τ_0 … τ_s), the nearest one of the step before (τ_{s−1} − 1) and with the step-end
    velocity as its slope at τ = 1 (value ``h v_k``), evaluated at this step's nodes
    ``1 + τ_ν``: row 0 weighs the earlier point, rows 1 … s + 1 the last step's, row s + 2
    ``h v_k``. Against the degree-2s polynomial through both steps' 2s + 1 points it
    extrapolates from points nearer the new step and from the slope the step left, which
    the end projection made exact to the method's order. On the chaotic double pendulum its
    guesses are closer in the median by 1.7× (s = 2, h = 0.02) and 10× (s = 4, h = 0.025)
    and at the 90th percentile by 1.3–5×; for s = 3, whose degree-6 guess was already
    good, about as close (docs/decisions/0008-predictor.md). The value rows of each column sum to 1
    exactly and its slope row is untouched (a guess of increments from ``q_k``).
    """
    s = len(tau) - 1
    nodes = np.concatenate([[tau[s - 1] - 1.0], tau])
    deg = s + 2
    V = np.zeros((deg + 1, deg + 1))
    V[: s + 2] = np.vander(nodes, deg + 1, increasing=True)
    V[s + 2, 1:] = np.arange(1, deg + 1)  # d/dτ of τ^p at τ = 1
    at = np.vander(1.0 + tau, deg + 1, increasing=True)
    EH = np.linalg.solve(V.T, at.T)  # (inputs, targets): at @ V⁻¹, transposed
    values, _ = _consistent(EH[: s + 2], np.zeros((s + 2, s + 1)))
    EH[: s + 2] = values
    return np.ascontiguousarray(EH)


def _basis_at_end(tau: np.ndarray) -> np.ndarray:
    """``(2, s + 1)``: the barycentric weights ``1 / Π_{k≠μ} (τ_μ − τ_k)`` of the control
    nodes and the slopes ``ℓ'_μ(1)`` of their Lagrange basis at the step's end, from exact
    rational arithmetic on the rounded nodes (the variable-step predictor's tables)."""
    t = [Fraction(x) for x in tau]
    out = np.zeros((2, len(t)))
    for mu, tm in enumerate(t):
        den = Fraction(1)
        for k, tk in enumerate(t):
            if k != mu:
                den *= tm - tk
        out[0, mu] = float(1 / den)
        # ℓ'_μ(1) = Σ_{j≠μ} Π_{k≠μ,j} (1 − τ_k) / den
        slope = Fraction(0)
        for j in range(len(t)):
            if j != mu:
                prod = Fraction(1)
                for k, tk in enumerate(t):
                    if k not in (mu, j):
                        prod *= 1 - tk
                slope += prod
        out[1, mu] = float(slope / den)
    return out


def _mass_block(b: np.ndarray, Ld: np.ndarray) -> np.ndarray:
    """``K[ν−1, μ−1] = Σ_i b_i ℓ'_ν(c_i) ℓ'_μ(c_i)`` for ν, μ = 1…s, exactly symmetric.

    For a constant ``M`` the mass part of ``∂S/∂Q^ν`` is ``(1/h) M Σ_μ K[ν−1, μ−1] ΔQ^μ``
    (ν ≥ 1) and that of ``∂S/∂Q^0`` minus their sum. The discrete Noether theorem needs the
    quadratic form to be exactly symmetric and its rows to sum exactly to zero: the kernel
    gets the second by forming row 0 as a sum, this table the first by rounding each exact
    (rational) entry once and mirroring it. Rounded separately, a few ulps of asymmetry
    made the spherical pendulum's L_z drift linearly (4.8e-11 over 10⁵ steps, against
    8.8e-14).
    """
    s = Ld.shape[0] - 1
    bq = [Fraction(x) for x in b]
    K = np.zeros((s, s))
    for nu in range(1, s + 1):
        for mu in range(nu, s + 1):
            exact = sum(w * Fraction(Ld[nu, i]) * Fraction(Ld[mu, i]) for i, w in enumerate(bq))
            K[nu - 1, mu - 1] = K[mu - 1, nu - 1] = float(exact)
    return K


def _constraint_points(code: str, k: int | None, tau: np.ndarray) -> tuple[str, np.ndarray]:
    if code == "E":
        return "ends", np.array([0.0, 1.0])
    if code == "N":
        return "nodes", np.array(tau)
    if k is None:
        raise ValueError(f"constraint placement `C{code}` needs a point count, e.g. `C{code}3`")
    if code == "L":
        if k < 2:
            raise ValueError(f"`CL<k>` needs k >= 2 Gauss–Lobatto points, got {k}")
        return f"lobatto{k}", np.array(gauss_lobatto(k)[0])
    if k < 1:
        raise ValueError(f"`CG<k>` needs k >= 1 Gauss points, got {k}")
    return f"gauss{k}", np.concatenate(([0.0], gauss_legendre(k)[0], [1.0]))


def _nominal_order(s: int, r: int, quad: str, nodes: str, cons: str) -> int | None:
    """The order a combination is known to reach (``docs/orders.md``), or None.

    Constraints at the step ends give order 2 whatever ``s``; constraints at the ``s + 1``
    Gauss–Lobatto points (``-NL-CN`` or ``-CL<s+1>``) give ``2s``, limited by the quadrature's
    exactness. Other placements lose order in ways the order table documents case by case
    (e.g. equidistant nodes with ``-CN`` give 4 for s = 3 and 5), so no order is promised.
    """
    if cons == "ends":
        return 2
    if (cons == "nodes" and nodes == "L") or cons == f"lobatto{s + 1}":
        exact = 2 * r - 1 if quad == "G" else 2 * r - 3
        return min(2 * s, exact + 1)
    return None


def _canonical(name: str) -> str:
    m = _NAME_RE.match(name.strip().upper())
    if m is None:
        raise ValueError(
            f"`method` {name!r} is not a method name; expected 'P<s>L-Q<r><G|L>' with optional "
            "'-N<E|L|C>' (control nodes) and '-C<E|N|L<k>|G<k>>' (constraint points), "
            "e.g. 'P2L-Q3G' or paper B's variant 'P2L-Q3G-NE-CE'"
        )
    nodes = m["nodes"] or "L"
    cons = m["cons"] or "N"
    k = m["k"] or ""
    if cons in "EN" and k:
        raise ValueError(f"constraint placement `C{cons}` takes no count, got `C{cons}{k}`")
    return f"P{m['s']}L-Q{m['r']}{m['q']}-N{nodes}-C{cons}{k}"


@lru_cache(maxsize=None)
def _build(canonical: str) -> Method:
    m = _NAME_RE.match(canonical)
    s, r, quad = int(m["s"]), int(m["r"]), m["q"]
    _check_count(s, 1, "degree s")
    _check_count(r, 1 if quad == "G" else 2, "quadrature points r")
    tau = control_nodes(s, NODE_FAMILIES[m["nodes"]])
    c, b = gauss_legendre(r) if quad == "G" else gauss_lobatto(r)
    cons, d = _constraint_points(m["cons"], int(m["k"]) if m["k"] else None, tau)
    if len(d) - 1 > s:
        # J·m constraint equations against s·n position unknowns: more constraint intervals
        # than control points over-determine the step (singular Newton matrix, or no
        # convergence; docs/orders.md)
        fits = f"`-CL{s + 1}`" + (f" or `-CG{s - 1}`" if s >= 2 else "")
        raise ValueError(
            f"constraint placement of `method` {canonical!r} has {len(d)} constraint points; a "
            f"degree-{s} step takes at most s + 1 = {s + 1} (e.g. {fits})"
        )
    L, Ld = _consistent(*lagrange_basis(tau, c))
    Lc, _ = lagrange_basis(tau, d)
    Lc, _ = _consistent(Lc, np.zeros_like(Lc))
    E, _ = lagrange_basis(tau, 1.0 + tau)
    E, _ = _consistent(E, np.zeros_like(E))
    arrays = {}
    for key, val in dict(tau=tau, c=c, b=b, d=d, L=L, Ld=Ld, Lc=Lc, E=E).items():
        arr = np.ascontiguousarray(val, dtype=np.float64)
        arr.setflags(write=False)
        arrays[key] = arr
    return Method(
        name=canonical,
        s=s,
        r=r,
        J=len(d) - 1,
        quadrature="gauss" if quad == "G" else "lobatto",
        nodes=NODE_FAMILIES[m["nodes"]],
        constraints=cons,
        nominal_order=_nominal_order(s, r, quad, m["nodes"], cons),
        **arrays,
    )


def method(name: str | Method) -> Method:
    """The :class:`Method` for a name (memoised), or ``name`` itself if it is one.

    Parameters
    ----------
    name : str or Method
        ``P<s>L-Q<r><G|L>[-N<E|L|C>][-C<E|N|L<k>|G<k>>]`` (case-insensitive; see the module
        docstring). Omitted parts take the defaults ``-NL-CN``.

    Returns
    -------
    Method
        The same object for every spelling of one combination.

    Raises
    ------
    ValueError
        For a name outside the grammar or an invalid count (e.g. ``Q1L``, ``CL1``).

    Examples
    --------
    >>> method("P2L-Q3G").name
    'P2L-Q3G-NL-CN'
    >>> method("P2L-Q3G-NE-CE").constraints      # paper B's scheme
    'ends'
    """
    if isinstance(name, Method):
        return name
    if not isinstance(name, str):
        raise TypeError(f"`method` must be a method name (str) or a Method, got {type(name).__name__}")
    return _build(_canonical(name))
