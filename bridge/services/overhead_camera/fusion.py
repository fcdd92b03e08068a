"""The thesis' comparator (Roy 2022, §3.2 of the digest): the camera's fix against the robot's encoder odometry, whose
error drives a correction. Here a complementary filter per robot, on the pose (x, y, yaw):

    predicted  p = last estimate moved by the odometry's displacement since the last frame (taken in the robot's own
                   frame, so it does not matter where the odometry's frame lies in the world); the odometry's pose
                   at a frame's time is its latest reading carried on at the reading's speed and turn rate, since
                   readings come at their own rate and arrive late (the robots' and the camera's clocks are the
                   same: the session's, or on real hardware synchronised)
    error      e = camera fix - p                      (the comparator's output; yaw wrapped to (-pi, pi])
    estimate   p + gain * e                            (the correction: ``position_gain`` for x and y,
                                                        ``heading_gain`` for the heading)

The odometry carries the motion between frames (smooth, drifting, slipping), the camera holds the estimate to the
world (noisy, drift-free). The camera's position is far better than a slipping wheel's (about a millimetre), its
heading less so (a few degrees from a small marker), hence a high position gain and a low heading gain: a wheel that
slips 40 % at 0.1 m/s drags a position gain of 0.3 about 1 cm behind the fixes, 0.8 about 1 mm. With gain 1, or
without fresh odometry (none within ``odometry_timeout_s``), the estimate is the fix.
A robot the camera does not see this frame gets no estimate (no pose rather than a wrong one) and starts again from
its next fix.

Velocity: the odometry's speed along the estimated heading when it is fresh; otherwise the displacement between the
last two fixes, smoothed (first-order, ``velocity_smoothing``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from swarm_logic.robots.sonpi.interfaces import OdometryReading


def wrap(a: float) -> float:
    return math.remainder(a, math.tau)


@dataclass
class Estimate:
    x: float
    y: float
    yaw: float
    vx: float
    vy: float


class PoseFilter:
    """One robot's fused pose."""

    def __init__(
        self, position_gain: float, heading_gain: float, odometry_timeout_s: float, velocity_smoothing: float
    ) -> None:
        self.gain = position_gain
        self.heading_gain = heading_gain
        self.timeout = odometry_timeout_s
        self.alpha_v = velocity_smoothing
        self.est: Estimate | None = None
        self.t_est = 0.0
        self.odom: OdometryReading | None = None  # the latest reading
        # the odometry's pose at the last frame's time (extrapolated from the reading then latest), None: not fused
        self.odom_used: tuple[float, float, float] | None = None
        self.last_error = (0.0, 0.0, 0.0)

    def odometry(self, reading: OdometryReading) -> None:
        if self.odom is None or reading.t_s >= self.odom.t_s:
            self.odom = reading

    def _fresh(self, t_s: float) -> bool:
        return self.odom is not None and t_s - self.odom.t_s <= self.timeout

    def odometry_at(self, t_s: float) -> tuple[float, float, float]:
        """The odometry's pose at ``t_s``: the latest reading carried on at its speed and turn rate (readings come at
        their own rate and reach the service late; frames at theirs)."""
        o = self.odom
        assert o is not None
        dt = t_s - o.t_s
        mid = o.yaw_rad + o.w_rps * dt / 2
        return (o.x_m + o.v_mps * dt * math.cos(mid), o.y_m + o.v_mps * dt * math.sin(mid),
                wrap(o.yaw_rad + o.w_rps * dt))

    def update(self, t_s: float, fix: tuple[float, float, float] | None) -> Estimate | None:
        """The estimate at frame time ``t_s`` given this frame's camera fix (None: unseen, no estimate)."""
        if fix is None:
            self.est = None
            self.odom_used = None
            return None
        fx, fy, fyaw = fix
        fresh = self._fresh(t_s)
        prev = self.est
        if prev is None:
            x, y, yaw = fx, fy, fyaw
            self.last_error = (0.0, 0.0, 0.0)
        else:
            px, py, pyaw = prev.x, prev.y, prev.yaw
            if fresh and self.odom_used is not None:
                (x0, y0, yaw0), (x1, y1, yaw1) = self.odom_used, self.odometry_at(t_s)
                c0, s0 = math.cos(yaw0), math.sin(yaw0)
                dx, dy = x1 - x0, y1 - y0
                fwd, left = c0 * dx + s0 * dy, -s0 * dx + c0 * dy  # the move in the robot's own frame
                px += fwd * math.cos(pyaw) - left * math.sin(pyaw)
                py += fwd * math.sin(pyaw) + left * math.cos(pyaw)
                pyaw = wrap(pyaw + wrap(yaw1 - yaw0))
            g, gh = (self.gain, self.heading_gain) if fresh else (1.0, 1.0)
            ex, ey, eyaw = fx - px, fy - py, wrap(fyaw - pyaw)
            self.last_error = (ex, ey, eyaw)
            x, y, yaw = px + g * ex, py + g * ey, wrap(pyaw + gh * eyaw)
        if fresh:
            assert self.odom is not None
            vx, vy = self.odom.v_mps * math.cos(yaw), self.odom.v_mps * math.sin(yaw)
        elif prev is not None and t_s > self.t_est:
            dt = t_s - self.t_est
            a = self.alpha_v
            vx = a * (x - prev.x) / dt + (1 - a) * prev.vx
            vy = a * (y - prev.y) / dt + (1 - a) * prev.vy
        else:
            vx = vy = 0.0
        self.est = Estimate(x, y, yaw, vx, vy)
        self.t_est = t_s
        self.odom_used = self.odometry_at(t_s) if fresh else None
        return self.est
