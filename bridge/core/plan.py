"""A session plan: the config resolved into robots, initial poses, entities and processes.

The plan is computed once by the launcher and handed to every process, so they all agree on who is who.
Everything in it follows from the config and the seed alone.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import importlib.util
import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from bridge.core.arena_map import blocked as map_blocked
from bridge.core.arena_map import occupancy
from bridge.core.config import Config, ConfigError
from bridge.core.entities import entity
from bridge.core.registry import robot_spec
from bridge.core.rng import stream
from bridge.core.services import service_entity, service_proc
from swarm_logic.geometry import theodorus_spiral


@dataclass(frozen=True)
class RobotPlan:
    id: int
    name: str
    profile: str
    behaviour: str
    params: dict
    pose: tuple[float, float, float]  # x, y, yaw (rad)
    xbee: dict | None = None  # the group's XBeeCfg as a dict, or None without a radio
    uwb: bool = False
    pose_source: str = "odometry"  # "ground_truth": the LLC is fed the true pose (RobotGroup.pose_source)
    logic: str = "session"  # "external" | "remote" (RobotGroup.logic); "none" for an XBee gateway
    slcan_pty: str | None = None  # its CAN bus on a pseudo-terminal as an slcan adapter (RobotCanCfg.slcan_pty)
    can_device: dict | None = None  # its real LLC board's CAN interface, python-can Bus arguments (RobotCanCfg.device)
    vehicle: dict | None = None  # a MAVLink vehicle stands for it (VehicleCfg)
    motion: dict | None = None  # how the body moves when nothing simulated drives it (MotionCfg): kind, waypoints
    gateway: dict | None = None  # an XBee gateway, not a robot: the real module's settings (XBeeGatewayCfg)
    carrier: int | None = None  # it starts on board this robot (RobotGroup.carried_by) ...
    slot: int = 0  # ... in this slot, 1 being the first to drop off
    payload: tuple[int, ...] = ()  # a carrier: the robots on board, by slot
    options: dict = field(default_factory=dict)  # its robot model's options (the group's extra fields)
    devices: dict = field(default_factory=dict)  # the devices the session adds to its program (RobotGroup.devices)
    wifi_udp: str | None = None  # its Wi-Fi node as a UDP socket for an outside program (RobotGroup.wifi_udp)

    def modules(self) -> tuple[str, ...]:
        """The firmware entities' roles of this robot: its LLC (or the bridge to its real LLC's CAN bus), the radio
        modules it carries, the slcan adapter on its CAN bus when it is exposed, and its robot model's own (a
        legged robot's leg modules: ``RobotSpec.roles``)."""
        llc = () if self.llc_role is None else (self.llc_role,)
        own = () if self.gateway is not None else robot_spec(self.profile).own_roles(self)
        return (llc + (("xbee",) if self.sim_xbee else ()) + (("uwb",) if self.uwb else ())
                + (("slcan",) if self.slcan_pty else ()) + own)

    @property
    def llc_role(self) -> str | None:
        """``llc`` (simulated), ``can_bridge`` (its real board, reached through a CAN interface) or None (a MAVLink
        vehicle, an XBee gateway, a robot model without an LLC board)."""
        if self.vehicle is not None or self.gateway is not None:
            return None
        if self.can_device is not None:
            return "can_bridge"
        return "llc" if robot_spec(self.profile).board is not None else None

    @property
    def has_logic(self) -> bool:
        """The session runs its swarm logic (here or on a remote computer), as entity ``rNNN/logic``."""
        return self.logic in ("session", "remote")

    @property
    def sim_xbee(self) -> bool:
        """It carries an XBee the session simulates (not a real one on a device)."""
        return bool(self.xbee) and not self.xbee.get("device")

    def fault_problem(self, f: Any) -> str | None:
        """Why this robot cannot carry fault ``f`` (a ``[[faults]]`` entry, ``FaultCfg``), or None if it can: the
        reason starts with the field at fault."""
        from bridge.core.faults import ROBOT_FAULTS, robot_fault_problem

        if f.kind in ROBOT_FAULTS:
            return robot_fault_problem(self, f)
        kind, node, device = f.kind, f.node, f.device
        nodes = self.can_nodes()
        if kind.startswith("can_") and not nodes:
            return f"kind: robot {self.id} has no CAN bus"
        if kind == "can_bus_off" and (self.host_node if node == "host" else node) not in nodes:
            return f"node: robot {self.id} has no {node} node on its CAN bus"
        if kind == "unplugged" and device not in self.modules():
            return f"device: robot {self.id} has no {device} module"
        return None

    def can_nodes(self) -> tuple[str, ...]:
        """The roles of the nodes on this robot's CAN bus (none for a robot model without one): its LLC, its robot
        model's own boards on the bus (``RobotSpec.can_roles``), its companion computer, an slcan adapter."""
        if self.can_device is None and self.vehicle is None and not robot_spec(self.profile).has_can:
            return ()
        llc = () if self.llc_role is None else (self.llc_role,)
        spec = robot_spec(self.profile)
        own = () if self.gateway is not None else tuple(r for r in spec.own_roles(self) if r in spec.can_roles)
        return llc + own + (("logic",) if self.has_logic else ()) + (("slcan",) if self.slcan_pty else ())

    @property
    def host_node(self) -> str:
        """The role of the companion computer's CAN node: its session logic, or the slcan adapter an external
        logic uses."""
        return "logic" if self.has_logic else "slcan"

    @property
    def scripted(self) -> bool:
        """Its body follows a stated motion (fixed or scripted), not the world's motor model."""
        return self.motion is not None and self.motion["kind"] != "simulated"


@dataclass(frozen=True)
class ProcPlan:
    name: str
    kind: str  # "firmware" | "logic" | "service"
    robots: tuple[int, ...]
    remote: bool = False  # it joins from another computer (swarm-sitl join); the launcher does not start it
    service: str | None = None  # a service's process: the service's name (its one entity, svc/NAME)
    host: str | None = None  # the host of [[hosts]] it runs on (remote; joined by swarm-sitl join --host)
    # served in the launcher's own process (a test driving the session, ``run_session(hosted=...)``): not started,
    # never killed, and waited for without a hang timeout (it lives as long as the launcher, which the world dies with)
    inproc: bool = False

    def entities(self, robots: list[RobotPlan]) -> list[str]:
        if self.kind == "service":
            return [service_entity(str(self.service))]
        if self.kind == "logic":
            return [entity(r, "logic") for r in self.robots]
        return [entity(r, role) for r in self.robots for role in robots[r].modules()]


@dataclass
class Plan:
    config: dict
    robots: list[RobotPlan]
    procs: list[ProcPlan] = field(default_factory=list)

    def to_json(self) -> dict:
        return {"config": self.config, "robots": [asdict(r) for r in self.robots],
                "procs": [asdict(p) for p in self.procs]}

    @classmethod
    def from_json(cls, d: dict) -> Plan:
        robots = [RobotPlan(**{**r, "pose": tuple(r["pose"]), "payload": tuple(r.get("payload", ()))})
                  for r in d["robots"]]
        procs = [ProcPlan(p["name"], p["kind"], tuple(p["robots"]), p.get("remote", False), p.get("service"),
                          p.get("host"), p.get("inproc", False)) for p in d["procs"]]
        return cls(d["config"], robots, procs)


def make_plan(cfg: Config, path: str = "config") -> Plan:
    robots: list[RobotPlan] = []
    first = [sum(g.count for g in cfg.robots[:gi]) for gi in range(len(cfg.robots))]  # each group's first id
    load: dict[int, int] = {}  # carrier group -> robots loaded so far
    for gi, group in enumerate(cfg.robots):
        prof = cfg.profile(group)
        carriers: list[tuple[int, int]] = []  # (carrier id, slot) per robot of a carried group
        if group.carried_by is not None:
            slots = cfg.profile(cfg.robots[group.carried_by]).capacity
            for _ in range(group.count):
                k = load.get(group.carried_by, 0)
                load[group.carried_by] = k + 1
                carriers.append((first[group.carried_by] + k // slots, k % slots + 1))
            poses = [(0.0, 0.0, 0.0)] * group.count  # on board: where its carrier is (set below)
        else:
            poses = _place(cfg, gi, prof.radius_m, path)
        for j, pose in enumerate(poses):
            rid = len(robots)
            if group.motion.kind == "scripted":  # it starts where its path starts
                _, x, y, yaw_deg = group.motion.waypoints[0]
                pose = (x, y, math.radians(yaw_deg))
            carrier, slot = carriers[j] if carriers else (None, 0)
            robots.append(RobotPlan(rid, f"r{rid:03d}", group.profile, group.behaviour, dict(group.params), pose,
                                    group.xbee.model_dump() if group.xbee else None, group.uwb, group.pose_source,
                                    group.logic, group.can.slcan_pty, group.can.device,
                                    group.vehicle.model_dump() if group.vehicle else None,
                                    group.motion.model_dump(mode="json"), carrier=carrier, slot=slot,
                                    options=dict(group.model_extra or {}), devices=dict(group.devices),
                                    wifi_udp=group.wifi_udp))
    for i, rp in enumerate(robots):  # a carried robot starts where its carrier is
        if rp.carrier is not None:
            robots[i] = replace(rp, pose=robots[rp.carrier].pose)
    for c in {rp.carrier for rp in robots if rp.carrier is not None}:
        load_c = sorted((rp.slot, rp.id) for rp in robots if rp.carrier == c)
        robots[c] = replace(robots[c], payload=tuple(r for _, r in load_c))
    for gi, gw in enumerate(cfg.xbee_gateways):  # after the robots, so robot ids do not depend on gateways
        rid = len(robots)
        waypoints = [[t, x, y, 0.0] for t, x, y in gw.waypoints]
        twin = {"series": gw.series, "api_mode": 1, "baud": 115200, "power_level": gw.power_level,
                "pan_id": gw.pan_id, "channel": gw.channel, "pty": None, "device": None}
        robots.append(RobotPlan(rid, f"gateway{gi}", cfg.robots[0].profile, "", {}, (gw.pose[0], gw.pose[1], 0.0),
                                twin, logic="none", gateway=gw.model_dump(),
                                motion={"kind": "scripted" if waypoints else "fixed", "waypoints": waypoints}))
    # each robot's hosts (firmware, logic) by its group; an XBee gateway's firmware is the world computer's
    group_hosts = [g.hosts() for g in cfg.robots for _ in range(g.count)]
    group_hosts += [(None, None)] * (len(robots) - len(group_hosts))
    procs = _packed(cfg, "fw", "firmware", [(r.id, group_hosts[r.id][0]) for r in robots])
    # an external logic is nobody's process here
    procs += _packed(cfg, "lg", "logic", [(r.id, group_hosts[r.id][1]) for r in robots if r.logic == "session"])
    # a remote logic is its robot's own process, started by swarm-sitl join on the other computer
    procs += [ProcPlan(f"remote{r.id}", "logic", (r.id,), remote=True) for r in robots if r.logic == "remote"]
    procs += [ProcPlan(service_proc(s.name), "service", (), service=s.name, remote=s.host is not None, host=s.host)
              for s in cfg.services]
    for i, f in enumerate(cfg.faults):
        if f.robot is not None and f.robot < len(robots) and (why := robots[f.robot].fault_problem(f)):
            raise ConfigError(f"{path}: faults[{i}].{why}")
    return Plan(cfg.model_dump(mode="json"), robots, procs)


def _packed(cfg: Config, prefix: str, kind: str, placed: list[tuple[int, str | None]]) -> list[ProcPlan]:
    """Robots (id, host) packed ``robots_per_process`` to a process of ``kind``, in id order, never two hosts in one
    process: the world computer's first (``prefix`` 0, 1, ...), then each host's in the order of ``[[hosts]]``."""
    k = cfg.session.robots_per_process
    procs: list[ProcPlan] = []
    for host in [None, *(h.name for h in cfg.hosts)]:
        ids = [r for r, h in placed if h == host]
        for i in range(0, len(ids), k):
            procs.append(ProcPlan(f"{prefix}{len(procs)}", kind, tuple(ids[i:i + k]), remote=host is not None,
                                  host=host))
    return procs


def _blocked(cfg: Config, x: float, y: float, clearance: float, occ: np.ndarray | None = None) -> bool:
    a = cfg.arena
    if not (clearance < x < a.width_m - clearance and clearance < y < a.length_m - clearance):
        return True
    if occ is not None and map_blocked(occ, a.map_resolution_m, x, y, clearance):
        return True
    return any(ob.overlaps(x, y, clearance) for ob in cfg.obstacles)


def _place(cfg: Config, gi: int, radius: float, path: str) -> list[tuple[float, float, float]]:
    g = cfg.robots[gi]
    pl = g.placement
    rng = stream(cfg.session.seed, "placement", gi)
    clearance = radius + 0.02
    occ = occupancy(cfg.arena) if cfg.arena.map else None

    def yaw() -> float:
        return float(rng.uniform(-math.pi, math.pi)) if pl.yaw_deg == "random" else math.radians(pl.yaw_deg)

    out: list[tuple[float, float, float]] = []
    if pl.kind == "explicit":
        for j, (x, y, _) in enumerate(pl.poses):
            if _blocked(cfg, x, y, radius, occ):
                raise ConfigError(f"{path}: robots[{gi}].placement.poses[{j}]: ({x}, {y}) is inside a wall or an "
                                  "obstacle (or closer to one than the robot's radius)")
        return [(x, y, math.radians(yd)) for x, y, yd in pl.poses]
    if pl.kind == "spiral":
        blocks = len(pl.centres)
        for b, centre in enumerate(pl.centres):
            n_b = sum(1 for i in range(g.count) if i * blocks // g.count == b)
            # a random orientation and turning sense per spiral (placements vary between trials), redrawn
            # while a robot would land outside the arena or in an obstacle
            for _attempt in range(200):
                phi0 = float(rng.uniform(-math.pi, math.pi))
                sigma = 1 if rng.random() < 0.5 else -1
                pts = theodorus_spiral(n_b, pl.spacing_m, centre, phi0, sigma)
                if not any(_blocked(cfg, x, y, clearance, occ) for x, y in pts):
                    break
            else:
                raise ConfigError(f"{path}: robots[{gi}].placement: spiral {b} of {n_b} robots around {tuple(centre)} "
                                  f"does not fit in the free space in any orientation (move the centre or shorten "
                                  "spacing_m)")
            out.extend((x, y, yaw()) for x, y in pts)
        return out
    if pl.kind == "grid":
        for i in range(g.count):
            x = pl.origin[0] + (i % pl.columns) * pl.spacing_m
            y = pl.origin[1] + (i // pl.columns) * pl.spacing_m
            if _blocked(cfg, x, y, clearance, occ):
                raise ConfigError(
                    f"{path}: robots[{gi}].placement: grid position {i} at ({x:.2f}, {y:.2f}) is outside the "
                    "arena or inside an obstacle"
                )
            out.append((x, y, yaw()))
        return out
    a = cfg.arena
    x0, y0, x1, y1 = pl.region or (0.0, 0.0, a.width_m, a.length_m)
    pts = np.empty((0, 2))
    for _ in range(g.count):
        for _attempt in range(10000):
            x, y = float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1))
            if _blocked(cfg, x, y, clearance, occ):
                continue
            if len(pts) and np.min(np.hypot(pts[:, 0] - x, pts[:, 1] - y)) < pl.min_separation_m:
                continue
            break
        else:
            raise ConfigError(
                f"{path}: robots[{gi}].placement: could not place {g.count} robots {pl.min_separation_m} m apart "
                "in the free space of the region"
            )
        pts = np.vstack([pts, [x, y]])
        out.append((x, y, yaw()))
    return out


# between a world and a joiner (swarm-sitl join): the tick/done/plan exchange; bump on any incompatible change (the
# version check catches the rest)
PROTOCOL = 2


CODE_PACKAGES = ("bridge", "firmware_sim", "swarm_logic")  # the code a session or a trial runs
CODE_SUFFIXES = frozenset({".py", ".dbc", ".toml", ".json", ".yaml", ".yml", ".csv", ".urdf", ".xml"})  # and data


def version() -> str:
    """This computer's swarm-sitl version (the installed package's)."""
    try:
        return importlib.metadata.version("swarm-sitl")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


@functools.cache
def code_fingerprint() -> str:
    """This process's swarm-sitl version and a hash of its code: the sorted paths (relative to each package) and
    bytes of the source and data files of ``CODE_PACKAGES``, as imported here. Computers that join one session, or
    run one experiment's trials, must show the same (the same code gives the same digest). Computed once per
    process."""
    h = hashlib.sha256()
    for package in CODE_PACKAGES:
        spec = importlib.util.find_spec(package)
        roots = list(spec.submodule_search_locations or []) if spec else []
        if not roots:
            h.update(f"{package}: missing\0".encode())
            continue
        root = Path(roots[0])
        files = sorted(
            (p.relative_to(root).as_posix(), p)
            for p in root.rglob("*")
            if p.suffix in CODE_SUFFIXES and "__pycache__" not in p.parts and p.is_file()
        )
        for rel, p in files:
            data = p.read_bytes()
            h.update(f"{package}/{rel}\0{len(data)}\0".encode())
            h.update(data)
    return f"{version()}+{h.hexdigest()[:16]}"


def plan_offer(plan: Plan, joinable: frozenset[str] | None) -> bytes:
    """The world's answer to a joiner's ``plan`` query (JSON): the session's name, the software version with its code's
    fingerprint and the protocol, the plan, and which remote processes (a remote logic's, a host's) may still join
    (``None``: the session has started)."""
    return json.dumps({"session": plan.config["session"]["name"], "version": code_fingerprint(), "protocol": PROTOCOL,
                       "joinable": None if joinable is None else sorted(joinable), "plan": plan.to_json()}).encode()
