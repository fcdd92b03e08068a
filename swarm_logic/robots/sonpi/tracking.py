"""The SonPI's tracking layer: the thesis' controllers command a holonomic point (a world-frame velocity); the robot is
a differential drive, which the thesis never maps to (digest 001 §5.1 item 4). This is the mapping.

**Law: feedback linearisation about a point ahead of the axle.** A point P at ``lookahead_m`` ahead of the wheels'
axle centre, on the heading, moves at

    [Px', Py'] = [[cos t, -l sin t], [sin t, l cos t]] [v, w]

which is invertible for l > 0. Asking P to move at the commanded world-frame velocity (vx, vy) gives

    v = vx cos t + vy sin t,        w = (-vx sin t + vy cos t) / l,

and the wheel rim speeds are v -/+ w b (left, right; b the half track). P then follows the commanded velocity exactly
while no wheel saturates; the body turns towards it on its own (a velocity at right angles to the heading turns the
robot at |u| / l). When a wheel would exceed ``max_wheel_mps`` both are scaled down together, so the turn's share is
kept (the path bends as asked, more slowly). The commanded speed is clipped to ``max_speed_mps`` first.

The heading t comes from the robot's pose estimate (the overhead camera's, ``sonpi_pose``) when the robot has one,
else from the encoders' dead reckoning (``sonpi_odometry``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class TrackingParams:
    half_track_m: float
    max_speed_mps: float  # the commanded speed is clipped to this
    max_wheel_mps: float  # a wheel's rim speed at most
    lookahead_m: float = 0.1  # l: about the body's radius, so P is near the robot's front

    def __post_init__(self) -> None:
        for name in ("half_track_m", "max_speed_mps", "max_wheel_mps", "lookahead_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"tracking {name} must be > 0, got {v}")


def clip_speed(vx: float, vy: float, max_speed: float) -> tuple[float, float]:
    """(vx, vy) with its norm at most ``max_speed`` (non-finite components count as 0)."""
    vx = vx if math.isfinite(vx) else 0.0
    vy = vy if math.isfinite(vy) else 0.0
    s = math.hypot(vx, vy)
    if s > max_speed:
        return vx * max_speed / s, vy * max_speed / s
    return vx, vy


def unicycle(vx: float, vy: float, yaw: float, p: TrackingParams) -> tuple[float, float]:
    """(v, w): the forward speed and turn rate that move the point ahead at (vx, vy), clipped to the max speed."""
    vx, vy = clip_speed(vx, vy, p.max_speed_mps)
    c, s = math.cos(yaw), math.sin(yaw)
    return vx * c + vy * s, (-vx * s + vy * c) / p.lookahead_m


def wheel_speeds(vx: float, vy: float, yaw: float, p: TrackingParams) -> tuple[float, float]:
    """(left, right) rim speeds (m/s) that make the point ahead follow (vx, vy) at heading ``yaw``, scaled together
    so that neither exceeds ``max_wheel_mps``."""
    v, w = unicycle(vx, vy, yaw, p)
    left, right = v - w * p.half_track_m, v + w * p.half_track_m
    peak = max(abs(left), abs(right))
    if peak > p.max_wheel_mps:
        k = p.max_wheel_mps / peak
        left, right = left * k, right * k
    return left, right
