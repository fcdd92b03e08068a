"""The run loop of a robot with a MAVLink face (``swarm_logic.runner`` hands over to it): a ``Supervisor`` runs the
robot as a ground station expects a rover to behave (``swarm_logic.mavlink.face``): it services the face whenever the
face asks (``next_due()``, at least every 0.1 s, also while the controller waits for its next step) and acts on its
state. AUTO and armed: the controller steps at its own period, as without a face. GUIDED and armed: ``GoTo`` drives
the LLC to the face's target at 10 Hz and the behaviour is paused. HOLD, or disarmed: the LLC is stopped on entry
(its watchdog keeps it stopped) and the behaviour is paused. A reboot request destroys the controller and starts a
fresh instance of its class, in the boot state. At start the supervisor sets the LLC's odometry to
``robot.start_pose`` when the robot has one, so the MAVLink local frame is the arena frame.
"""

from __future__ import annotations

import math
from typing import Any, Protocol

from pymavlink.dialects.v20.common import MAV_SEVERITY_NOTICE, MAV_SEVERITY_WARNING

from swarm_logic.clock import Clock
from swarm_logic.geometry import wrap
from swarm_logic.mavlink.face import (
    AUTO,
    EPS,
    GUIDED,
    TARGET_TIMEOUT_S,
    FaceController,
    FaceRobot,
    HeadingTarget,
    MavlinkFace,
    PositionTarget,
    Target,
)

GOTO_PERIOD_S = 0.1
REACHED_M = 0.05  # a go-to stops this close to its point; it sets off again only when twice as far
HEADING_TOL_RAD = 0.02  # a heading target is reached this close
ROTATE_FIRST_RAD = 0.5  # with a larger heading error the robot turns in place before it drives
OBSTACLE_M = 0.25  # the sonar reading below which the robot does not drive forward
K_TURN = 2.0  # rad/s of turn rate per rad of heading error
W_MAX, W_MIN = 1.5, 0.3  # rad/s: the turn rate's bounds (turning in place never crawls below W_MIN)
K_APPROACH = 0.8  # 1/s: the approach speed per metre left, so the robot slows down near its point
V_MIN = 0.03  # m/s: the slowest approach


class SupervisedRobot(FaceRobot, Protocol):
    """The robot as the supervisor runs it (a ``swarm_logic.robot.Robot``; this package does not import it)."""

    clock: Clock
    mavlink: MavlinkFace | None
    start_pose: tuple[float, float, float] | None

    def poll(self) -> None: ...


class SupervisedController(FaceController, Protocol):
    """The controller as the supervisor runs it (a ``swarm_logic.controller.Controller``); a reboot makes a fresh
    one of its class."""

    period_s: float

    def init(self, robot: Any) -> None: ...

    def step(self) -> None: ...

    def destroy(self) -> None: ...


def supervise(controller: SupervisedController, robot: SupervisedRobot, duration_s: float | None) -> None:
    """``Supervisor.start``, then its ticks until ``duration_s`` of the robot's clock; the controller is destroyed
    at the end."""
    sup = Supervisor(controller, robot)
    sup.start()
    clock = robot.clock
    start = clock.now()
    try:
        while duration_s is None or clock.now() - start < duration_s:
            clock.sleep_until(sup.tick())
    finally:
        sup.controller.destroy()


class Supervisor:
    """Arming and modes of a robot with a MAVLink face: ``start()``, then ``tick()`` whenever the last one said."""

    def __init__(self, controller: SupervisedController, robot: SupervisedRobot) -> None:
        if robot.mavlink is None:
            raise ValueError("a supervisor needs a robot with a MAVLink face (robot.mavlink)")
        self.robot = robot
        self.face: MavlinkFace = robot.mavlink
        self.controller = controller
        self.goto = GoTo(robot, self.face)
        self.activity: str | None = None  # "auto", "guided" or "hold" (disarmed too) as of the last tick
        self.t_step = self.t_goto = 0.0

    def start(self) -> None:
        r = self.robot
        if r.start_pose is not None:
            r.llc.set_odometry(*r.start_pose)
        self.controller.init(r)
        self.face.bind(r, self.controller)

    def tick(self) -> float:
        """Poll the devices, service the face, act on its state, step what is due; returns the next wake-up."""
        r, face = self.robot, self.face
        now = r.clock.now()
        r.poll()
        face.service()
        if face.reboot_requested:
            self._reboot()
        activity = {AUTO: "auto", GUIDED: "guided"}.get(face.mode, "hold") if face.armed else "hold"
        if activity != self.activity:
            self._enter(activity, now)
        wake = face.next_due()
        if activity == "auto":
            if now >= self.t_step - EPS:
                self.controller.step()
                self.t_step += self.controller.period_s
            wake = min(wake, self.t_step)
        elif activity == "guided":
            if now >= self.t_goto - EPS:
                self.goto.step(now)
                self.t_goto += GOTO_PERIOD_S
            wake = min(wake, self.t_goto)
        return wake

    def _enter(self, activity: str, now: float) -> None:
        self.activity = activity
        if activity == "auto":
            self.t_step = now  # the behaviour goes on at once
            return
        self.robot.llc.stop()  # also ends a move the behaviour handed the LLC
        if activity == "guided":
            self.goto.reset()
            self.t_goto = now

    def _reboot(self) -> None:
        """A fresh controller of the same class in the boot state. It starts where the robot now is: a start pose
        becomes the current pose, so a controller that sets the odometry at init keeps the arena frame."""
        r, face = self.robot, self.face
        self.controller.destroy()
        if r.start_pose is not None:
            st = r.llc.state
            r.start_pose = (float(st.x), float(st.y), float(st.theta))
        face.reset()
        fresh = type(self.controller)()
        fresh.init(r)
        self.controller = fresh
        face.bind(r, fresh)
        self.activity = None


class GoTo:
    """GUIDED: drives ``robot.llc`` toward the face's target with ``drive(v, w)``, one command per ``step``.

    A point: heading P-control, turning in place first while the heading error exceeds ``ROTATE_FIRST_RAD``,
    slowing down near the point, stopping within ``REACHED_M`` (a STATUSTEXT says so) and holding there. A heading:
    turn to it, then drive along it at the target's speed. A velocity: drive so. Velocity and heading targets
    lapse (the robot stops) when the face's deadline passes. Never forward while the sonar reads an obstacle
    closer than ``OBSTACLE_M``; turning stays allowed, so a point behind the robot is still reached.
    """

    def __init__(self, robot: SupervisedRobot, face: MavlinkFace) -> None:
        self.robot = robot
        self.face = face
        self.reset()

    def reset(self) -> None:
        """Forget the last target; the supervisor has just stopped the robot."""
        self.target: Target | None = None
        self.reached = False
        self.blocked = False
        self.stopped = True

    def step(self, now: float) -> None:
        t = self.face.target
        if t != self.target:  # a new target (the same point sent again is not one)
            self.target = t
            self.reached = False
        st = self.robot.llc.state
        if t is None:
            v = w = 0.0
        elif isinstance(t, PositionTarget):
            v, w = self._to_point(t, st)
        elif now > t.until:
            self.face.target = None
            self.face.statustext(f"target not renewed for {TARGET_TIMEOUT_S:g} s: stopped")
            v = w = 0.0
        elif isinstance(t, HeadingTarget):
            v, w = self._to_heading(t.theta, t.v, st)
        else:
            v, w = t.v, t.w
        if v > 0 and st.sonar_valid and st.sonar_m < OBSTACLE_M:
            if not self.blocked:
                self.face.statustext(f"obstacle at {st.sonar_m:.2f} m: not driving on", MAV_SEVERITY_WARNING)
            self.blocked = True
            v = 0.0
        else:
            self.blocked = False
        if v == 0 and w == 0:
            if not self.stopped:
                self.robot.llc.stop()
            self.stopped = True
        else:
            self.robot.llc.drive(v, w)
            self.stopped = False

    def _to_point(self, t: PositionTarget, st: Any) -> tuple[float, float]:
        x, y, theta = st.x, st.y, st.theta
        d = math.hypot(t.x - x, t.y - y)
        if d <= (2 * REACHED_M if self.reached else REACHED_M):
            if not self.reached:
                self.face.statustext(f"reached N {t.y:.2f} E {t.x:.2f}", MAV_SEVERITY_NOTICE)
            self.reached = True
            return 0.0, 0.0
        self.reached = False
        err = wrap(math.atan2(t.y - y, t.x - x) - theta)
        if abs(err) > ROTATE_FIRST_RAD:
            return 0.0, _turn(err)
        return min(self.face.speed_mps, max(V_MIN, K_APPROACH * d)) * math.cos(err), _turn(err, w_min=0.0)

    def _to_heading(self, heading: float, v: float, st: Any) -> tuple[float, float]:
        err = wrap(heading - st.theta)
        if abs(err) <= HEADING_TOL_RAD:
            return v, 0.0
        if abs(err) > ROTATE_FIRST_RAD:
            return 0.0, _turn(err)
        return v * math.cos(err), _turn(err, w_min=0.0 if v else W_MIN)


def _turn(err: float, w_min: float = W_MIN) -> float:
    """Turn rate for a heading error: proportional, within [w_min, W_MAX] in magnitude."""
    return math.copysign(min(W_MAX, max(w_min, K_TURN * abs(err))), err)
