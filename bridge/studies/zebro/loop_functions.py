"""The Zebro study's loop functions (Agrawal 2019): the food particles in a session's world, who consumed which and
when (``/world/consumptions``), and the thesis' decision figures from them (``summary.json``'s ``particles``)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from bridge.core.loop_functions import LoopFunctions
from bridge.core.recorder import register_schema
from bridge.studies.zebro.particles import Particles

if TYPE_CHECKING:
    from bridge.core.config import Config
    from bridge.core.hub import Hub

register_schema("swarm_sitl.Consumption", {
    "type": "object",
    "description": "A robot reached a food particle and consumed it",
    "properties": {"robot": {"type": "integer"}, "particle": {"type": "integer"}, "utility": {"type": "integer"}},
})


class ZebroLoopFunctions(LoopFunctions):
    @classmethod
    def wanted(cls, cfg: Config) -> bool:
        return bool(cfg.section("particles"))

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        self.particles = Particles(hub.cfg.section("particles"))
        hub.world.objects["particles"] = self.particles
        self.consumed: list[dict[str, Any]] = []

    def pre_step(self, t: int) -> None:
        """Particles reached since the last quantum are consumed, before this quantum's sensors read the cone."""
        world = self.hub.world
        for k, r in self.particles.reached(world.pos, world.alive):
            u = int(self.particles.utility[k])
            self.hub.rec.write(t, "/world/consumptions", "swarm_sitl.Consumption",
                               {"robot": r, "particle": k, "utility": u})
            self.consumed.append({"t_s": t / 1e9, "robot": r, "particle": k, "utility": u})

    def summary(self) -> dict[str, Any]:
        """Which particles were consumed, by whom and when; whether the first was the best (A-17's best decision)."""
        positive = [int(u) for u in self.particles.utility if u > 0]
        first = self.consumed[0]["utility"] if self.consumed else None
        return {"particles": {
            "consumed": self.consumed,
            "left": [int(k) for k in self.particles.left.nonzero()[0]],
            "best_decision": None if first is None or len(positive) < 2 else first == max(positive),
        }}
