"""The controller API, in the spirit of ARGoS: ``init`` / ``step`` / ``reset`` / ``destroy``.

A controller sees only its ``Robot`` (devices, clock, parameters, random stream); it knows nothing of
the simulator. The runner calls ``step()`` every ``period_s`` of the robot's clock.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any, ClassVar

if TYPE_CHECKING:
    from swarm_logic.robot import Robot


class Controller(ABC):
    period_s: float = 0.1
    defaults: ClassVar[dict[str, Any]] = {}  # parameters and their defaults: configs are checked against them

    def init(self, robot: Robot) -> None:
        self.robot = robot

    @abstractmethod
    def step(self) -> None: ...

    def reset(self) -> None:
        """Return to the state right after ``init``."""

    def destroy(self) -> None:
        """Leave the robot safe (motors stopped)."""
