"""``global_controller``: the SonPI swarm's central controller (Roy 2022: a PC, or the leader's Raspberry Pi), a
service on the swarm's Wi-Fi. Every ``period_s`` it steps its controller class, broadcasts the mission that returns
(``pose_packet.MISSION``: run or hold, the target) and takes in the robots' status packets.

The controller class is the extension point: a study gives its own (entry point group
``swarm_sitl.global_controllers``, or ``module:Class``), a ``GlobalController`` subclass. The built-in ``mission``
runs chapter 3's: go to ``target`` from ``start_s`` to ``stop_s``, and it scores arrivals from the robots' own status
(the first time each reports a pose within ``goal_radius_m``). The built-in ``region`` (``regions.py``) hosts a
chapter 4-6 region planner and broadcasts its plans (docs/global-controller.md).

    [[services]]
    kind = "global_controller"
    name = "controller"
    options = { target = [3.0, 3.0], start_s = 1.0 }
"""

from __future__ import annotations

import math
from typing import Any

from pydantic import Field

from bridge.core.services import Service, ServiceContext, ServiceOptions, ServiceSpec
from bridge.services.global_controller import scene  # noqa: F401 - the world records its scenes: their schema
from swarm_logic.plugins import PluginError, Registry
from swarm_logic.robots.sonpi import pose_packet as pp


class GlobalController:
    """A study's global controller: ``on_status`` for each robot's status packet, ``on_packet`` for the other robot
    packets it ``accepts`` (their types), ``step`` each period returning the mission to broadcast (None: none this
    period), ``summary`` its figures; it may ``send`` packets and ``log`` records of its own. ``ctx`` is the
    service's context (arena, robots, options), ``options`` the service's options. ``check_params`` refuses bad
    ``options.params`` before the session starts (a ValueError naming ``params.FIELD``)."""

    accepts: tuple[type, ...] = ()

    def __init__(self, ctx: ServiceContext, options: Any) -> None:
        self.ctx = ctx
        self.options = options
        self.service: Service | None = None  # the service hosting it, once it is built
        self.now_s = 0.0  # the service's time while it hands over the datagrams and steps

    @classmethod
    def check_params(cls, params: dict[str, Any]) -> None:
        """ValueError naming the first bad entry of ``params``."""

    def on_status(self, t_s: float, status: pp.Status) -> None:
        """A robot's status arrived (``t_s``: the robot's time stamp)."""

    def on_packet(self, t_s: float, head: pp.Header, content: Any) -> None:
        """A robot's packet of a type in ``accepts`` arrived (``t_s``: the service's time; ``head.t_s`` the robot's)."""

    def send(self, data: bytes, dest: str | None = None) -> None:
        assert self.service is not None
        self.service.send(data, dest)

    def log(self, topic: str, values: dict[str, Any], schema: str | None = None) -> None:
        assert self.service is not None
        self.service.log(topic, values, schema)

    def step(self, t_s: float) -> pp.Mission | None:
        return None

    def summary(self) -> dict[str, Any]:
        return {}


class MissionController(GlobalController):
    """Chapter 3's mission: the target, run between ``start_s`` and ``stop_s``; arrivals from the robots' status."""

    def __init__(self, ctx: ServiceContext, options: Any) -> None:
        super().__init__(ctx, options)
        self.last: dict[int, pp.Status] = {}
        self.reports: dict[int, int] = {}
        self.arrived: dict[int, float] = {}

    def running(self, t_s: float) -> bool:
        o = self.options
        return t_s >= o.start_s and (o.stop_s is None or t_s < o.stop_s)

    def on_status(self, t_s: float, status: pp.Status) -> None:
        self.last[status.id] = status
        self.reports[status.id] = self.reports.get(status.id, 0) + 1
        tx, ty = self.options.target
        if (
            status.has_pose
            and status.id not in self.arrived
            and self.running(t_s)
            and math.hypot(status.x_m - tx, status.y_m - ty) <= self.options.goal_radius_m
        ):
            self.arrived[status.id] = round(t_s, 6)

    def step(self, t_s: float) -> pp.Mission:
        return pp.Mission(self.running(t_s), *self.options.target)

    def summary(self) -> dict[str, Any]:
        n = len(self.ctx.robots)
        return {
            "robots_reporting": len(self.reports),
            "status_reports": sum(self.reports.values()),
            "arrived": {str(k): v for k, v in sorted(self.arrived.items())},
            "all_arrived_s": max(self.arrived.values()) if len(self.arrived) == n and n else None,
            "last_state": {str(k): s.state for k, s in sorted(self.last.items())},
        }


def _is_controller(obj: Any) -> bool:
    return isinstance(obj, type) and issubclass(obj, GlobalController)


CONTROLLERS: Registry[type[GlobalController]] = Registry(
    "swarm_sitl.global_controllers", "global controller", _is_controller
)


class GlobalControllerOptions(ServiceOptions):
    controller: str = Field(
        "mission", description="the controller class (swarm_sitl.global_controllers, or module:Class)"
    )
    period_s: float = Field(
        0.25, gt=0, le=60, description="how often it steps and broadcasts the mission (the thesis' 250 ms windows)"
    )
    target: tuple[float, float] = Field((0.0, 0.0), description="the mission's target (m)")
    start_s: float = Field(0.0, ge=0, description="the mission runs from then")
    stop_s: float | None = Field(None, gt=0, description="and holds from then (none: to the end)")
    goal_radius_m: float = Field(0.3, gt=0, description="a robot reporting a pose this close has arrived")
    params: dict[str, Any] = Field({}, description="the controller class's own parameters")


class GlobalControllerService(Service):
    def __init__(self, ctx: ServiceContext) -> None:
        super().__init__(ctx)
        o = ctx.options
        self.period_ns = round(o.period_s * 1e9)
        self.controller = CONTROLLERS.get(o.controller)(ctx, o)
        self.controller.service = self
        self.kinds = (pp.Status, *self.controller.accepts)
        self.address = {r.address: r.id for r in ctx.robots}
        self.seq = 0
        self.counts = {"missions": 0, "status": 0, "ignored": 0, "malformed": 0}
        if self.controller.accepts:
            self.counts["packets"] = 0

    def step(self, t_ns: int, datagrams: list[tuple[str, bytes]], sensed: dict[str, Any]) -> int | None:
        t_s = self.controller.now_s = t_ns / 1e9
        for src, data in datagrams:
            verdict, head, content = pp.accept(data, self.kinds, self.address.get(src))
            if verdict != "ok":
                self.counts[verdict] += 1  # ignored: another node's broadcast (the camera's poses)
                continue
            assert head is not None
            if isinstance(content, pp.Status):
                self.counts["status"] += 1
                self.controller.on_status(head.t_s, content)
            else:
                self.counts["packets"] += 1
                self.controller.on_packet(t_s, head, content)
        mission = self.controller.step(t_s)
        if mission is not None:
            self.send(pp.encode_mission(self.seq, t_s, mission))
            self.seq += 1
            self.counts["missions"] += 1
            self.log("mission", {"run": mission.run, "target": [mission.target_x_m, mission.target_y_m]})
        return (t_ns // self.period_ns + 1) * self.period_ns

    def summary(self) -> dict[str, Any]:
        return {"controller": self.ctx.options.controller, **self.counts, **self.controller.summary()}


def _check(o: GlobalControllerOptions, cfg: Any) -> None:
    try:
        cls = CONTROLLERS.get(o.controller)
    except PluginError as e:
        raise ValueError(f"controller: {e}") from None
    cls.check_params(o.params)
    if o.stop_s is not None and o.stop_s <= o.start_s:
        raise ValueError(f"stop_s: {o.stop_s} is not after start_s ({o.start_s})")
    tx, ty = o.target
    if not (0 <= tx <= cfg.arena.width_m and 0 <= ty <= cfg.arena.length_m):
        raise ValueError(f"target: ({tx}, {ty}) is outside the {cfg.arena.width_m} x {cfg.arena.length_m} m arena")


SPEC = ServiceSpec(
    "global_controller",
    GlobalControllerService,
    GlobalControllerOptions,
    title="global controller: broadcasts the mission, collects the robots' status",
    check=_check,
)
