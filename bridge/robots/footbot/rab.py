"""The foot-bot's infrared range-and-bearing link in a session: the board as a firmware entity (role ``rab``, a node of
the robot's CAN bus: ``firmware_sim.robots.footbot.rab_board``), the link's physics as a part of the robot
(``RabParams``: who sees whom, and what range and bearing each receiver measures) and the air between the boards (the
``rab`` medium).

An emission ``["rab", {"op": "tx", "data"}]`` of robot ``s`` reaches every live foot-bot ``d`` whose board is within
``range_m`` of it and whose line of sight no wall, obstacle or other robot crosses (one ray from body surface to
disc to disc at the boards' height: another robot's body, a wall or an obstacle; ARGoS checks occlusions by
embodied entities), unless lost (``loss``); the
receiver measures range and bearing with Gaussian errors (``range_noise_rel`` of the range, ``bearing_noise_deg``).
It is delivered at the next quantum boundary as ``["rab", {"src", "range_m", "bearing_rad", "data"}]``. The
figures and their sources are in ``docs/footbot.md``. Each receiving robot draws its errors from its own stream, a
fixed number per emission in range and in sight, in the order of the senders' ids.

Recorded: ``/rNNN/rab/tx`` per emission (``swarm_sitl.RabTx``: payload, who heard it, who was in range but
occluded or lost it). ``summary.json``: ``radio.rab`` (totals) and ``rab`` per robot.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from bridge.core.entities import entity
from bridge.core.medium import Medium
from bridge.core.parts import Part, WorldModel
from bridge.core.recorder import register_schema
from bridge.core.rng import stream
from firmware_sim.robots.footbot.rab_board import RabBoard

if TYPE_CHECKING:
    from bridge.core.hub import Hub

ROLE = "rab"

register_schema("swarm_sitl.RabTx", {
    "type": "object",
    "properties": {
        "data": {"type": "string", "description": "the payload, hex"},
        "heard": {"type": "array", "description": "robots that received it"},
        "range_m": {"type": "array", "description": "the range each of them measured (as heard)"},
        "bearing_deg": {"type": "array", "description": "the bearing each of them measured (+ = left)"},
        "occluded": {"type": "array", "description": "robots in range whose line of sight was blocked"},
        "lost": {"type": "array", "description": "robots in range and sight that lost it"},
    },
})


class RabParams(Part):
    """The range-and-bearing link's figures (``docs/footbot.md``)."""

    range_m: float = 3.0
    period_ms: int = 100
    max_payload: int = 10
    range_noise_rel: float = 0.0
    bearing_noise_deg: float = 0.0
    loss: float = 0.0
    occlusion: bool = True
    height_m: float = 0.10  # the emitters' and receivers' height (ARGoS's RAB_ELEVATION): bodies occlude


class RabLinks(WorldModel):
    """Who sees whom on the range-and-bearing link, and what each receiver measures."""

    name = "range_and_bearing"

    def __init__(self, world: Any, robots: list[int], parts: list[RabParams]) -> None:
        super().__init__(world, robots, parts)
        self._rng = {r: stream(world.seed, "rab", r) for r in robots}
        self._radius = {r: world.profiles[r].radius_m for r in robots}
        self._z = {r: q.height_m for r, q in zip(robots, parts, strict=True)}
        z = min(q.height_m for q in parts) if parts else 0.0
        # the bodies that can block the link: every robot taller than the boards (ARGoS: lower objects do not)
        self._blockers = np.array([r for r in range(world.n) if world.profiles[r].height_m > z], dtype=int)
        self._blocker_radius = np.array([world.profiles[r].radius_m for r in self._blockers])
        self._interior = len(world.static_rects) > 4 or bool(world.cylinders)  # obstacles besides the arena walls

    def receivers(self, src: int) -> tuple[list[tuple[int, float, float]], list[int], list[int]]:
        """Who hears ``src``'s emission now: [(robot, measured range m, measured bearing rad)], and the robots in
        range that were occluded, and those that lost it."""
        w = self.world
        q = self.parts[self.local[src]]
        others = [d for d in self.robots if d != src and w.alive[d]]
        if not others:
            return [], [], []
        dst = np.array(others)
        dx, dy = w.pos[src, 0] - w.pos[dst, 0], w.pos[src, 1] - w.pos[dst, 1]  # from each receiver to the sender
        dist = np.hypot(dx, dy)
        near = np.flatnonzero(dist <= q.range_m)
        if not len(near):
            return [], [], []
        blocked = self._occluded(src, dst[near], dist[near]) if q.occlusion else np.zeros(len(near), bool)
        heard, occluded, lost = [], [], []
        for j, k in enumerate(near.tolist()):
            d = int(dst[k])
            if blocked[j]:
                occluded.append(d)
                continue
            g = self._rng[d]
            u, zr, zb = g.random(), g.standard_normal(), g.standard_normal()  # a fixed number of draws per emission
            if u < q.loss:
                lost.append(d)
                continue
            r_true = float(dist[k])
            rng = max(0.0, r_true * (1.0 + q.range_noise_rel * zr))
            b = math.atan2(float(dy[k]), float(dx[k])) - float(w.yaw[d]) + math.radians(q.bearing_noise_deg) * zb
            heard.append((d, rng, math.remainder(b, math.tau)))
        return heard, occluded, lost

    def _occluded(self, src: int, dst: np.ndarray, dist: np.ndarray) -> np.ndarray:
        """Whether anything blocks the line of sight from ``src`` to each of ``dst`` at the boards' height: another
        robot taller than that whose body (a disc of its radius) the segment crosses, or a wall or obstacle inside
        the arena (the world's static ray test: the arena's own walls cannot stand between two robots in it)."""
        w = self.world
        others = self._blockers
        p = w.pos[:, :2]
        s = p[src]
        seg = p[dst] - s  # (m, 2)
        rel = p[others] - s  # (k, 2)
        ll = np.maximum(dist * dist, 1e-18)
        dot = seg @ rel.T  # (m, k)
        cross = seg[:, 0:1] * rel[None, :, 1] - seg[:, 1:2] * rel[None, :, 0]
        rad = self._blocker_radius[None, :]
        blocked = (dot > 0) & (dot < ll[:, None]) & (cross * cross < rad * rad * ll[:, None])
        blocked &= (others[None, :] != src) & (others[None, :] != dst[:, None]) & w.alive[others][None, :]
        out = blocked.any(axis=1)
        if self._interior:
            out |= np.asarray(w.walls(src, dst), dtype=int) > 0
        return out


RabParams.world_model = RabLinks


class RabEntity:
    """The range-and-bearing board as the firmware host runs it: CAN frames and the air's deliveries in, its report
    frames and its emissions out, at its update period."""

    def __init__(self, rp: Any, cfg: Any, q: RabParams) -> None:
        phase = int(stream(cfg.session.seed, "rab", "phase", rp.id).integers(q.period_ms))  # the boards run unsynced
        self.board = RabBoard(period_ms=q.period_ms, phase_ms=phase, max_payload=q.max_payload)
        self.counters = self.board.counters

    def run(self, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        can_rx: list[tuple[int, bytes]] = []
        air: list[dict[str, Any]] = []
        for item in inputs["in"]:
            if item[0] == "can0" and len(item) == 5:
                can_rx.append((item[1], item[2]))
            elif item[0] == ROLE:
                air.append(item[1])
        res = self.board.step(t_ns, can_rx, air)
        out: list[list] = [["can0", arb_id, data, False] for arb_id, data in res.can]
        out += [[ROLE, a] for a in res.air]
        return {"out": out, "wake": self.board.next_wake(), "wom": False}


class RabAir(Medium):
    """The foot-bots' range-and-bearing air: each emission to the boards that see it, as they measure it."""

    name = "rab"
    order = 42
    routes = {(ROLE, ROLE): "transmit"}  # noqa: RUF012

    @classmethod
    def wanted(cls, hub: Hub) -> bool:
        return any(ROLE in hub.roles[r] for r in range(hub.n))

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        self.team = [r for r in range(hub.n) if ROLE in hub.roles[r]]
        self.pending: list[tuple[int, bytes]] = []
        keys = ("emitted", "heard_by", "occluded", "lost", "received", "payload_bytes")
        self.count: dict[int, dict[str, int]] = {r: dict.fromkeys(keys, 0) for r in self.team}

    def transmit(self, e: str, r: int, t: int, item: list) -> None:
        """``["rab", {"op": "tx", "data": bytes}]``: an emission, resolved at the end of the quantum."""
        req = item[1]
        if not isinstance(req, dict) or req.get("op") != "tx" or not isinstance(req.get("data"), bytes):
            raise ValueError
        if r not in self.count or len(req["data"]) > 255:
            raise ValueError
        self.pending.append((r, req["data"]))

    def end_outputs(self, t: int) -> None:
        if not self.pending:
            return
        hub = self.hub
        links = hub.world.model("range_and_bearing")
        t_deliver = t + hub.q_ns
        for src, data in sorted(self.pending, key=lambda p: p[0]):
            if src in hub.dead:
                continue
            heard, occluded, lost = links.receivers(src)
            c = self.count[src]
            c["emitted"] += 1
            c["payload_bytes"] += len(data)
            c["heard_by"] += len(heard)
            c["occluded"] += len(occluded)
            c["lost"] += len(lost)
            for d, rng, b in heard:
                if d in hub.dead:
                    continue
                self.count[d]["received"] += 1
                hub.deliver_at(t_deliver, hub.to_inbox, entity(d, ROLE),
                               [ROLE, {"src": src, "range_m": rng, "bearing_rad": b, "data": data}])
            hub.rec.write(t, f"/r{src:03d}/rab/tx", "swarm_sitl.RabTx", {
                "data": data.hex(), "heard": [h[0] for h in heard], "range_m": [round(h[1], 4) for h in heard],
                "bearing_deg": [round(math.degrees(h[2]), 2) for h in heard], "occluded": occluded, "lost": lost})
        self.pending.clear()

    def radio_report(self, out: dict[str, Any]) -> None:
        """Emissions, receptions, occlusions and losses (``summary.json``: ``radio.rab``, ``rab`` per robot)."""
        if not self.count:
            return
        tot = {k: sum(c[k] for c in self.count.values()) for k in next(iter(self.count.values()))}
        out["rab"] = {"robots": len(self.team), **tot}
        for r, c in self.count.items():
            out["per_robot"].setdefault(r, {})["rab"] = dict(c)
