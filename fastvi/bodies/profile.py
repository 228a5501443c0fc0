r"""Prescribed functions of time for drives and loads: :class:`Profile`.

A drive (a prescribed joint angle or displacement) or a time-varying load needs a function
of time the compiled callbacks can evaluate from the parameter vector alone, so the family
is fixed and its six coefficients travel in ``params``:

.. math::

    θ(t) = θ_0 + ω t + \tfrac12 α t^2 + A \sin(Ω t + ψ),
    \qquad θ'(t) = ω + α t + A Ω \cos(Ω t + ψ).

It covers a motor at constant speed, a ramp, and a harmonic excitation, and their sums.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Profile", "PROFILE_SIZE"]

#: floats a profile takes in the parameter vector
PROFILE_SIZE = 6


@dataclass(frozen=True)
class Profile:
    r"""``θ(t) = value + rate·t + ½·acceleration·t² + amplitude·sin(frequency·t + phase)``.

    Parameters
    ----------
    value, rate, acceleration : float, default 0
        The polynomial part.
    amplitude, frequency, phase : float, default 0
        The harmonic part (``frequency`` in rad/s).

    Examples
    --------
    >>> from fastvi.bodies import Profile
    >>> motor = Profile(rate=2.0)            # θ = 2 t
    >>> float(motor(1.5)), float(motor.derivative(1.5))
    (3.0, 2.0)
    """

    value: float = 0.0
    rate: float = 0.0
    acceleration: float = 0.0
    amplitude: float = 0.0
    frequency: float = 0.0
    phase: float = 0.0

    def __post_init__(self):
        for key in ("value", "rate", "acceleration", "amplitude", "frequency", "phase"):
            x = getattr(self, key)
            if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(x):
                raise ValueError(f"Profile: `{key}` must be a finite number, got {x!r}")
            object.__setattr__(self, key, float(x))

    @classmethod
    def constant(cls, value: float) -> "Profile":
        """The constant ``θ(t) = value``."""
        return cls(value=value)

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        return (self.value + self.rate * t + 0.5 * self.acceleration * t * t
                + self.amplitude * np.sin(self.frequency * t + self.phase))

    def derivative(self, t):
        """``θ'(t)``."""
        t = np.asarray(t, dtype=float)
        return (self.rate + self.acceleration * t
                + self.amplitude * self.frequency * np.cos(self.frequency * t + self.phase))

    def second_derivative(self, t):
        """``θ''(t)``."""
        t = np.asarray(t, dtype=float)
        return (self.acceleration
                - self.amplitude * self.frequency ** 2 * np.sin(self.frequency * t + self.phase))

    def pack(self) -> np.ndarray:
        """The six coefficients as the callbacks read them (``½ α`` stored, not ``α``)."""
        return np.array([self.value, self.rate, 0.5 * self.acceleration, self.amplitude,
                         self.frequency, self.phase])


def as_profile(x, name: str, owner: str) -> Profile:
    """A :class:`Profile`, or a number as a constant one; a ValueError naming ``name``."""
    if isinstance(x, Profile):
        return x
    if isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool):
        return Profile.constant(float(x))
    raise TypeError(f"{owner}: `{name}` must be a number or a fastvi.bodies.Profile, got {x!r}")
