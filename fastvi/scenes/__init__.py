"""Ready-made mechanisms, each a function returning a :class:`fastvi.Model`.

Every scene model carries ``initial_state(...)`` turning natural coordinates (angles from
the downward vertical, angular velocities) into a consistent Cartesian ``(q0, v0)``, and is
registered in :data:`SCENES` by name.
"""

from .double_pendulum import double_pendulum
from .pendulum import pendulum

#: Scene constructors by name (used by the CLI, the docs and pickling of scene models).
SCENES = {
    "pendulum": pendulum,
    "double_pendulum": double_pendulum,
}

__all__ = ["SCENES", "pendulum", "double_pendulum"]
