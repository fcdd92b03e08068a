"""The chapter 3 controller's target must be reachable: a session whose ``roy_apf`` (or ``roy_gathering``) target
lies inside an obstacle, or whose goal region (``goal_tol`` around it) an obstacle or a wall crosses, is refused when
its config is loaded (``check``, the study's config check), and so is a numerical scenario whose lines, moving circle
or walls do (``scenario_target_error``, which ``numerical.Ch3Scenario`` raises). The swarm would otherwise press
against the obstacle until its time ran out, and the run would look like a controller that failed."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

Point = tuple[float, float]

BEHAVIOURS = ("roy_apf", "roy_gathering")  # the study's controllers that head for (target_x, target_y)


def segment_distance(p: Point, a: Point, b: Point) -> float:
    """The distance from ``p`` to the segment ``a``-``b``."""
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    n2 = dx * dx + dy * dy
    s = 0.0 if n2 == 0 else min(1.0, max(0.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / n2))
    return math.hypot(p[0] - ax - s * dx, p[1] - ay - s * dy)


def _describe(ob: Any) -> str:
    if hasattr(ob, "radius"):
        return f"a cylinder at ({ob.x:g}, {ob.y:g}), radius {ob.radius:g} m"
    return f"a box at ({ob.x:g}, {ob.y:g}), {ob.size[0]:g} x {ob.size[1]:g} m, yaw {ob.yaw_deg:g} degrees"


def session_target_error(
    target: Point, goal_m: float, arena: tuple[float, float], obstacles: Iterable[Any]
) -> str | None:
    """Why a session's target (m) cannot be reached, or None: outside the ``arena`` (width, length), its goal region
    (radius ``goal_m``) across a wall, inside or crossed by one of ``obstacles`` (the config's boxes and cylinders,
    with those ``random_obstacles`` drew once they are drawn)."""
    x, y = target
    w, length = arena
    if not (0 < x < w and 0 < y < length):
        return f"is outside the {w:g} x {length:g} m arena"
    if not (goal_m < x < w - goal_m and goal_m < y < length - goal_m):
        return f"is within goal_tol ({goal_m:g} m) of the arena's wall: its goal region crosses the wall"
    for j, ob in enumerate(obstacles):
        if ob.overlaps(x, y):
            return f"is inside obstacles[{j}], {_describe(ob)}"
        if ob.overlaps(x, y, goal_m):
            return f"has obstacles[{j}], {_describe(ob)}, across its goal region (goal_tol, {goal_m:g} m)"
    return None


def scenario_target_error(
    target: Point, goal: float, side: float, lines: Iterable[tuple[Point, Point]], movers: Iterable[Any]
) -> str | None:
    """Why a numerical scenario's target (units) cannot be reached, or None: outside the ``side`` x ``side`` world,
    its goal region (radius ``goal``) across a wall, on or within ``goal`` of a line, or on the path of a moving
    circle (within its radius plus ``goal`` of the segment it sweeps)."""
    x, y = target
    if not (0 < x < side and 0 < y < side):
        return f"is outside the {side:g} x {side:g} world"
    if not (goal < x < side - goal and goal < y < side - goal):
        return f"is within goal_radius ({goal:g}) of the wall: its goal region crosses the wall"
    for j, (a, b) in enumerate(lines):
        if segment_distance(target, a, b) <= goal:
            return f"is within goal_radius ({goal:g}) of lines[{j}] {a}-{b}: the line crosses its goal region"
    for j, m in enumerate(movers):
        if segment_distance(target, m.a, m.b) < m.radius + goal:
            return (
                f"is on the path of movers[{j}] (radius {m.radius:g}, between {m.a} and {m.b}): the circle "
                "crosses its goal region"
            )
    return None


def check(cfg: Any) -> None:
    """The study's config check: each group running one of its controllers has a reachable target (ValueError naming
    the group's params and why)."""
    from swarm_logic.behaviours import load_behaviour

    for i, g in enumerate(cfg.robots):
        if g.behaviour not in BEHAVIOURS:
            continue
        try:
            p = load_behaviour(g.behaviour).with_defaults(dict(g.params))
            unit, tx, ty = float(p["unit_m"]), float(p["target_x"]), float(p["target_y"])
            goal = float(p.get("goal_tol", 0.0)) * unit
        except (ValueError, TypeError, KeyError):
            continue  # the behaviour's own check names a bad parameter
        why = session_target_error((tx * unit, ty * unit), goal, (cfg.arena.width_m, cfg.arena.length_m), cfg.obstacles)
        if why is not None:
            raise ValueError(
                f"robots[{i}].params.target_x, target_y: the target ({tx:g}, {ty:g}) units x unit_m {unit:g} = "
                f"({tx * unit:g}, {ty * unit:g}) m {why}: the swarm cannot reach it"
            )
