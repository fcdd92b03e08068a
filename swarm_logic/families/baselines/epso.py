"""EPSO, the Extended PSO of Pugh & Martinoli (2006, 2007) as the thesis benchmarks it (section 8.1.1).

Standard PSO in which a robot's social attractor comes only from the robots it hears, within ``range_m`` (single
hop, one broadcast per robot per iteration, no relaying, no connectivity maintenance, no sub-optimum escape):

    v[t+1] = w v[t] + c1 r1 o (p - x[t]) + c2 r2 o (n - x[t]),   |v| <= dx_max

with p the robot's personal best position and n the best personal best among itself and the robots heard this
iteration (an lbest PSO over the range-limited neighbourhood). Obstacles are handled outside the PSO: a
Braitenberg-style reaction on the sonar deflects the move, and the robot drives in the new direction without its
PSO velocity changing (``common.braitenberg``).

The frame (``Frame``, little-endian ``<BBHfffff``, 24 bytes): magic 0x45 ("E"), robot id, iteration mod 65536,
position (x, y), personal best value and where it was sensed.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar

from swarm_logic.families.baselines.common import (
    COMMON_DEFAULTS,
    COMMON_RANGES,
    Iterated,
    WindowBest,
    braitenberg,
    pso_stability_warnings,
    pso_velocity,
    wire,
)
from swarm_logic.geometry import clamp

MAGIC = 0x45  # "E"
FRAME = struct.Struct("<BBHfffff")
WHITE, RED = (255, 255, 255), (255, 0, 0)


@dataclass(frozen=True, slots=True)
class Frame:
    robot: int
    k: int  # iteration number mod 65536
    x: float
    y: float
    pbest: float  # personal best value
    px: float  # where it was sensed
    py: float


def encode(f: Frame) -> bytes:
    return FRAME.pack(MAGIC, f.robot, f.k & 0xFFFF, f.x, f.y, wire(f.pbest), f.px, f.py)


@lru_cache(maxsize=1024)
def decode(data: bytes) -> Frame | None:
    """The EPSO frame in ``data``, or None (another application's frame, wrong length, non-finite numbers).
    Cached (a broadcast reaches many robots with the same bytes): treat the result as read-only."""
    if len(data) != FRAME.size or data[0] != MAGIC:
        return None
    _, robot, k, *vals = FRAME.unpack(data)
    if not all(math.isfinite(v) for v in vals):
        return None
    return Frame(robot, k, *vals)


class Epso(Iterated):
    """One robot of the EPSO swarm."""

    topic = "epso"
    decode = staticmethod(decode)
    defaults: ClassVar[dict[str, Any]] = {
        **COMMON_DEFAULTS,
        "w": 0.6,  # inertia (Pugh & Martinoli)
        "c1": 2.0,  # cognitive coefficient (personal best)
        "c2": 2.0,  # social coefficient (neighbourhood best)
        "range_m": math.inf,  # R_r: neighbours farther than this (by the positions they send) are ignored
        "avoid_m": 0.3,  # Braitenberg reaction radius on the sonar
        "avoid_turn_deg": 90.0,  # deflection of a move when the echo is at contact (scaled by proximity)
        "memory_iterations": 0,  # the personal best is the best of the last this many iterations (0: ever)
    }
    ranges: ClassVar[dict[str, str]] = {
        **COMMON_RANGES,
        "w": "[0, 1)",  # the inertia: >= 1 the velocity never decays
        "c1": "[0, inf)",  # attraction coefficients
        "c2": "[0, inf)",
        "range_m": "(0, inf]",
        "avoid_m": "(0, inf)",
        "avoid_turn_deg": "[0, 180]",
        "memory_iterations": "[0, inf)",
    }

    @classmethod
    def warnings(cls, params: dict[str, Any]) -> list[str]:
        """Stability warnings for a valid parameter set (each names the bound it breaks)."""
        p = cls.resolve(params)
        return pso_stability_warnings(p["w"], p["c1"], p["c2"], ("w", "c1", "c2"))

    def reset_algorithm(self) -> None:
        self.v = (0.0, 0.0)  # the PSO's internal velocity (m per iteration)
        self.pbest = -math.inf
        self.pbest_at = (0.0, 0.0)
        self.nbest = -math.inf  # the neighbourhood best of the last iteration (logged)
        self.nbest_at = (0.0, 0.0)
        self.memory = WindowBest(int(self.p["memory_iterations"]))

    def telemetry(self) -> dict[str, float | int]:
        """Iteration, neighbours heard, personal and neighbourhood bests (-3e38: none yet)."""
        return {"k": self.k, "heard": len(self.heard), "pbest": wire(self.pbest), "nbest": wire(self.nbest)}

    def tell(self) -> bytes:
        if self.memory.window:  # a changing objective: the best of the last memory_iterations readings
            self.memory.add(self.k, self.h, (self.x, self.y))
            self.pbest, self.pbest_at = self.memory.best()  # type: ignore[misc]
        elif self.h > self.pbest:
            self.pbest, self.pbest_at = self.h, (self.x, self.y)
        return encode(Frame(self.robot.id, self.k, self.x, self.y, self.pbest, *self.pbest_at))

    def neighbourhood_best(self) -> tuple[float, tuple[float, float]]:
        """The best personal best among this robot and the robots heard this iteration within range_m."""
        best, at = self.pbest, self.pbest_at
        r = self.p["range_m"]
        for f in self.heard.values():
            if f.pbest > best and math.hypot(f.x - self.x, f.y - self.y) <= r:
                best, at = f.pbest, (f.px, f.py)
        return best, at

    def decide(self) -> dict[str, Any]:
        p = self.p
        self.nbest, self.nbest_at = self.neighbourhood_best()
        rng = self.robot.rng_py
        v = pso_velocity(self.v, (self.x, self.y), p["w"], ((p["c1"], self.pbest_at), (p["c2"], self.nbest_at)),
                         rng.random)
        vx, vy = self.v = clamp(*v, p["dx_max_m"])  # |v| <= dx_max (the PSO's V_max)
        heading, avoided = braitenberg(math.atan2(vy, vx), self.theta, self.sonar, p["avoid_m"],
                                       math.radians(p["avoid_turn_deg"]), tie=rng.random() - 0.5)
        self.move_along(heading, math.hypot(vx, vy))
        self.show(RED if avoided else WHITE)
        return {"pbest": wire(self.pbest), "nbest": wire(self.nbest), "v": self.v, "avoided": avoided}
