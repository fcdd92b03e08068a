"""``region``: the global controller hosting a region planner (Roy 2022 chapters 4-6; ``RegionPlanner``, chosen by
name from the entry point group ``swarm_sitl.region_planners`` or as ``module:Class``). Every period it builds an
``Observation`` from what the robots sent, calls the planner's ``plan``, broadcasts the plan (``pose_packet.PLAN``),
records the plan and its events, and records the regions as a scene a viewer draws (``scene.py``).

What it observes, in thesis units of ``unit_m`` m: each robot's pose from the latest camera broadcast that had it
within ``silent_s`` (else its own latest status with a pose), its heading, and its latest sonar window
(``pose_packet.SONAR``, beams at ``sonar_angles_deg`` from the heading). A robot is in the observation while its own
packets (status, sonar windows) keep coming: one silent for ``silent_s`` is left out until it reports again; each
change is a decision (event ``input``). A window with the wrong beam count, or readings missing (no reading) or
beyond ``max_range_m`` (garbage), is counted; those readings are NaN in the observation, as "no echo" is (the
planner contract's convention).

A planner that raises keeps its last plan: the exception is counted and logged (event ``planner_error``) and the last
plan is broadcast again. A plan the wire cannot carry (too large for a datagram, a parameter without an encoding) is
counted and logged (event ``unsendable``) and the last one sent is sent again.

    [[services]]
    kind = "global_controller"
    name = "controller"
    options = { controller = "region", params = { planner = "converge", planner_params = { r_c = 3.0 } } }
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from bridge.core.services import ServiceContext
from bridge.services.global_controller import GlobalController
from bridge.services.global_controller.scene import SCENE_SCHEMA, region_scene
from swarm_logic.families.roy.regions.agent import to_packet
from swarm_logic.families.roy.regions.planner import PLANNERS, Observation, Plan, RegionPlanner
from swarm_logic.log import plain
from swarm_logic.plugins import PluginError
from swarm_logic.robots.sonpi import pose_packet as pp
from swarm_logic.robots.sonpi.interfaces import SONAR_ANGLES_RAD


class RegionOptions(BaseModel):
    """The region controller's own options (the service's ``options.params``)."""

    model_config = ConfigDict(extra="forbid")

    planner: str = Field(description="the region planner (swarm_sitl.region_planners, or module:Class)")
    planner_params: dict[str, Any] = Field({}, description="the planner's parameters (keyword arguments)")
    unit_m: float = Field(0.1, gt=0, description="the thesis' length unit, m (digest 5.4: 0.1 m)")
    sonar_angles_deg: list[float] = Field(
        [math.degrees(a) for a in SONAR_ANGLES_RAD],
        min_length=1,
        max_length=255,
        description="the robots' beams from the heading, in their windows' order (the SonPI's 5 front sonars)",
    )
    max_range_m: float = Field(4.0, gt=0, description="a reading beyond this is garbage (the HC-SR04's rated range)")
    silent_s: float = Field(1.0, gt=0, description="a robot whose own packets stop this long leaves the observation")
    scene_z_m: float = Field(0.01, description="the height the regions are drawn at")


def _options(params: dict[str, Any]) -> RegionOptions:
    try:
        return RegionOptions.model_validate(params)
    except ValidationError as e:
        err = e.errors()[0]
        where = ".".join(str(x) for x in err["loc"])
        raise ValueError(f"params.{where}: {err['msg']}") from None


def _planner(o: RegionOptions) -> RegionPlanner:
    try:
        cls = PLANNERS.get(o.planner)
    except PluginError as e:
        raise ValueError(f"params.planner: {e}") from None
    try:
        return cls(**o.planner_params)
    except (TypeError, ValueError) as e:
        raise ValueError(f"params.planner_params: {e}") from None


class RegionController(GlobalController):
    """Hosts a ``RegionPlanner``: observation in, plan out, every period (see the module)."""

    accepts = (pp.SonarWindow, list)  # list: the camera's pose broadcasts (``pose_packet.POSES``)

    @classmethod
    def check_params(cls, params: dict[str, Any]) -> None:
        _planner(_options(params))

    def __init__(self, ctx: ServiceContext, options: Any) -> None:
        super().__init__(ctx, options)
        self.o = _options(options.params)
        self.planner = _planner(self.o)
        self.ids = sorted(r.id for r in ctx.robots)
        self.angles = np.radians(self.o.sonar_angles_deg)
        self.camera: dict[int, tuple[float, pp.PoseEntry]] = {}  # the camera's latest valid pose per robot, and when
        self.status: dict[int, pp.Status] = {}
        self.windows: dict[int, tuple[float, np.ndarray]] = {}  # arrival time, ranges (units; NaN: none)
        self.heard: dict[int, float] = {}  # when each robot's own packet last arrived (service time)
        self.silent: set[int] = set()
        self.last: Plan | None = None
        self.last_packet: pp.PlanPacket | None = None
        self.seq = 0
        self.counts = Counter(
            plans=0,
            plans_sent=0,
            windows=0,
            window_shape=0,
            readings_missing=0,
            readings_garbage=0,
            went_silent=0,
            came_back=0,
            planner_errors=0,
            unsendable=0,
            camera_poses=0,
            scenes=0,
        )
        self.events: Counter[str] = Counter()
        self.done_t: float | None = None
        self.last_error: dict[str, Any] | None = None  # the planner's last exception, and the plan kept
        self.scene_key: Any = None

    # -- input ------------------------------------------------------------------------------------------------
    def on_status(self, t_s: float, status: pp.Status) -> None:
        self.status[status.id] = status
        self.heard[status.id] = self.now_s

    def on_packet(self, t_s: float, head: pp.Header, content: Any) -> None:
        if isinstance(content, list):
            for e in content:
                if e.valid:
                    self.camera[e.id] = (t_s, e)
                    self.counts["camera_poses"] += 1
            return
        assert isinstance(content, pp.SonarWindow)
        self.heard[content.id] = t_s
        self.counts["windows"] += 1
        m = len(self.angles)
        if len(content.ranges_m) != m:
            self.counts["window_shape"] += 1
            self.windows[content.id] = (t_s, np.full(m, np.nan))
            self.decision(
                t_s,
                {
                    "kind": "input",
                    "robot": content.id,
                    "reason": "window_shape",
                    "beams": len(content.ranges_m),
                    "expected": m,
                },
            )
            return
        r = np.array([np.nan if x is None else x for x in content.ranges_m], float)
        missing = np.array([x is None for x in content.ranges_m])
        garbage = np.isfinite(r) & ((r < 0) | (r > self.o.max_range_m))
        self.counts["readings_missing"] += int(missing.sum())
        self.counts["readings_garbage"] += int(garbage.sum())
        r[garbage | ~np.isfinite(r)] = np.nan  # no echo (inf), no reading and garbage: NaN, "no echo"
        self.windows[content.id] = (t_s, r / self.o.unit_m)

    def decision(self, t_s: float, event: dict[str, Any]) -> None:
        self.events[str(event.get("kind"))] += 1
        self.log("event", plain({"t": t_s, **event}))

    # -- the period ---------------------------------------------------------------------------------------------
    def observe(self, t_s: float) -> Observation:
        rows = []
        for i in self.ids:
            seen = i in self.heard and t_s - self.heard[i] <= self.o.silent_s
            if not seen and i in self.heard and i not in self.silent:
                self.silent.add(i)
                self.counts["went_silent"] += 1
                self.decision(t_s, {"kind": "input", "robot": i, "reason": "silent", "last_s": self.heard[i]})
            elif seen and i in self.silent:
                self.silent.discard(i)
                self.counts["came_back"] += 1
                self.decision(t_s, {"kind": "input", "robot": i, "reason": "back"})
            if not seen:
                continue
            cam, st = self.camera.get(i), self.status.get(i)
            if cam is not None and t_s - cam[0] <= self.o.silent_s:
                pose = (cam[1].x_m, cam[1].y_m, cam[1].yaw_rad)
            elif st is not None and st.has_pose:
                pose = (st.x_m, st.y_m, st.yaw_rad)
            else:
                continue  # reporting, but nobody knows where it is
            w = self.windows.get(i)
            ranges = w[1] if w is not None and t_s - w[0] <= self.o.silent_s else np.full(len(self.angles), np.nan)
            rows.append((i, pose, ranges))
        u = self.o.unit_m
        n = len(rows)
        return Observation(
            t_s,
            np.array([r[0] for r in rows], int),
            np.array([[r[1][0] / u, r[1][1] / u] for r in rows], float).reshape(n, 2),
            np.array([r[1][2] for r in rows], float),
            np.array([r[2] for r in rows], float).reshape(n, len(self.angles)),
            self.angles,
            np.asarray(self.options.target, float) / u,
        )

    def step(self, t_s: float) -> None:
        obs = self.observe(t_s)
        try:
            plan = self.planner.plan(obs)
        except Exception as e:  # a planner's fault must not end the swarm's control: keep the last plan
            self.counts["planner_errors"] += 1
            kept = None if self.last is None else self.last.t
            self.last_error = {"t": t_s, "error": f"{type(e).__name__}: {e}", "kept": kept}
            self.decision(t_s, {"kind": "planner_error", "error": self.last_error["error"], "kept": kept})
            plan = None
        if plan is not None:
            self.counts["plans"] += 1
            self.last = plan
            for ev in plan.events:
                self.decision(t_s, dict(ev))
            if plan.done and self.done_t is None:
                self.done_t = t_s
            self.log("plan", plan.as_dict())
            self.draw(t_s, plan)
            try:
                packet = to_packet(plan, self.o.unit_m)
                data = pp.encode_plan(self.seq, t_s, packet)
            except ValueError as e:  # PacketTooLarge included
                self.counts["unsendable"] += 1
                self.decision(t_s, {"kind": "unsendable", "error": str(e)})
            else:
                self.last_packet = packet
                self.send(data)
                self.seq += 1
                self.counts["plans_sent"] += 1
                return None
        if self.last_packet is not None:  # the last plan again: the robots must not see it go stale
            self.send(pp.encode_plan(self.seq, t_s, self.last_packet))
            self.seq += 1
            self.counts["plans_sent"] += 1
        return None

    def draw(self, t_s: float, plan: Plan) -> None:
        """The plan's regions as a scene, when they changed."""
        key = [r.as_dict() for r in plan.regions]
        if key == self.scene_key:
            return
        self.scene_key = key
        self.counts["scenes"] += 1
        self.log("regions", region_scene(round(t_s * 1e9), plan.regions, self.o.unit_m, self.o.scene_z_m), SCENE_SCHEMA)

    def summary(self) -> dict[str, Any]:
        return {
            "planner": self.o.planner,
            **dict(self.counts),
            "events": dict(sorted(self.events.items())),
            "done_s": self.done_t,
            "silent": sorted(self.silent),
            "last_planner_error": self.last_error,
            "planner_summary": plain(self.planner.summary()),
        }
