"""Static swarms for the Zebro unit targets: robots at given places and headings, particles in given cones."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bridge.studies.zebro.numerical import Model, Scenario, Swarm
from swarm_logic.controller import Controller

UP, DOWN = math.pi / 2, -math.pi / 2


def scenario(pos: list[tuple[float, float]], heading: list[float], particles: list[tuple[float, float, int]],
             r: float) -> Scenario:
    return Scenario(np.array(pos, float), np.array(heading, float), particles, r, ())


def line(n: int, contenders: dict[int, int], spacing: float = 1.0, r: float = 1.2) -> Scenario:
    """Robots 0..n-1 along x, ``spacing`` apart (a line graph for r < 2 spacing); each contender faces up at a
    particle of its utility 1.5 u ahead, the others face down (nothing in their cones)."""
    pos = [(i * spacing, 0.0) for i in range(n)]
    heading = [UP if i in contenders else DOWN for i in range(n)]
    parts = [(i * spacing, 1.5, u) for i, u in contenders.items()]
    return scenario(pos, heading, parts, r)


def ring(n: int, contenders: dict[int, int]) -> Scenario:
    """Robots on a circle, neighbours 1 u apart (r 1.2: a ring); contenders face out at their particle."""
    rad = 0.5 / math.sin(math.pi / n)
    ang = [2 * math.pi * i / n for i in range(n)]
    pos = [(rad * math.cos(a), rad * math.sin(a)) for a in ang]
    heading = [a if i in contenders else a + math.pi for i, a in enumerate(ang)]
    parts = [((rad + 1.5) * math.cos(ang[i]), (rad + 1.5) * math.sin(ang[i]), u) for i, u in contenders.items()]
    return scenario(pos, heading, parts, 1.2)


def star(leaves: int, contenders: dict[int, int]) -> Scenario:
    """Robot 0 in the centre, the leaves 1 u out (r 1.05: only the centre links them); contenders face out."""
    ang = [0.0] + [2 * math.pi * k / leaves for k in range(leaves)]
    pos = [(0.0, 0.0)] + [(math.cos(a), math.sin(a)) for a in ang[1:]]
    heading = [ang[i] if i in contenders else ang[i] + math.pi for i in range(leaves + 1)]
    parts = [((1 + 1.5) * math.cos(ang[i]), (1 + 1.5) * math.sin(ang[i]), u) for i, u in contenders.items()]
    return scenario(pos, heading, parts, 1.05)


def swarm(cls: type[Controller], sc: Scenario, seed: int = 0, params: dict[str, Any] | None = None,
          **model: Any) -> Swarm:
    return Swarm(cls, params or {}, sc, seed, Model(**model), keep_logs=True)
