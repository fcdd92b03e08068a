"""What the foot-bot's base board senses in the world, for every foot-bot at once: the 24 infrared proximity sensors
(one batched ray test), the 24 light sensors (the arena's light sources), the 4 motor-ground sensors and the 8 base
ground sensors (the arena's
floor patches). All three sample together at the base board's sensor rate; ``seq`` counts the samples, so the
board's wiring sends a new set of readings only when there is one (``take_new``).

The readings are ARGoS's where it has them (``docs/footbot.md`` has the figures and their sources): a proximity
sensor reads ARGoS's curve of the distance to the first thing its ray meets within ``range_m`` of the body (0
nothing, 1 touching: ``argos_proximity``), a light sensor the illuminance of each source
at the robot relative to its peak, times the cosine of the sensor's angle off the source's direction (0 facing
away; no occlusion), a motor-ground sensor the floor's grey level under it, a base ground sensor 1 where that level
is 0.5 or more and 0 below (ARGoS's black-and-white sensors). Each adds Gaussian noise of ``noise`` (ARGoS:
0 by default) and is clipped to [0, 1].
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pybullet as pb

from bridge.core.parts import Part, WorldModel
from bridge.core.rng import stream
from swarm_logic.robots.footbot.interfaces import (
    BASE_GROUND_OFFSETS_M,
    LIGHT_COUNT,
    MOTOR_GROUND_OFFSETS_M,
    PROXIMITY_COUNT,
    PROXIMITY_RANGE_M,
    ring_angles,
)

RAY_GAP_M = 0.002  # the proximity rays start this far outside the body (not to meet it)


class FootbotSensorsParams(Part):
    """The base board's sensors: the rings' sizes and range, the sampling rate, the noise."""

    proximity_count: int = PROXIMITY_COUNT
    proximity_range_m: float = PROXIMITY_RANGE_M
    proximity_height_m: float = 0.06  # the ring's height above the floor (ARGoS footbot_entity.cpp)
    light_count: int = LIGHT_COUNT
    ground_offsets_m: tuple[tuple[float, float], ...] = MOTOR_GROUND_OFFSETS_M
    base_ground_offsets_m: tuple[tuple[float, float], ...] = BASE_GROUND_OFFSETS_M
    rate_hz: float = 10.0  # one sample per ARGoS control step (assumed for the real boards: docs/footbot.md)
    proximity_noise: float = 0.0
    light_noise: float = 0.0
    ground_noise: float = 0.0


class FootbotSensors(WorldModel):
    name = "footbot_sensors"

    def __init__(self, world: Any, robots: list[int], parts: list[FootbotSensorsParams]) -> None:
        super().__init__(world, robots, parts)
        n = len(robots)
        self.seq = 0
        self._taken = [0] * n  # the sample each robot's board last took
        self._period_ns = round(1e9 / max(q.rate_hz for q in parts)) if n else 0
        self._next_ns = 0
        self._rng = [stream(world.seed, "robot", r, "footbot_sensors") for r in robots]
        prof = [world.profiles[r] for r in robots]
        self._r0 = np.array([q.radius_m + RAY_GAP_M for q in prof])  # rays start just outside the body
        self._angles = [np.array(ring_angles(q.proximity_count)) for q in parts]
        self._light_angles = [np.array(ring_angles(q.light_count)) for q in parts]
        self.proximity: list[list[float]] = [[0.0] * q.proximity_count for q in parts]
        self.light: list[list[float]] = [[0.0] * q.light_count for q in parts]
        self.ground: list[list[float]] = [[1.0] * len(q.ground_offsets_m) for q in parts]
        self.base_ground: list[list[int]] = [[1] * len(q.base_ground_offsets_m) for q in parts]

    def sample(self, t_end_ns: int) -> None:
        if len(self.robots) and t_end_ns >= self._next_ns:
            self._update()
            self.seq += 1
            while self._next_ns <= t_end_ns:
                self._next_ns += self._period_ns

    def _update(self) -> None:
        w = self.world
        live = [k for k, r in enumerate(self.robots) if w.alive[r]]
        if not live:
            return
        self._proximity(live)
        cfg = w.cfg
        for k in live:
            r, q, rng = self.robots[k], self.parts[k], self._rng[k]
            x, y, yaw = float(w.pos[r, 0]), float(w.pos[r, 1]), float(w.yaw[r])
            light = np.zeros(q.light_count)
            for s in cfg.light.sources:
                rel = math.exp(-((x - s.x) ** 2 + (y - s.y) ** 2) / (2 * s.sigma_m * s.sigma_m))
                b = math.atan2(s.y - y, s.x - x) - yaw
                light += rel * np.maximum(0.0, np.cos(self._light_angles[k] - b))
            self.light[k] = _noisy(light, q.light_noise, rng)
            c, sn = math.cos(yaw), math.sin(yaw)
            gx = np.array([x + ox * c - oy * sn for ox, oy in q.ground_offsets_m])
            gy = np.array([y + ox * sn + oy * c for ox, oy in q.ground_offsets_m])
            self.ground[k] = _noisy(np.asarray(cfg.arena.grey_at(gx, gy), dtype=float), q.ground_noise, rng)
            bx = np.array([x + ox * c - oy * sn for ox, oy in q.base_ground_offsets_m])
            by = np.array([y + ox * sn + oy * c for ox, oy in q.base_ground_offsets_m])
            self.base_ground[k] = (np.asarray(cfg.arena.grey_at(bx, by)) >= 0.5).astype(int).tolist()

    def _proximity(self, live: list[int]) -> None:
        """One ray batch for every live foot-bot's proximity ring."""
        w = self.world
        froms: list[list[float]] = []
        tos: list[list[float]] = []
        for k in live:
            r, q = self.robots[k], self.parts[k]
            ang = float(w.yaw[r]) + self._angles[k]
            ca, sa = np.cos(ang), np.sin(ang)
            x, y, r0, z = float(w.pos[r, 0]), float(w.pos[r, 1]), self._r0[k], q.proximity_height_m
            r1 = r0 + q.proximity_range_m - RAY_GAP_M  # the ring reaches proximity_range_m from the body
            froms += np.column_stack([x + r0 * ca, y + r0 * sa, np.full(len(ang), z)]).tolist()
            tos += np.column_stack([x + r1 * ca, y + r1 * sa, np.full(len(ang), z)]).tolist()
        hits = pb.rayTestBatch(froms, tos, numThreads=1, physicsClientId=w.cid)
        frac = np.array([h[2] if h[0] >= 0 else 1.0 for h in hits])
        i = 0
        for k in live:
            q = self.parts[k]
            m = q.proximity_count
            d = RAY_GAP_M + frac[i:i + m] * (q.proximity_range_m - RAY_GAP_M)  # from the body, as ARGoS measures
            self.proximity[k] = _noisy(argos_proximity(d, frac[i:i + m] < 1.0), q.proximity_noise, self._rng[k])
            i += m

    def take_new(self, r: int) -> dict[str, Any]:
        """Robot ``r``'s rings and ground sensors when they were sampled since it last took them, else nothing (its
        board's inputs hold the last sample)."""
        k = self.local[r]
        if self._taken[k] == self.seq:
            return {}
        self._taken[k] = self.seq
        return {"proximity": self.proximity[k], "light": self.light[k], "ground": self.ground[k],
                "base_ground": self.base_ground[k]}


def argos_proximity(d: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """ARGoS's foot-bot proximity curve (footbot_proximity_default_sensor.cpp): 1 closer than 9.9 mm, else
    0.0100527 / (d + 0.000163144) (about 0.1 at the 0.1 m range), 0 when the ray meets nothing."""
    v = np.where(d < 0.009889556, 1.0, 0.0100527 / (d + 0.000163144))
    return np.where(hit, v, 0.0)


def _noisy(values: np.ndarray, sigma: float, rng: np.random.Generator) -> list[float]:
    """``values`` with Gaussian noise of ``sigma`` (none drawn when 0), clipped to [0, 1]."""
    if sigma > 0:
        values = values + sigma * rng.standard_normal(len(values))
    return np.clip(values, 0.0, 1.0).tolist()


FootbotSensorsParams.world_model = FootbotSensors
