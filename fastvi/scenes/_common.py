"""Helpers shared by scene modules."""

from __future__ import annotations

import numpy as np


def check_positive(**values: float) -> None:
    """Raise naming the first argument that is not a positive finite number."""
    for key, val in values.items():
        if not (isinstance(val, (int, float, np.integer, np.floating)) and np.isfinite(val) and val > 0):
            raise ValueError(f"`{key}` must be positive and finite, got {val!r}")


def attach(model, scene: str, kwargs: dict, **helpers):
    """Record how to rebuild the scene (pickling) and attach its helpers to the model."""
    model._recipe = (scene, dict(kwargs))
    for name, fn in helpers.items():
        setattr(model, name, fn)
    return model
