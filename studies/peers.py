r"""Compiled peers for the speed-vs-error study: DOP853, LSODA and Radau from CyRK.

A speed-minded user who does not need exact constraints integrates a hand-written compiled
right-hand side with a compiled adaptive solver. This module is that user's code, so that
``python -m fastvi wpd`` (:mod:`studies.wpd`) can race fastvi against it:

* the **solver**: CyRK's C++ solvers (``CyRK.nbsolve2_ivp``: DOP853, LSODA, Radau; the
  right-hand side is a numba ``cfunc`` called through a C function pointer, no Python in
  the loop). CyRK's older pure-numba ``nbsolve_ivp`` (DOP853 with the right-hand side
  inlined) was measured and is ≈ 1.8× slower on the double pendulum (it keeps a Python-style
  list of every step), so the faster one is used;
* the **right-hand sides**, written by hand with ``@njit`` (no fastvi code):

  (a) the double pendulum in Cartesian index-1 form, ``y = (q, v)``, ``q = (x1, y1, x2, y2)``,
      ``M = diag(m1, m1, m2, m2)``, ``f = −∇V = (0, −m1 g, 0, −m2 g)``, constraints
      ``g1 = ½(x1² + y1² − l1²)``, ``g2 = ½((x2 − x1)² + (y2 − y1)² − l2²)``. The
      acceleration solves

      .. math::

          \begin{pmatrix} M & G^T \\ G & 0 \end{pmatrix}
          \begin{pmatrix} a \\ λ \end{pmatrix} =
          \begin{pmatrix} f \\ −\dot G v \end{pmatrix},
          \qquad (G M^{-1} G^T) λ = G M^{-1} f + \dot G v,\quad a = M^{-1}(f − G^T λ),

      with ``Ġv = (|v1|², |v2 − v1|²)``, the 2×2 system solved inline (Cramer). No
      Baumgarte terms: the constraints drift, and that drift is what is reported;
  (b) the double pendulum in angle coordinates (θ1, θ2 from the downward vertical), its
      best case (no constraints at all):

      .. math::

          D = 2m_1 + m_2 − m_2\cos 2Δ,\ Δ = θ_1 − θ_2,\\
          \ddot θ_1 = \frac{−g(2m_1 + m_2)\sin θ_1 − m_2 g \sin(θ_1 − 2θ_2)
                      − 2\sin Δ\, m_2(\dot θ_2^2 l_2 + \dot θ_1^2 l_1 \cos Δ)}{l_1 D},\\
          \ddot θ_2 = \frac{2\sin Δ\,(\dot θ_1^2 l_1 (m_1 + m_2) + g(m_1 + m_2)\cos θ_1
                      + \dot θ_2^2 l_2 m_2 \cos Δ)}{l_2 D};

  (c) the rotary rod–slider of :mod:`fastvi.scenes.rotary_rod_slider` in its minimal
      coordinates (θ, r) (the scene's constraint is φ = θ), same parameters
      ``(l, mA, mB, k, r0, g)``, ``I = mA l²/3``:

      .. math::

          (I + m_B r^2)\ddot θ = −2 m_B r \dot r \dot θ − (m_A g l/2 + m_B g r)\cos θ,\qquad
          m_B \ddot r = m_B r \dot θ^2 − m_B g \sin θ − k (r − r_0).

Energies (and, for (a), the constraint residuals ``max |g_i(q)|`` in fastvi's own
normalisation) are evaluated afterwards by compiled loops at **every accepted step** of the
solver (CyRK stores each step; no dense output is requested): a denser sample than fastvi's
saved steps (every 0.1 s in the study, ``studies.wpd.config.PEER_SAMPLE_DT``), so never in
the peer's favour.

CyRK is an optional dependency (the ``bench`` extra): ``pip install -e .[bench]`` or
``make bench``. It is imported lazily by :func:`require_cyrk`.
"""

from __future__ import annotations

import time

import numba as nb
import numpy as np
from numba import carray

#: how to get the peer when it is missing
INSTALL_HINT = ("the compiled peer needs CyRK: `pip install -e .[bench]` (or `make bench`, which "
                "installs the bench extra into .venv)")
#: lower bound of the tested CyRK (its C++ ``nbsolve2_ivp`` API)
CYRK_MIN = "0.20"

#: state sizes of the three right-hand sides
N_CART = 8  # (x1, y1, x2, y2, vx1, vy1, vx2, vy2)
N_ANG = 4  # (θ1, θ2, ω1, ω2)
N_SLIDER = 4  # (θ, r, θ̇, ṙ)
#: DOP853 evaluates the right-hand side 12 times per accepted step (CyRK does not count)
DOP853_STAGES = 12


def require_cyrk():
    """Import CyRK, or raise ImportError saying how to install it."""
    try:
        import CyRK  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(INSTALL_HINT) from exc
    return CyRK


def have_cyrk() -> bool:
    try:
        require_cyrk()
    except ImportError:
        return False
    return True


# ----------------------------------------------------------------------------- physics
# All kernels take the parameters as an array, in the scenes' order:
# double pendulum p = (m1, m2, l1, l2, g); rod–slider p = (l, mA, mB, k, r0, g).


@nb.njit(cache=True, inline="always")
def dp_cartesian_rhs(y, p, dy):
    """(a) Index-1 Cartesian double pendulum: ``dy = (v, a)`` (see the module docstring)."""
    m1, m2, g = p[0], p[1], p[4]
    x1, y1, x2, y2 = y[0], y[1], y[2], y[3]
    u1, w1, u2, w2 = y[4], y[5], y[6], y[7]
    dx, dyy = x2 - x1, y2 - y1
    du, dw = u2 - u1, w2 - w1
    # G = [[x1, y1, 0, 0], [−dx, −dy, dx, dy]]; S = G M⁻¹ Gᵀ
    i1, i2 = 1.0 / m1, 1.0 / m2
    s11 = (x1 * x1 + y1 * y1) * i1
    s12 = -(x1 * dx + y1 * dyy) * i1
    s22 = (dx * dx + dyy * dyy) * (i1 + i2)
    # right side G M⁻¹ f + Ġ v, with M⁻¹ f = (0, −g, 0, −g)
    b1 = -y1 * g + (u1 * u1 + w1 * w1)
    b2 = du * du + dw * dw  # G₂ M⁻¹ f = −dy·(−g) + dy·(−g) = 0 for equal gravity per mass
    det = s11 * s22 - s12 * s12
    lam1 = (b1 * s22 - s12 * b2) / det
    lam2 = (s11 * b2 - s12 * b1) / det
    dy[0], dy[1], dy[2], dy[3] = u1, w1, u2, w2
    # a = M⁻¹ f − M⁻¹ Gᵀ λ
    dy[4] = -(x1 * lam1 - dx * lam2) * i1
    dy[5] = -g - (y1 * lam1 - dyy * lam2) * i1
    dy[6] = -(dx * lam2) * i2
    dy[7] = -g - (dyy * lam2) * i2


@nb.njit(cache=True, inline="always")
def dp_angles_rhs(y, p, dy):
    """(b) Double pendulum in angle coordinates (see the module docstring)."""
    m1, m2, l1, l2, g = p[0], p[1], p[2], p[3], p[4]
    t1, t2, w1, w2 = y[0], y[1], y[2], y[3]
    d = t1 - t2
    sd, cd = np.sin(d), np.cos(d)
    den = 2.0 * m1 + m2 - m2 * np.cos(2.0 * d)
    dy[0] = w1
    dy[1] = w2
    dy[2] = (-g * (2.0 * m1 + m2) * np.sin(t1) - m2 * g * np.sin(t1 - 2.0 * t2)
             - 2.0 * sd * m2 * (w2 * w2 * l2 + w1 * w1 * l1 * cd)) / (l1 * den)
    dy[3] = (2.0 * sd * (w1 * w1 * l1 * (m1 + m2) + g * (m1 + m2) * np.cos(t1)
                         + w2 * w2 * l2 * m2 * cd)) / (l2 * den)


@nb.njit(cache=True, inline="always")
def slider_rhs(y, p, dy):
    """(c) Rod–slider in minimal coordinates (θ, r) (see the module docstring)."""
    l, mA, mB, k, r0, g = p[0], p[1], p[2], p[3], p[4], p[5]
    th, r, om, rd = y[0], y[1], y[2], y[3]
    inertia = mA * l * l / 3.0
    c = np.cos(th)
    dy[0] = om
    dy[1] = rd
    dy[2] = (-2.0 * mB * r * rd * om - (mA * g * 0.5 * l + mB * g * r) * c) / (inertia + mB * r * r)
    dy[3] = r * om * om - g * np.sin(th) - k * (r - r0) / mB


@nb.njit(cache=True)
def dp_cartesian_energy(q, v, p):
    m1, m2, g = p[0], p[1], p[4]
    return (0.5 * m1 * (v[0] * v[0] + v[1] * v[1]) + 0.5 * m2 * (v[2] * v[2] + v[3] * v[3])
            + g * (m1 * q[1] + m2 * q[3]))


@nb.njit(cache=True)
def dp_angles_energy(th1, th2, w1, w2, p):
    """``H = ½(m1 + m2) l1² ω1² + ½ m2 l2² ω2² + m2 l1 l2 ω1 ω2 cos Δ − (m1 + m2) g l1 cos θ1
    − m2 g l2 cos θ2`` (the Cartesian ``V = g(m1 y1 + m2 y2)`` in angles)."""
    m1, m2, l1, l2, g = p[0], p[1], p[2], p[3], p[4]
    return (0.5 * (m1 + m2) * l1 * l1 * w1 * w1 + 0.5 * m2 * l2 * l2 * w2 * w2
            + m2 * l1 * l2 * w1 * w2 * np.cos(th1 - th2)
            - (m1 + m2) * g * l1 * np.cos(th1) - m2 * g * l2 * np.cos(th2))


@nb.njit(cache=True)
def slider_energy(th, r, om, rd, p):
    """``H = ½(I + mB r²) θ̇² + ½ mB ṙ² + mA g (l/2) sin θ + mB g r sin θ + ½ k (r − r0)²``."""
    l, mA, mB, k, r0, g = p[0], p[1], p[2], p[3], p[4], p[5]
    inertia = mA * l * l / 3.0
    return (0.5 * (inertia + mB * r * r) * om * om + 0.5 * mB * rd * rd
            + mA * g * 0.5 * l * np.sin(th) + mB * g * r * np.sin(th) + 0.5 * k * (r - r0) ** 2)


@nb.njit(cache=True)
def observe(kind, Y, p):
    """Max ``|H − H(0)|``, max ``|g_i(q)|`` and max ``|(G v)_i|`` over the rows of ``Y``.

    ``kind``: 0 Cartesian pendulum, 1 angle pendulum, 2 rod–slider (the last two have no
    constraints: residuals 0)."""
    dH = 0.0
    gmax = 0.0
    gvmax = 0.0
    H0 = 0.0
    for j in range(Y.shape[0]):
        y = Y[j]
        if kind == 0:
            H = dp_cartesian_energy(y[:4], y[4:], p)
            dx, dyy = y[2] - y[0], y[3] - y[1]
            g1 = 0.5 * (y[0] * y[0] + y[1] * y[1] - p[2] * p[2])
            g2 = 0.5 * (dx * dx + dyy * dyy - p[3] * p[3])
            gv1 = y[0] * y[4] + y[1] * y[5]
            gv2 = dx * (y[6] - y[4]) + dyy * (y[7] - y[5])
            gmax = max(gmax, abs(g1), abs(g2))
            gvmax = max(gvmax, abs(gv1), abs(gv2))
        elif kind == 1:
            H = dp_angles_energy(y[0], y[1], y[2], y[3], p)
        else:
            H = slider_energy(y[0], y[1], y[2], y[3], p)
        if j == 0:
            H0 = H
        dH = max(dH, abs(H - H0))
    return dH, gmax, gvmax


# ----------------------------------------------------------------------------- solver glue
_CFUNCS: dict[str, int] = {}
_SIZES = {"cartesian": N_CART, "angles": N_ANG, "slider": N_SLIDER}
_KIND = {"cartesian": 0, "angles": 1, "slider": 2}
_PARAMS = {"cartesian": 5, "angles": 5, "slider": 6}


def _cfunc_address(system: str) -> int:
    """Address of the ``cfunc`` ``f(dy*, t, y*, args*)`` CyRK calls (compiled once)."""
    if system not in _CFUNCS:
        from CyRK import cyjit

        n, npar = _SIZES[system], _PARAMS[system]
        body = {"cartesian": dp_cartesian_rhs, "angles": dp_angles_rhs, "slider": slider_rhs}[system]

        @cyjit
        def f(dyp, t, yp, ap):
            body(carray(yp, n), carray(ap, npar), carray(dyp, n))

        _CFUNCS[system] = f.address
    return _CFUNCS[system]


_SOLVE = None


def _solver():
    """The compiled call of CyRK's C++ solver (built lazily: CyRK is optional).

    One compiled function solves, copies the stored steps out of CyRK's result and frees it
    (handing CyRK's result object back to Python between calls crashed CyRK 0.20). The copy
    is part of the timing: a memcpy of ``steps × len(y)`` doubles, < 1 % of a run."""
    global _SOLVE
    if _SOLVE is None:
        from CyRK import nbsolve2_ivp

        @nb.njit
        def solve(addr, y0, T, tol, method, args):
            sol = nbsolve2_ivp(addr, (0.0, T), y0, method=method, args=args, rtol=tol, atol=tol)
            Y = sol.y.T.copy()  # a copy: sol.y is a view of memory that free() releases
            steps = np.int64(sol.steps_taken)
            success = sol.success
            status = np.int64(sol.status)
            t_last = sol.t[-1] if sol.size > 0 else 0.0
            sol.free()
            return Y, steps, success, status, t_last

        _SOLVE = solve
    return _SOLVE


def run_peer(system: str, y0, params, *, T: float, tol: float, method: str = "DOP853") -> dict:
    """Integrate ``system`` ("cartesian", "angles", "slider") with CyRK at ``rtol = atol = tol``.

    Only the solver call is timed (``time.process_time``): the C++ solver with the compiled
    right-hand side, storing every accepted step (its default; no dense output, no
    ``t_eval``). The energies and residuals at every stored step are evaluated afterwards.

    Returns
    -------
    dict
        ``cpu`` (s), ``wall`` (s), ``dH`` = max ``|H − H(0)|``, ``g`` = max ``|g_i(q)|`` and
        ``gv`` = max ``|(G v)_i|`` (0 for the unconstrained systems), ``steps`` (accepted),
        ``ok`` (solver success and ``t`` reached ``T``), ``status``.
    """
    require_cyrk()
    addr = _cfunc_address(system)
    solve = _solver()
    y0 = np.ascontiguousarray(y0, dtype=float)
    args = np.ascontiguousarray(params, dtype=float)
    w0, c0 = time.perf_counter(), time.process_time()
    Y, steps, success, status, t_last = solve(addr, y0, float(T), float(tol), method, args)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    dH, g, gv = observe(_KIND[system], Y, args)
    ok = bool(success) and bool(np.isclose(t_last, T)) and bool(np.isfinite(dH))
    return dict(cpu=cpu, wall=wall, dH=float(dH), g=float(g), gv=float(gv), steps=int(steps),
                ok=ok, status=int(status), y_end=Y[-1].copy())


def warm_up_peers(methods=("DOP853", "LSODA", "Radau")) -> None:
    """Compile the right-hand sides, the solver call and the observers before any timing."""
    for system, y0, p in (("cartesian", cartesian_start(), DP_PARAMS),
                          ("angles", angles_start(), DP_PARAMS),
                          ("slider", slider_start(1e3), slider_params(1e3))):
        for method in methods:
            run_peer(system, y0, p, T=0.1, tol=1e-6, method=method)


# ----------------------------------------------------------------------------- problems
#: paper B's double pendulum (the defaults of ``fastvi.scenes.double_pendulum``)
DP_PARAMS = (1.0, 1.0, 1.0, 1.0, 9.81)
THETA0 = (np.pi / 2, np.pi / 2)
#: paper B's rod–slider (``fastvi.scenes.rotary_rod_slider``) without k
SLIDER_L, SLIDER_MA, SLIDER_MB, SLIDER_R0, SLIDER_G = 2.0, 2.0, 5.0, 1.0, 9.81
#: energy stored in the spring at the start of the stiff panel (J): the slider starts
#: stretched by δ = sqrt(2 E/k), so the fast mode carries the same energy at every k and a
#: solver that damps it (BDF) pays in energy error instead of skipping it
SPRING_ENERGY = 1.0


def angles_start(theta=THETA0):
    return np.array([theta[0], theta[1], 0.0, 0.0])


def cartesian_start(theta=THETA0, p=DP_PARAMS):
    from fastvi.scenes.double_pendulum import state_from_angles

    q, v = state_from_angles(theta[0], theta[1], 0.0, 0.0, p[2], p[3])
    return np.concatenate((q, v))


def slider_params(k: float):
    return (SLIDER_L, SLIDER_MA, SLIDER_MB, float(k), SLIDER_R0, SLIDER_G)


def slider_stretch(k: float) -> float:
    """Initial spring stretch δ with ½ k δ² = :data:`SPRING_ENERGY`."""
    return float(np.sqrt(2.0 * SPRING_ENERGY / k))


def slider_start(k: float):
    """(θ, r, θ̇, ṙ) at the start: rod horizontal at rest, spring stretched by δ(k)."""
    return np.array([0.0, SLIDER_R0 + slider_stretch(k), 0.0, 0.0])


def slider_omega(k: float) -> float:
    """Angular frequency of the spring mode, ``sqrt(k/mB)`` (rad/s)."""
    return float(np.sqrt(k / SLIDER_MB))
