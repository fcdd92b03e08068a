"""A light sensor on the robot's top: the illuminance where it stands, from the arena's light field (or the field a
study installs, ``World.lux_field``), with relative noise from the robot's seeded stream."""

from __future__ import annotations

from typing import Any

from bridge.core.parts import Part, WorldModel
from bridge.core.rng import stream


class LightParams(Part):
    noise_rel: float  # relative 1-sigma noise per reading


class LightSensor(WorldModel):
    name = "light"
    sensors = ("light",)

    def __init__(self, world: Any, robots: list[int], parts: list[LightParams]) -> None:
        super().__init__(world, robots, parts)
        self._rng = [stream(world.seed, "robot", r, "light") for r in robots]
        self._lux: list[float] | None = None
        self._t_ns = 0

    def start_quantum(self, t_ns: int, q_ns: int) -> None:
        self._lux = None
        self._t_ns = t_ns + q_ns  # readings are taken at the quantum's end

    def sense(self, r: int) -> dict[str, Any]:
        """Illuminance (lux), never negative."""
        w = self.world
        if self._lux is None:  # once per physics state, for every robot
            x, y = w.pos[:, 0], w.pos[:, 1]
            lux = w.lux_field.lux(x, y) if w.lux_field is not None else w.cfg.light.illuminance(x, y)
            self._lux = lux.tolist()
        k = self.local[r]
        noisy = max(self._lux[r] * (1 + self.parts[k].noise_rel * self._rng[k].standard_normal()), 0.0)
        if (r, "light") in w.sensor_faults.faults:  # a faulty light sensor (bridge.core.faults)
            noisy = w.sensor_faults.apply(r, "light", noisy, self._t_ns)
        return {"lux": noisy}


LightParams.world_model = LightSensor
