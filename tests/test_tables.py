"""The tables are the method: quadrature exactness, basis identities, name parsing."""

import math

import numpy as np
import pytest

from fastvi import tables
from fastvi.tables import control_nodes, gauss_legendre, gauss_lobatto, lagrange_basis, method


def _moment_error(c, b, degree):
    return max(abs(np.dot(b, c**k) - 1.0 / (k + 1)) for k in range(degree + 1))


@pytest.mark.parametrize("r", range(1, 13))
def test_gauss_legendre_is_exact_to_degree_2r_minus_1(r):
    c, b = gauss_legendre(r)
    assert np.all(np.diff(c) > 0) and np.all(b > 0)
    assert _moment_error(c, b, 2 * r - 1) < 1e-15 * 4  # measured ≤ 2.2e-16
    # and not beyond: the error on x^(2r) is the theoretical (r!)^4 / ((2r+1) ((2r)!)^2)
    theory = math.factorial(r) ** 4 / ((2 * r + 1) * math.factorial(2 * r) ** 2)
    if theory > 1e-12:
        err = 1.0 / (2 * r + 1) - np.dot(b, c ** (2 * r))
        assert err == pytest.approx(theory, rel=1e-3)


@pytest.mark.parametrize("r", range(2, 13))
def test_gauss_lobatto_is_exact_to_degree_2r_minus_3_and_includes_the_ends(r):
    c, b = gauss_lobatto(r)
    assert c[0] == 0.0 and c[-1] == 1.0 and np.all(np.diff(c) > 0) and np.all(b > 0)
    assert _moment_error(c, b, 2 * r - 3) < 1e-15 * 4  # measured ≤ 2.2e-16
    for i in range(r // 2):  # symmetric in floating point
        assert c[r - 1 - i] == 1.0 - c[i] and b[r - 1 - i] == b[i]


@pytest.mark.parametrize("family", ["equidistant", "lobatto", "chebyshev"])
@pytest.mark.parametrize("s", [1, 2, 3, 5, 8])
def test_lagrange_basis_reproduces_polynomials_of_degree_s(family, s):
    tau = control_nodes(s, family)
    x = np.linspace(-0.3, 1.7, 23)
    ell, dell = lagrange_basis(tau, x)
    rng = np.random.default_rng(s)
    coef = rng.normal(size=s + 1)
    f = np.polynomial.polynomial.polyval(tau, coef)
    df = np.polynomial.polynomial.polyval(x, np.polynomial.polynomial.polyder(coef))
    np.testing.assert_allclose(f @ ell, np.polynomial.polynomial.polyval(x, coef), atol=1e-12)
    np.testing.assert_allclose(f @ dell, df, atol=1e-10)


def test_lagrange_basis_is_exactly_kronecker_at_the_nodes():
    tau = control_nodes(4, "lobatto")
    ell, _ = lagrange_basis(tau, tau)
    np.testing.assert_array_equal(ell, np.eye(5))


@pytest.mark.parametrize("name", ["P1L-Q2G", "P2L-Q3G", "P3L-Q4G", "P4L-Q5G", "P5L-Q6G", "P6L-Q7G-NE",
                                  "P5L-Q7L-NC-CG3", "P8L-Q9G"])
def test_method_tables_are_a_partition_of_unity_in_floating_point(name):
    """Rows used with increments from q_k must sum to exactly 1 (values) and 0 (derivatives):
    a few ulps off makes the scheme non-variational and the energy drift linearly."""
    m = method(name)
    for i in range(m.r):
        assert math.fsum(m.L[:, i]) == 1.0
        assert math.fsum(m.Ld[:, i]) == 0.0
    for j in range(m.J + 1):
        assert math.fsum(m.Lc[:, j]) == 1.0
    for nu in range(m.s + 1):
        assert math.fsum(m.E[:, nu]) == 1.0


@pytest.mark.parametrize("name", ["P2L-Q3G", "P3L-Q4G", "P4L-Q5G", "P5L-Q7L-NC-CG3", "P8L-Q9G"])
def test_mass_block_is_exactly_symmetric_and_correctly_rounded(name):
    """The constant-mass residual's quadratic form: asymmetric by an ulp, the discrete
    Noether theorem fails and a conserved momentum drifts linearly (tests of the spherical
    pendulum's L_z)."""
    from fractions import Fraction

    m = method(name)
    K = m.kernel_tables.Am
    assert K.shape == (m.s, m.s)
    assert np.array_equal(K, K.T)
    for nu in range(1, m.s + 1):
        for mu in range(1, m.s + 1):
            exact = sum(Fraction(b) * Fraction(m.Ld[nu, i]) * Fraction(m.Ld[mu, i])
                        for i, b in enumerate(m.b))
            assert K[nu - 1, mu - 1] == float(exact)
    # the same numbers as the mechanics matrix's A (rows 1…s−1) and As (row s), to rounding
    A = np.einsum("i,vi,ui->vu", m.b, m.Ld, m.Ld[1:])[1:]
    assert np.allclose(K, A, rtol=1e-13, atol=1e-13 * np.abs(A).max())


def test_paper_b_names_mean_the_order_2s_default():
    m = method("P2L-Q3G")
    assert m.name == "P2L-Q3G-NL-CN"
    assert (m.s, m.r, m.quadrature, m.nodes, m.constraints) == (2, 3, "gauss", "lobatto", "nodes")
    assert m.nominal_order == 4
    b = method("P2L-Q3G-NE-CE")
    assert (b.nodes, b.constraints, b.J, b.nominal_order) == ("equidistant", "ends", 1, 2)
    np.testing.assert_array_equal(b.d, [0.0, 1.0])


def test_method_names_are_memoised_and_case_insensitive():
    assert method("p2l-q3g") is method("P2L-Q3G-NL-CN")


@pytest.mark.parametrize("bad", ["RK4", "P0L-Q2G", "P2L-Q0G", "P2L-Q3G-CL", "P2L-Q3G-CN3", "P2L-Q1L", "P2L-Q3G-CL1"])
def test_bad_method_names_are_rejected_naming_the_argument(bad):
    with pytest.raises(ValueError, match=r"method|degree|quadrature|C[LGN]"):
        method(bad)


def test_method_type_is_checked():
    with pytest.raises(TypeError, match="`method`"):
        method(3)


def test_constraint_point_families():
    assert method("P3L-Q4G-CL4").d.shape == (4,)
    g = method("P3L-Q4G-CG2")
    assert g.d[0] == 0.0 and g.d[-1] == 1.0 and g.J == 3
    np.testing.assert_allclose(g.d[1:-1], gauss_legendre(2)[0])


def test_node_family_must_be_known():
    with pytest.raises(ValueError, match="`family`"):
        control_nodes(3, "random")
    assert set(tables.NODE_FAMILIES.values()) == {"equidistant", "lobatto", "chebyshev"}


@pytest.mark.parametrize("name", ["P1L-Q2G-CL3", "P1L-Q2G-CG1", "P2L-Q3G-CL4", "P3L-Q4G-CG3"])
def test_more_constraint_points_than_the_degree_allows_are_refused(name):
    """J > s over-determines the step (docs/orders.md measured singular or stalled Newton)."""
    with pytest.raises(ValueError, match=r"at most s \+ 1"):
        method(name)


def test_nominal_order_is_promised_only_where_measured():
    assert method("P3L-Q4G").nominal_order == 6
    assert method("P3L-Q4G-NE-CL4").nominal_order == 6  # the same s + 1 Lobatto points
    assert method("P3L-Q2G").nominal_order == 4  # capped by the quadrature
    assert method("P5L-Q6G-NE-CN").nominal_order is None  # measured 4, no general rule


@pytest.mark.parametrize("s", [1, 2, 3, 4, 5])
def test_two_step_predictor_is_the_hermite_polynomial_of_degree_s_plus_2(s):
    """The predictor's table reproduces every polynomial of degree ≤ s + 2 from its value at
    τ_{s−1} − 1 and at the last step's nodes and its slope at τ = 1, and no polynomial of
    degree s + 3 (so it is that interpolant, not another); its value rows sum to exactly 1
    (a guess of increments: a constant shift of the points moves it by the same shift)."""
    from fastvi.tables import hermite_predictor

    tau = method(f"P{s}L-Q{s + 1}G").tau
    EH = hermite_predictor(tau)
    assert EH.shape == (s + 3, s + 1)
    nodes = np.concatenate([[tau[s - 1] - 1.0], tau])

    def guess(p):
        return nodes ** p @ EH[: s + 2] + (p if p else 0.0) * EH[s + 2]

    for p in range(s + 3):
        assert np.allclose(guess(p), (1.0 + tau) ** p, rtol=0, atol=1e-11), p
    assert np.abs(guess(s + 3) - (1.0 + tau) ** (s + 3)).max() > 1e-3
    for nu in range(s + 1):
        assert math.fsum(EH[: s + 2, nu]) == 1.0
