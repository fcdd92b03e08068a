"""The PFSM study's loop functions (Khan, digest 4.1): in a session of foot-bots running ``pfsm_searcher`` and
``pfsm_target``, the figures the document's loop functions logged: the swarm's energy per control step (searchers
not resting, K-7), the time each target was found (given energy: its ``pfsm_target`` log leaving ``waiting``), the
targets found and home, and P_STA (eq. 2, ``numerical.p_sta``). The session ends ``end_after_found_s`` after the
last target is found (``[search]``), as the numerical model's runs do.

The robots' states come from their own logs (``pfsm_state``, ``pfsm_target``), as an experimenter's tracking
would; energy is sampled every ``tick_s`` of simulated time (ARGoS's control step). Recorded: ``/world/pfsm_found``
per discovery.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from bridge.core import foxglove as fx
from bridge.core.loop_functions import LoopFunctions
from bridge.core.recorder import register_schema
from bridge.studies.pfsm.config import SearchCfg
from bridge.studies.pfsm.numerical import p_sta

if TYPE_CHECKING:
    from bridge.core.config import Config
    from bridge.core.hub import Hub

SEARCHER, TARGET = "pfsm_searcher", "pfsm_target"

register_schema("swarm_sitl.PfsmFound", {
    "type": "object",
    "description": "A target was given energy by a searcher (it left its waiting state)",
    "properties": {"target": {"type": "integer"}, "t_s": {"type": "number"}},
})


def _roles(cfg: Config) -> tuple[list[int], list[int]]:
    """The searchers' and the targets' robot ids, in robot order."""
    searchers, targets, first = [], [], 0
    for g in cfg.robots:
        ids = range(first, first + g.count)
        if g.behaviour == SEARCHER:
            searchers += ids
        elif g.behaviour == TARGET:
            targets += ids
        first += g.count
    return searchers, targets


def _finite(v: float) -> float | None:
    return None if math.isnan(v) else v


class PfsmLoopFunctions(LoopFunctions):
    @classmethod
    def wanted(cls, cfg: Config) -> bool:
        s, t = _roles(cfg)
        return bool(s and t)

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        cfg = hub.cfg
        self.cfg: SearchCfg = cfg.section("search") or SearchCfg()
        self.searchers, self.targets = _roles(cfg)
        self.resting: set[int] = set()
        self.found_s: dict[int, float] = {}
        self.home: set[int] = set()
        self.tick_ns = round(self.cfg.tick_s * 1e9)
        self.next_tick = 0
        self.energy: list[int] = []  # per tick: searchers not resting
        self.energy_all: list[int] = []  # and targets driving home
        self.area = self.cfg.area_m2 or cfg.arena.width_m * cfg.arena.length_m

    def pre_step(self, t: int) -> None:
        while t >= self.next_tick:
            self.next_tick += self.tick_ns
            dead = self.hub.dead
            walking = sum(1 for r in self.searchers if r not in self.resting and r not in dead)
            homing = sum(1 for r in self.found_s if r not in self.home and r not in dead)
            self.energy.append(walking)
            self.energy_all.append(walking + homing)

    def on_log(self, robot: int, topic: str, values: dict[str, Any], t: int) -> None:
        if topic == "pfsm_state" and robot in self.searchers:
            state = values.get("state")
            if not isinstance(state, str):
                raise ValueError
            (self.resting.add if state == "timeout" else self.resting.discard)(robot)
        elif topic == "pfsm_target" and robot in self.targets:
            state = values.get("state")
            if not isinstance(state, str):
                raise ValueError
            if state != "waiting" and robot not in self.found_s:
                self.found_s[robot] = t / 1e9
                self.hub.rec.write(t, "/world/pfsm_found", "swarm_sitl.PfsmFound", {"target": robot, "t_s": t / 1e9})
                if len(self.found_s) == len(self.targets) and self.cfg.end_after_found_s is not None:
                    q = self.hub.q_ns
                    end = t + round(self.cfg.end_after_found_s * 1e9)
                    self.hub.end_ns = min(self.hub.end_ns, max(t + q, -(-end // q) * q))
            if state == "home":
                self.home.add(robot)

    def scene(self, t: int) -> list[dict[str, Any]]:
        """The targets: a ring around each, red while it waits to be found, green once found, blue once home."""
        w = self.hub.world
        out = []
        for r in self.targets:
            colour = (fx.color(0.1, 0.4, 0.95) if r in self.home else fx.color(0.1, 0.8, 0.2) if r in self.found_s
                      else fx.color(0.9, 0.1, 0.1))
            x, y = float(w.pos[r, 0]), float(w.pos[r, 1])
            ring = [(x + 0.25 * math.cos(a), y + 0.25 * math.sin(a), 0.02) for a in
                    (2 * math.pi * i / 24 for i in range(24))]
            state = "home" if r in self.home else "found" if r in self.found_s else "waiting"
            out.append(fx.entity(t, f"pfsm/target{r}", metadata={"state": state},
                                 lines=[fx.line(ring, colour, fx.LINE_LOOP, 0.03)]))
        return out

    def summary(self) -> dict[str, Any]:
        """``search``: each target's discovery time, the targets found and home, T_total, E_total and P_STA."""
        nt, ns = len(self.targets), len(self.searchers)
        n_found = len(self.found_s)
        sim_s = len(self.energy) * self.cfg.tick_s
        t_total = max(self.found_s.values()) if n_found == nt and nt else sim_s
        k = round(t_total / self.cfg.tick_s)
        e, e_all = sum(self.energy[:k]), sum(self.energy_all[:k])
        return {"search": {
            "searchers": ns, "targets": nt, "area_m2": self.area,
            "found_s": {str(r): round(self.found_s[r], 3) for r in sorted(self.found_s)},
            "found": n_found, "all_found": n_found == nt, "home": len(self.home),
            "t_total_s": round(t_total, 3), "e_total": e, "e_total_all": e_all,
            "p_sta": _finite(p_sta(e, t_total, n_found, nt, self.area, ns)) if nt and ns else None,
            "p_sta_all": _finite(p_sta(e_all, t_total, n_found, nt, self.area, ns)) if nt and ns else None,
        }}
