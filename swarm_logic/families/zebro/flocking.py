"""Flocking (thesis Algorithm 2) as heading changes only: a Zebro can turn but not accelerate (section 3.5.1).

Every rule turns a heading towards (or away from) a target by at most its own turn per tick (the thesis' "minimum
and maximum turning angles", values not given; NetLogo's Flocking model's 5, 3 and 1.5 degrees by default). The
rules, after the NetLogo library model the thesis most plausibly adapted (digest section 2.2):

- SEPARATE when the nearest neighbour is closer than ``d_min``: turn away from its heading (NetLogo's
  ``turn-away``), or, literally (A-2), towards its heading + 90 degrees;
- otherwise ALIGN: turn towards the neighbours' mean heading, circular (A-1, repaired) or the arithmetic mean of
  the angles in [0, 2 pi) that the pseudo-code writes (literal; wrong across 0/2 pi);
- and COHERE with the neighbours farther than ``d_max``: turn towards the mean bearing to them (A-2, repaired; the
  comment "move towards") or towards their mean heading (literal "heading <- heading_of_that_neighbour").

Headings are absolute (rad, counter-clockwise); a neighbour's bearing is relative to our heading.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from swarm_logic.geometry import wrap
from swarm_logic.robots.decizebro.interfaces import Neighbour

TAU = 2 * math.pi


def turn_towards(h: float, target: float, max_turn: float) -> float:
    """``h`` turned towards ``target`` by at most ``max_turn`` (the shorter way)."""
    d = wrap(target - h)
    return wrap(h + max(-max_turn, min(max_turn, d)))


def turn_away(h: float, target: float, max_turn: float) -> float:
    """``h`` turned away from ``target`` by at most ``max_turn`` (NetLogo ``turn-away``: no turn when equal)."""
    d = wrap(h - target)
    return wrap(h + max(-max_turn, min(max_turn, d)))


def circular_mean(angles: Sequence[float]) -> float | None:
    """The mean direction of ``angles``; None for none, or when they cancel out."""
    s = sum(math.sin(a) for a in angles)
    c = sum(math.cos(a) for a in angles)
    if abs(s) < 1e-12 and abs(c) < 1e-12:
        return None
    return math.atan2(s, c)


def arithmetic_mean(angles: Sequence[float]) -> float | None:
    """The literal "sum of headings / number of neighbours", the angles taken in [0, 2 pi)."""
    if not angles:
        return None
    return wrap(sum(a % TAU for a in angles) / len(angles))


@dataclass(frozen=True, slots=True)
class FlockRules:
    """Algorithm 2's parameters (metres, radians per tick) and the readings of A-1 and A-2."""

    d_min: float
    d_max: float
    align_turn: float
    cohere_turn: float
    separate_turn: float
    align_mean: str = "circular"  # circular | arithmetic
    cohere_mode: str = "bearing"  # bearing | heading
    separate_mode: str = "turn_away"  # turn_away | plus90


def mean_heading(nbrs: Sequence[Neighbour], how: str = "circular") -> float | None:
    hs = [n.heading_rad for n in nbrs if n.heading_rad is not None]
    return circular_mean(hs) if how == "circular" else arithmetic_mean(hs)


def align(h: float, nbrs: Sequence[Neighbour], r: FlockRules) -> float:
    """ALIGN: towards the neighbours' mean heading."""
    m = mean_heading(nbrs, r.align_mean)
    return h if m is None else turn_towards(h, m, r.align_turn)


def cohere(h: float, nbrs: Sequence[Neighbour], r: FlockRules) -> float:
    """COHERE: towards the neighbours beyond ``d_max`` (their mean bearing; literally their mean heading)."""
    far = [n for n in nbrs if n.range_m > r.d_max]
    if not far:
        return h
    if r.cohere_mode == "heading":
        m = mean_heading(far, "circular" if r.align_mean == "circular" else "arithmetic")
    else:
        m = circular_mean([h + n.bearing_rad for n in far])
    return h if m is None else turn_towards(h, m, r.cohere_turn)


def separate(h: float, nearest: Neighbour, r: FlockRules) -> float:
    """SEPARATE from the nearest neighbour: away from its heading, or literally to its heading + 90 degrees."""
    other = nearest.heading_rad if nearest.heading_rad is not None else h + nearest.bearing_rad
    if r.separate_mode == "plus90":
        return turn_towards(h, other + math.pi / 2, r.separate_turn)
    return turn_away(h, other, r.separate_turn)


def flock(h: float, nbrs: Sequence[Neighbour], r: FlockRules) -> float:
    """Algorithm 2: the heading after one tick of flocking with ``nbrs`` (unchanged without neighbours)."""
    if not nbrs:
        return h
    nearest = min(nbrs, key=lambda n: n.range_m)
    if nearest.range_m < r.d_min:
        return separate(h, nearest, r)
    return cohere(align(h, nbrs, r), nbrs, r)
