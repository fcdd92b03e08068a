"""Session configuration: TOML files in ``hil_configs/``, validated with pydantic.

Every error names the file, the field and the reason, e.g.
``hil_configs/demo.toml: robots[0].count: Input should be greater than 0``.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    TypeAdapter,
    ValidationError,
    ValidationInfo,
    create_model,
    field_validator,
    model_validator,
)

from bridge.core.profile import RobotProfile
from bridge.core.registry import SERVICES, STUDIES, PluginError, default_robot, robot_profile, robot_spec
from bridge.media.impairments import AIR_FAULTS, UWB_RADIO_ROLE
from bridge.media.radio import RadioCfg
from bridge.media.uwb import UwbCfg
from bridge.media.wifi import WifiCfg


class ConfigError(Exception):
    """A config that cannot be used; the message names file, field and reason."""


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=False)

    def _only_for_kind(self, kind: str, applies: set[str], always: set[str]) -> None:
        """Refuse fields set away from their defaults that ``kind`` does not use (a config meant for another kind)."""
        fields = type(self).model_fields
        stray = sorted(f for f in self.model_fields_set - applies - always if getattr(self, f) != fields[f].default)
        if stray:
            raise ValueError(f"{', '.join(stray)} do(es) not apply to kind = {kind!r}")


class Section(_Model):
    """A config section's base: a study's own sections (``Study.config``) derive from it, so theirs refuse unknown
    fields as the core's do."""


class SessionCfg(_Model):
    name: str = "session"
    duration_s: float = Field(60.0, gt=0, le=30 * 24 * 3600)
    seed: int = Field(1, ge=0, lt=2**63)
    quantum_ms: float = Field(10.0, gt=0, le=1000)
    speed: float | Literal["max"] = "max"
    robots_per_process: int = Field(1, ge=1)
    on_robot_failure: Literal["continue", "stop"] = "continue"
    hang_timeout_s: float = Field(20.0, gt=0, description="wall seconds a process may take for one quantum")
    startup_timeout_s: float = Field(120.0, gt=0)
    poses_every_quanta: int = Field(1, ge=1, description="ground-truth pose recording period, in quanta")
    scene_hz: float = Field(10.0, ge=0, le=1000, description="Foxglove scene updates (/scene/robots, /tf) per "
                                                             "simulated second in the recording; 0: no scene channels")
    record_ticks: bool = Field(False, description="record every run of every entity of the robots' processes (its "
                                                  "inputs and its answer, /ticks/<entity>), so swarm-sitl replay can "
                                                  "re-run one process against them")
    live: str | None = Field(None, description="HOST:PORT (loopback; port 0: any free one) where Foxglove's WebSocket "
                                               "server serves the scene while the session runs (swarm-sitl run --live)")
    end_after_deployment: bool = Field(False, description="end the session 1 s after the study's loop functions "
                                                          "say the deployment is done (deployment studies need no "
                                                          "mission)")
    listen: str | None = Field(None, description="tcp/HOST:PORT: the world also listens here (besides its private "
                                                 "unix socket), so the swarm logic of robots with logic = \"remote\" "
                                                 "joins from another computer (swarm-sitl join); HOST is an address of "
                                                 "this machine, 127.0.0.1 to stay on it")

    @field_validator("listen")
    @classmethod
    def _tcp_endpoint(cls, v: str | None) -> str | None:
        if v is not None:
            host, _, port = v.removeprefix("tcp/").rpartition(":")
            if not v.startswith("tcp/") or not host or not port.isdigit() or not 0 < int(port) < 65536:
                raise ValueError(f"{v!r} is not tcp/HOST:PORT (e.g. tcp/127.0.0.1:7447, or tcp/192.168.1.10:7447 "
                                 "for a logic on another computer)")
        return v

    @field_validator("live")
    @classmethod
    def _live_loopback(cls, v: str | None) -> str | None:
        if v is not None:
            from bridge.core.live import parse_listen

            parse_listen(v)
        return v

    @model_validator(mode="after")
    def _live_needs_a_scene(self) -> SessionCfg:
        if self.live is not None and self.scene_hz <= 0:
            raise ValueError("live: serves the scene, which scene_hz = 0 switches off")
        return self

    @field_validator("speed")
    @classmethod
    def _speed_positive(cls, v: float | str) -> float | str:
        if v != "max" and not (isinstance(v, float | int) and v > 0):
            raise ValueError('must be a positive number or "max"')
        return v

    @property
    def quantum_ns(self) -> int:
        return round(self.quantum_ms * 1e6)


class WorldCfg(_Model):
    physics_hz: float = Field(240.0, gt=0, le=10000)
    solver_iterations: int = Field(10, ge=1, le=200)


class FloorPatch(_Model):
    """A rectangle of the floor in a grey level of its own (ARGoS's floor entity: a nest painted grey, a black line),
    what a robot's ground sensors read there."""

    x_min: float
    y_min: float
    x_max: float
    y_max: float
    grey: float = Field(ge=0, le=1, description="0 black, 1 white")

    @model_validator(mode="after")
    def _ordered(self) -> FloorPatch:
        if not (self.x_min < self.x_max and self.y_min < self.y_max):
            raise ValueError("a floor patch needs x_min < x_max and y_min < y_max")
        return self


class ArenaCfg(_Model):
    width_m: float = Field(10.0, gt=0, le=1000, description="extent along x")
    length_m: float = Field(20.0, gt=0, le=1000, description="extent along y")
    wall_height_m: float = Field(0.5, gt=0)
    wall_thickness_m: float = Field(0.1, gt=0)
    map: str | None = Field(None, description="monochrome bitmap, dark pixels are obstacles")
    map_resolution_m: float = Field(0.05, gt=0, description="metres per map pixel")
    map_threshold: int = Field(128, ge=1, le=255)
    floor_grey: float = Field(1.0, ge=0, le=1, description="the floor's grey level where no patch is (0 black, 1 "
                                                           "white), as ground sensors read it")
    floor: list[FloorPatch] = Field([], description="patches of another grey level; a later one covers an earlier")

    def grey_at(self, x: Any, y: Any) -> Any:
        """The floor's grey level at (x, y): floats or numpy arrays of any shape."""
        out = np.zeros(np.broadcast(x, y).shape) + self.floor_grey
        for p in self.floor:
            out = np.where((x >= p.x_min) & (x < p.x_max) & (y >= p.y_min) & (y < p.y_max), p.grey, out)
        return out


class ObstacleMotion(_Model):
    """A kinematic path for an obstacle (a programmable toy car, a trolley): it starts at the obstacle's (x, y) and
    moves in straight lines at constant speed to each waypoint in turn, keeping its yaw; nothing pushes it off its
    path (it pushes what it meets). ``repeat``: the path starts over after its last waypoint, which must then be the
    start."""

    waypoints: list[tuple[float, float, float]] = Field(
        description="[t_s, x, y]: where the obstacle is at t_s (increasing, > 0)", min_length=1
    )
    repeat: bool = Field(False, description="start over after the last waypoint (a loop back to the start)")

    @field_validator("waypoints")
    @classmethod
    def _increasing(cls, v: list[tuple[float, float, float]]) -> list[tuple[float, float, float]]:
        ts = [w[0] for w in v]
        if ts[0] <= 0 or any(b <= a for a, b in itertools.pairwise(ts)):
            raise ValueError("waypoint times must be > 0 and increasing")
        return v


class _Obstacle(_Model):
    motion: ObstacleMotion | None = Field(None, description="a moving obstacle's path (none: it stays put)")

    @model_validator(mode="after")
    def _loop_closes(self) -> _Obstacle:
        m = self.motion
        if m is not None and m.repeat and math.hypot(m.waypoints[-1][1] - self.x, m.waypoints[-1][2] - self.y) > 1e-6:
            raise ValueError("motion.repeat: the last waypoint must be the obstacle's start (x, y)")
        return self


class BoxObstacle(_Obstacle):
    type: Literal["box"]
    x: float
    y: float
    size: tuple[float, float, float] = Field(description="full extents x, y, z in metres")
    yaw_deg: float = 0.0

    def overlaps(self, x: float, y: float, clearance: float = 0.0) -> bool:
        """The disc of radius ``clearance`` at (x, y) reaches into the box."""
        c, s = math.cos(math.radians(self.yaw_deg)), math.sin(math.radians(self.yaw_deg))
        dx, dy = x - self.x, y - self.y
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        return abs(lx) < self.size[0] / 2 + clearance and abs(ly) < self.size[1] / 2 + clearance

    @field_validator("size")
    @classmethod
    def _positive(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        if min(v) <= 0:
            raise ValueError("all extents must be > 0")
        return v


class CylinderObstacle(_Obstacle):
    type: Literal["cylinder"]
    x: float
    y: float
    radius: float = Field(gt=0)
    height: float = Field(0.5, gt=0)

    def overlaps(self, x: float, y: float, clearance: float = 0.0) -> bool:
        """The disc of radius ``clearance`` at (x, y) reaches into the cylinder."""
        return math.hypot(x - self.x, y - self.y) < self.radius + clearance


Obstacle = Annotated[BoxObstacle | CylinderObstacle, Field(discriminator="type")]


class RandomObstaclesCfg(_Model):
    """Boxes scattered at random (field trials move their obstacles between runs): drawn from the session seed
    when the config is loaded and added to ``obstacles``, so one seed gives one layout and the world sees
    ordinary boxes."""

    count: int = Field(ge=1, le=1000)
    side_m: tuple[float, float] = Field((0.3, 1.0), description="range of each box side (x and y drawn apart)")
    height_m: float = Field(0.5, gt=0)
    clearance_m: float = Field(0.8, ge=0, description="free gap kept to the robots' start poses, the walls and "
                                                      "the other obstacles")
    keep_clear: list[tuple[float, float, float]] = Field([], description="(x, y, radius) discs kept free of boxes, "
                                                                         "e.g. an entrance")

    @field_validator("side_m")
    @classmethod
    def _sides(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not 0 < v[0] <= v[1]:
            raise ValueError(f"need 0 < min <= max, got {list(v)}")
        return v


class LightSource(_Model):
    """A light spot: illuminance adds a Gaussian of ``peak_lux`` and ``sigma_m`` to the ambient."""

    x: float
    y: float
    peak_lux: float = Field(gt=0)
    sigma_m: float = Field(gt=0)


class LightCfg(_Model):
    ambient_lux: float = Field(50.0, ge=0)
    sources: list[LightSource] = []

    def illuminance(self, x: Any, y: Any) -> Any:
        """Illuminance (lux) at (x, y): floats or numpy arrays of any shape."""
        total = np.zeros(np.broadcast(x, y).shape) + self.ambient_lux
        for s in self.sources:
            total = total + s.peak_lux * np.exp(-((x - s.x) ** 2 + (y - s.y) ** 2) / (2 * s.sigma_m * s.sigma_m))
        return total


class Placement(_Model):
    kind: Literal["grid", "random", "explicit", "spiral"] = "grid"
    origin: tuple[float, float] = (1.0, 1.0)
    spacing_m: float = Field(0.5, gt=0)
    columns: int = Field(5, ge=1)
    region: tuple[float, float, float, float] | None = Field(
        None, description="x_min, y_min, x_max, y_max for random placement (default: whole arena)"
    )
    min_separation_m: float = Field(0.3, gt=0)
    poses: list[tuple[float, float, float]] = Field([], description="explicit [x, y, yaw_deg] per robot")
    centres: list[tuple[float, float]] = Field([], description="spiral: one spiral of Theodorus per centre; the "
                                               "robots are split into as many consecutive blocks (initial "
                                               "subgroups), spacing_m apart")
    yaw_deg: float | Literal["random"] = "random"

    @model_validator(mode="after")
    def _fields_fit_kind(self) -> Placement:
        applies = {"grid": {"origin", "spacing_m", "columns", "yaw_deg"},
                   "random": {"region", "min_separation_m", "yaw_deg"},
                   "explicit": {"poses"},
                   "spiral": {"centres", "spacing_m", "yaw_deg"}}[self.kind]
        self._only_for_kind(self.kind, applies, {"kind"})
        if self.kind == "spiral" and not self.centres:
            raise ValueError("centres: a spiral placement needs at least one centre")
        return self


XBEE_BAUDS = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200)  # the BD table of the XBee modules


def _xbee_baud(v: int) -> int:
    if v not in XBEE_BAUDS:
        raise ValueError(f"{v} is not an XBee BD rate; one of {', '.join(map(str, XBEE_BAUDS))}")
    return v


XBeeBaud = Annotated[int, AfterValidator(_xbee_baud)]


class XBeeCfg(_Model):
    """A robot's XBee module: which firmware it runs and how its UART is set up (as configured with XCTU)."""

    series: Literal[1, 2] = Field(2, description="1: 802.15.4 firmware (frames 0x00/0x01/0x80/0x81/0x89); "
                                                 "2: ZigBee firmware (0x10/0x8B/0x90)")
    api_mode: Literal[1, 2] = Field(1, description="AP: 1 plain API frames, 2 API frames with escaped bytes")
    baud: XBeeBaud = Field(9600, description="BD: UART rate in bit/s (the modules' default is 9600)")
    power_level: int = Field(4, ge=0, le=4, description="PL: transmit power level, 4 is the highest")
    pan_id: int = Field(0x3332, ge=0, le=0xFFFF, description="ID: PAN id; modules hear only their own PAN")
    channel: int = Field(0x0C, ge=0x0B, le=0x1A, description="CH: 802.15.4 channel 11-26")
    routing: Literal["mesh", "one_hop"] = Field("one_hop", description="Series 2: 'mesh', the ZigBee firmware's "
                                                   "own routing (address and route discovery, relayed broadcasts, "
                                                   "the broadcast table's limits); 'one_hop', a unicast reaches "
                                                   "only a module that hears it and nobody relays. Series 1 is "
                                                   "always one hop")
    pty: str | None = Field(None, description="expose this XBee's UART on a pseudo-terminal, linked at this path "
                                              "(relative to the session's output directory; '{id}' is replaced by "
                                              "the robot id); the robot's own logic then cannot open sitl://xbee")
    device: str | None = Field(None, description="a real XBee on this serial device (or pyserial URL) is the robot's "
                                                 "radio: its logic talks to it at series/api_mode/baud as set here, it "
                                                 "transmits on the real air, and the simulated radio channel does not "
                                                 "include it")

    @model_validator(mode="after")
    def _one_way_out(self) -> XBeeCfg:
        if self.pty and self.device:
            raise ValueError("pty and device exclude each other: the module is either simulated (its UART on a pty) or "
                             "real (on the device)")
        return self



def _check_times(waypoints: list[tuple[float, ...]], field: str = "") -> None:
    """A path's waypoints are in time order, from 0 on."""
    times = [w[0] for w in waypoints]
    if times and (times[0] < 0 or any(b <= a for a, b in itertools.pairwise(times))):
        raise ValueError(f"{field}times must start at 0 or later and increase strictly")


class MotionCfg(_Model):
    """How a robot body moves that the session does not drive: its LLC is a real board (``can.device``) or it is a
    MAVLink vehicle. The session cannot know where the real thing goes, so the config states it."""

    kind: Literal["simulated", "fixed", "scripted"] = Field(
        "simulated", description="simulated: the world drives the body from the LLC's motor outputs; fixed: the body "
                                 "stays at its placement; scripted: it follows waypoints")
    waypoints: list[tuple[float, float, float, float]] = Field(
        [], description="scripted: [t_s, x, y, yaw_deg] in increasing time; the pose is interpolated linearly "
                        "between them, the first holds before and the last after")

    @model_validator(mode="after")
    def _fields_fit_kind(self) -> MotionCfg:
        self._only_for_kind(self.kind, {"waypoints"} if self.kind == "scripted" else set(), {"kind"})
        if self.kind == "scripted":
            if not self.waypoints:
                raise ValueError("waypoints: a scripted motion needs at least one [t_s, x, y, yaw_deg]")
            _check_times(self.waypoints, "waypoints: ")
        return self


class RobotCanCfg(_Model):
    """A robot's CAN bus: outside access to the simulated bus, or the real board the bus bridges to."""

    slcan_pty: str | None = Field(
        None, description="expose the robot's CAN bus on a pseudo-terminal as a LAWICEL (slcan) USB-CAN adapter, "
                          "linked at this path (relative to the session's output directory; '{id}' is replaced by the "
                          "robot id): python-can's slcan interface, candump-style tools and a real robot's logic "
                          "open it")
    device: dict[str, Any] | None = Field(
        None, description="the robot's real LLC board is on this CAN interface, given as python-can Bus arguments, "
                          "e.g. { interface = \"socketcan\", channel = \"can0\" } or { interface = \"slcan\", "
                          "channel = \"/dev/ttyACM0\", bitrate = 500000 }: the session bridges the robot's bus to it "
                          "and does not simulate the LLC (state the body's motion)")

    @field_validator("device")
    @classmethod
    def _python_can_args(cls, v: dict[str, Any] | None) -> dict[str, Any] | None:
        if v is not None:
            from can.interfaces import VALID_INTERFACES

            if not isinstance(v.get("interface"), str) or "channel" not in v:
                raise ValueError("needs interface and channel, e.g. { interface = \"socketcan\", channel = \"can0\" }")
            if v["interface"] == "sitl":
                raise ValueError("interface 'sitl' is the session's own simulated bus; name the interface of the "
                                 "real board's adapter")
            if v["interface"] not in VALID_INTERFACES:
                raise ValueError(f"interface {v['interface']!r} is not a python-can interface; one of "
                                 f"{', '.join(sorted(VALID_INTERFACES))}")
        return v


class VehicleCfg(_Model):
    """A vehicle that speaks only MAVLink (an ArduPilot Rover, another swarm's robot) stands in the swarm for this
    robot: the session's swarm logic drives it through ``swarm_logic.mavlink.low_level`` instead of an LLC."""

    url: str = Field(description="where the vehicle is: a pymavlink connection (udpin:0.0.0.0:14551, "
                                 "udpout:192.168.4.1:14550, tcp:HOST:PORT) or a serial device (/dev/ttyUSB1)")
    target_system: int = Field(1, ge=1, le=255, description="the vehicle's MAVLink system id")
    target_component: int = Field(1, ge=0, le=255)
    baudrate: int = Field(57600, gt=0, description="serial devices: the telemetry radio's rate")
    timeout_s: float = Field(10.0, gt=0, description="how long the logic waits for the vehicle's first heartbeat")


def _registered(get: Any, name: str, rename: tuple[str, str] = ("", "")) -> str:
    """``name`` if a plugin registry knows it (``get(name)``), else a ValueError saying which there are."""
    try:
        get(name)
    except PluginError as e:
        raise ValueError(str(e).replace(*rename) if rename[0] else str(e)) from None
    return name


class _NoOptions(_Model):
    """The options of a robot model that declares none."""


class RobotGroup(_Model):
    profile: str = Field(default_factory=default_robot, description="the robot model (swarm-sitl list robots); "
                                                                   "without it, the installed default")
    count: int = Field(1, ge=1, le=10000)
    behaviour: str = "random_walk"
    params: dict[str, Any] = {}
    placement: Placement = Placement()
    xbee: XBeeCfg | None = Field(None, description="the robot's XBee radio module (none: no radio)")
    uwb: bool = Field(False, description="fit a DWM1001-class UWB ranging module")
    pose_source: Literal["odometry", "ground_truth"] = Field(
        "odometry", description="odometry: the LLC reports its dead-reckoned pose in ODOMETRY (from (0, 0, 0) at "
                                "power-up, or ODOM_SET); ground_truth: the LLC reports the true pose in ODOMETRY, "
                                "as if a motion-capture system fed it; an idealisation for algorithm tests, "
                                "flagged in STATUS and summary.json")

    logic: Literal["session", "external", "remote"] = Field(
        "session", description="session: the session runs the robot's swarm logic (in simulated time); external: "
                               "a program outside the session (a real robot's companion computer, a test) runs it in "
                               "wall time and reaches the robot's devices only through their ports (xbee.pty, and "
                               "those its robot model names: an eSwarBot's can.slcan_pty); remote: the session's own "
                               "logic process for the robot runs on "
                               "another computer, joining over zenoh (session.listen, swarm-sitl join), still in "
                               "simulated time")
    can: RobotCanCfg = RobotCanCfg()
    wifi_udp: str | None = Field(
        None, description="with logic = \"external\": the robot's node on the session's Wi-Fi network as a UDP socket "
                          "bound at HOST:PORT (port 0: any free one, reported when the session starts), e.g. "
                          "\"127.0.0.1:0\": what the network delivers to the robot goes to whoever last sent to it, "
                          "what it receives enters the network as the robot's broadcasts")
    vehicle: VehicleCfg | None = Field(None, description="the robot is a MAVLink vehicle: no LLC, the logic drives it "
                                                         "over MAVLink (state the body's motion)")
    motion: MotionCfg = Field(MotionCfg(), description="how the body moves when the session does not drive it")
    devices: dict[str, dict[str, Any]] = Field(
        {}, description="devices the robot program gets in a session beyond its model's, as HAL tables by device "
                        "name (a swarm_sitl.devices plugin), e.g. { sonpi_wifi = { url = \"sitl://wifi\" } }")
    carried_by: int | None = Field(None, ge=0, description="index of the robot group whose robots carry these on "
                                                           "board (e.g. on a conveyor): they start on "
                                                           "board, filled carrier by carrier in robot order, and go "
                                                           "down when the carrier's part releases them")
    host: str | GroupHostsCfg | None = Field(
        None, description="the host of [[hosts]] the robots' firmware and logic processes run on, or by kind, e.g. "
                          "{ logic = \"pi1\" } (the firmware stays on the world's computer); none: the world's")

    @field_validator("host", mode="before")
    @classmethod
    def _host_or_kinds(cls, v: Any) -> Any:
        """A host's name, or a table of hosts by process kind; anything else refused in one clear message."""
        if isinstance(v, dict):
            stray = sorted(set(v) - set(GroupHostsCfg.model_fields))
            if stray or not all(isinstance(h, str | None) for h in v.values()):
                raise ValueError(f"{v!r}: a table of hosts by process kind takes firmware and logic, each a host's "
                                 "name")
            return GroupHostsCfg(**v)
        if v is not None and not isinstance(v, str | GroupHostsCfg):
            raise ValueError(f"{v!r}: a host's name (all the group's processes there), or {{ firmware = ..., "
                             "logic = ... }")
        return v

    def hosts(self) -> tuple[str | None, str | None]:
        """The hosts of the group's firmware and logic processes (None: the world's computer)."""
        if isinstance(self.host, GroupHostsCfg):
            return self.host.firmware, self.host.logic
        return self.host, self.host

    # fields beyond these are the robot model's own options (RobotSpec.options)
    model_config = ConfigDict(extra="allow", frozen=False)

    @model_validator(mode="after")
    def _robot_options(self) -> RobotGroup:
        """Fields beyond a group's own are options of its robot model: its plugin's model validates them (an error
        names the field, as for the group's own)."""
        try:
            spec = robot_spec(self.profile)
        except PluginError:
            return self  # the profile's own error says why
        for name in sorted(set(spec.refuses) & self.model_fields_set):
            field = type(self).model_fields[name]
            if getattr(self, name) != field.get_default(call_default_factory=True):  # a plan's dump has them all
                raise ValueError(f"{name}: {spec.refuses[name]}")
        extra = self.model_extra or {}
        if extra:
            (spec.options or _NoOptions).model_validate(extra)
        return self

    @model_validator(mode="after")
    def _pty_per_robot(self) -> RobotGroup:
        for what, link in (("xbee.pty", self.xbee.pty if self.xbee else None), ("can.slcan_pty", self.can.slcan_pty),
                           *self.model_ptys().items()):
            if link and self.count > 1 and "{id}" not in link:
                raise ValueError(f"{what}: a group of several robots needs '{{id}}' in the link path")
        if self.logic == "external":
            for what, how in self._external_ports().items():  # the robot model says which ports its program needs
                if not self._field(what):
                    raise ValueError(f"{what}: {how}")
            if self.xbee is not None and not (self.xbee.pty or self.xbee.device):
                raise ValueError("xbee.pty: an external logic reaches the robot's XBee through a pseudo-terminal: give "
                                 "it one, e.g. xbee = { pty = \"r{id}-xbee\" }")
            if self.uwb:
                raise ValueError("uwb: a UWB module cannot be reached from an external logic (it has no port); "
                                 "drop it")
        if self.wifi_udp is not None:
            from swarm_logic.drivers.wifi import split_host_port

            _, port = split_host_port(self.wifi_udp, "wifi_udp")
            if self.logic != "external":
                raise ValueError("wifi_udp: the session's own logic is the robot's node on the Wi-Fi network; a UDP "
                                 "port is for a program outside the session (logic = \"external\")")
            if port and self.count > 1:
                raise ValueError(f"wifi_udp: {self.count} robots cannot share port {port}: give port 0 (each its own "
                                 "free port) or the robot a group of its own")
        if self.vehicle is not None:
            if self.can.device is not None:
                raise ValueError("vehicle: a MAVLink vehicle has no LLC on a CAN bus: drop can.device")
            if self.logic == "external":
                raise ValueError("vehicle: the session's logic drives a MAVLink vehicle; an external program talks to "
                                 "it directly, without the session")
        if self.logic == "remote":
            for what, on in (("xbee.device", bool(self.xbee and self.xbee.device)), ("vehicle", self.vehicle)):
                if on:
                    raise ValueError(f"{what}: a remote logic would open it on its own computer, where the session "
                                     "cannot check it before the start; run that robot's logic in the session")
        simulated_llc = self.can.device is None and self.vehicle is None
        if simulated_llc and self.motion.kind != "simulated":
            raise ValueError(f"motion.kind = {self.motion.kind!r}: the session drives this robot's body through its "
                             "simulated boards (wheels, legs); a stated motion is for a robot whose LLC is real "
                             "(can.device) or that is a MAVLink vehicle (vehicle)")
        if not simulated_llc:
            what = "can.device" if self.vehicle is None else "vehicle"
            if self.motion.kind == "simulated":
                raise ValueError(f"motion: with {what} the robot moves in the real world, where the session cannot "
                                 "see it: state where its body is, motion = { kind = \"fixed\" } (at its placement) "
                                 "or { kind = \"scripted\", waypoints = [[t_s, x, y, yaw_deg], ...] }")
            if self.pose_source == "ground_truth":
                raise ValueError(f"pose_source: with {what} the LLC that would report the true pose is not simulated")
        if self.carried_by is not None and self.placement != Placement():
            raise ValueError("placement: carried robots start on board; where they go down is their carrier's to "
                             "decide")
        if self.carried_by is not None and not simulated_llc:
            raise ValueError("carried_by: a carried robot is a simulated one")
        if self.motion.kind == "scripted" and self.count > 1:
            raise ValueError("motion: scripted waypoints are one body's path: give the robot a group of its own "
                             "(count = 1)")
        return self

    def _external_ports(self) -> dict[str, str]:
        try:
            return robot_spec(self.profile).external_ports
        except PluginError:
            return {}  # the profile's own error says why

    def _field(self, dotted: str) -> Any:
        """A group field by its dotted config name (``can.slcan_pty``), a robot model's option included."""
        head, _, rest = dotted.partition(".")
        value = getattr(self, head) if head in type(self).model_fields else (self.model_extra or {}).get(head)
        for part in rest.split(".") if rest else ():
            value = value.get(part) if isinstance(value, dict) else getattr(value, part, None)
        return value

    def model_ptys(self) -> dict[str, str]:
        """The robot model's options that expose one of its modules on a pseudo-terminal (an option named ``*_pty``
        holds the link path, as ``xbee.pty`` does): option -> path."""
        return {k: v for k, v in (self.model_extra or {}).items() if k.endswith("_pty") and isinstance(v, str) and v}

    def real_ports(self) -> list[str]:
        """The fields that open this group to the outside world (wall time): what makes a session real-time."""
        return [*self.model_ptys()] + [f for f, on in (("xbee.pty", bool(self.xbee and self.xbee.pty)),
                                ("xbee.device", bool(self.xbee and self.xbee.device)),
                                ("can.slcan_pty", bool(self.can.slcan_pty)),
                                ("can.device", self.can.device is not None), ("vehicle", self.vehicle is not None),
                                ("wifi_udp", self.wifi_udp is not None),
                                ("logic", self.logic == "external")) if on]

    @field_validator("devices")
    @classmethod
    def _known_devices(cls, v: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
        from swarm_logic.devices import BUILT_IN, DEVICES, NOT_DEVICES

        for name in v:
            if name in BUILT_IN or name in NOT_DEVICES or name not in DEVICES.names():
                raise ValueError(f"{name!r} is not a device the session can add; devices: "
                                 f"{', '.join(DEVICES.names()) or 'none'}")
        return v

    @field_validator("profile")
    @classmethod
    def _known_profile(cls, v: str) -> str:
        return _registered(robot_spec, v, ("unknown robot", "unknown robot profile"))


class XBeeGatewayCfg(_Model):
    """A real XBee on this machine joined to the simulated radio channel: the gateway is a simulated module at a
    stated pose, wired back to back to the real one (as two radios and a relay board would be). What the
    simulated module hears it sends on the real air; what the real one hears it sends into the simulation."""

    device: str = Field(description="the real XBee's serial device (or pyserial URL), e.g. /dev/ttyUSB0")
    baud: XBeeBaud = Field(9600, description="BD of the real module, as configured with XCTU")
    api_mode: Literal[1, 2] = Field(1, description="AP of the real module")
    series: Literal[1, 2] = Field(2, description="firmware of both modules (the real one's and its simulated "
                                                 "twin's): the desk radio's and the swarm's")
    pose: tuple[float, float] = Field(description="x, y of the gateway's simulated antenna in the arena (m)")
    waypoints: list[tuple[float, float, float]] = Field(
        [], description="or a path: [t_s, x, y] in increasing time, interpolated linearly (pose is where it starts)")
    pan_id: int = Field(0x3332, ge=0, le=0xFFFF, description="ID of the simulated twin: the swarm's PAN")
    channel: int = Field(0x0C, ge=0x0B, le=0x1A, description="CH of the simulated twin: the swarm's channel")
    power_level: int = Field(4, ge=0, le=4, description="PL of the simulated twin")
    peer: str | None = Field(None, description="64-bit address (16 hex digits) of the desk radio: what the swarm "
                                               "sends goes to it as a unicast; none: as a broadcast")

    @field_validator("peer")
    @classmethod
    def _addr64(cls, v: str | None) -> str | None:
        if v is not None and not (len(v) == 16 and all(c in "0123456789abcdefABCDEF" for c in v)):
            raise ValueError(f"{v!r} is not a 64-bit address of 16 hex digits (e.g. 0013A20041A7B2C3)")
        return v

    @field_validator("waypoints")
    @classmethod
    def _increasing(cls, v: list[tuple[float, float, float]]) -> list[tuple[float, float, float]]:
        _check_times(v)
        return v


class FaultCfg(_Model):
    """An injected fault, from ``at_s`` on.

    ``battery_depleted``: the robot's battery is exhausted: its motors stop and its radio falls silent, for good
    (battery deaths). ``firmware_crash``: the robot's firmware crashes and the robot is dead from then on (as a
    battery death: motors stop, its radio goes silent, its logic stops). ``can_bus_off``: every frame the robot's CAN
    node ``node`` transmits is destroyed (a failing transceiver, a loose CAN_H/CAN_L wire at its connector), so its
    error counter climbs to bus-off within a few milliseconds and again after each recovery, for ``duration_s``.
    ``can_noise``: every frame on the robot's bus is destroyed with ``probability`` (EMI), for ``duration_s``.
    ``unplugged``: the robot's ``device`` module (its XBee or UWB module on a USB serial adapter) is pulled out, for
    good: the module is gone from the air, and its serial port raises ``SerialException`` in the robot program, as
    pyserial's does for a disconnected device.

    Faults of the swarm's air, given without ``robot``: ``partition``: the robots split into ``groups`` (a robot in
    none hears all), a frame of one group lost at every receiver of another, for ``duration_s``. ``burst_loss``:
    Gilbert-Elliott loss on every link of the ``medium``, or on those of ``robots``: each directed link goes bad with
    ``p_gb`` and recovers with ``p_bg`` per frame it carries, losing a frame with ``loss_bad`` when bad and
    ``loss_good`` when good, for ``duration_s`` (seeded: the same seed, the same losses). On ``medium = "uwb"`` they
    take the UWB radios' frames (ranging exchanges, a DWM1001's data) instead.

    Faults a robot lives through (``docs/faults.md``): ``freeze``: its ``process`` (``logic`` or ``firmware``) stops
    for ``duration_s`` and then goes on with what queued meanwhile (as after SIGSTOP, SIGCONT), or with
    ``hung_after_s`` the world declares the robot hung once it has been frozen that long. ``firmware_reboot``: its
    ``board`` (``llc``, or a robot model's own board) restarts: held in reset ``boot_s``, RAM lost, ``setup()`` again.
    ``brown_out``: its battery sags by ``sag_v`` for ``duration_s``; below ``reset_v`` its boards reset and reboot
    (``boot_s``) once it recovers. ``sensor``: its ``sensor`` (``sonar``, ``encoder``, ``light``, ``uwb``) goes
    ``stuck``, ``noisy`` (``sigma``), ``dead`` or biased (``bias``), for ``duration_s``. ``wheel_slip``: its ``wheel``
    loses ``slip`` of its grip (the encoder counts on, the robot moves less); ``motor_stall``: its ``wheel``'s motor
    turns no more; both for ``duration_s``. ``clock_drift``: its ``board``'s clock (``millis()``) runs ``ppm`` parts
    per million fast (slow when negative), for ``duration_s``.
    """

    robot: int | None = Field(None, ge=0, description="robot id (a fault of the air: none)")
    at_s: float = Field(gt=0, description="simulated time the fault starts")
    kind: Literal["firmware_crash", "battery_depleted", "can_bus_off", "can_noise", "unplugged", "partition",
                  "burst_loss", "freeze", "firmware_reboot", "brown_out", "sensor", "wheel_slip", "motor_stall",
                  "clock_drift"] = "firmware_crash"
    node: Literal["host", "llc", "slcan"] = Field(
        "host", description="can_bus_off: whose transmissions fail: host (the companion computer's CAN adapter), llc "
                            "or slcan")
    duration_s: float | None = Field(None, gt=0, description="how long it lasts (none: to the end; a freeze and a "
                                                             "brown-out need one)")
    probability: float = Field(0.01, gt=0, le=1, description="can_noise: share of frames destroyed")
    device: Literal["xbee", "uwb"] = Field("xbee", description="unplugged: which module is pulled out")
    medium: Literal["radio", "uwb"] = Field("radio", description="partition, burst_loss: the XBees' 2.4 GHz channel "
                                                                 "(radio) or the UWB radios (uwb)")
    groups: list[list[Annotated[int, Field(ge=0)]]] | None = Field(
        None, description="partition: the groups of robot ids that hear nothing of each other")
    robots: list[Annotated[int, Field(ge=0)]] | None = Field(
        None, description="burst_loss: the robots whose links it takes (none: every link)")
    p_gb: float | None = Field(None, gt=0, le=1, description="burst_loss: chance per frame that a good link goes bad")
    p_bg: float | None = Field(None, gt=0, le=1, description="burst_loss: chance per frame that a bad link recovers")
    loss_good: float = Field(0.0, ge=0, le=1, description="burst_loss: chance a good link loses a frame")
    loss_bad: float = Field(1.0, ge=0, le=1, description="burst_loss: chance a bad link loses a frame")
    process: Literal["logic", "firmware"] = Field(
        "logic", description="freeze: which of the robot's processes stops: its swarm logic or its firmware")
    hung_after_s: float | None = Field(None, gt=0, description="freeze: the world declares the robot hung once it "
                                                               "has been frozen this long (none: it comes back)")
    board: str = Field("llc", description="firmware_reboot, clock_drift: which board: llc, or a robot model's own "
                                          "board role (a Zebro's leg1...)")
    boot_s: float = Field(1.0, ge=0, le=60, description="firmware_reboot, brown_out: from reset to setup() (the "
                                                        "bootloader's wait: Optiboot's is about 1 s)")
    sag_v: float | None = Field(None, gt=0, description="brown_out: how far the battery's voltage sags (V)")
    reset_v: float = Field(6.0, gt=0, description="brown_out: the battery voltage below which the robot's boards "
                                                  "reset (its regulator's dropout, the MCU's brown-out detector)")
    sensor: Literal["sonar", "encoder", "light", "uwb"] | None = Field(
        None, description="sensor: which (sonar: every sonar; encoder: both; uwb: its ranges)")
    mode: Literal["stuck", "noisy", "dead", "bias"] = Field(
        "stuck", description="sensor: stuck (holds its reading), noisy (adds sigma), dead (reads nothing: 0 V, no "
                             "pulses, no range), bias (adds bias)")
    sigma: float | None = Field(None, gt=0, description="sensor, noisy: 1-sigma noise in the reading's unit (m, "
                                                        "pulses, lux)")
    bias: float | None = Field(None, description="sensor, bias: the offset in the reading's unit (m, pulses, lux)")
    wheel: Literal["left", "right", "both"] = Field("left", description="wheel_slip, motor_stall: which wheel")
    slip: float = Field(0.5, gt=0, le=1, description="wheel_slip: the share of the wheel's rim speed lost to slip")
    ppm: float | None = Field(None, ge=-200_000, le=200_000, description="clock_drift: how fast the clock runs (parts "
                                                                        "per million; negative: slow)")

    @model_validator(mode="after")
    def _fields_fit_kind(self) -> FaultCfg:
        applies = {"firmware_crash": set(), "battery_depleted": set(), "can_bus_off": {"node", "duration_s"},
                   "can_noise": {"duration_s", "probability"}, "unplugged": {"device"},
                   "partition": {"groups", "duration_s", "medium"},
                   "burst_loss": {"duration_s", "medium", "robots", "p_gb", "p_bg", "loss_good", "loss_bad"},
                   "freeze": {"duration_s", "process", "hung_after_s"}, "firmware_reboot": {"board", "boot_s"},
                   "brown_out": {"duration_s", "sag_v", "reset_v", "boot_s"},
                   "sensor": {"duration_s", "sensor", "mode", "sigma", "bias"},
                   "wheel_slip": {"duration_s", "wheel", "slip"}, "motor_stall": {"duration_s", "wheel"},
                   "clock_drift": {"duration_s", "board", "ppm"},
                   }[self.kind]
        self._only_for_kind(self.kind, applies, {"robot", "at_s", "kind"})
        if self.kind in AIR_FAULTS:
            if self.robot is not None:
                raise ValueError(f"robot: a {self.kind} is a fault of the air, not of one robot (give "
                                 f"{'groups' if self.kind == 'partition' else 'robots'} instead)")
            if self.kind == "partition":
                ids = [r for g in self.groups or [] for r in g]
                if len(self.groups or []) < 2 or not all(self.groups or []) or len(ids) != len(set(ids)):
                    raise ValueError("groups: a partition needs two or more non-empty groups, no robot in two")
            elif self.p_gb is None or self.p_bg is None:
                raise ValueError("p_gb, p_bg: a burst_loss needs both (its chances per frame of going bad and back)")
        elif self.robot is None:
            raise ValueError(f"robot: a {self.kind} fault needs the robot it strikes")
        need = {"freeze": ("duration_s",), "brown_out": ("duration_s", "sag_v"), "sensor": ("sensor",),
                "clock_drift": ("ppm",)}.get(self.kind, ())
        if missing := [k for k in need if getattr(self, k) is None]:
            raise ValueError(f"{', '.join(missing)}: a {self.kind} needs it")
        if self.kind == "sensor" and self.mode in ("noisy", "bias") and getattr(
                self, "sigma" if self.mode == "noisy" else "bias") is None:
            raise ValueError(f"{'sigma' if self.mode == 'noisy' else 'bias'}: a {self.mode} sensor needs it")
        if self.kind == "clock_drift" and self.ppm == 0:
            raise ValueError("ppm: a clock that drifts runs fast or slow (not 0)")
        if self.kind == "freeze" and self.hung_after_s is not None and self.hung_after_s >= (self.duration_s or 0):
            raise ValueError("hung_after_s: the world can only declare the robot hung while it is frozen (less than "
                             "duration_s)")
        return self

    def robot_ids(self) -> list[int]:
        """The robots the fault names: its robot, a partition's groups, a burst loss's robots."""
        if self.robot is not None:
            return [self.robot]
        return [r for g in self.groups or [] for r in g] + list(self.robots or [])


class CanCfg(_Model):
    """Every robot's CAN bus: the LLC's controller (MCP2515) and the companion computer's adapter (docs/models.md)."""

    bitrate: Literal[125_000, 250_000, 500_000, 1_000_000] = Field(500_000, description="bit/s, as the nodes are "
                                                                                        "set up")
    host_restart_ms: float | None = Field(100.0, ge=0, description="after bus-off, the companion computer's adapter "
                                                                   "restarts this long after the bus allows it "
                                                                   "(socketcan restart-ms); none: it stays bus-off")


class MavlinkCfg(_Model):
    """Every robot's MAVLink face behind one UDP endpoint for ground stations (docs/hil.md)."""

    endpoint: str | None = Field(None, description="udpout:HOST:PORT (send to a ground station listening there, e.g. "
                                                   "udpout:127.0.0.1:14550) or udpin:HOST:PORT (listen there; port 0: "
                                                   "any free port); none: the robots have no MAVLink face")
    per_robot: bool = Field(False, description="one endpoint per robot, at the endpoint's port + robot id")
    system_id_base: int = Field(1, ge=1, le=255, description="robot r is MAVLink system system_id_base + r")
    boot: Literal["auto", "hold", "disarmed"] = Field(
        "auto", description="auto: armed, the swarm behaviour runs from the start (as without a ground station); "
                            "hold: armed, waiting in HOLD; disarmed: waiting to be armed and set to AUTO or GUIDED")
    rates: dict[str, float] = Field({}, description="telemetry rates in Hz by message name, e.g. { ATTITUDE = 5 }")

    @field_validator("endpoint")
    @classmethod
    def _endpoint(cls, v: str | None) -> str | None:
        if v is not None:
            from bridge.core.endpoints import parse_endpoint

            parse_endpoint(v)
        return v


LAUNCH_PLACEHOLDERS = {"name": "the host's name", "endpoint": "the world's endpoint for other computers "
                       "(session.listen, a wildcard address replaced by one of this machine's)",
                       "session": "the session's name", "join": "the whole swarm-sitl join command for the host"}


class HostCfg(_Model):
    """A computer other than the world's that runs some of the session's processes (``[[hosts]]``): the robot groups
    and services that name it (``host``) have their processes there, started by one ``swarm-sitl join ENDPOINT
    --session NAME --host NAME`` on it, still in the session's simulated lock-step."""

    name: str = Field(description="the host's name, which robot groups and services give as their host")
    launch: str | None = Field(None, description="a shell command the launcher runs to start the host's join, e.g. "
                                                 "\"ssh {name}.lan {join}\" (placeholders: "
                                                 + ", ".join(f"{{{k}}} {v}" for k, v in LAUNCH_PLACEHOLDERS.items())
                                                 + ", each shell-quoted); none: the launcher prints the join command "
                                                   "and waits for it (session.startup_timeout_s)")

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        import re

        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_-]{0,62}", v):
            raise ValueError(f"{v!r}: a host name is letters, digits, '-' and '_' (at most 63, the first a letter or "
                             "digit)")
        return v

    @field_validator("launch")
    @classmethod
    def _placeholders(cls, v: str | None) -> str | None:
        import string

        if v is not None:
            try:
                fields = [f for _, f, _, _ in string.Formatter().parse(v) if f is not None]
            except ValueError as e:
                raise ValueError(f"{v!r}: {e} (a literal brace is written {{{{ or }}}})") from None
            for f in fields:
                if f not in LAUNCH_PLACEHOLDERS:
                    raise ValueError(f"{{{f}}} is not a placeholder (placeholders: "
                                     + ", ".join(f"{{{k}}}" for k in LAUNCH_PLACEHOLDERS) + ")")
        return v


class GroupHostsCfg(_Model):
    """Where a robot group's processes run, by kind (a host of ``[[hosts]]``; none: the world's computer)."""

    firmware: str | None = Field(None, description="the host of the robots' firmware processes")
    logic: str | None = Field(None, description="the host of the robots' logic processes")


RESERVED_SERVICE_NAMES = ("world", "radio", "session", "wifi", "mavlink", "svc")


class ServiceCfg(_Model):
    """A centralised program of the session (``[[services]]``), in a process of its own, on the Wi-Fi network
    (``bridge.core.services``): a localisation service, a global controller."""

    kind: str = Field(description="the service kind (swarm-sitl list services)")
    name: str = Field(description="its name: its address on the Wi-Fi network, its process svc-NAME, its records "
                                  "/svc/NAME/...")
    options: dict[str, Any] = Field({}, description="the kind's own options")
    host: str | None = Field(None, description="the host of [[hosts]] its process runs on (none: the world's computer)")

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        ok = v.isidentifier() and v.isascii() and v == v.lower() and len(v) <= 32
        if not ok or v in RESERVED_SERVICE_NAMES or (v[0] == "r" and v[1:].isdigit()):
            raise ValueError(f"{v!r}: a service name is a lower-case identifier of up to 32 characters, not a robot's "
                             f"address (rNNN) nor one of {', '.join(RESERVED_SERVICE_NAMES)}")
        return v

    @field_validator("kind")
    @classmethod
    def _known_kind(cls, v: str) -> str:
        return _registered(SERVICES.get, v)

    @model_validator(mode="after")
    def _options(self) -> ServiceCfg:
        """The kind's options model validates them; an error names the option."""
        try:
            SERVICES.get(self.kind).options.model_validate(self.options)
        except ValidationError as e:
            raise ValueError("; ".join(f"options.{_loc(x['loc'])}: {x['msg'].removeprefix('Value error, ')}"
                                       for x in e.errors())) from None
        except PluginError:
            pass  # the kind's own error says why
        return self


class Config(_Model):
    # top-level sections beyond these are studies' own (Study.config)
    model_config = ConfigDict(extra="allow", frozen=False)

    session: SessionCfg = SessionCfg()
    world: WorldCfg = WorldCfg()
    arena: ArenaCfg = ArenaCfg()
    obstacles: list[Obstacle] = []
    random_obstacles: RandomObstaclesCfg | None = Field(None, description="boxes drawn from the session seed at "
                                                                          "load, added to obstacles")
    light: LightCfg = LightCfg()
    radio: RadioCfg = Field(RadioCfg(), description="the 2.4 GHz channel the XBees share (docs/radio.md)")
    uwb: UwbCfg = Field(UwbCfg(), description="UWB ranging noise and TDMA budget (docs/uwb.md)")
    robots: list[RobotGroup] = Field(min_length=1)
    faults: list[FaultCfg] = Field([], description="injected faults (a firmware crash, CAN bus-off or noise)")
    can: CanCfg = Field(CanCfg(), description="the robots' CAN buses")
    mavlink: MavlinkCfg = Field(MavlinkCfg(), description="the robots' MAVLink faces and the ground-station endpoint")
    xbee_gateways: list[XBeeGatewayCfg] = Field([], description="real XBees joined to the simulated radio channel")
    wifi: WifiCfg = Field(WifiCfg(), description="the Wi-Fi network between the robots and the services")
    services: list[ServiceCfg] = Field([], description="centralised programs, each in a process of its own")
    hosts: list[HostCfg] = Field([], description="other computers that run some of the session's processes "
                                                 "(swarm-sitl join --host)")

    @model_validator(mode="after")
    def _quantum_fits_physics(self) -> Config:
        steps = self.session.quantum_ms * 1e-3 * self.world.physics_hz
        if steps < 1 - 1e-9:
            raise ValueError(
                f"session.quantum_ms = {self.session.quantum_ms} is shorter than one physics step "
                f"(world.physics_hz = {self.world.physics_hz})"
            )
        m = self.mavlink
        if m.endpoint is not None and m.system_id_base + self.robot_count - 1 > 255:
            raise ValueError(f"mavlink.system_id_base = {m.system_id_base}: {self.robot_count} robots need system "
                             f"ids up to {m.system_id_base + self.robot_count - 1}, beyond MAVLink's 255")
        real = [f"robots[{i}].{f}" for i, g in enumerate(self.robots) for f in g.real_ports()]
        real += [f"xbee_gateways[{i}]" for i in range(len(self.xbee_gateways))]
        remote = [f"robots[{i}].logic" for i, g in enumerate(self.robots) if g.logic == "remote"]
        if remote and self.session.listen is None:
            raise ValueError(f"session.listen: {', '.join(remote)} = \"remote\" joins over zenoh from another "
                             "computer: give the world an endpoint to listen on, e.g. listen = \"tcp/0.0.0.0:7447\"")
        if real and self.session.speed != 1:
            raise ValueError(f"session.speed = {self.session.speed!r}: a session with ports to the outside world "
                             f"({', '.join(real)}) runs paced to wall time: set speed = 1 (or --speed 1)")
        capacity: dict[int, int] = {}
        for i, g in enumerate(self.robots):
            c = g.carried_by
            if c is None:
                continue
            if c >= len(self.robots) or c == i:
                raise ValueError(f"robots[{i}].carried_by = {c}: not another robot group (there are "
                                 f"{len(self.robots)})")
            carrier = self.robots[c]
            slots = self.profile(carrier).capacity
            if not slots or carrier.carried_by is not None:
                raise ValueError(f"robots[{i}].carried_by = {c}: robots[{c}] ({carrier.profile}) has no conveyor "
                                 "or other part to carry robots on")
            capacity[c] = capacity.get(c, 0) + g.count
            if capacity[c] > carrier.count * slots:
                raise ValueError(f"robots[{i}].count: robots[{c}] carries at most {carrier.count} x {slots} = "
                                 f"{carrier.count * slots} robots, {capacity[c]} would ride on them")
        for g in self.robots:
            period_ms = 1000.0 / robot_profile(g.profile).llc_loop_hz
            if self.session.quantum_ms > period_ms + 1e-9:
                raise ValueError(
                    f"session.quantum_ms = {self.session.quantum_ms} is longer than the {g.profile} LLC loop "
                    f"period ({period_ms:g} ms): a board cannot run its loop more than once per quantum"
                )
        return self

    @model_validator(mode="after")
    def _services(self, info: ValidationInfo) -> Config:
        """Service names are unique (each is an address); each kind checks its options against the whole config
        (not again in a session's processes: ``from_plan``)."""
        seen: set[str] = set()
        for i, sc in enumerate(self.services):
            if sc.name in seen:
                raise ValueError(f"services[{i}].name: {sc.name!r} names another service already")
            seen.add(sc.name)
            spec = SERVICES.get(sc.kind)
            if spec.check is not None and not _planned(info):
                try:
                    spec.check(spec.options.model_validate(sc.options), self)
                except ValueError as e:
                    raise ValueError(f"services[{i}].options.{e}") from None
        return self

    @model_validator(mode="after")
    def _hosts(self) -> Config:
        """Each host is named once, joins over session.listen and runs some process; each place names a host; what
        a remote host cannot reach (this computer's devices and pseudo-terminals) stays here."""
        names = [h.name for h in self.hosts]
        for i, n in enumerate(names):
            if n in names[:i]:
                raise ValueError(f"hosts[{i}].name: {n!r} names another host already")
        if self.hosts and self.session.listen is None:
            raise ValueError("session.listen: [[hosts]] join over zenoh from other computers: give the world an "
                             "endpoint to listen on, e.g. listen = \"tcp/192.168.1.10:7447\"")
        have = ", ".join(names) or "none"
        used: set[str] = set()
        for i, g in enumerate(self.robots):
            fw, lg = g.hosts()
            where = "host" if isinstance(g.host, str) else None
            for kind, h in (("firmware", fw), ("logic", lg)):
                if h is None:
                    continue
                field = f"robots[{i}].{where or 'host.' + kind}"
                if h not in names:
                    raise ValueError(f"{field}: {h!r} is not a host of [[hosts]] (hosts: {have})")
                if kind == "logic" and g.logic != "session":
                    if where is None:
                        raise ValueError(f"{field}: logic = {g.logic!r}: the session runs no logic process for "
                                         "these robots to place on a host")
                    continue  # the group's firmware only
                if kind == "firmware":
                    here = [f for f in g.real_ports() if f not in ("logic", "wifi_udp", "vehicle")]
                    if here:
                        raise ValueError(f"{field}: {', '.join(here)} is a device or port of the world's computer: "
                                         "keep these robots' firmware there")
                else:
                    for what, on in (("xbee.device", bool(g.xbee and g.xbee.device)), ("vehicle", g.vehicle)):
                        if on:
                            raise ValueError(f"{field}: {what}: a logic on another host would open it there, where "
                                             "the session cannot check it before the start; keep the logic here")
                used.add(h)
        for i, sc in enumerate(self.services):
            if sc.host is not None:
                if sc.host not in names:
                    raise ValueError(f"services[{i}].host: {sc.host!r} is not a host of [[hosts]] (hosts: {have})")
                used.add(sc.host)
        for i, h in enumerate(self.hosts):
            if h.name not in used:
                raise ValueError(f"hosts[{i}]: host {h.name!r} runs no process: give a robot group host = "
                                 f"\"{h.name}\" (or a service) or drop it")
        return self

    @model_validator(mode="after")
    def _study_sections(self, info: ValidationInfo) -> Config:
        """Top-level sections beyond the core's are the studies' (``Study.config``): each study validates its own,
        and a section no study declares is refused as an unknown field; then the studies' checks across the config
        (not again in a session's processes: ``from_plan``)."""
        extra = self.model_extra or {}
        if extra:
            _study_sections_model().model_validate(extra)
        if not _planned(info):
            _study_checks(self)
        return self

    @classmethod
    def from_plan(cls, config: dict[str, Any]) -> Config:
        """The config a session's plan carries, in one of the session's processes: validated again (it crossed a
        process boundary), but without the services' and studies' checks across the whole config, which the launcher
        ran on this very config before it wrote the plan; they load plugin classes (a region controller's planners,
        scipy) that a process which does not run them should not pay for."""
        return cls.model_validate(config, context={"planned": True})

    def section(self, name: str) -> Any:
        """A study's config section, validated (its defaults, or an empty list, if the file does not set it)."""
        kind = study_section(name)
        raw = (self.model_extra or {}).get(name)
        if isinstance(kind, type) and issubclass(kind, BaseModel):
            return kind.model_validate(raw or {})
        return TypeAdapter(kind).validate_python([] if raw is None else raw)

    @property
    def robot_count(self) -> int:
        return sum(g.count for g in self.robots)

    def profile(self, group: RobotGroup) -> RobotProfile:
        """The group's robot profile, as its robot model's options make it."""
        return robot_profile(group.profile, group.model_extra)


def _planned(info: ValidationInfo) -> bool:
    """Whether the config is validated from a session's plan (``Config.from_plan``)."""
    return bool(info.context and info.context.get("planned"))


def _study_checks(cfg: Config) -> None:
    """Each study's check across the config, when the config has one of its sections or a group runs one of its
    behaviours (``Study.check``, ``Study.behaviours``)."""
    extra = cfg.model_extra or {}
    for _, study in STUDIES.items():
        if study.check is not None and (
            any(name in extra for name in study.config) or any(g.behaviour in study.behaviours for g in cfg.robots)
        ):
            study.check(cfg)


def study_section(name: str) -> Any:
    """The type of a study's config section ``name`` (a ``PluginError`` if no study declares it)."""
    for _, study in STUDIES.items():
        if name in study.config:
            return study.config[name]
    raise PluginError(f"no study declares a config section {name!r}")


def _study_sections_model() -> type[BaseModel]:
    """Every study's config sections as one model that refuses any other field."""
    fields: dict[str, Any] = {n: (m | None, None) for _, st in STUDIES.items() for n, m in st.config.items()}
    return create_model("StudySections", __base__=_Model, **fields)


def _loc(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in ("box", "cylinder", "function-after[_positive(), tuple[float, float, float]]"):
            continue  # discriminator tags add nothing for a reader
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


def _format(path: str, err: ValidationError) -> str:
    lines = []
    for e in err.errors():
        msg = e["msg"].removeprefix("Value error, ")
        if e["loc"]:
            lines.append(f"{path}: {_loc(e['loc'])}: {msg}")
        else:  # a check across the whole config: its message names the field
            lines.append(f"{path}: {msg}")
    return "\n".join(lines)


def read_toml(p: Path, what: str = "config") -> dict[str, Any]:
    """The TOML file ``p`` as a dict, or a ConfigError naming the file and why it cannot be read (``what`` names the
    kind of file in the messages)."""
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such file") from None
    except IsADirectoryError:
        raise ConfigError(f"{p}: is a directory, not a {what} file") from None
    except UnicodeDecodeError as e:
        raise ConfigError(f"{p}: not a text file (byte {e.start} is not UTF-8): a {what} is a TOML file") from None
    except OSError as e:
        raise ConfigError(f"{p}: cannot read it: {e.strerror or e}") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{p}: not valid TOML: {e}") from None


def _override(raw: dict[str, Any], p: Path, dotted: str, value: Any) -> None:
    """Set one override in the raw config: ``session.seed``, a list's entry by index (``robots.0.params.speed``), or
    a whole top-level table or list (``services``). Missing tables on the way are created."""
    keys = dotted.split(".")
    node: Any = raw
    for i, key in enumerate(keys):
        last = i == len(keys) - 1
        if isinstance(node, list):
            if not key.isdigit() or int(key) >= len(node):
                raise ConfigError(f"{p}: override {dotted}: {'.'.join(keys[:i]) or key} has no entry {key!r}")
            key = int(key)  # type: ignore[assignment]
        elif not isinstance(node, dict):
            raise ConfigError(f"{p}: override {dotted}: {'.'.join(keys[:i])} is a value, not a table")
        if last:
            node[key] = value
        else:
            if isinstance(node, dict) and key not in node:
                node[key] = {}
            node = node[key]


def load_config(path: str | Path, overrides: dict[str, Any] | None = None) -> Config:
    """Read and validate ``path``; ``overrides`` are command-line values (``session.seed`` etc.)."""
    p = Path(path)
    raw = read_toml(p)
    _refuse_hal_config(p, raw)
    for dotted, value in (overrides or {}).items():
        if value is None:
            continue
        if dotted == "robots.count":
            groups = raw.get("robots", [])
            if len(groups) != 1:
                raise ConfigError(f"{p}: robots: --robots needs exactly one [[robots]] group, found {len(groups)}")
            groups[0]["count"] = value
            continue
        _override(raw, p, dotted, value)
    try:
        cfg = Config.model_validate(raw)
    except ValidationError as e:
        raise ConfigError(_format(str(p), e)) from None
    base = p.parent
    if cfg.arena.map is not None:
        mp = (base / cfg.arena.map).resolve()
        if not mp.is_file():
            raise ConfigError(f"{p}: arena.map: no such file {cfg.arena.map!r} (relative to the config)")
        cfg.arena.map = str(mp)
        try:
            from bridge.core.arena_map import occupancy

            occupancy(cfg.arena)
        except Exception as e:
            raise ConfigError(f"{p}: arena.map: cannot read {mp.name} as an image: {e}") from None
    expand_random_obstacles(str(p), cfg)
    if cfg.random_obstacles is not None:  # the studies' checks again, on the boxes just drawn too
        try:
            _study_checks(cfg)
        except ValueError as e:
            raise ConfigError(f"{p}: {e} (random_obstacles drew it: keep the place clear with keep_clear)") from None
    _check_geometry(str(p), cfg)
    _check_links(str(p), cfg)
    _check_behaviours(str(p), cfg)
    return cfg


# Top-level keys of a robot's HAL config (``python -m swarm_logic --hal FILE``, ``swarm_logic/__main__.py``) that a
# session config never has: the devices of one real robot.
HAL_KEYS = ("llc_can", "llc_mavlink")


def _refuse_hal_config(p: Path, raw: dict[str, Any]) -> None:
    """A HAL config is TOML too, and would fail validation field by field; say what it is instead."""
    from swarm_logic.devices import DEVICES

    own = [k for k in DEVICES.names() if isinstance(raw.get(k), dict)]  # a robot model's own devices (its legs)
    if "robots" in raw or "session" in raw or not (any(k in raw for k in HAL_KEYS) or own):
        return
    raise ConfigError(f"{p}: a HAL config for a real robot (it names one robot's devices: "
                      f"{', '.join([*(k for k in HAL_KEYS if k in raw), *own])}), not a session config. Run it on "
                      "that "
                      f"robot's companion computer: python -m swarm_logic --hal {p}; a session needs a session "
                      "config ([session], [[robots]]), e.g. hil_configs/demos/random_walk.toml")


def _check_behaviours(path: str, cfg: Config) -> None:
    """Each group's behaviour must load, and its params must be ones it declares, each of its declared kind and in its
    declared range (``Controller.param_error``, as the MAVLink face checks a PARAM_SET), then pass its ``resolve``."""
    from swarm_logic.behaviours import load_behaviour

    for i, g in enumerate(cfg.robots):
        try:
            cls = load_behaviour(g.behaviour)
        except Exception as e:
            raise ConfigError(f"{path}: robots[{i}].behaviour: {e}") from None
        declared = getattr(cls, "defaults", None)
        if not declared:
            continue
        unknown = sorted(set(g.params) - set(declared))
        if unknown:
            raise ConfigError(f"{path}: robots[{i}].params: unknown parameters {unknown} for {g.behaviour}; "
                              f"known: {sorted(declared)}")
        for k, v in g.params.items():  # each a value of its kind, in the range the controller declares for it
            error = cls.param_error(k, v)
            if error is not None:
                raise ConfigError(f"{path}: robots[{i}].params.{k}: {error}")
        if getattr(cls, "needs_radio", False) and g.xbee is None:
            raise ConfigError(f"{path}: robots[{i}].xbee: {g.behaviour} talks over the radio: give the group an "
                              "XBee, e.g. xbee = { series = 2, baud = 115200 }")
        resolve = getattr(cls, "resolve", None)  # a controller that checks the meaning of its parameters
        if resolve is not None:
            try:
                resolve(dict(g.params))
            except ValueError as e:
                raise ConfigError(f"{path}: robots[{i}].params: {e}") from None


def config_warnings(cfg: Config) -> list[str]:
    """What is allowed but unwise: e.g. controller parameters outside their stable region (each names the bound)."""
    from swarm_logic.behaviours import load_behaviour

    out = []
    if cfg.mavlink.endpoint is not None:
        from bridge.core.endpoints import is_loopback, parse_endpoint

        if not is_loopback(parse_endpoint(cfg.mavlink.endpoint).host):
            out.append(f"mavlink.endpoint: {cfg.mavlink.endpoint} is not on this machine: MAVLink traffic leaves it")
    if cfg.session.listen is not None:
        from bridge.core.endpoints import is_loopback

        host = cfg.session.listen.removeprefix("tcp/").rpartition(":")[0].removeprefix("[").removesuffix("]")
        if not is_loopback(host):
            out.append(f"session.listen: {cfg.session.listen} is reachable from other machines: the session's traffic "
                       "(ticks, frames, the plan with the whole config) leaves this one unencrypted, and anyone who "
                       "can reach the port can join or disturb the session (use a trusted network or a firewall)")
    for i, g in enumerate(cfg.robots):
        warn = getattr(load_behaviour(g.behaviour), "warnings", None)
        if warn is not None:
            out += [f"robots[{i}].params: {w}" for w in warn(dict(g.params))]
    return out


def expand_random_obstacles(path: str, cfg: Config) -> None:
    """Draw ``random_obstacles`` from the session seed (bridge.core.rng) and append them to ``obstacles`` as boxes, each
    inside the arena and, by its circumscribed disc, at least ``clearance_m`` from the walls, the other obstacles
    and the explicit and grid start poses, and outside the ``keep_clear`` discs."""
    ro = cfg.random_obstacles
    if ro is None:
        return
    from bridge.core.rng import stream

    w, length = cfg.arena.width_m, cfg.arena.length_m
    lo, hi = ro.side_m
    gap = ro.clearance_m
    if math.hypot(lo, lo) / 2 + gap >= min(w, length) / 2:
        raise ConfigError(f"{path}: random_obstacles.side_m: a box of side {lo} m with clearance_m {gap} does not fit "
                          f"the {w} x {length} m arena")
    for j, (x, y, r) in enumerate(ro.keep_clear):
        if not (0 <= x <= w and 0 <= y <= length and r >= 0):
            raise ConfigError(f"{path}: random_obstacles.keep_clear[{j}]: ({x}, {y}) is outside the arena or the "
                              f"radius {r} is negative")
    discs = [(x, y, r) for x, y, r in ro.keep_clear]
    for g in cfg.robots:  # the start poses the config fixes (random placements keep clear of obstacles themselves)
        radius = robot_profile(g.profile).radius_m + gap
        if g.placement.kind == "explicit":
            discs += [(x, y, radius) for x, y, _ in g.placement.poses]
        elif g.placement.kind == "grid" and g.carried_by is None:
            pl = g.placement
            discs += [(pl.origin[0] + (i % pl.columns) * pl.spacing_m, pl.origin[1] + (i // pl.columns) * pl.spacing_m,
                       radius) for i in range(g.count)]
    discs += [(gw.pose[0], gw.pose[1], gap) for gw in cfg.xbee_gateways]
    placed = [(ob.x, ob.y, ob.radius if isinstance(ob, CylinderObstacle) else math.hypot(*ob.size[:2]) / 2)
              for ob in cfg.obstacles]
    rng = stream(cfg.session.seed, "random_obstacles")
    new: list[Obstacle] = []
    tries = 0
    while len(new) < ro.count:
        tries += 1
        if tries > 5000:  # in a row without a place for the next box
            raise ConfigError(f"{path}: random_obstacles.count: placed only {len(new)} of {ro.count} boxes clear of "
                              f"the start poses, keep_clear discs and each other (lower count, side_m or "
                              "clearance_m)")
        sx, sy = (float(v) for v in rng.uniform(lo, hi, 2))
        yaw = float(rng.uniform(0.0, 180.0))
        rb = math.hypot(sx, sy) / 2
        if rb + gap >= min(w, length) / 2:
            continue
        x, y = float(rng.uniform(rb + gap, w - rb - gap)), float(rng.uniform(rb + gap, length - rb - gap))
        if any(math.hypot(x - cx, y - cy) < rb + cr for cx, cy, cr in discs) or \
                any(math.hypot(x - cx, y - cy) < rb + cr + gap for cx, cy, cr in placed):
            continue
        tries = 0
        placed.append((x, y, rb))
        new.append(BoxObstacle(type="box", x=round(x, 3), y=round(y, 3),
                               size=(round(sx, 3), round(sy, 3), ro.height_m), yaw_deg=round(yaw, 1)))
    cfg.obstacles = [*cfg.obstacles, *new]


def _check_links(path: str, cfg: Config) -> None:
    """Every pseudo-terminal a session links (an XBee's UART, an slcan adapter, a robot model's port) needs its own
    path: two links on one path would leave one program talking to the other robot's, or the other module's, port."""
    seen: dict[str, str] = {}
    rid = 0
    for i, g in enumerate(cfg.robots):
        links = [("xbee.pty", g.xbee.pty if g.xbee else None), ("can.slcan_pty", g.can.slcan_pty),
                 *g.model_ptys().items()]
        for r in range(rid, rid + g.count):
            for what, link in links:
                if not link:
                    continue
                at = os.path.normpath(link.replace("{id}", str(r)))
                here = f"robots[{i}].{what}"
                if at in seen:
                    raise ConfigError(f"{path}: {here}: robot {r}'s link {at!r} is also {seen[at]}: each "
                                      "pseudo-terminal needs a path of its own ('{id}' in a group's path)")
                seen[at] = f"{here} of robot {r}"
        rid += g.count


def _check_geometry(path: str, cfg: Config) -> None:
    w, length = cfg.arena.width_m, cfg.arena.length_m
    for i, ob in enumerate(cfg.obstacles):
        if not (0 <= ob.x <= w and 0 <= ob.y <= length):
            raise ConfigError(f"{path}: obstacles[{i}]: centre ({ob.x}, {ob.y}) is outside the {w} x {length} m arena")
    groups = [g for g in cfg.robots for _ in range(g.count)]
    for i, f in enumerate(cfg.faults):
        where = "robot" if f.robot is not None else "groups" if f.groups else "robots"
        for r in f.robot_ids():
            if r >= cfg.robot_count:
                raise ConfigError(f"{path}: faults[{i}].{where}: no robot {r} (the session has {cfg.robot_count})")
        if f.robot is None:
            if f.medium == "uwb" and not any(g.uwb or UWB_RADIO_ROLE in robot_spec(g.profile).ports
                                             for g in cfg.robots):
                raise ConfigError(f"{path}: faults[{i}].medium: no robot has a UWB module, so nothing carries a "
                                  f"{f.kind} on uwb")
            if f.medium == "radio" and not any(g.xbee is not None for g in cfg.robots):
                raise ConfigError(f"{path}: faults[{i}].medium: no robot has an XBee, so nothing carries a {f.kind}")
            continue
        if f.kind == "can_bus_off" and f.node == "slcan" and not groups[f.robot].can.slcan_pty:
            raise ConfigError(f"{path}: faults[{i}].node: robot {f.robot} has no slcan adapter (can.slcan_pty)")
        if f.kind == "unplugged" and not (groups[f.robot].xbee if f.device == "xbee" else groups[f.robot].uwb):
            raise ConfigError(f"{path}: faults[{i}].device: robot {f.robot} has no {f.device} module")
    for i, light in enumerate(cfg.light.sources):
        if not (math.isfinite(light.x) and math.isfinite(light.y)):
            raise ConfigError(f"{path}: light.sources[{i}]: position must be finite")
    def inside(x: float, y: float) -> bool:
        return 0 < x < w and 0 < y < length

    for i, g in enumerate(cfg.robots):
        for j, (_, x, y, _) in enumerate(g.motion.waypoints):
            if not inside(x, y):
                raise ConfigError(f"{path}: robots[{i}].motion.waypoints[{j}]: ({x}, {y}) is outside the arena")
    for i, gw in enumerate(cfg.xbee_gateways):
        for where, (x, y) in [("pose", gw.pose)] + [(f"waypoints[{j}]", (x, y)) for j, (_, x, y) in
                                                    enumerate(gw.waypoints)]:
            if not inside(x, y):
                raise ConfigError(f"{path}: xbee_gateways[{i}].{where}: ({x}, {y}) is outside the arena")
    for i, g in enumerate(cfg.robots):
        pl = g.placement
        if pl.kind == "explicit":
            if len(pl.poses) != g.count:
                raise ConfigError(
                    f"{path}: robots[{i}].placement.poses: {len(pl.poses)} poses for count = {g.count}"
                )
            for j, (x, y, _) in enumerate(pl.poses):
                if not (0 < x < w and 0 < y < length):
                    raise ConfigError(f"{path}: robots[{i}].placement.poses[{j}]: ({x}, {y}) is outside the arena")
        if pl.region is not None:
            x0, y0, x1, y1 = pl.region
            if not (0 <= x0 < x1 <= w and 0 <= y0 < y1 <= length):
                raise ConfigError(f"{path}: robots[{i}].placement.region: must lie inside the arena with x0<x1, y0<y1")


def to_toml(d: dict[str, Any]) -> str:
    """A minimal TOML writer for config dicts (tables, arrays of tables, scalars, arrays of scalars)."""
    lines: list[str] = []

    def scalar(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, int | float):
            return repr(v)
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list | tuple):
            return "[" + ", ".join(scalar(x) for x in v) + "]"
        raise TypeError(f"cannot write {v!r} as TOML")

    def table(prefix: str, t: dict[str, Any], header: str | None) -> None:
        if header is not None:
            lines.append(header)
        subs = []
        for k, v in t.items():
            if isinstance(v, dict):
                subs.append((k, v, False))
            elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
                subs.append((k, v, True))
            else:
                lines.append(f"{k} = {scalar(v)}")
        for k, v, many in subs:
            name = f"{prefix}{k}"
            if many:
                for item in v:
                    lines.append("")
                    table(name + ".", item, f"[[{name}]]")
            else:
                lines.append("")
                table(name + ".", v, f"[{name}]")

    table("", d, None)
    return "\n".join(lines).lstrip("\n") + "\n"
