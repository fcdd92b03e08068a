"""Hosts one service of a session (``bridge.core.services``): a centralised program in a process of its own, as the
firmware host runs a robot's boards.

Per tick the host hands the service the datagrams the Wi-Fi network delivered and the ground truth its kind senses,
and returns what it sent and logged and when it next runs. At the end its ``summary()`` goes back with the goodbye,
and becomes its entry in ``summary.json``'s ``services``.
"""

from __future__ import annotations

from typing import Any

from bridge.core.plan import Plan
from bridge.core.services import service_context, service_entity


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
