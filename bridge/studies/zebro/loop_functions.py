"""The Zebro study's loop functions (Agrawal 2019): the food particles in a session's world, who consumed which and
when (``/world/consumptions``), and the thesis' decision figures (``summary.json``'s ``particles`` and ``decision``):
the first sensing, the-leader, the frames by type, the communication graph's components (``/world/components``)
and A-13's split."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from bridge.core.loop_functions import LoopFunctions
from bridge.core.recorder import register_schema
from bridge.studies.zebro.decision import SplitWatch, components
from bridge.studies.zebro.particles import Particles
from swarm_logic.families.zebro.messages import NAMES

if TYPE_CHECKING:
    from bridge.core.config import Config
    from bridge.core.hub import Hub

register_schema("swarm_sitl.Consumption", {
    "type": "object",
    "description": "A robot reached a food particle and consumed it",
    "properties": {"robot": {"type": "integer"}, "particle": {"type": "integer"}, "utility": {"type": "integer"}},
})
register_schema("swarm_sitl.Components", {
    "type": "object",
    "description": "The live robots' communication graph at the decision's radius: its connected components",
    "properties": {"count": {"type": "integer"}, "radius_m": {"type": "number"}},
})

ELECTED = "zebro_elected"


class ZebroLoopFunctions(LoopFunctions):
    @classmethod
    def wanted(cls, cfg: Config) -> bool:
        return bool(cfg.section("particles"))

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        cfg = hub.cfg
        self.particles = Particles(cfg.section("particles"))
        hub.world.objects["particles"] = self.particles
        self.consumed: list[dict[str, Any]] = []
        d = cfg.section("decision")
        self.cfg = d
        self.radius = d.comm_range_m if d.comm_range_m is not None else cfg.uwb.max_range_m
        self.sample_ns = round(d.sample_s * 1e9)
        self.next_sample = 0
        self.split = SplitWatch(d.split_s)
        self.first_sensed: dict[str, Any] | None = None
        self.leaders: list[dict[str, Any]] = []
        self._cone = self._cones()

    def _quantum_ceil(self, t_ns: int) -> int:
        q = self.hub.q_ns
        return -(-t_ns // q) * q

    def _cones(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The utility sensors' robots, half-angles and ranges (None: no robot has one)."""
        model = self.hub.world.model("utility")
        if model is None:
            return None
        half = np.array([math.radians(p.cone_deg) / 2 for p in model.parts])
        return model.ids, half, np.array([p.range_m for p in model.parts])

    def pre_step(self, t: int) -> None:
        """Particles reached since the last quantum are consumed, before this quantum's sensors read the cone; the
        first sensing is looked for until it happens; the components are counted every ``sample_s``."""
        world, hub = self.world, self.hub
        for k, r in self.particles.reached(world.pos, world.alive):
            u = int(self.particles.utility[k])
            hub.rec.write(t, "/world/consumptions", "swarm_sitl.Consumption", {"robot": r, "particle": k, "utility": u})
            self.consumed.append({"t_s": t / 1e9, "robot": r, "particle": k, "utility": u})
            if len(self.consumed) == 1 and self.cfg.end_after_meal_s is not None:
                hub.end_ns = min(hub.end_ns, self._quantum_ceil(t + round(self.cfg.end_after_meal_s * 1e9)))
        if self.first_sensed is None:
            self._look_for_sensing(t)
        if t >= self.next_sample:
            self.next_sample = t + self.sample_ns
            count = components(world.pos, world.alive, self.radius)
            self.split.sample(t / 1e9, count)
            hub.rec.write(t, "/world/components", "swarm_sitl.Components", {"count": count, "radius_m": self.radius})

    @property
    def world(self) -> Any:
        return self.hub.world

    def _look_for_sensing(self, t: int) -> None:
        if self._cone is None or not self.particles.left.any():
            return
        ids, half, rng = self._cone
        w = self.world
        left = np.flatnonzero(self.particles.left & (self.particles.utility > 0))
        if not len(left):
            return
        d = self.particles.xy[left][None, :, :] - w.pos[ids, None, :2]
        dist = np.hypot(d[..., 0], d[..., 1])
        rel = np.angle(np.exp(1j * (np.arctan2(d[..., 1], d[..., 0]) - w.yaw[ids, None])))
        seen = (dist <= rng[:, None]) & (np.abs(rel) <= half[:, None]) & w.alive[ids, None]
        if seen.any():
            i, j = np.argwhere(seen)[0]
            self.first_sensed = {"t_s": t / 1e9, "robot": int(ids[i]), "particle": int(left[j]),
                                 "utility": int(self.particles.utility[left[j]])}

    def on_log(self, robot: int, topic: str, values: dict[str, Any], t: int) -> None:
        """Each robot that became the-leader (the mature election's ``zebro_elected``): when, with which utility."""
        if topic == ELECTED:
            self.leaders.append({"t_s": t / 1e9, "robot": robot, "utility": values.get("utility"),
                                 "seq": values.get("seq")})

    def summary(self) -> dict[str, Any]:
        """Which particles were consumed, by whom and when; whether the first was the best (A-17's best decision);
        the decision's timing, its leaders, A-13's split and the frames on the air by type."""
        positive = [int(u) for u in self.particles.utility if u > 0]
        first = self.consumed[0] if self.consumed else None
        best = None if first is None or len(positive) < 2 else first["utility"] == max(positive)
        return {
            "particles": {"consumed": self.consumed, "left": [int(k) for k in self.particles.left.nonzero()[0]],
                          "best_decision": best},
            "decision": {
                "first_sensed": self.first_sensed,
                "first_meal": first,
                "decision_s": None if first is None else first["t_s"],
                "ignored": first is None,
                "best": best,
                "leaders": self.leaders,
                "radius_m": self.radius,
                **self.split.report(),
                "frames_by_type": self._frames_by_type(),
            },
        }

    def _frames_by_type(self) -> dict[str, dict[str, int]]:
        """The data frames the UWB radios sent, by the family's frame type (its payload's first byte)."""
        air = self.hub.media.get("uwb_radio")
        if air is None:
            return {}
        out: dict[str, dict[str, int]] = {}
        for b, (frames, size) in sorted(air.first_bytes.items()):
            out[NAMES.get(b, f"0x{b:02x}")] = {"frames": frames, "bytes": size}
        return out
