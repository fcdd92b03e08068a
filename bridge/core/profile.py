"""A robot model's figures as the world, the firmware host and the config checks read them: its body, its battery,
its firmware's loop rate, and its parts (``bridge.core.parts``: a drive, sensors, a conveyor...) with their own.

Each robot plugin (``bridge/robots/<robot>/``) declares one; the figures and their sources are in ``docs/models.md``.
"""


from __future__ import annotations

import math
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict

from bridge.core.parts import Part

P = TypeVar("P", bound=Part)


class RobotProfile(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str
    # body (world): a cylinder of radius_m, or a box of length_m x width_m (radius_m then bounds it: placements keep
    # robots that far apart)
    radius_m: float
    height_m: float
    mass_kg: float
    length_m: float | None = None  # a box body: along the heading
    width_m: float | None = None
    # battery
    battery_capacity_mah: float
    battery_cells: int
    battery_internal_ohm: float
    current_idle_ma: float  # the boards, with the parts idle (each part adds what it draws)
    # firmware
    llc_loop_hz: float
    parts: tuple[Any, ...] = ()  # its Parts, at most one of each kind

    def model_post_init(self, __context: Any) -> None:
        kinds = [type(p) for p in self.parts]
        if not all(isinstance(p, Part) for p in self.parts) or len(set(kinds)) != len(kinds):
            raise ValueError(f"robot profile {self.name!r}: parts must be Parts, at most one of each kind")
        if (self.length_m is None) != (self.width_m is None):
            raise ValueError(f"robot profile {self.name!r}: a box body needs length_m and width_m")
        if self.is_box and self.radius_m < 0.5 * math.hypot(self.length_m, self.width_m) - 1e-9:
            raise ValueError(f"robot profile {self.name!r}: radius_m must bound the box (half its diagonal)")

    @property
    def is_box(self) -> bool:
        return self.length_m is not None

    def part(self, kind: type[P]) -> P | None:
        """Its part of this kind, None if it has none."""
        return next((p for p in self.parts if isinstance(p, kind)), None)

    def part_named(self, name: str) -> Part | None:
        """Its part simulated by the world model called ``name`` (``"conveyor"``), None if it has none."""
        return next((p for p in self.parts if type(p).world_model.name == name), None)

    def with_part(self, part: Part) -> RobotProfile:
        """This profile with ``part`` in place of its part of the same kind."""
        return self.model_copy(update={"parts": tuple(part if type(p) is type(part) else p for p in self.parts)})

    @property
    def capacity(self) -> int:
        """Robots it carries on board (its parts' slots)."""
        return sum(p.capacity for p in self.parts)
