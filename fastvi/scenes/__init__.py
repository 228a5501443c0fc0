"""Ready-made mechanisms, each a function returning a :class:`fastvi.Model`.

Every scene model carries ``initial_state(...)`` turning natural coordinates (angles from
the downward vertical, angular velocities) into a consistent Cartesian ``(q0, v0)``, and is
registered in :data:`SCENES` by name.
"""

from .chain import chain
from .closed_chain import closed_chain
from .double_pendulum import double_pendulum
from .four_bar import four_bar
from .kapitza import kapitza_pendulum
from .ladder import ladder
from .pendulum import pendulum
from .rotary_rod_slider import rotary_rod_slider
from .slider_crank import slider_crank
from .spherical_pendulum import spherical_pendulum
from .tree import tree
from .triple_pendulum import triple_pendulum


def _rigid(name: str):
    """The rigid-body scene ``fastvi.bodies.scenes.<name>``, imported on first use (the rigid
    bodies' modules stay out of ``import fastvi``)."""
    def make(*args, **kwargs):
        from ..bodies import scenes

        return getattr(scenes, name)(*args, **kwargs)

    make.__name__ = make.__qualname__ = name
    make.__doc__ = f"See :func:`fastvi.bodies.scenes.{name}`."
    return make


#: Scene constructors by name (used by the CLI, the docs and pickling of scene models).
SCENES = {
    "pendulum": pendulum,
    "double_pendulum": double_pendulum,
    "rotary_rod_slider": rotary_rod_slider,
    "spherical_pendulum": spherical_pendulum,
    "triple_pendulum": triple_pendulum,
    "four_bar": four_bar,
    "chain": chain,
    "closed_chain": closed_chain,
    "ladder": ladder,
    "tree": tree,
    "kapitza_pendulum": kapitza_pendulum,
    "slider_crank": slider_crank,
    # rigid bodies in director coordinates (fastvi.bodies.scenes)
    "heavy_top": _rigid("heavy_top"),
    "lagrange_top": _rigid("lagrange_top"),
    "fast_top": _rigid("fast_top"),
    "spatial_slider_crank": _rigid("spatial_slider_crank"),
    "bricard": _rigid("bricard"),
    "flyball_governor": _rigid("flyball_governor"),
    "body_chain": _rigid("body_chain"),
}

__all__ = ["SCENES", "pendulum", "double_pendulum", "rotary_rod_slider", "triple_pendulum",
           "spherical_pendulum", "four_bar", "chain", "closed_chain", "ladder", "tree",
           "kapitza_pendulum", "slider_crank"]
