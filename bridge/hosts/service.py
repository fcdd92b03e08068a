"""Hosts one service of a session (``bridge.core.services``): a centralised program in a process of its own, as the
firmware host runs a robot's boards.

Per tick the host hands the service the datagrams the Wi-Fi network delivered and the ground truth its kind senses,
and returns what it sent and logged and when it next runs. At the end its ``summary()`` goes back with the goodbye,
and becomes its entry in ``summary.json``'s ``services``.
"""

from __future__ import annotations

from typing import Any

from bridge.core.config import Config
from bridge.core.plan import Plan
from bridge.core.registry import SERVICES, robot_profile
from bridge.core.services import RobotInfo, ServiceContext, ServiceSpec, service_entity
from bridge.models.marker import TopMarker


class ServiceHost:
    def __init__(self, plan: Plan, name: str) -> None:
        spec, ctx = service_context(plan, name)
        self.entity = service_entity(name)
        self.service = spec.make(ctx)

    def run(self, ent: str, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        if ent != self.entity:
            raise KeyError(f"this process hosts {self.entity}, not {ent}")
        return self.service.run(t_ns, inputs)

    def stats(self) -> dict[str, dict]:
        return {self.entity: self.service.summary()}

    def stop(self) -> None:
        self.service.close()


def service_context(plan: Plan, name: str) -> tuple[ServiceSpec, ServiceContext]:
    """Service ``name``'s kind and the context it is built with, from the session's plan."""
    cfg = Config.from_plan(plan.config)
    sc = next(s for s in cfg.services if s.name == name)
    spec = SERVICES.get(sc.kind)
    robots = []
    for rp in plan.robots:
        if rp.gateway is not None:
            continue
        prof = robot_profile(rp.profile, rp.options)
        marker = next((p for p in prof.parts if isinstance(p, TopMarker)), None)
        robots.append(
            RobotInfo(
                rp.id,
                f"r{rp.id:03d}",
                rp.profile,
                prof.radius_m,
                prof.height_m,
                prof.length_m,
                prof.width_m,
                None if marker is None else marker.radius_m,
            )
        )
    ctx = ServiceContext(
        name, spec.options.model_validate(sc.options), cfg, robots, cfg.session.quantum_ns, cfg.session.seed
    )
    return spec, ctx
