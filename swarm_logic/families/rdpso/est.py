"""Marsupial deployment (Couceiro 2013, §5.1, Algorithm 5.1): a ranger carries its subgroup of scouts and drops them
along an Extended Spiral of Theodorus, each where the radio link to the last ones reaches the threshold, so the
network starts connected (k = 1) or 2-connected (k = 2); or, as the baseline, each at random within d_max of the
last one.

The ranger (``EstRanger``, behaviour ``est_ranger``) drives to a random spot (first leg), drops scout 1 and tells it
its pose; then heads off at a random bearing, listening to scout 1's beacons, and drops scout 2 where their RSSI
falls to k·q_min (eq. 5.6, 5.13); then for each next scout heads for the spiral point of eq. 5.3-5.5 and drops it
there, or earlier when the weakest of the last k scouts' beacons reaches q_min, or when an obstacle blocks it.
After the last scout it broadcasts START. A scout (``ScoutDeployment``, used by the RDPSO controller with
``deployed = 1``) waits on board for its pose, then beacons its id and pose until it hears START, relays START
once, and starts its mission.

Messages are XBee broadcasts (``POSE``, ``BEACON``, ``START``: ``encode``/``decode`` below); poses are in the
arena frame, which the ranger's odometry uses from its start pose. Obstacles: the ranger turns toward the side
whose sonar reads more room, then goes on (the thesis' wall following, simplified).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Any, ClassVar

from swarm_logic.controller import DBM_RANGE, MAX_SPEED_MPS, MAX_TURN_RATE_RPS, Controller
from swarm_logic.families.rdpso.spiral import est_next, k_first_threshold_dbm
from swarm_logic.geometry import wrap
from swarm_logic.robot import Robot

MAGIC = 0x44  # "D": deployment
POSE, BEACON, START = 1, 2, 3
_POSE = struct.Struct("<BBBBfff")  # magic, type, ranger, scout, x, y, theta
_BEACON = struct.Struct("<BBBBff")  # magic, type, scout, ranger, x, y
_START = struct.Struct("<BBBB")  # magic, type, ranger, hops


@dataclass(frozen=True)
class Msg:
    kind: int
    ranger: int
    scout: int = 0
    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    hops: int = 0


def encode(m: Msg) -> bytes:
    if m.kind == POSE:
        return _POSE.pack(MAGIC, POSE, m.ranger, m.scout, m.x, m.y, m.theta)
    if m.kind == BEACON:
        return _BEACON.pack(MAGIC, BEACON, m.scout, m.ranger, m.x, m.y)
    return _START.pack(MAGIC, START, m.ranger, m.hops)


def decode(data: bytes) -> Msg | None:
    """A deployment message, or None for anything else (another protocol's frame, a malformed one)."""
    if len(data) < 2 or data[0] != MAGIC:
        return None
    kind = data[1]
    try:
        if kind == POSE and len(data) == _POSE.size:
            _, _, ranger, scout, x, y, th = _POSE.unpack(data)
            return Msg(POSE, ranger, scout, x, y, th) if all(map(math.isfinite, (x, y, th))) else None
        if kind == BEACON and len(data) == _BEACON.size:
            _, _, scout, ranger, x, y = _BEACON.unpack(data)
            return Msg(BEACON, ranger, scout, x, y) if math.isfinite(x) and math.isfinite(y) else None
        if kind == START and len(data) == _START.size:
            _, _, ranger, hops = _START.unpack(data)
            return Msg(START, ranger, hops=hops)
    except struct.error:
        return None
    return None


class ScoutDeployment:
    """A scout's side: on board until the ranger tells it its pose; then beacon until START; then go."""

    BEACON_S = 0.5

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.state = "board"  # -> "beacon" -> "started"
        self.ranger: int | None = None
        self.pose: tuple[float, float, float] | None = None
        self.next_beacon = 0.0
        self.malformed = 0

    @property
    def started(self) -> bool:
        return self.state == "started"

    def step(self) -> None:
        r = self.robot
        now = r.clock.now()
        while (pkt := r.xbee.recv(timeout=0)) is not None:
            m = decode(pkt.data)
            if m is None:
                self.malformed += pkt.data[:1] == bytes((MAGIC,))
                continue
            if m.kind == POSE and m.scout == r.id and self.state == "board":
                self.state, self.ranger, self.pose = "beacon", m.ranger, (m.x, m.y, m.theta)
                r.llc.set_odometry(m.x, m.y, m.theta)
                r.log("deployment", event="landed", ranger=m.ranger, x=m.x, y=m.y, theta=m.theta)
            elif m.kind == START and self.state == "beacon" and m.ranger == self.ranger:
                self.state = "started"
                relayed = encode(Msg(START, m.ranger, hops=min(255, m.hops + 1)))
                r.xbee.send_nowait(None, relayed, radius=1)  # relay once
                r.log("deployment", event="start", ranger=m.ranger, hops=m.hops, malformed=self.malformed)
                return
        if self.state == "beacon" and now >= self.next_beacon:
            self.next_beacon = now + self.BEACON_S
            x, y, _ = self.pose or (0.0, 0.0, 0.0)
            r.xbee.send_nowait(None, encode(Msg(BEACON, self.ranger or 0, r.id, x, y)), radius=1)


class EstRanger(Controller):
    """A TraxBot ranger deploying the scouts on its conveyor (``robot.payload``), then broadcasting START."""

    period_s = 0.1
    defaults: ClassVar[dict[str, Any]] = {
        "mode": "est",  # "est" (Extended Spiral of Theodorus) or "random" (within d_max of the last scout)
        "k": 1,  # connectivity of the deployment (1 or 2)
        "q_min_dbm": -75.0,  # the link threshold (RSSI of the scouts' beacons)
        "d_max_m": 3.0,  # the random baseline's radius; the spiral's leg when no beacon is heard
        "first_leg_min_m": 1.0,  # the first leg, to a random spot: a random length in this range ...
        "first_leg_max_m": 3.0,
        "speed_mps": 0.2,
        "turn_rate_rps": 0.8,
        "avoid_m": 0.45,  # an obstacle nearer than this on the front sonar: turn away
        "reach_m": 0.15,  # a spiral point within this is reached
        "drop_back_m": 0.193,  # where a dropped scout lands, behind the ranger's centre (ranger + scout radius + gap)
        "rssi_smoothing": 0.5,  # weight of the newest beacon RSSI
        "max_leg_m": 8.0,  # a leg longer than this ends with a drop anyway (a scout out of range never fades)
        "max_leg_s": 60.0,  # a leg that takes longer than this (circling an obstacle) ends with a drop anyway
        "min_leg_m": 0.4,  # a leg shorter than this never ends with a drop (the scouts would land on each other)
        # the area to deploy in, [x_min, y_min, x_max, y_max] in the arena frame (the building's plan, as a rescue
        # team would give it): points to drive to are kept inside it, area_margin_m from its edges; None: unbounded
        "area_m": None,
        "area_margin_m": 0.4,
    }
    ranges: ClassVar[dict[str, str]] = {
        "k": "[1, 5]",  # the ranger listens to the last k scouts
        "q_min_dbm": DBM_RANGE,
        "d_max_m": "(0, inf)",
        "first_leg_min_m": "[0, inf)",  # and <= first_leg_max_m
        "first_leg_max_m": "(0, inf)",
        "speed_mps": f"(0, {MAX_SPEED_MPS:g}]",
        "turn_rate_rps": f"(0, {MAX_TURN_RATE_RPS:g}]",
        "avoid_m": "[0, inf)",
        "reach_m": "(0, inf)",
        "drop_back_m": "[0, inf)",
        "rssi_smoothing": "(0, 1]",
        "max_leg_m": "(0, inf)",
        "max_leg_s": "(0, inf)",
        "min_leg_m": "(0, inf)",
        "area_margin_m": "[0, inf)",
    }

    @classmethod
    def resolve(cls, params: dict[str, Any]) -> dict[str, Any]:
        p = cls.with_defaults(params)  # each value of its kind and in its range
        if p["mode"] not in ("est", "random"):
            raise ValueError(f"mode: 'est' or 'random', got {p['mode']!r}")
        if not p["first_leg_min_m"] <= p["first_leg_max_m"]:
            raise ValueError("first_leg_min_m: must lie in [0, first_leg_max_m]")
        if p["mode"] == "random" and not p["d_max_m"] > p["min_leg_m"]:
            raise ValueError(f"d_max_m: must exceed min_leg_m = {p['min_leg_m']!r} (random points lie between "
                             f"the two), got {p['d_max_m']!r}")
        if p["area_m"] is not None:
            a = p["area_m"]
            if not (isinstance(a, list | tuple) and len(a) == 4 and all(isinstance(v, int | float) for v in a)):
                raise ValueError(f"area_m: [x_min, y_min, x_max, y_max] expected, got {a!r}")
            m = p["area_margin_m"]
            if not (a[2] - a[0] > 2 * m and a[3] - a[1] > 2 * m):
                raise ValueError(f"area_m: {list(a)} leaves no room inside area_margin_m = {m!r}")
        return p

    def init(self, robot: Robot) -> None:
        super().init(robot)
        if robot.xbee is None:
            raise ValueError("est_ranger talks to its scouts over the radio: give it an XBee")
        self.p = self.resolve(robot.params)
        if robot.start_pose is not None:
            robot.llc.set_odometry(*robot.start_pose)
        rng = robot.rng
        self.sigma = 1 if rng.random() < 0.5 else -1
        self.heading = float(rng.uniform(-math.pi, math.pi))
        self.leg_left = float(rng.uniform(self.p["first_leg_min_m"], self.p["first_leg_max_m"]))
        self.dropped: list[tuple[int, float, float, float]] = []  # (scout, x, y, theta) in drop order
        self.rssi: dict[int, float] = {}  # scout -> smoothed beacon RSSI
        self.heard: set[int] = set()  # scouts whose beacon came (they have their pose)
        self.state = "leg" if robot.payload else "done"
        self.target: tuple[float, float] | None = None
        self.leg_start: tuple[float, float] | None = None
        self.leg_t0 = 0.0  # when this leg began
        self.why: str | None = None  # why the last leg ended: first_leg, reached, rssi, blocked, max_leg, timeout
        self.releasing_from: int | None = None  # the conveyor position when a drop was asked for
        self.avoid_until = 0.0
        self.turn_dir = 1.0
        self.blocked_s = 0.0  # time spent turning away from obstacles on this leg
        self.next_pose = 0.0
        self.starts = 0
        self.t0 = self.next_log = robot.clock.now()
        self.malformed = 0

    # -- the loop ------------------------------------------------------------------------------------------
    def step(self) -> None:
        r = self.robot
        now = r.clock.now()
        self._listen()
        st = r.llc.state
        if st.odom_t is None:
            return
        if now >= self.next_log:  # where the deployment stands, once a second
            self.next_log = now + 1.0
            r.log("ranger", state=self.state, x=round(st.x, 3), y=round(st.y, 3), dropped=len(self.dropped),
                  target=None if self.target is None else [round(v, 3) for v in self.target],
                  heading=round(self.heading, 3), blocked_s=round(self.blocked_s, 1), malformed=self.malformed)
        if self.state == "leg":
            self._drive(now)
        elif self.state == "dropping":
            r.llc.drive(0.0, 0.0)
            if st.conveyor_position > (self.releasing_from or 0) and not st.conveyor_moving:
                self._dropped(now)
        elif self.state == "telling":  # the new scout has its pose once its beacon comes
            r.llc.drive(0.0, 0.0)
            scout = self.dropped[-1][0]
            if scout in self.heard:
                self._next_leg(now)
            elif now >= self.next_pose:
                self._tell(scout)
        elif self.state == "start":
            r.llc.drive(0.0, 0.0)
            if now >= self.next_pose and self.starts < 3:
                self.next_pose = now + 0.5
                self.starts += 1
                r.xbee.send_nowait(None, encode(Msg(START, r.id)), radius=1)
            if self.starts >= 3:
                self.state = "done"
                r.log("deployment", event="done", scouts=len(self.dropped), t=now - self.t0)
        else:
            r.llc.drive(0.0, 0.0)

    def _listen(self) -> None:
        a = self.p["rssi_smoothing"]
        while (pkt := self.robot.xbee.recv(timeout=0)) is not None:
            m = decode(pkt.data)
            if m is None:
                self.malformed += pkt.data[:1] == bytes((MAGIC,))
                continue
            if m.kind == BEACON and m.ranger == self.robot.id:
                self.heard.add(m.scout)
                if pkt.rssi_dbm is not None:
                    old = self.rssi.get(m.scout)
                    self.rssi[m.scout] = pkt.rssi_dbm if old is None else a * pkt.rssi_dbm + (1 - a) * old

    # -- driving a leg -------------------------------------------------------------------------------------------
    def _drive(self, now: float) -> None:
        r, p = self.robot, self.p
        st = r.llc.state
        x, y = st.x, st.y
        if self.leg_start is None:
            self.leg_start, self.leg_t0 = (x, y), now
        travelled = math.hypot(x - self.leg_start[0], y - self.leg_start[1])
        self.why = self._drop_reason(travelled, now - self.leg_t0)
        if self.why is not None:
            self._drop()
            return
        if now < self.avoid_until:  # turning away from an obstacle, toward the side with more room
            self.blocked_s += self.period_s
            r.llc.drive(0.0, self.turn_dir * p["turn_rate_rps"])
            return
        if st.sonar_m < p["avoid_m"]:
            if now >= self.avoid_until + self.period_s * 1.5:  # a new obstacle: pick the side
                left, right = st.sonar_left_m, st.sonar_right_m
                self.turn_dir = 1.0 if left > right else -1.0 if right > left else (
                    1.0 if r.rng.random() < 0.5 else -1.0)
            self.avoid_until = now + 0.6
            r.llc.drive(0.0, self.turn_dir * p["turn_rate_rps"])
            return
        if self.avoid_until > 0 and now < self.avoid_until + 2.0:  # clear: follow the new direction a while
            if self.target is None:  # a leg with no point to reach goes on this way
                self.heading = st.theta
            r.llc.drive(p["speed_mps"], 0.0)
            return
        if self.target is not None:  # the point is the scout's: aim from where a scout dropped now would land
            lx, ly = self._landing()
            self.heading = math.atan2(self.target[1] - ly, self.target[0] - lx)
        err = wrap(self.heading - st.theta)
        if abs(err) > 0.3:
            r.llc.drive(0.0, math.copysign(p["turn_rate_rps"], err))
        else:
            r.llc.drive(p["speed_mps"], 2.0 * err)

    def _landing(self) -> tuple[float, float]:
        """Where a scout dropped now would land: behind the ranger (the points to reach are the scouts')."""
        st, back = self.robot.llc.state, self.p["drop_back_m"]
        return st.x - back * math.cos(st.theta), st.y - back * math.sin(st.theta)

    def _drop_reason(self, travelled: float, took_s: float) -> str | None:
        """Why to drop the next scout now (logged with the drop), or None to drive on."""
        p = self.p
        n = len(self.dropped)
        x, y = self._landing()
        if n and math.hypot(x - self.dropped[-1][1], y - self.dropped[-1][2]) < p["min_leg_m"]:
            # never drop a scout onto the last one
            if self.blocked_s > 6.0:  # boxed in right after a drop: give up the point, turn back the way it came
                self.blocked_s = 0.0
                self.target = None
                self.heading = self.robot.llc.state.theta + math.pi
            return None
        if self.blocked_s > 6.0:  # blocked: drop it here
            return "blocked"
        if travelled >= p["max_leg_m"]:
            return "max_leg"
        if took_s >= p["max_leg_s"]:
            return "timeout"
        if n == 0:  # the first leg: to a random spot
            return "first_leg" if travelled >= self.leg_left else None
        if self.target is not None and math.hypot(self.target[0] - x, self.target[1] - y) <= p["reach_m"]:
            return "reached"
        if p["mode"] == "random":
            return None
        last = [s for s, *_ in self.dropped[-int(p["k"]):]]
        rssi = [self.rssi[s] for s in last if s in self.rssi]
        threshold = k_first_threshold_dbm(p["q_min_dbm"], int(p["k"])) if n == 1 else p["q_min_dbm"]
        return "rssi" if rssi and min(rssi) <= threshold else None

    # -- dropping a scout ------------------------------------------------------------------------------------
    def _drop(self) -> None:
        r = self.robot
        r.llc.drive(0.0, 0.0)
        self.releasing_from = r.llc.state.conveyor_position
        r.llc.release(1)
        self.state = "dropping"

    def _dropped(self, now: float) -> None:
        r, p = self.robot, self.p
        st = r.llc.state
        scout = r.payload[len(self.dropped)]
        x, y = self._landing()
        self.dropped.append((scout, x, y, st.theta))
        r.log("deployment", event="dropped", scout=scout, x=x, y=y, theta=st.theta, t=now - self.t0, why=self.why,
              target=None if self.target is None else [round(self.target[0], 3), round(self.target[1], 3)],
              rssi=[round(self.rssi[s], 1) for s, *_ in self.dropped[-int(p["k"]) - 1:-1] if s in self.rssi])
        self.state = "telling"
        self._tell(scout)

    def _tell(self, scout: int) -> None:
        r = self.robot
        _, x, y, th = self.dropped[-1]
        self.next_pose = r.clock.now() + 0.5
        r.xbee.send_nowait(None, encode(Msg(POSE, r.id, scout, x, y, th)), radius=1)

    def _next_leg(self, now: float) -> None:
        r, p = self.robot, self.p
        n = len(self.dropped)
        if n >= len(r.payload):
            self.state = "start"
            self.next_pose = now
            return
        self.state = "leg"
        self.leg_start = None
        self.target = None
        self.blocked_s = 0.0
        if p["mode"] == "random":  # the baseline: uniformly within d_max of the last scout (and inside the area),
            _, lx, ly, _ = self.dropped[-1]  # but not nearer than min_leg_m, where no scout may be dropped
            lo, hi = p["min_leg_m"] ** 2, p["d_max_m"] ** 2
            for _ in range(100):
                rad = math.sqrt(lo + (hi - lo) * float(r.rng.random()))
                ang = float(r.rng.uniform(-math.pi, math.pi))
                self.target = (lx + rad * math.cos(ang), ly + rad * math.sin(ang))
                if self._inside(self.target):
                    break
            self.target = self._clip(self.target)
        elif n == 1:  # away at a random bearing, until scout 1's beacons fade to k q_min
            self.heading = float(r.rng.uniform(-math.pi, math.pi))
        else:  # the spiral point of eq. 5.3-5.5 from the last two scouts, with their measured leg
            (_, x1, y1, _), (_, x2, y2, th2) = self.dropped[-2], self.dropped[-1]
            d = math.hypot(x2 - x1, y2 - y1)
            self.target = self._clip(est_next((x1, y1), (x2, y2), th2, max(d, p["min_leg_m"]), n - 1,
                                              self.sigma))

    def _inside(self, pt: tuple[float, float]) -> bool:
        a, m = self.p["area_m"], self.p["area_margin_m"]
        return a is None or (a[0] + m <= pt[0] <= a[2] - m and a[1] + m <= pt[1] <= a[3] - m)

    def _clip(self, pt: tuple[float, float]) -> tuple[float, float]:
        """``pt`` moved to the nearest point inside the deployment area (unchanged without one)."""
        a, m = self.p["area_m"], self.p["area_margin_m"]
        if a is None:
            return pt
        return (min(max(pt[0], a[0] + m), a[2] - m), min(max(pt[1], a[1] + m), a[3] - m))

    def telemetry(self) -> dict[str, float | int]:
        return {"dropped": len(self.dropped), "carried": len(self.robot.payload) - len(self.dropped),
                "started": int(self.state == "done")}
