"""``sonpi_wifi``: the SonPI's Wi-Fi, as its Raspberry Pi sees it: the localisation service's pose broadcasts serve
``sonpi_pose`` (this robot's own) and ``sonpi_localisation`` (every other robot's), the global controller's mission
serves ``sonpi_mission`` and a region controller's plan ``sonpi_plan`` (which also sends the robot's sonar windows to
the controller); the robot sends its encoder odometry to the localisation service (when it has an
``sonpi_odometry`` face) and its status to the controller (``pose_packet``'s wire format).

HAL table (``swarm_sitl.devices`` name ``sonpi_wifi``):

    [sonpi_wifi]
    url = "udp://0.0.0.0:5005"       # a real SonPI; in a session: "sitl://wifi"
    localisation = "192.168.1.10:5005"  # where odometry goes (a session: the service's name); none: broadcast
    controller = "192.168.1.10:5006"    # where status goes (a session: the controller's name); none: not sent
    odometry_period_s = 0.1
    status_period_s = 1.0
    first_pose_timeout_s = 5.0       # how long the first sonpi_pose read waits for the first broadcast
    log_period_s = 0.0               # > 0: Robot.log its own pose estimate (topic wifi_pose) this often

Packets are taken in whenever the robot polls its devices (each controller step) and when a read waits for the first
pose. A datagram that is not a SonPI packet is counted (``counters["malformed"]``) and dropped. The pose a robot gets
is the latest the service could give: when the camera loses it (the service sends no pose rather than a wrong one),
``sonpi_pose`` carries the last one on by the robot's own odometry (when it has an ``sonpi_odometry`` face; else it
keeps the last one) and ``fresh`` says it is not the camera's; the others' list holds only those the service saw in its
latest broadcast.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from swarm_logic.drivers.wifi import open_link
from swarm_logic.robots.sonpi import pose_packet as pp
from swarm_logic.robots.sonpi.interfaces import LOCALISATION, POSE, AgentPose, NoPose

MISSION = "sonpi_mission"
PLAN = "sonpi_plan"
ODOMETRY_FACE = "sonpi_odometry"  # the robot's own odometry (its board's device), if it has one


@dataclass(frozen=True, slots=True)
class MissionOrder:
    """The global controller's latest mission: run or hold, and the target (m, world frame)."""

    run: bool
    target_x_m: float
    target_y_m: float
    t_s: float


class _OwnPose:
    def __init__(self, dev: SonpiWifi) -> None:
        self.dev = dev

    def read(self) -> AgentPose:
        """This robot's latest pose estimate (the first read waits up to ``first_pose_timeout_s`` for the first one;
        ``NoPose`` after that, and at once from then on until one comes). While the camera has lost it, the last
        broadcast pose carried on by the robot's own odometry when it has some."""
        d = self.dev
        if d.own is None:
            d.wait_first_pose()
        assert d.own is not None
        return d.own if d.own_fresh else d.dead_reckoned()

    @property
    def fresh(self) -> bool:
        """The latest broadcast had this robot's pose (False: the camera lost it, ``read`` gives the last one
        carried on by odometry, or the last one as it was without odometry)."""
        return self.dev.own_fresh


class _Localisation:
    def __init__(self, dev: SonpiWifi) -> None:
        self.dev = dev

    def poses(self) -> list[AgentPose]:
        """The other robots the latest broadcast had a pose for."""
        return list(self.dev.others)


class _Mission:
    def __init__(self, dev: SonpiWifi) -> None:
        self.dev = dev

    def read(self) -> MissionOrder | None:
        """The latest mission the controller broadcast (None before the first)."""
        return self.dev.mission


@dataclass(frozen=True, slots=True)
class PlanOrder:
    """The region controller's latest plan (``pose_packet.PlanPacket``) and the controller's time stamp on it."""

    plan: pp.PlanPacket
    t_s: float


class _Plan:
    def __init__(self, dev: SonpiWifi) -> None:
        self.dev = dev

    def read(self) -> PlanOrder | None:
        """The latest plan the controller broadcast (None before the first)."""
        return self.dev.plan

    def send_sonar(self, t_s: float, ranges_m: list[float | None]) -> None:
        """Send the sonar window that ended at ``t_s`` to the controller (``inf``: no echo; None or NaN: no reading;
        ValueError for a negative range or one beyond the wire's 65.533 m)."""
        d = self.dev
        d._send(pp.encode_sonar(d._seq, t_s, pp.SonarWindow(d.robot.id, tuple(ranges_m))), d.controller)
        d.counters["sonar_sent"] += 1


class SonpiWifi:
    def __init__(self, cfg: dict[str, Any], robot: Any) -> None:
        known = {
            "url",
            "localisation",
            "controller",
            "odometry_period_s",
            "status_period_s",
            "first_pose_timeout_s",
            "log_period_s",
        }
        unknown = sorted(set(cfg) - known)
        if unknown:
            raise ValueError(f"HAL config sonpi_wifi: unknown settings {unknown}; known: {sorted(known)}")
        if not cfg.get("url"):
            raise ValueError("HAL config sonpi_wifi.url: a link URL is needed (udp://0.0.0.0:5005, sitl://wifi)")
        self.robot = robot
        self.clock = robot.clock
        self.localisation = cfg.get("localisation")
        self.controller = cfg.get("controller")
        self.odom_period = float(cfg.get("odometry_period_s", 0.1))
        self.status_period = float(cfg.get("status_period_s", 1.0))
        self.first_timeout = float(cfg.get("first_pose_timeout_s", 5.0))
        self.log_period = float(cfg.get("log_period_s", 0.0))
        self.link = open_link(str(cfg["url"]))
        self.own: AgentPose | None = None
        self.own_fresh = False
        self.others: list[AgentPose] = []
        self.mission: MissionOrder | None = None
        self.plan: PlanOrder | None = None
        self.last_seq: int | None = None
        self.counters = {
            "pose_packets": 0,
            "missions": 0,
            "plans": 0,
            "malformed": 0,
            "other": 0,
            "odometry_sent": 0,
            "status_sent": 0,
            "sonar_sent": 0,
        }
        self._odom_face: Any = None
        self._odom_at_own: tuple[float, float, float] | None = None  # the odometry's pose when the last own pose came
        self._odom_looked = False
        self._waited = False  # the first read's wait for a pose is over
        self._next_odom = 0.0
        self._next_status = 0.0
        self._next_log = 0.0
        self._seq = 0
        self._faces = {
            POSE: _OwnPose(self),
            LOCALISATION: _Localisation(self),
            MISSION: _Mission(self),
            PLAN: _Plan(self),
        }

    def faces(self) -> dict[str, Any]:
        return dict(self._faces)

    # -- receiving ---------------------------------------------------------------------------------------------
    def _take(self, data: bytes) -> None:
        try:
            head, content = pp.decode(data)
        except pp.PacketError:
            self.counters["malformed"] += 1
            return
        if head.type == pp.POSES:
            assert isinstance(content, list)
            self.counters["pose_packets"] += 1
            me = self.robot.id
            others = []
            fresh = False
            for e in content:
                if not e.valid:
                    continue
                pose = AgentPose(e.id, e.x_m, e.y_m, e.yaw_rad, e.vx_mps, e.vy_mps)
                if e.id == me:
                    self.own, fresh = pose, True
                    odom = self._odometry()
                    if odom is not None:
                        o = odom.read()
                        self._odom_at_own = (o.x_m, o.y_m, o.yaw_rad)
                else:
                    others.append(pose)
            self.own_fresh = fresh
            self.others = others
            self.last_seq = head.seq
        elif head.type == pp.MISSION:
            assert isinstance(content, pp.Mission)
            self.counters["missions"] += 1
            self.mission = MissionOrder(content.run, content.target_x_m, content.target_y_m, head.t_s)
        elif head.type == pp.PLAN:
            assert isinstance(content, pp.PlanPacket)
            self.counters["plans"] += 1
            self.plan = PlanOrder(content, head.t_s)
        else:  # another robot's odometry or status on a broadcast: not for us
            self.counters["other"] += 1

    def _drain(self) -> None:
        while (got := self.link.recv(0)) is not None:
            self._take(got[0])

    def wait_first_pose(self) -> None:
        """Wait for the first own pose, once: a robot the camera never saw must not stall every read."""
        if self._waited:
            self._drain()
            if self.own is None:
                raise NoPose(f"robot {self.robot.id}: still no pose from the localisation service")
            return
        self._waited = True
        deadline = self.clock.now() + self.first_timeout
        while self.own is None:
            left = deadline - self.clock.now()
            if left <= 0:
                raise NoPose(
                    f"robot {self.robot.id}: no pose from the localisation service within "
                    f"{self.first_timeout:g} s (sonpi_wifi.first_pose_timeout_s)"
                )
            got = self.link.recv(left)
            if got is not None:
                self._take(got[0])

    def dead_reckoned(self) -> AgentPose:
        """The last broadcast own pose moved by the odometry's displacement since it arrived (in the robot's own
        frame, so the odometry frame's offset does not matter); the pose as it was without odometry."""
        own, o0 = self.own, self._odom_at_own
        odom = self._odometry()
        assert own is not None
        if o0 is None or odom is None:
            return own
        o1 = odom.read()
        x0, y0, yaw0 = o0
        c0, s0 = math.cos(yaw0), math.sin(yaw0)
        dx, dy = o1.x_m - x0, o1.y_m - y0
        fwd, left = c0 * dx + s0 * dy, -s0 * dx + c0 * dy
        c, s = math.cos(own.yaw_rad), math.sin(own.yaw_rad)
        yaw = math.remainder(own.yaw_rad + (o1.yaw_rad - yaw0), math.tau)
        return AgentPose(
            own.id,
            own.x_m + fwd * c - left * s,
            own.y_m + fwd * s + left * c,
            yaw,
            o1.v_mps * math.cos(yaw),
            o1.v_mps * math.sin(yaw),
        )

    # -- sending -----------------------------------------------------------------------------------------------
    def _odometry(self) -> Any:
        """The robot's odometry face, looked up once (absent: the camera alone localises it)."""
        if not self._odom_looked:
            self._odom_looked = True
            self._odom_face = self.robot.faces.get(ODOMETRY_FACE) or self.robot.devices.get(ODOMETRY_FACE)
        return self._odom_face

    def _send(self, data: bytes, dest: str | None) -> None:
        self.link.send(data, dest)
        self._seq += 1

    def poll(self) -> None:
        """Take in what arrived; send the odometry and the status when they are due."""
        self._drain()
        now = self.clock.now()
        odom = self._odometry()
        if odom is not None and now >= self._next_odom:
            self._next_odom = _next(self._next_odom, now, self.odom_period)
            o = odom.read()
            self._send(
                pp.encode_odometry(
                    self._seq,
                    o.t_s,
                    pp.Odometry(
                        self.robot.id,
                        o.x_m,
                        o.y_m,
                        o.yaw_rad,
                        o.v_mps,
                        o.w_rps,
                        int(o.left_counts),
                        int(o.right_counts),
                    ),
                ),
                self.localisation,
            )
            self.counters["odometry_sent"] += 1
        if self.controller and now >= self._next_status:
            self._next_status = _next(self._next_status, now, self.status_period)
            own = self.own
            state = "running" if self.mission is not None and self.mission.run else "idle"
            self._send(
                pp.encode_status(
                    self._seq,
                    now,
                    pp.Status(
                        self.robot.id, state, own is not None, *((own.x_m, own.y_m, own.yaw_rad) if own else (0.0,) * 3)
                    ),
                ),
                self.controller,
            )
            self.counters["status_sent"] += 1
        if self.log_period > 0 and now >= self._next_log and self.own is not None:
            self._next_log = _next(self._next_log, now, self.log_period)
            p = self.own
            self.robot.log(
                "wifi_pose",
                x=p.x_m,
                y=p.y_m,
                yaw=p.yaw_rad,
                vx=p.vx_mps,
                vy=p.vy_mps,
                fresh=self.own_fresh,
                seq=self.last_seq,
                others=len(self.others),
                malformed=self.counters["malformed"],
            )

    def close(self) -> None:
        self.link.close()


def _next(due: float, now: float, period: float) -> float:
    """The next time a periodic send is due: one period after the last due time (so polls that come a little late
    keep the rate), or one period from now after a long gap (no burst to catch up)."""
    return due + period if now - due < period else now + period


def open_sonpi_wifi(cfg: dict[str, Any], robot: Any) -> SonpiWifi:
    """The HAL ``sonpi_wifi`` table's device: poses and the mission over Wi-Fi (``url``: ``udp://HOST:PORT``,
    ``sitl://wifi``), odometry and status sent back."""
    return SonpiWifi(cfg, robot)
