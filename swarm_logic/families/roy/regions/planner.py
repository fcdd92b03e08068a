"""The contract between a chapter's global controller and the agents (Roy 2022, chapters 4-6): every period the
global controller takes an ``Observation`` (the agents' poses and sonar windows) and returns a ``Plan``: each agent's
point of attraction, the local law that pulls it there and the law's parameters, the regions to draw and the
decisions it took. The numerical model applies a plan to all agents at once (``velocities``); on the robots, each
agent applies it to its own row with the poses the overhead camera broadcasts and its own sonar points.

A chapter's planner is a ``RegionPlanner`` subclass: ``plan`` each period, ``summary`` its figures at the end. It
keeps whatever state it needs (the region, the formation, the sub-swarms); it never sees a simulator.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarm_logic.families.roy.regions import laws
from swarm_logic.families.roy.regions.shapes import Ellipse
from swarm_logic.log import plain
from swarm_logic.plugins import Registry


@dataclass(frozen=True)
class Observation:
    """What the global controller knows at ``t`` (s): the reporting agents' ``ids`` (N,), ``positions`` (N, 2) and
    ``headings`` (N,) in thesis units and rad, their sonar ``ranges`` (N, m) (NaN: no echo), the beams' ``angles``
    (m,) from the heading, and the mission's ``target`` (2,). An agent that did not report this period is absent
    (the planner decides what absence means: failed, dead, late)."""

    t: float
    ids: np.ndarray
    positions: np.ndarray
    headings: np.ndarray
    ranges: np.ndarray
    angles: np.ndarray
    target: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.ids)
        if np.shape(self.positions) != (n, 2) or np.shape(self.headings) != (n,):
            raise ValueError(
                f"positions/headings: expected ({n}, 2) and ({n},), got "
                f"{np.shape(self.positions)} and {np.shape(self.headings)}"
            )
        if np.shape(self.ranges) != (n, len(self.angles)):
            raise ValueError(f"ranges: expected ({n}, {len(self.angles)}), got {np.shape(self.ranges)}")


@dataclass(frozen=True)
class Region:
    """A region to draw and record: sub-swarm ``group``'s ellipse, or its polygon's ``vertices`` (K, 2)."""

    group: int
    ellipse: Ellipse | None = None
    vertices: np.ndarray | None = None

    def __post_init__(self) -> None:
        if (self.ellipse is None) == (self.vertices is None):
            raise ValueError("a region is an ellipse or a polygon, exactly one of them")

    @property
    def area(self) -> float:
        if self.ellipse is not None:
            return self.ellipse.area
        v = np.asarray(self.vertices, dtype=float)
        return float(0.5 * abs(np.dot(v[:, 0], np.roll(v[:, 1], 1)) - np.dot(v[:, 1], np.roll(v[:, 0], 1))))

    def as_dict(self) -> dict[str, Any]:
        if self.ellipse is not None:
            return {"group": self.group, "kind": "ellipse", **self.ellipse.as_dict(), "area": self.area}
        return plain({"group": self.group, "kind": "polygon", "vertices": self.vertices, "area": self.area})


@dataclass(frozen=True)
class Plan:
    """One period's decision. ``goals`` (N, 2): each of ``ids``' point of attraction (the region's centre, its place
    in the formation, its packed circle, its sub-region's centre); ``law`` a name in ``LAWS`` and ``params`` its
    keyword arguments (JSON values: numbers, lists); ``groups`` (N,) each agent's sub-swarm, ``leaders`` the
    sub-swarms' leaders; ``regions`` what to draw; ``events`` the decisions taken this period (each a JSON dict with a
    ``kind``: "split", "merge", "formation", "failure", "held", "input", ...); ``done`` when the mission is over;
    ``face`` the world heading (rad) the robots should face, if any (no law takes it: chapter 6's planner sets it
    while the region is held before a wall ahead, so that sonars fixed to the robots' fronts look at it)."""

    t: float
    ids: np.ndarray
    goals: np.ndarray
    law: str
    params: dict[str, Any] = field(default_factory=dict)
    groups: np.ndarray | None = None
    leaders: tuple[int, ...] = ()
    regions: tuple[Region, ...] = ()
    events: tuple[dict[str, Any], ...] = ()
    done: bool = False
    face: float | None = None

    def __post_init__(self) -> None:
        if self.law not in LAWS:
            raise ValueError(f"law: expected one of {', '.join(LAWS)}, got {self.law!r}")
        if self.face is not None and not math.isfinite(self.face):
            raise ValueError(f"face: a heading must be finite, got {self.face}")
        if np.shape(self.goals) != (len(self.ids), 2):
            raise ValueError(f"goals: expected ({len(self.ids)}, 2), got {np.shape(self.goals)}")

    def as_dict(self) -> dict[str, Any]:
        return plain(
            {
                "t": self.t,
                "ids": self.ids,
                "goals": self.goals,
                "law": self.law,
                "params": self.params,
                "groups": self.groups,
                "leaders": list(self.leaders),
                "regions": [r.as_dict() for r in self.regions],
                "events": list(self.events),
                "done": self.done,
                "face": self.face,
            }
        )


class RegionPlanner:
    """A chapter's global controller: ``plan`` once per ``period_s`` of the caller's clock, ``summary`` at the end."""

    period_s: float = 0.25

    def plan(self, obs: Observation) -> Plan:
        raise NotImplementedError

    def summary(self) -> dict[str, Any]:
        return {}


def _is_planner(obj: Any) -> bool:
    return isinstance(obj, type) and issubclass(obj, RegionPlanner)


# the planners a global controller can host, by name (entry point group ``swarm_sitl.region_planners``, or
# ``module:Class``); a planner is built with its parameters as keyword arguments
PLANNERS: Registry[type[RegionPlanner]] = Registry("swarm_sitl.region_planners", "region planner", _is_planner)


Law = Callable[..., np.ndarray]
SAFETY_DEFAULTS: dict[str, float] = {}  # the formation law's safety term with its defaults (never mutated)


def _formation(
    x: np.ndarray,
    goals: np.ndarray,
    obstacles: np.ndarray | None,
    v_max: float | None,
    desired: Any,
    k_c: float,
    k_f: float,
    safety: dict[str, float] | None = SAFETY_DEFAULTS,
) -> np.ndarray:
    """Eq. 4.6 over ``desired`` (rho o Delta, N x N); ``safety``: the safety term's fields (erratum 16; {} its
    defaults), None the law as printed."""
    sf = None if safety is None else laws.Safety(**safety)
    return laws.formation_law(x, goals, k_c, k_f, np.asarray(desired, dtype=float), safety=sf, v_max=v_max)


def _scalable(
    x: np.ndarray, goals: np.ndarray, obstacles: np.ndarray | None, v_max: float | None, **kw: Any
) -> np.ndarray:
    return laws.scalable_law(x, goals, v_max=v_max, **kw)


def _packing(
    x: np.ndarray, goals: np.ndarray, obstacles: np.ndarray | None, v_max: float | None, **kw: Any
) -> np.ndarray:
    return laws.packing_law(x, goals, v_max=v_max, **kw)


def _split_merge(
    x: np.ndarray, goals: np.ndarray, obstacles: np.ndarray | None, v_max: float | None, **kw: Any
) -> np.ndarray:
    return laws.split_merge_law(x, goals, obstacles=obstacles, v_max=v_max, **kw)


# the local laws a plan may name (chapter 4: eqs. 4.6 and 4.41, chapter 5: eq. 5.2, chapter 6: eq. 6.5)
LAWS: dict[str, Law] = {
    "formation": _formation,
    "scalable": _scalable,
    "packing": _packing,
    "split_merge": _split_merge,
}


def velocities(
    plan: Plan, positions: np.ndarray, obstacles: np.ndarray | None = None, v_max: float | None = None
) -> np.ndarray:
    """The plan's law for the agents at ``positions`` (N, 2), rows in the plan's ``ids`` order (an agent the plan
    does not know must not be passed): their commanded velocities (N, 2), saturated at ``v_max``. ``obstacles``
    (K, 2): sensed obstacle points, for the laws that repel from them (chapter 6's)."""
    x = np.asarray(positions, dtype=float)
    if x.shape != np.shape(plan.goals):
        raise ValueError(f"positions: expected {np.shape(plan.goals)} (the plan's agents), got {x.shape}")
    return LAWS[plan.law](x, np.asarray(plan.goals, dtype=float), obstacles, v_max, **plan.params)
