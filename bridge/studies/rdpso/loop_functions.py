"""The RDPSO study's loop functions (Couceiro 2013): what its sessions measure beyond the world's own figures.

- the rangers' marsupial deployment (chapter 5): when each ranger says it is done (its ``deployment`` log), where its
  scouts are, their dispersion (eq. 5.11) and the arena they cover; ``session.end_after_deployment`` ends the session
  1 s after the last ranger;
- each ranger's subgroup in the radio graph: its partition events, before and after its START;
- the thesis' Table 5.2 link statistics of the deployed scouts' RDPSO subgroups as they are at each sample (their
  members by the ``rdpso`` log's ``sid``, links as the scouts judge them, by q_min): hops, relays, lambda2, and the
  one-hop signal quality the scouts measured (the log's ``mate_rssi``);
- the chapter 6 routing layer's counters (the ``rdpso`` log's ``comm``), summed in ``comm_stats``;
- the chapter 8 mapping objective (``[objective] kind = "mapping"``): the light sensors read it, the robots scan from
  where they stand every ``scan_period_s`` (``/world/mapping``), and eta_exp with its AUC go to the summary.
"""

from __future__ import annotations

from collections import defaultdict
from typing import TYPE_CHECKING, Any

import numpy as np

from bridge.core import foxglove as fx
from bridge.core.loop_functions import LoopFunctions
from bridge.core.recorder import register_schema
from bridge.media.radio import splits
from bridge.studies.rdpso.comm_stats import comm_report
from bridge.studies.rdpso.deployment import covered_share, dispersion, link_stats, mean_sd
from swarm_logic.families.rdpso.graph import adjacency
from swarm_logic.graph import components

if TYPE_CHECKING:
    from bridge.core.config import Config
    from bridge.core.hub import Hub

register_schema("swarm_sitl.Mapping", {
    "type": "object",
    "description": "The chapter 8 mapping objective after a scan of all live robots (objective kind mapping)",
    "properties": {
        "eta_exp": {"type": "number", "description": "exploration ratio: explored free cells / free cells"},
        "scans": {"type": "integer", "description": "scans so far, this one included"},
        "explored_free_cells": {"type": "integer"},
        "free_cells": {"type": "integer"},
        "entropy_bits": {"type": "number", "description": "the map's total entropy, eq. 8.2 summed over cells"},
    },
})

BEHAVIOURS = ("rdpso", "est_ranger")  # the study's controllers: their logs are read here


SUBGROUP_COLOURS = ((0.9, 0.6, 0.0), (0.0, 0.6, 0.9), (0.8, 0.2, 0.6), (0.2, 0.7, 0.3), (0.6, 0.4, 0.9))


class RdpsoLoopFunctions(LoopFunctions):
    @classmethod
    def wanted(cls, cfg: Config) -> bool:
        return (cfg.section("objective").kind == "mapping" or any(g.carried_by is not None for g in cfg.robots)
                or any(g.behaviour in BEHAVIOURS for g in cfg.robots))

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        robots = hub.plan.robots
        self.group_of = {rp.id: rp.carrier for rp in robots if rp.carrier is not None}  # scout -> its ranger
        self.carriers = set(self.group_of.values())  # rangers with scouts on board
        self.group_pieces: dict[int, list[int]] = defaultdict(list)
        self.mission_pieces: dict[int, list[int]] = defaultdict(list)  # ranger -> its scouts' pieces after START
        # each RDPSO subgroup of deployed scouts, per sample (Table 5.2; link_stats)
        self.mission_links: list[dict[str, Any]] = []
        self.sid_of: dict[int, int] = {}  # robot -> its subgroup in its latest rdpso record (0: excluded)
        self.mate_rssi: list[int] = []  # dBm of every hello a deployed scout heard from a subgroup mate
        self.q_min = {rp.carrier: float(rp.params["q_min_dbm"]) for rp in robots if rp.carrier is not None
                      and rp.params.get("link_mode") == "rssi" and "q_min_dbm" in rp.params}  # ranger -> its scouts'
        self.deployed: dict[int, dict[str, Any]] = {}  # ranger -> its deployment as it ended (deployment_report)
        self.comm: dict[int, dict[str, Any]] = {}  # robot -> its routing layer's latest counters (comm_report)
        self.particles: dict[int, tuple[int, tuple[float, float]]] = {}  # robot -> (subgroup, its ledger's best)
        self.mapping = None
        if hub.cfg.section("objective").kind == "mapping":
            from bridge.studies.rdpso.mapping import SessionMap

            self.mapping = hub.world.lux_field = SessionMap(hub.cfg)

    def pre_step(self, t: int) -> None:
        """With the mapping objective, the robots scan from where they stand if a scan is due, so this quantum's
        light readings see it."""
        world = self.hub.world
        if self.mapping is not None and self.mapping.tick(t, world.pos, world.alive):
            self.hub.rec.write(t, "/world/mapping", "swarm_sitl.Mapping", self.mapping.record())

    def on_log(self, robot: int, topic: str, values: dict[str, Any], t: int) -> None:
        if topic == "deployment" and values.get("event") == "done" and robot in self.carriers:
            self._deployed(robot, t)
        elif topic == "rdpso":
            if isinstance(values.get("comm"), dict):
                self.comm[robot] = values["comm"]
            if isinstance(values.get("sid"), int):
                self.sid_of[robot] = values["sid"]
            if robot in self.group_of and isinstance(values.get("mate_rssi"), list):
                self.mate_rssi += [v for v in values["mate_rssi"] if isinstance(v, int | float)]
            chi2 = values.get("chi2")
            if isinstance(values.get("sid"), int) and isinstance(chi2, list | tuple) and len(chi2) == 2:
                self.particles[robot] = (values["sid"], (float(chi2[0]), float(chi2[1])))

    def scene(self, t: int) -> list[dict[str, Any]]:
        """The swarm as particles: each subgroup's best solution as its members last logged it (chi_2, a sphere in
        the subgroup's colour), joined to the members that know it; the socially excluded are left undrawn."""
        w = self.hub.world
        best: dict[int, tuple[float, float]] = {}
        members: dict[int, list[int]] = defaultdict(list)
        for r, (sid, chi2) in sorted(self.particles.items()):
            if sid and w.alive[r] and all(np.isfinite(chi2)):
                best.setdefault(sid, chi2)
                members[sid].append(r)
        out = []
        for sid in sorted(best):
            rgba = fx.color(*SUBGROUP_COLOURS[sid % len(SUBGROUP_COLOURS)], 0.9)
            bx, by = best[sid]
            pts = []
            for r in members[sid]:
                pts += [(float(w.pos[r, 0]), float(w.pos[r, 1]), 0.05), (bx, by, 0.05)]
            out.append(fx.entity(t, f"rdpso/subgroup{sid}", metadata={"members": ",".join(map(str, members[sid]))},
                                 spheres=[fx.shape(bx, by, 0.1, (0.2, 0.2, 0.2), rgba)],
                                 lines=[fx.line(pts, {**rgba, "a": 0.35}, fx.LINE_LIST, 0.01)],
                                 texts=[fx.text(bx, by, 0.3, f"subgroup {sid}", rgba)]))
        return out

    def _deployed(self, carrier: int, t: int) -> None:
        """A ranger says it has deployed its scouts (and broadcast START): where they are, by ground truth."""
        world = self.hub.world
        scouts = [r for r, c in self.group_of.items() if c == carrier and r not in world.carried]
        pts = world.pos[scouts] if scouts else np.zeros((0, 2))
        self.deployed[carrier] = {"t_s": t / 1e9, "scouts": scouts, "dispersion_m": round(dispersion(pts), 3),
                                  "positions": np.round(pts, 3).tolist()}
        if self.hub.cfg.session.end_after_deployment and len(self.deployed) == len(self.carriers):
            self.hub.end_ns = min(self.hub.end_ns, t + 1_000_000_000)

    def on_radio_sample(self, t: int, live: list[int], adj: np.ndarray) -> None:
        """Each ranger's group (its live scouts off the conveyor): how many pieces, before and after its START; after
        it, each RDPSO subgroup of two or more of its scouts, with links as they judge them (the mean RSSI clears
        their q_min both ways, else any link)."""
        if not self.group_of:
            return
        world = self.hub.world
        idx = {r: i for i, r in enumerate(live)}
        rssi_live = None
        subgroups: dict[int, list[int]] = defaultdict(list)  # sid -> members (recruits may come from any ranger)
        judge: dict[int, int] = {}  # sid -> the ranger whose scouts' q_min judges its links (its first member's)
        for g in sorted(self.carriers):
            members = [r for r, c in self.group_of.items() if c == g and r in idx and r not in world.carried]
            ix = [idx[r] for r in members]
            self.group_pieces[g].append(components(adj[np.ix_(ix, ix)]) if members else 0)
            if g in self.deployed and members:  # the mission has begun for this group (its START)
                if rssi_live is None:
                    rssi_live = self.hub.medium("radio").medium.mean_rssi()[np.ix_(live, live)]
                self.mission_pieces[g].append(components(self._judged(g, ix, adj, rssi_live)))
                for r in members:
                    if sid := self.sid_of.get(r):
                        subgroups[sid].append(idx[r])
                        judge.setdefault(sid, g)
        for sid, ix in sorted(subgroups.items()):
            if len(ix) >= 2:
                sub = self._judged(judge[sid], ix, adj, rssi_live)
                self.mission_links.append({"sid": sid, **link_stats(sub, rssi_live[np.ix_(ix, ix)])})

    def _judged(self, g: int, ix: list[int], adj: np.ndarray, rssi_live: np.ndarray) -> np.ndarray:
        """The links among ``ix`` (indices into the live robots) as ranger ``g``'s scouts judge them: the mean RSSI
        clears their q_min both ways (else any link of the radio graph)."""
        q = self.q_min.get(g)
        if q is None:
            return adj[np.ix_(ix, ix)]
        good = adjacency(rssi_live[np.ix_(ix, ix)], "rssi", q)
        return good & good.T

    def radio_report(self, connectivity: dict[str, Any]) -> None:
        if self.group_pieces:
            connectivity["subgroups"] = {str(g): {"partition_events": splits(v), "pieces_max": max(v)}
                                         for g, v in sorted(self.group_pieces.items())}
        if self.mission_pieces:  # the deployed scouts' subgroups, once a second (mean, sd)
            ml = self.mission_links
            connectivity["mission"] = {
                "q_min_dbm": {str(g): q for g, q in sorted(self.q_min.items())},
                "rssi_dbm": mean_sd(self.mate_rssi),  # over every hello from a mate: the scouts' own measure
                "link_rssi_dbm": mean_sd([s["rssi_dbm"] for s in ml]),  # the mean link budget of the q_min graph
                **{k: mean_sd([s[k] for s in ml]) for k in ("hops", "relays", "lambda2")},
                "partition_events": sum(splits(v) for _, v in sorted(self.mission_pieces.items()))}

    def summary(self) -> dict[str, Any]:
        sim_s = self.hub.sim_end_ns / 1e9
        return {"deployment": self.deployment_report(),
                "comm": comm_report(self.comm, sim_s) if self.comm else None,
                "mapping": self.mapping.summary() if self.mapping is not None else None}

    def deployment_report(self) -> dict[str, Any] | None:
        """Per ranger: when it was done, its scouts' dispersion (eq. 5.11) and positions then; over all, the share
        of the arena within 1 m of a deployed scout (each where it was when its ranger was done)."""
        if not self.carriers:
            return None
        pts = [p for d in self.deployed.values() for p in d["positions"]]
        a = self.hub.cfg.arena
        return {"rangers": {str(c): self.deployed.get(c) for c in sorted(self.carriers)},
                "done": len(self.deployed), "rangers_total": len(self.carriers),
                "time_s_max": max((d["t_s"] for d in self.deployed.values()), default=None),
                "covered_share": round(covered_share(np.array(pts), a.width_m, a.length_m), 4) if pts else 0.0,
                "left_on_board": sorted(self.hub.world.carried)}
