"""Ultrasonic range finders (MaxBotix-class): a cone of rays per sonar, each robot's sonars at their own rate (its
part's ``rate_hz``, or the times its board fires them: ``Sonars.schedule``), the sonars due at one time in one batched
ray test; the nearest echo in the cone is the range, with range-proportional noise, spurious echoes while the robot
drives, and the minimum range inside the blind zone."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pybullet as pb

from bridge.core.parts import Part, WorldModel
from bridge.core.rng import stream


class SonarParams(Part):
    max_range_m: float
    min_range_m: float
    half_beam_deg: float
    rays: int  # rays per cone
    rate_hz: float
    noise_m: float
    noise_rel: float
    outlier_p: float  # probability of a spurious echo per reading while the robot moves
    angles_deg: tuple[float, ...] = (0.0,)  # one sonar per angle from the heading; the first is the front


class Sonars(WorldModel):
    name = "sonar"
    sensors = ("sonar",)

    def __init__(self, world: Any, robots: list[int], parts: list[SonarParams]) -> None:
        super().__init__(world, robots, parts)
        n, p = len(robots), parts
        self.ranges = [np.full(len(q.angles_deg), q.max_range_m) for q in p]  # each robot's sonars, front first
        self._rng = [stream(world.seed, "robot", r, "sonar") for r in robots]
        counts = [len(q.angles_deg) for q in p]
        # per sonar (every robot's, consecutively): its cast period and next cast time (taken at the quantum end at
        # or after it); the part's rate for all of a robot's sonars until its board sets their times (``schedule``)
        self._period_ns = np.repeat(np.array([round(1e9 / q.rate_hz) for q in p], dtype=np.int64), counts)
        self._next_ns = np.zeros(int(sum(counts)), dtype=np.int64)
        # a cone per sonar; ``_ray_sonar`` numbers every robot's sonars consecutively (robot k's first is
        # ``_base[k]``), ``_ray_owner`` is the robot's row
        cones = [np.linspace(-1, 1, q.rays) * math.radians(q.half_beam_deg) if q.rays > 1 else np.zeros(1) for q in p]
        offsets = [np.concatenate([c + math.radians(a) for a in q.angles_deg]) for c, q in zip(cones, p, strict=True)]
        self._base = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int) if n else np.zeros(0, int)
        self._ray_owner = np.concatenate([np.full(len(o), k) for k, o in enumerate(offsets)]) if n else np.zeros(0, int)
        self._ray_sonar = (
            np.concatenate(
                [
                    self._base[k] + np.repeat(np.arange(m), len(c))
                    for k, (m, c) in enumerate(zip(counts, cones, strict=True))
                ]
            )
            if n
            else np.zeros(0, int)
        )
        self._count = int(sum(counts))
        self._sonar_owner = np.repeat(np.arange(n), counts) if n else np.zeros(0, int)
        self._ray_angle = np.concatenate(offsets) if n else np.zeros(0)
        prof = [world.profiles[r] for r in robots]
        # rays start just outside the body: a cylinder's side, a box's front face (side sonars of a box: assumed at
        # the same distance)
        self._ray_r0 = np.array([(q.length_m / 2 if q.is_box else q.radius_m) + 0.005 for q in prof])
        self._ray_len = np.array([q.max_range_m for q in p])
        self._ray_z = np.array([q.height_m * 0.6 for q in prof])

    def schedule(self, r: int, next_ns: list[int], period_ns: list[int]) -> None:
        """Robot ``r``'s board fires its sonars at known times (an HC-SR04 board's slots): sonar j (the part's order)
        is cast next at the first quantum end at or after ``next_ns[j]``, then every ``period_ns[j]``, in place of
        the part's ``rate_hz``: the world casts only what the board will read. ValueError on a malformed schedule."""
        k = self.local[r]
        m = len(self.parts[k].angles_deg)
        if len(next_ns) != m or len(period_ns) != m or not all(int(v) > 0 for v in period_ns):
            raise ValueError(f"robot {r}: a sonar schedule needs {m} times and {m} positive periods")
        b = int(self._base[k])
        self._next_ns[b : b + m] = [int(v) for v in next_ns]
        self._period_ns[b : b + m] = [int(v) for v in period_ns]

    def sample(self, t_end_ns: int) -> None:
        due = self._next_ns <= t_end_ns
        if due.any():
            self._update(due, t_end_ns)
            nxt, per = self._next_ns[due], self._period_ns[due]
            self._next_ns[due] = nxt + ((t_end_ns - nxt) // per + 1) * per

    def _update(self, due: np.ndarray, t_ns: int) -> None:
        """One ray batch for the due sonar cones of every live robot."""
        w = self.world
        due = due & w.alive[self.ids][self._sonar_owner]
        if not due.any():
            return
        live = np.unique(self._sonar_owner[due])
        rays = due[self._ray_sonar]
        owner = self._ray_owner[rays]
        robot = self.ids[owner]
        ang = w.yaw[robot] + self._ray_angle[rays]
        ca, sa = np.cos(ang), np.sin(ang)
        x, y = w.pos[robot, 0], w.pos[robot, 1]
        r0, r1, z = self._ray_r0[owner], self._ray_r0[owner] + self._ray_len[owner], self._ray_z[owner]
        froms = np.column_stack([x + r0 * ca, y + r0 * sa, z])
        tos = np.column_stack([x + r1 * ca, y + r1 * sa, z])
        hits = pb.rayTestBatch(froms.tolist(), tos.tolist(), numThreads=1, physicsClientId=w.cid)
        frac = np.array([h[2] if h[0] >= 0 else 1.0 for h in hits])
        nearest = np.ones(self._count)
        np.minimum.at(nearest, self._ray_sonar[rays], frac)
        for k in live.tolist():
            q = self.parts[k]
            rng = self._rng[k]
            moving = w.drive_speed[self.robots[k]] > 0.01
            out = self.ranges[k]
            b = int(self._base[k])
            for j in range(len(out)):
                if not due[b + j]:
                    continue
                frac = float(nearest[b + j])
                true_r = frac * q.max_range_m + 0.005
                noise = rng.standard_normal()
                outlier = rng.random() < q.outlier_p
                spurious = rng.uniform(q.min_range_m, q.max_range_m)
                if frac >= 1.0:
                    r = q.max_range_m
                else:
                    r = true_r + noise * (q.noise_m + q.noise_rel * true_r)
                if moving and outlier:
                    r = spurious
                # inside its blind zone the sensor reports its minimum range (as MaxBotix sensors do)
                out[j] = float(min(max(r, q.min_range_m), q.max_range_m))
            if (self.robots[k], "sonar") in w.sensor_faults.faults:  # a faulty sonar (bridge.core.faults)
                out[:] = w.sensor_faults.apply(self.robots[k], "sonar", out.copy(), t_ns)

    def sense(self, r: int) -> dict[str, Any]:
        """The front sonar's range (m), and a robot with more sonars the others', left then right."""
        out = self.ranges[self.local[r]]
        reading: dict[str, Any] = {"sonar_m": float(out[0])}
        if len(out) > 1:
            reading["side_sonars_m"] = tuple(out[1:].tolist())
        return reading


SonarParams.world_model = Sonars
