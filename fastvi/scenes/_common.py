"""Helpers shared by scene modules."""

from __future__ import annotations

import numpy as np

from ..drawing import for_scene


def check_positive(**values: float) -> None:
    """Raise naming the first argument that is not a positive finite number."""
    for key, val in values.items():
        if not (isinstance(val, (int, float, np.integer, np.floating)) and np.isfinite(val) and val > 0):
            raise ValueError(f"`{key}` must be positive and finite, got {val!r}")


def attach(model, scene: str, kwargs: dict, drawing=None, **helpers):
    """Record how to rebuild the scene (pickling) and attach its drawing and helpers."""
    model.recipe = (scene, dict(kwargs))
    if drawing is not None:
        model.drawing = for_scene(drawing, scene, kwargs)
    for name, fn in helpers.items():
        setattr(model, name, fn)
    return model
