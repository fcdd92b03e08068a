"""The controller API, in the spirit of ARGoS: ``init`` / ``step`` / ``reset`` / ``destroy``.

A controller sees only its ``Robot`` (devices, clock, parameters, random stream); it knows nothing of
the simulator. The runner calls ``step()`` every ``period_s`` of the robot's clock.

Two hooks serve a ground station (``swarm_logic.mavlink.face``): ``set_param`` changes a parameter while the robot
runs, ``telemetry`` names a few numbers of the behaviour's state.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any, ClassVar

if TYPE_CHECKING:
    from swarm_logic.robot import Robot


class Controller(ABC):
    period_s: float = 0.1
    defaults: ClassVar[dict[str, Any]] = {}  # parameters and their defaults: configs are checked against them
    # parameters read only by ``init``: ``set_param`` stores them for the next start (a reboot) and no sooner
    static_params: ClassVar[frozenset[str]] = frozenset()

    def init(self, robot: Robot) -> None:
        self.robot = robot

    @classmethod
    def with_defaults(cls, params: dict[str, Any]) -> dict[str, Any]:
        """``defaults`` overlaid with ``params``; ValueError naming any parameter the controller does not have."""
        unknown = sorted(set(params) - set(cls.defaults))
        if unknown:
            raise ValueError(f"{cls.__name__}: unknown parameters {unknown}; known: {sorted(cls.defaults)}")
        return {**cls.defaults, **params}

    @abstractmethod
    def step(self) -> None: ...

    def reset(self) -> None:
        """Return to the state right after ``init``."""

    def destroy(self) -> None:
        """Leave the robot safe (motors stopped)."""

    def set_param(self, name: str, value: Any) -> None:
        """Change parameter ``name`` at run time: stored in ``robot.params`` (a restart keeps it) and, unless it is
        one of ``static_params``, in ``self.p`` where the controller keeps its parameters there. ValueError for an
        unknown name or a value the controller refuses (overrides check theirs, then call this)."""
        if name not in self.defaults:
            raise ValueError(f"unknown parameter {name!r}")
        self.robot.params[name] = value
        p = getattr(self, "p", None)
        if isinstance(p, dict) and name not in self.static_params:
            p[name] = value

    def telemetry(self) -> dict[str, float | int]:
        """A few numbers of the behaviour's state for a ground station, by name (at most 10 characters)."""
        return {}
