"""The TraxBot's conveyor: a stepper-driven belt on its deck that carries scouts in slots and drops each one behind
the ranger when the belt has moved its slot past the end (Couceiro 2013, section 3.2.2).

The world keeps which robots ride on which (``World.carried``) and carries them along; this part decides when a scout
goes down and where: on the floor behind its carrier, facing the carrier's way."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bridge.core.parts import Part, WorldModel


class ConveyorParams(Part):
    slots: int  # scouts it carries
    pitch_m: float = 0.15  # belt per slot
    speed_m_s: float = 0.05
    m_per_step: float = 0.0005  # belt travel per stepper step

    @property
    def capacity(self) -> int:
        return self.slots


class Conveyor(WorldModel):
    name = "conveyor"

    def __init__(self, world: Any, robots: list[int], parts: list[ConveyorParams]) -> None:
        super().__init__(world, robots, parts)
        self.belt_m = np.zeros(len(robots))  # each carrier's belt travel since power-up

    def set_belt(self, r: int, steps: int) -> None:
        """The conveyor's stepper has turned ``steps`` steps since power-up."""
        if self.world.alive[r]:
            k = self.local[r]
            self.belt_m[k] = steps * self.parts[k].m_per_step

    def settle(self, t_end_ns: int) -> None:
        """A robot whose slot the belt has passed drops off behind its carrier."""
        w = self.world
        for i, (carrier, slot) in list(w.carried.items()):
            k = self.local.get(carrier)
            if k is None or self.belt_m[k] + 1e-9 < slot * self.parts[k].pitch_m:
                continue
            yaw = float(w.yaw[carrier])
            back = w.profiles[carrier].radius_m + w.profiles[i].radius_m + 0.02
            x = float(w.pos[carrier, 0]) - back * math.cos(yaw)
            y = float(w.pos[carrier, 1]) - back * math.sin(yaw)
            w.drop_off(i, x, y, yaw, t_end_ns)


ConveyorParams.world_model = Conveyor
