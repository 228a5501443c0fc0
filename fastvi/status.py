"""Status codes of the kernels and their messages (programs branch on numbers, people read words)."""

from enum import IntEnum

__all__ = ["Status", "MESSAGES"]


class Status(IntEnum):
    """Outcome of an integration. ``>= 0`` is success; negative codes are failures by cause."""

    SUCCESS = 0
    TERMINATED = 1
    NEWTON_NOT_CONVERGED = -1
    SINGULAR_JACOBIAN = -2
    NONFINITE = -3
    SINGULAR_MASS = -4
    SINGULAR_CONSTRAINTS = -5
    UNRELIABLE = -6


MESSAGES = {
    Status.SUCCESS: "The integration reached the final time.",
    Status.TERMINATED: "A termination event occurred.",
    Status.NEWTON_NOT_CONVERGED: "Newton's method did not converge within `max_iter` iterations; "
    "try a smaller step `h`.",
    Status.SINGULAR_JACOBIAN: "The Newton matrix is singular to working precision "
    "(constraint Jacobian losing rank, or a step too large).",
    Status.NONFINITE: "A model callback or the Newton iteration produced NaN or inf.",
    Status.SINGULAR_MASS: "The mass matrix is singular at the end of a step.",
    Status.SINGULAR_CONSTRAINTS: "G M⁻¹ Gᵀ is singular at the end of a step "
    "(the constraint Jacobian lost rank).",
    Status.UNRELIABLE: "Every step converged, but the reliability monitor found the trajectory "
    "untrustworthy (energy, constraints or step displacement beyond what a step that resolves "
    "the motion leaves); try a smaller step `h`.",
}
