"""A robot's parts as the world simulates them: a drive, a sensor, a conveyor, soon legs.

A robot plugin lists its parts in its profile (``RobotProfile.parts``), each a frozen set of figures (a ``Part``)
that names the world model simulating it. The world builds one model per kind of part, for every robot that has
one, vectorised across them (as ARGoS's sensors and actuators are plugins the core only calls), and calls it at
fixed points of a quantum; the core knows no part by name.

Most robots are one rigid box or cylinder of their profile's size that the world makes; a part may make its robot's
body itself instead (``WorldModel.build_body``: a multibody with jointed legs), and may ask for a finer physics step
than the session's (``Part.physics_hz``).

A quantum, as the world runs it::

    start_quantum            (commands of the last tick are in: set the targets)
    repeat per physics step:  before_step -> pybullet step -> scripted bodies -> after_step
    the true poses are read back
    settle(t_end)            (what the quantum's motion changes: a carried robot goes down)
    the batteries drain by load_a (what the parts draw beyond the board's idle current)
    drive_speed               (how fast each robot's drive is driving it, for the sensors)
    sample(t_end)            (sensors whose readings are updated at their own rate)

and between quanta ``sense(r)`` gives what robot ``r``'s board reads from the part.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict

if TYPE_CHECKING:
    from bridge.core.world import World


class Part(BaseModel):
    """A part's figures in a robot's profile; ``world_model`` is the class that simulates every part of its kind."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    world_model: ClassVar[type[WorldModel]]

    @property
    def capacity(self) -> int:
        """Robots this part carries on board (a conveyor's slots; most parts carry none)."""
        return 0

    @property
    def physics_hz(self) -> float:
        """The physics rate the part needs at least (Hz; 0: the session's ``world.physics_hz`` is fine): a session
        with this part steps at the higher of the two."""
        return 0.0


class WorldModel:
    """One kind of part for every robot that has it. ``robots`` are their ids in robot order, ``parts`` their
    figures; ``local[r]`` is robot ``r``'s row in the model's arrays. Hooks do nothing unless overridden."""

    name: ClassVar[str]
    #: the readings it makes that a ``sensor`` fault can take (``sonar``, ``encoder``, ``light``): it passes each
    #: fresh one through ``world.sensor_faults.apply``
    sensors: ClassVar[tuple[str, ...]] = ()
    #: the robot fault kinds it carries out itself (a drive's ``wheel_slip``, ``motor_stall``: ``wheel_fault``)
    faults: ClassVar[tuple[str, ...]] = ()

    def __init__(self, world: World, robots: list[int], parts: list[Any]) -> None:
        self.world = world
        self.robots = robots
        self.ids = np.array(robots, dtype=int)
        self.parts = parts
        self.local = {r: k for k, r in enumerate(robots)}

    @classmethod
    def build_body(cls, world: World, part: Any, profile: Any, pose: tuple[float, float, float]) -> int | None:
        """Make the robot's body at ``pose`` (x, y, yaw) and return its pybullet id, for a part that is more than
        the profile's rigid box or cylinder (jointed legs); None, as most parts do: the world makes that body. Called
        before any model exists, in robot order."""
        return None

    def start_quantum(self, t_ns: int, q_ns: int) -> None: ...

    def before_step(self) -> None: ...

    def after_step(self) -> None: ...

    def settle(self, t_end_ns: int) -> None: ...

    def load_a(self, load: np.ndarray) -> None:
        """Add the current the part draws (A) to ``load``, a per-robot array."""

    def drive_speed(self, speed: np.ndarray) -> None:
        """A drive writes how fast it is driving each of its robots (m/s) into ``speed`` (what shakes a sensor)."""

    def sample(self, t_end_ns: int) -> None: ...

    def sense(self, r: int) -> dict[str, Any]:
        """What robot ``r``'s board reads from this part now, by name."""
        return {}

    def kill(self, r: int) -> None:
        """Robot ``r`` is dead: the part stops."""

    def close(self) -> None: ...
