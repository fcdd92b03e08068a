"""The UWB data radio's air: DWM1001 modules running AN-TDMA firmware with data (the DeciZebro's radio, entity role
``uwb_radio``), each sending at most one frame per TDMA slot it owns, heard by every module in range.

A module's output ``["uwb_radio", {"op": "tx", "t_ns": slot start, "kind": "beacon", "heading_cdeg"}]`` (a ranging
beacon) or ``{..., "kind": "data", "seq", "data"}`` (a broadcast payload) is one frame on the air. The medium checks
that its time is the start of a slot the sender owns (the swarm's ``frames_per_s`` slots a second, slot ``m``
belonging to team member ``m mod n``; team = the modules in robot order) and not a slot it used before: a frame off
its slots would collide with a neighbour's and is dropped, counted (``off_slot``). So the frames on the air never
exceed the budget, and the per-robot rate measured here is the Z-H1 figure (``summary.json``: ``uwb_radio``).

Every live module within ``max_range_m`` (60 m) hears the frame at the end of its slot (delivered at the first
quantum boundary after that; geometry of the quantum in which the frame was sent):

- realistic (the default): a beacon gives the receiver a range with the DW1000 error model of the UWB ranging medium
  (``bridge.media.uwb.UwbMedium.measure``: link bias, LOS noise, NLOS excess through walls, dropouts growing near the
  range limit; a lost beacon gives nothing), the sine of the angle of arrival its two antennas measure (the true sine
  plus N(0, sin ``pdoa_sigma_deg``), plus ``pdoa_nlos_sigma_deg`` through walls: the phase noise of PDoA, which spreads
  the angle as 1 / cos towards broadside, and the front-back ambiguity of two antennas), and the sender's heading as
  it sent it; a data frame is lost with the same dropout probability as a ranging exchange.
- faithful (the robot option ``sensing = "faithful"``, per receiving robot): the true range and bearing (all round)
  and every frame within range delivered, as the thesis assumes (section 3.1: communication and sensing error-free).

Faults (``bridge.media.uwb_faults``): a partition or burst loss on ``medium = "uwb"`` takes beacons and data frames
(counted per sender: ``beacons_impaired``, ``data_impaired``); a receiver's sensor fault (``sensor = "uwb"``) changes
the ranges it measures (stuck, noisy; a biased module's ranges are off whoever measures them) or, dead, leaves it
hearing no beacon. In the faithful mode too: a fault is injected on purpose.

Each link direction draws from streams of its own (``rng.stream(seed, "uwb_radio", ...)``; the range draws from the
ranging medium's per-pair stream), a fixed number per frame, so nothing else shifts another link's noise.

Recorded: ``/rNNN/uwb_radio/tx`` per frame sent (``swarm_sitl.UwbRadioTx``: kind, sequence, payload, heading, who heard
it and who lost it, and for a beacon the ranges and bearings its receivers measured).
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import TYPE_CHECKING, Any

import numpy as np

from bridge.core.entities import entity
from bridge.core.medium import Medium
from bridge.core.recorder import register_schema
from bridge.core.rng import stream
from bridge.media.impairments import UWB_RADIO_ROLE
from bridge.media.uwb import UwbMedium
from bridge.media.uwb_faults import UwbFaultCarrier, UwbFaults

if TYPE_CHECKING:
    from bridge.core.hub import Hub

ROLE = UWB_RADIO_ROLE
HEADING_UNKNOWN = 0xFFFF

register_schema("swarm_sitl.UwbRadioTx", {
    "type": "object",
    "properties": {
        "kind": {"enum": ["beacon", "data"]},
        "slot_ns": {"type": "integer", "description": "start of the slot the frame went in"},
        "seq": {"type": "integer", "description": "data: the host's sequence number"},
        "data": {"type": "string", "description": "data: the payload, hex"},
        "heading_cdeg": {"type": "integer", "description": "beacon: the sender's heading, centidegrees (65535 unset)"},
        "heard": {"type": "array", "description": "robots that received it"},
        "lost": {"type": "array", "description": "robots in range that did not"},
        "range_m": {"type": "array", "description": "beacon: the range each receiver measured (as heard)"},
        "bearing_deg": {"type": "array", "description": "beacon: the bearing each receiver measured (realistic: "
                                                        "the folded angle of arrival, asin of the measured sine)"},
    },
})


class UwbRadioAir(Medium):
    """The UWB data radios' air (a DeciZebro's ``uwb_radio``): frames checked against the TDMA slot plan, heard in
    range with the DW1000 error model and PDoA bearings, frames per robot per second (Z-H1)."""

    name = "uwb_radio"
    order = 41
    routes = {("uwb_radio", ROLE): "transmit"}  # noqa: RUF012

    @classmethod
    def wanted(cls, hub: Hub) -> bool:
        return any(ROLE in hub.roles[r] for r in range(hub.n))

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        cfg = hub.cfg.uwb
        self.cfg = cfg
        self.team = [r for r in range(hub.n) if ROLE in hub.roles[r]]
        self.slot_of = {r: i for i, r in enumerate(self.team)}
        self.errors = UwbMedium(cfg, hub.n, hub.cfg.session.seed, hub.geometry)
        # a robot model's option: the DeciZebro's ``sensing``, per receiving robot
        self.ideal = [rp.options.get("sensing") == "faithful" for rp in hub.plan.robots]
        self.seed = hub.cfg.session.seed
        self._rng: dict[tuple[str, int, int], np.random.Generator] = {}
        self.last_slot: dict[int, int] = {}
        keys = ("beacons", "data", "off_slot", "beacons_heard", "beacons_lost", "data_heard", "data_lost",
                "out_of_range", "beacons_impaired", "data_impaired")
        self.count: dict[int, dict[str, int]] = {r: dict.fromkeys(keys, 0) for r in self.team}
        self.received: dict[int, dict[str, int]] = defaultdict(lambda: {"beacons": 0, "data": 0})
        self.per_second: dict[int, dict[int, int]] = {r: {} for r in self.team}  # frames sent in each whole second
        # data frames and their payload bytes by the payload's first byte (a protocol's frame type, if it has one)
        self.first_bytes: dict[int, list[int]] = defaultdict(lambda: [0, 0])
        # the config's UWB faults (partition, burst_loss with medium = "uwb"; sensor = "uwb"), and injected ones
        self.faults = UwbFaults(self.seed, "uwb_radio")
        self.carrier = UwbFaultCarrier(hub, self.faults, self.team, "UWB data radios")

    def inject_fault(self, f: Any, t: int) -> bool:
        """A fault of the UWB air, or a radio's sensor fault, injected while the session runs."""
        return self.carrier.take(f)

    def end_fault(self, f: Any, t: int) -> bool:
        """End fault ``f`` (as injected) at ``t``, if this medium carries it."""
        return self.carrier.end(f, t)

    def _stream(self, what: str, rx: int, tx: int) -> np.random.Generator:
        key = (what, rx, tx)
        g = self._rng.get(key)
        if g is None:
            g = self._rng[key] = stream(self.seed, "uwb_radio", what, rx, tx)
        return g

    def _slot(self, r: int, t_ns: int) -> int | None:
        """The slot index a frame of ``r`` at ``t_ns`` occupies, None when ``t_ns`` is not the start of one of its
        own slots."""
        fps = self.cfg.frames_per_s
        m = t_ns * fps // 1_000_000_000
        if (m * 1_000_000_000) // fps != t_ns or m % len(self.team) != self.slot_of[r]:
            return None
        return m

    def transmit(self, e: str, r: int, t: int, item: list) -> None:
        """``["uwb_radio", {op: "tx", t_ns, kind, ...}]``: one frame in one of ``r``'s slots, to the modules in
        range."""
        hub = self.hub
        req = item[1]
        if not isinstance(req, dict) or req.get("op") != "tx" or type(req.get("t_ns")) is not int:
            raise ValueError
        kind = req.get("kind")
        if kind == "data":
            seq, data = req.get("seq"), req.get("data")
            if type(seq) is not int or not isinstance(data, bytes):
                raise ValueError
        elif kind == "beacon":
            heading = req.get("heading_cdeg")
            if type(heading) is not int:
                raise ValueError
        else:
            raise ValueError
        t_ns = req["t_ns"]
        if r not in self.slot_of:
            raise ValueError
        m, c = self._slot(r, t_ns), self.count[r]
        if m is None or m <= self.last_slot.get(r, -1):
            c["off_slot"] += 1
            return
        self.last_slot[r] = m
        c["beacons" if kind == "beacon" else "data"] += 1
        if kind == "data" and data:
            fb = self.first_bytes[data[0]]
            fb[0] += 1
            fb[1] += len(data)
        sec = self.per_second[r]
        sec[t_ns // 1_000_000_000] = sec.get(t_ns // 1_000_000_000, 0) + 1
        q = hub.q_ns
        t_rx = (m + 1) * 1_000_000_000 // self.cfg.frames_per_s  # the end of the slot
        t_deliver = max(t + q, -(-t_rx // q) * q)
        others = [i for i in self.team if i != r and i not in hub.dead]
        rec: dict[str, Any] = {"kind": kind, "slot_ns": t_ns, "heard": [], "lost": []}
        if kind == "data":
            rec.update(seq=seq, data=data.hex())
        else:
            rec.update(heading_cdeg=heading, range_m=[], bearing_deg=[])
        if others:
            world = hub.world
            pos = np.asarray(world.pos, dtype=float)
            walls = np.asarray(world.walls(r, np.array(others)), dtype=int).tolist()
            for i, w in zip(others, walls, strict=True):
                ev = self._hear(t_ns, t_rx, i, r, w, pos, float(world.yaw[i]), req, c)
                if ev is None:
                    continue
                if not ev:
                    rec["lost"].append(i)
                    continue
                rec["heard"].append(i)
                self.received[i]["beacons" if kind == "beacon" else "data"] += 1
                if kind == "beacon":
                    rec["range_m"].append(round(ev["range_m"], 4))
                    b = ev.get("bearing_rad", math.asin(max(-1.0, min(1.0, ev.get("aoa_sin", 0.0)))))
                    rec["bearing_deg"].append(round(math.degrees(b), 3))
                hub.deliver_at(t_deliver, hub.to_inbox, entity(i, ROLE), ["uwb_radio", ev])
        hub.rec.write(t, f"/r{r:03d}/uwb_radio/tx", "swarm_sitl.UwbRadioTx", rec)

    def _hear(self, t_ns: int, t_rx: int, i: int, r: int, walls: int, pos: np.ndarray, yaw_i: float,
              req: dict[str, Any], c: dict[str, int]) -> dict[str, Any] | None:
        """What module ``i`` gets of ``r``'s frame: the event, ``{}`` if lost, None if out of range."""
        cfg = self.cfg
        dx, dy = pos[r] - pos[i]
        d = float(math.hypot(dx, dy))
        if d > cfg.max_range_m:
            c["out_of_range"] += 1
            return None
        ideal = self.ideal[i]
        kind = req["kind"]
        if kind == "data":
            u = float(self._stream("data", i, r).random())
            if not ideal and u >= self.errors.p_ok(d, walls):
                c["data_lost"] += 1
                return {}
            if self.faults.any and self.faults.air(t_ns, r, i) is not None:
                c["data_impaired"] += 1
                return {}
            c["data_heard"] += 1
            return {"ev": "data", "src": r, "t_ns": t_rx, "seq": req["seq"], "data": req["data"]}
        bearing = math.remainder(math.atan2(dy, dx) - yaw_i, math.tau)  # + = left of the receiver's heading
        u, meas, rx, fp = self.errors.measure(t_ns, i, r, d, walls)
        z = float(self._stream("pdoa", i, r).standard_normal())
        if not ideal and u >= self.errors.p_ok(d, walls):
            c["beacons_lost"] += 1
            return {}
        if self.faults.any:
            if self.faults.air(t_ns, r, i) is not None:
                c["beacons_impaired"] += 1
                return {}
            if (dead := self.faults.dead(i, t_ns)) is not None:  # its ranging is dead: the beacon gives it nothing
                dead.failed += 1
                return {}
        c["beacons_heard"] += 1
        ev: dict[str, Any] = {"ev": "beacon", "src": r, "t_ns": t_rx, "heading_cdeg": req["heading_cdeg"]}
        got = self.faults.reading(i, r, d if ideal else meas, t_ns)  # a faulty module's, a biased peer's
        if ideal:
            return {**ev, "range_m": got, "rx_dbm": rx, "fp_dbm": rx, "bearing_rad": bearing}
        sigma = math.sin(math.radians(cfg.pdoa_sigma_deg + (cfg.pdoa_nlos_sigma_deg if walls else 0.0)))
        return {**ev, "range_m": got, "rx_dbm": rx, "fp_dbm": fp, "aoa_sin": math.sin(bearing) + sigma * z}

    def radio_report(self, out: dict[str, Any]) -> None:
        """Z-H1: the frames each robot put on the air per second, against the budget share (``summary.json``:
        ``radio.uwb_radio``, and ``uwb_radio`` per robot)."""
        hub = self.hub
        dur = max(1e-9, (getattr(hub, "sim_end_ns", None) or hub.k * hub.q_ns) / 1e9)
        n = len(self.team)
        rates = {r: (c["beacons"] + c["data"]) / dur for r, c in self.count.items()}
        vals = list(rates.values())
        tot = {k: sum(c[k] for c in self.count.values()) for k in next(iter(self.count.values()))}
        out["uwb_radio"] = {
            "robots": n, "frames_per_s": self.cfg.frames_per_s, "budget_per_robot_per_s": self.cfg.frames_per_s / n,
            "swarm_frames_per_s": round(sum(vals), 3),
            "frames_per_robot_per_s": {"mean": round(float(np.mean(vals)), 3), "max": round(max(vals), 3),
                                       "min": round(min(vals), 3)},
            # the most frames any robot sent within one whole second of simulated time: never above the budget share
            "max_frames_per_robot_in_a_second": max((max(s.values(), default=0) for s in self.per_second.values()),
                                                    default=0),
            **tot,
            "modes": sorted({"faithful" if self.ideal[r] else "realistic" for r in self.team}),
            # data frames sent, by their payload's first byte: [frames, payload bytes]
            "data_by_first_byte": {f"0x{b:02x}": v for b, v in sorted(self.first_bytes.items())},
        }
        if (faults := self.carrier.report()) is not None:
            out["uwb_radio"]["faults"] = faults
        for r, c in self.count.items():
            out["per_robot"].setdefault(r, {})["uwb_radio"] = {**c, "frames_per_s": round(rates[r], 3),
                                                               "received": dict(self.received[r])}
