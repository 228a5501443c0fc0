r"""The time-reversible adaptive step: how long the next step is.

Hairer & Söderlind's explicit, time-reversible step-size rule (SIAM J. Sci. Comput. 26,
1838–1851, 2005), with the step density of the kinetic energy on the energy shell: with
``KE(q) = E0 − V(q)`` (E0 the energy of the start) and an energy scale ``K_r``,

    ρ(q) = sqrt(1 + KE(q) / K_r),      G(q, v) = dρ/dτ = −∇V(q)·v / (2 (K_r + KE(q))),

along the flow in the fictive time τ, dt/dτ = 1/ρ. With ε the step where the motion is slow
(KE ≪ K_r), step k has the length ``h_k = ε / ρ_{k+1/2}``, where

    ρ_{1/2} = ρ(q_0) + (ε/2) G(q_0, v_0),      ρ_{k+3/2} = ρ_{k+1/2} + ε G(q_{k+1}, v_{k+1}).

The rule is explicit (no extra equations in a step) and symmetric: with a symmetric step
(every Lobatto–Gauss method of fastvi) and G odd in v, the map (q_k, v_k, ρ_{k−1/2}) →
(q_{k+1}, v_{k+1}, ρ_{k+1/2}) is time-reversible. It is *not* symplectic: no modified
Hamiltonian bounds its energy error (reversibility does near quasi-periodic motion; on a
chaotic one it may random-walk), so docs/decisions/0002-adaptive-step.md measures it.
Steps shrink like 1/|v| where the motion is fast (a pendulum whipping over): at equal
maximum energy error over T = 1000 s of the chaotic double pendulum, 1.34–1.40× fewer steps
than the fixed step.

The state of the rule lives in the ``info`` vector of :func:`.drive.run` (slots ``I_KR`` …
``I_RHO`` of :mod:`.layout`); ``I_KR = 0`` is a fixed-step run, for which nothing here runs.
"""

import numpy as np

from .._numba import hot_inline, ptr
from .layout import (H_FG, I_E0, I_KR, I_RHO, I_T, I_TC, I_TEND, PGRAD, POT,
                     linear_potential)


@hot_inline
def density(md, q, v, ws, E0, Kr):
    """(ρ(q), G(q, v)) of the module docstring; ``ws.g`` and ``ws.fa`` are scratch. A
    potential declared linear has its gradient in ``ws.Fg`` (−∇V, once the first step set
    it): no callback for it then."""
    md.fns[POT](ptr(q), ptr(q), ptr(md.prm), ptr(ws.g))
    ke = max(E0 - ws.g[0], 0.0)
    rate = 0.0
    if linear_potential(md) and ws.hold[H_FG] != 0:
        for a in range(q.shape[0]):
            rate -= ws.Fg[a] * v[a]
    else:
        md.fns[PGRAD](ptr(q), ptr(q), ptr(md.prm), ptr(ws.fa))
        for a in range(q.shape[0]):
            rate += ws.fa[a] * v[a]
    return np.sqrt(1.0 + ke / Kr), -rate / (2.0 * (Kr + ke))


@hot_inline
def next_step(md, eps, state, ws, info):
    """The length of the next step from ``ε`` (``info[I_RHO]``, started from the state at
    the first step), ending exactly at ``info[I_TEND]``: the last step is the time left,
    and the one before takes half of it when less than two steps remain (no sliver of a
    step at the end). Sets ``ws.time`` and returns the length."""
    if info[I_RHO] == 0.0:
        rho, g = density(md, state[0], state[2], ws, info[I_E0], info[I_KR])
        info[I_RHO] = rho + 0.5 * eps * g
    hk = eps / info[I_RHO]
    left = info[I_TEND] - info[I_T]
    if hk >= left:
        hk = left
    elif 2.0 * hk > left:
        hk = 0.5 * left
    ws.time[0] = info[I_T]
    ws.time[1] = info[I_T] + hk if hk < left else info[I_TEND]
    return hk


@hot_inline
def advance(md, eps, hk, state, ws, info):
    """After a step of length ``hk`` (rows 0–2 of ``state`` hold its end): the time, summed
    with its rounding error carried (Kahan), and the density of the next step."""
    y = hk - info[I_TC]
    t = info[I_T] + y
    info[I_TC] = (t - info[I_T]) - y
    info[I_T] = t if ws.time[1] < info[I_TEND] else info[I_TEND]
    _, g = density(md, state[0], state[2], ws, info[I_E0], info[I_KR])
    info[I_RHO] += eps * g


@hot_inline
def finished(info):
    """Whether an adaptive run has reached its end time (never, for a fixed step)."""
    return info[I_KR] > 0.0 and info[I_T] >= info[I_TEND]
