"""Food particles (Agrawal 2019, section 3.2): world objects with an integer utility, placed by the config
(``[[particles]]``), sensed by the Zebros' forward utility sensor and consumed by the first robot that reaches one.

A negative utility marks an obstacle for the utility sensor (the thesis' convention); no two particles share a
utility (section 3.2: utilities are distinct), which the config check enforces.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from pydantic import Field

from bridge.core.config import Section


class ParticleCfg(Section):
    """One ``[[particles]]`` entry."""

    x: float
    y: float
    utility: int = Field(ge=-128, le=127, description="integer utility, one byte (thesis A-14); negative: an "
                                                      "obstacle for the utility sensor; no two particles alike")
    reach_m: float = Field(0.134, gt=0, description="a robot whose centre comes this close consumes it (half a "
                                                    "body length, thesis A-19's 0.5 u)")


def check(cfg: Any) -> None:
    """Particles inside the arena, outside obstacles, with distinct utilities."""
    parts = cfg.section("particles")
    seen: dict[int, int] = {}
    for i, p in enumerate(parts):
        where = f"particles[{i}]"
        if not (0 < p.x < cfg.arena.width_m and 0 < p.y < cfg.arena.length_m):
            raise ValueError(f"{where}: ({p.x}, {p.y}) is outside the {cfg.arena.width_m} x {cfg.arena.length_m} m "
                             "arena")
        for j, ob in enumerate(cfg.obstacles):
            if _inside(ob, p.x, p.y):
                raise ValueError(f"{where}: ({p.x}, {p.y}) is inside obstacles[{j}]: no robot could reach it")
        if p.utility in seen:
            raise ValueError(f"{where}.utility = {p.utility}: particles[{seen[p.utility]}] has it already (the "
                             "thesis' particles have distinct utilities)")
        seen[p.utility] = i


def _inside(ob: Any, x: float, y: float) -> bool:
    if hasattr(ob, "radius"):
        return math.hypot(x - ob.x, y - ob.y) <= ob.radius
    c, s = math.cos(-math.radians(ob.yaw_deg)), math.sin(-math.radians(ob.yaw_deg))
    dx, dy = x - ob.x, y - ob.y
    lx, ly = c * dx - s * dy, s * dx + c * dy
    return abs(lx) <= ob.size[0] / 2 and abs(ly) <= ob.size[1] / 2


class Particles:
    """The particles in a session's world (``world.objects["particles"]``): where, how much, and which are left."""

    def __init__(self, cfgs: list[ParticleCfg]) -> None:
        self.xy = np.array([[p.x, p.y] for p in cfgs], dtype=float).reshape(len(cfgs), 2)
        self.utility = np.array([p.utility for p in cfgs], dtype=int)
        self.reach = np.array([p.reach_m for p in cfgs], dtype=float)
        self.left = np.ones(len(cfgs), dtype=bool)
        self.eaten: dict[int, list[int]] = {}  # robot -> the utilities of the particles it ate, in order

    def in_cone(self, x: float, y: float, heading: float, half_angle: float, range_m: float) -> int:
        """The sum of the utilities of the particles left within ``range_m`` and ``half_angle`` of ``heading``."""
        return self.cone(x, y, heading, half_angle, range_m)[0]

    def cone(self, x: float, y: float, heading: float, half_angle: float,
             range_m: float) -> tuple[int, float | None]:
        """The cone's sum, and the direction of what it sees relative to ``heading`` (rad, + = left; weighted by
        each particle's utility's size; None when it sees nothing)."""
        if not self.left.any():
            return 0, None
        d = self.xy - (x, y)
        dist = np.hypot(d[:, 0], d[:, 1])
        rel = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - heading)))
        seen = self.left & (dist <= range_m) & (np.abs(rel) <= half_angle)
        if not seen.any():
            return 0, None
        w = np.abs(self.utility[seen]).astype(float)
        bearing = float(np.average(rel[seen], weights=w)) if w.sum() > 0 else float(rel[seen].mean())
        return int(self.utility[seen].sum()), bearing

    def reached(self, pos: np.ndarray, alive: np.ndarray) -> list[tuple[int, int]]:
        """(particle, robot) for every particle left that a live robot has reached, the nearest robot consuming it;
        those particles are gone."""
        out = []
        for k in np.flatnonzero(self.left).tolist():
            d = np.hypot(pos[:, 0] - self.xy[k, 0], pos[:, 1] - self.xy[k, 1])
            d[~alive] = np.inf
            r = int(np.argmin(d)) if len(d) else -1
            if r >= 0 and d[r] <= self.reach[k]:
                self.left[k] = False
                self.eaten.setdefault(r, []).append(int(self.utility[k]))
                out.append((k, r))
        return out
