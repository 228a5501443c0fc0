r"""The parameter vector of a mechanism: the tables the compiled callbacks read.

The callbacks (:mod:`fastvi.bodies.callbacks`) are written once for every mechanism; what a
mechanism *is* travels in ``params``. Its layout (offsets in floats):

=====================  ================================================================
``[0, HEADER)``        header: offsets of the row and load tables, counts
``[HEADER, HEADER+n)`` ``c``: the linear potential ``V_lin = c·q`` (gravity)
row table              ``m`` records of ``ROW_W`` floats, one per constraint row
load table             ``LOAD_CAPACITY(n, m)`` records of ``LOAD_W`` floats
=====================  ================================================================

so its length depends on ``n`` and ``m`` only (unless a mechanism has more loads than the
capacity), and ``fastvi.Model`` compiles the callbacks once per ``(n, m)``.

**Rows.** Every constraint of the library is at most bilinear in ``q``. A row is

.. math::

    g = f_1(t)\, U_1·W_1 + f_2(t)\, U_2·W_2 + c_0 - s(t),

where each ``U, W`` is a *vector expression*: a linear combination of the eight 3-vectors
``Q_j`` of the row's two bodies (``φ, d₁, d₂, d₃`` of body A, then of body B) plus a
constant 3-vector (``EXPR`` = 8 weights + 3 constants). A point ``X`` of body A is the
weights ``(1, X₁, X₂, X₃)`` on A's slots, an axis ``u`` the weights ``(0, u₁, u₂, u₃)``; on
the ground both are constants. A static row has ``f₁ = 1``, ``f₂ = 0``, ``s = 0``; a driven
angle ``f₁ = cos θ(t)``, ``f₂ = −sin θ(t)``; a driven displacement ``s = θ(t)``. Then
``∂g/∂Q_j = Σ f (u_j W + w_j U)`` and the Hessian is constant per row,
``∂²g/∂Q_i∂Q_j = Σ f (u_i w_j + w_i u_j) 1₃``.

**Loads.** A record of ``LOAD_W`` floats: kind, bodies, three vector expressions, stiffness,
damping, rest length or angle, and a :class:`~fastvi.bodies.profile.Profile`.
"""

from __future__ import annotations

import numpy as np

from .profile import PROFILE_SIZE
from .rigid import Ground, PointMass

# ---------------------------------------------------------------- header
HEADER = 8
H_ROWS, H_LOADS, H_NLOADS, H_M, H_N = 0, 1, 2, 3, 4

# ---------------------------------------------------------------- vector expressions
SLOTS = 8  # φ, d1, d2, d3 of body A, then of body B
EXPR = SLOTS + 3

# ---------------------------------------------------------------- rows
STATIC, DRIVE_ANGLE, DRIVE_SHIFT = 0, 1, 2
R_KIND, R_OFFA, R_NA, R_OFFB, R_NB = 0, 1, 2, 3, 4
R_U1 = 5
R_W1 = R_U1 + EXPR
R_U2 = R_W1 + EXPR
R_W2 = R_U2 + EXPR
R_C0 = R_W2 + EXPR
R_LAW = R_C0 + 1
ROW_W = R_LAW + PROFILE_SIZE

# ---------------------------------------------------------------- loads
SPRING, VECTOR_SPRING, ROTARY_SPRING, TORQUE, FORCE = 1, 2, 3, 4, 5
L_KIND, L_OFFA, L_NA, L_OFFB, L_NB = 0, 1, 2, 3, 4
L_V1 = 5
L_V2 = L_V1 + EXPR
L_V3 = L_V2 + EXPR
L_K = L_V3 + EXPR
L_C = L_K + 1
L_REST = L_C + 1
L_LAW = L_REST + 1
LOAD_W = L_LAW + PROFILE_SIZE


def load_capacity(n: int, m: int, count: int = 0) -> int:
    """Load records the parameter vector holds: ``n + m`` (so that the length depends on the
    sizes alone), or the next power of two above ``count`` for a mechanism with more loads."""
    cap = n + m
    while cap < count:
        cap *= 2
    return cap


def params_size(n: int, m: int, count: int = 0) -> int:
    """Length of the parameter vector of a mechanism of ``n`` coordinates and ``m`` rows."""
    return HEADER + n + m * ROW_W + load_capacity(n, m, count) * LOAD_W


# ---------------------------------------------------------------- building expressions
def slots_of(body) -> int:
    """Coordinate 3-vectors of a body: 4 (rigid), 1 (point mass), 0 (ground)."""
    if isinstance(body, Ground):
        return 0
    return 1 if isinstance(body, PointMass) else 4


def point(side: int, body, X) -> np.ndarray:
    """The expression of the point ``X`` (principal body coordinates; world on the ground)
    of ``body`` on ``side`` 0 (A) or 1 (B)."""
    e = np.zeros(EXPR)
    X = np.asarray(X, dtype=float)
    if isinstance(body, Ground):
        e[SLOTS:] = X
    else:
        e[4 * side] = 1.0
        if slots_of(body) == 4:
            e[4 * side + 1: 4 * side + 4] = X
    return e


def direction(side: int, body, u) -> np.ndarray:
    """The expression of the body-fixed direction ``u`` of ``body`` on ``side``."""
    e = np.zeros(EXPR)
    u = np.asarray(u, dtype=float)
    if isinstance(body, Ground):
        e[SLOTS:] = u
    else:
        e[4 * side + 1: 4 * side + 4] = u
    return e


def constant(c) -> np.ndarray:
    """A constant world vector as an expression."""
    e = np.zeros(EXPR)
    e[SLOTS:] = c
    return e


def row_record(kind: int, off_a: int, n_a: int, off_b: int, n_b: int, terms, c0: float = 0.0,
               law=None) -> np.ndarray:
    """One row of the table: ``terms`` is one or two pairs ``(U, W)`` of expressions."""
    r = np.zeros(ROW_W)
    r[R_KIND], r[R_OFFA], r[R_NA], r[R_OFFB], r[R_NB] = kind, off_a, n_a, off_b, n_b
    for (U, W), (iu, iw) in zip(terms, ((R_U1, R_W1), (R_U2, R_W2))):
        r[iu: iu + EXPR] = U
        r[iw: iw + EXPR] = W
    r[R_C0] = c0
    if law is not None:
        r[R_LAW: R_LAW + PROFILE_SIZE] = law
    return r


def row_columns(record: np.ndarray) -> list[int]:
    """The columns of ``G`` a row may touch: the coordinates of every slot with a non-zero
    weight in one of its expressions (what the Jacobian callback writes)."""
    cols = []
    for j in range(SLOTS):
        side = j // 4
        off, count = (record[R_OFFA], record[R_NA]) if side == 0 else (record[R_OFFB], record[R_NB])
        if j % 4 >= count:
            continue
        if any(record[base + j] != 0.0 for base in (R_U1, R_W1, R_U2, R_W2)):
            start = int(off) + 3 * (j % 4)
            cols.extend((start, start + 1, start + 2))
    return cols


def pack(n: int, linear: np.ndarray, rows: np.ndarray, loads: np.ndarray) -> np.ndarray:
    """The parameter vector: header, linear potential ``c`` (n), rows (m × ROW_W), loads."""
    m = rows.shape[0]
    count = loads.shape[0]
    p = np.zeros(params_size(n, m, count))
    p[H_ROWS] = HEADER + n
    p[H_LOADS] = HEADER + n + m * ROW_W
    p[H_NLOADS], p[H_M], p[H_N] = count, m, n
    p[HEADER: HEADER + n] = linear
    if m:
        p[HEADER + n: HEADER + n + m * ROW_W] = rows.ravel()
    if count:
        start = int(p[H_LOADS])
        p[start: start + count * LOAD_W] = loads.ravel()
    return p


def structural(params: np.ndarray) -> list[int]:
    """The entries of a parameter vector that say what the mechanism is rather than a
    quantity of it — the header, and each row's and load record's kind and bodies — for
    ``Model(fixed_params=...)``: the derivatives by the parameters leave them out."""
    out = list(range(HEADER))
    start, m = int(params[H_ROWS]), int(params[H_M])
    for r in range(m):
        out += range(start + r * ROW_W + R_KIND, start + r * ROW_W + R_NB + 1)
    start = int(params[H_LOADS])
    for r in range((params.shape[0] - start) // LOAD_W):
        out += range(start + r * LOAD_W + L_KIND, start + r * LOAD_W + L_NB + 1)
    return out


def rows_of(params: np.ndarray) -> np.ndarray:
    """The row table (m, ROW_W) of a parameter vector (a view)."""
    start, m = int(params[H_ROWS]), int(params[H_M])
    return params[start: start + m * ROW_W].reshape(m, ROW_W)
