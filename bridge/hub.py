"""The world process: clock authority, message router, physics and recorder of a session.

One quantum k (time t = k * q) flows like this:

1. deliver what is due at t: CAN frames that finished on a bus, LLC pin writes of quantum k-1; record
   each (sim-time order, canonical order within a time);
2. find the entities due at t: their wake time has come, or a message arrived and they wait on messages;
3. send each process hosting a due entity one ``tick`` with the entities' inputs (LLC: the physical
   sensor values at t and the frames delivered to it; logic: the frames delivered to it);
4. step physics from t to t+q while the processes compute;
5. wait for every ticked process's ``done`` (a process that dies, hangs or raises becomes a failed
   robot, handled by the failure policy);
6. offer the outputs to the media: frames go on the robot's CAN bus and arrive at k+1 or later, pin
   writes take effect at k+1.

Nothing produced in quantum k is seen before k+1, and every delivery is ordered by time, bus and wire
order, so the recording does not depend on process packing, speed or machine load.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import queue
import signal
import statistics
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from bridge import transport
from bridge.can_medium import (
    CAN_ERR_BUSOFF,
    CAN_ERR_CRTL,
    CAN_ERR_PROT,
    CAN_ERR_RESTARTED,
    OWN,
    CanMedium,
    error_frame,
    frame_fault,
)
from bridge.comm_stats import comm_report
from bridge.config import Config
from bridge.deployment import covered_share, dispersion, link_stats, mean_sd
from bridge.plan import Plan, entity, robot_of, uwb_addr16
from bridge.profiles import PROFILES
from bridge.radio_medium import RadioMedium
from bridge.recorder import Recorder
from bridge.rng import stream_seed
from bridge.uart import SerialLine, garble
from bridge.uwb_medium import UwbMedium
from bridge.world import World
from firmware_sim.xbee import valid_air_frame
from swarm_logic.interfaces import eswarbot_llc_db
from swarm_logic.rdpso import graph

LOGIC_BOOT_SPREAD_NS = 100_000_000  # companion computers start their programs within 100 ms of each other
CONNECTIVITY_EVERY_NS = 1_000_000_000  # how often the radio graph's algebraic connectivity is sampled


class Hub:
    def __init__(self, plan: Plan, session_dir: str, out_dir: str, namespace: str) -> None:
        self.plan = plan
        self.cfg = cfg = Config.model_validate(plan.config)
        self.q_ns = cfg.session.quantum_ns
        self.end_ns = -(-round(cfg.session.duration_s * 1e9) // self.q_ns) * self.q_ns
        self.out = Path(out_dir)
        self.endpoint = transport.endpoint_for(session_dir)
        self.namespace = namespace
        self.world = World(cfg, plan.robots)
        self.rec = Recorder(self.out / "session.mcap", {"config": json.dumps(plan.config, sort_keys=True),
                                                        "robots": str(len(plan.robots))})
        self.n = len(plan.robots)
        self.procs = {p.name: p for p in plan.procs}
        self.proc_of: dict[str, str] = {}
        for p in plan.procs:
            for e in p.entities(plan.robots):
                self.proc_of[e] = p.name
        self.ents = sorted(self.proc_of)
        self.next_wake: dict[str, int | None] = dict.fromkeys(self.ents, 0)
        for r, rp in enumerate(plan.robots):
            # Robots power up one quantum apart (cyclically), as real ones never boot in the same 10 ms; this
            # spreads LLC loops and controller steps evenly over quanta instead of waking everyone at once.
            period = round(1e9 / PROFILES[rp.profile].llc_loop_hz)
            boot = (r * self.q_ns) % max(period, self.q_ns) // self.q_ns * self.q_ns
            for role in rp.modules():
                self.next_wake[entity(r, role)] = boot
            if rp.has_logic:
                self.next_wake[entity(r, "logic")] = (r * self.q_ns) % max(LOGIC_BOOT_SPREAD_NS, self.q_ns)
        # wake on message: False, True (any input), or the input kinds that wake it (item[0] of inbox items)
        self.wom: dict[str, Any] = dict.fromkeys(self.ents, False)
        self.inbox: dict[str, list] = {e: [] for e in self.ents}
        self.seq: dict[str, int] = dict.fromkeys(self.ents, 0)
        self.can = [self._can_bus(r, rp) for r, rp in enumerate(plan.robots)]
        self.can_echo: set[str] = set()  # nodes whose own frames come back to them (receive_own_messages)
        self.can_events: list[dict[str, Any]] = []  # bus-off and recovery of every node, for the summary
        self.can_noticed: dict[str, tuple[int | None, int]] = {}  # node -> (last notice, events not told since)
        self.deliveries: dict[int, list[tuple]] = defaultdict(list)
        self._dead_detail: dict[str, str] = {}
        self.dead: set[int] = set()
        self.live_procs: set[str] = set(self.procs)
        self.unjoined: set[str] = set()  # processes that had not joined when start-up failed
        self.pids: dict[str, int] = {}
        self.failures: list[dict[str, Any]] = []
        self.stop_reason: str | None = None
        self.abort = False  # the launcher is gone: participants are gone too, do not wait for them
        self.failed_stop = False
        self.parent_pid = os.getppid()
        self.counts: dict[str, int] = defaultdict(int)
        self.barrier_us: list[float] = []
        self.lag_s: list[float] = []  # paced sessions: how far the simulated clock is behind wall time, per quantum
        self.wakeups: dict[str, int] = defaultdict(int)  # entity runs by role (llc, xbee, uwb, logic)
        self.ticks = 0
        self.proc_ticks = 0  # tick messages sent (one per due process per quantum)
        self.k = 0
        self.q: queue.SimpleQueue = queue.SimpleQueue()
        self.status_pub: Any = None
        self._names = {m.frame_id: m.name for m in eswarbot_llc_db().messages}
        self._topics = {r: (f"/r{r:03d}/can0", f"/r{r:03d}/llc/pins")
                        for r in range(self.n)}
        # radios: the 2.4 GHz medium of the XBees, the UWB ranging medium, and each robot's serial lines
        robots = plan.robots
        geometry = _Geometry(self.world)
        # every entity of a robot: its firmware's, and its logic when the session runs it
        self.roles = {r: rp.modules() + (("logic",) if rp.has_logic else ()) for r, rp in enumerate(robots)}
        self.radio = RadioMedium(cfg.radio, self.n, cfg.session.seed, geometry) if any(
            rp.sim_xbee for rp in robots) else None
        self.uwb = UwbMedium(cfg.uwb, self.n, cfg.session.seed, geometry) if any(rp.uwb for rp in robots) else None
        self.uwb_robot = {uwb_addr16(r): r for r, rp in enumerate(robots) if rp.uwb}
        self.lines: dict[tuple[int, str], SerialLine] = {}  # host -> module, paced at the host's baud
        self.host_baud: dict[tuple[int, str], int] = {}  # what the host's port is set to (last write)
        for r, rp in enumerate(robots):
            if rp.sim_xbee and not rp.xbee.get("pty") and rp.has_logic:
                self.lines[(r, "xbee")] = SerialLine(rp.xbee["baud"])
                self.host_baud[(r, "xbee")] = rp.xbee["baud"]
            if rp.uwb:
                self.lines[(r, "uwb")] = SerialLine(cfg.uwb.uart_baud)
                self.host_baud[(r, "uwb")] = cfg.uwb.uart_baud
        # the swarm's radio network, whose connectivity is sampled: the robots' XBees (not a gateway's)
        self.swarm_radios = [r for r, rp in enumerate(robots) if rp.sim_xbee and rp.gateway is None]
        self.releases: list[dict[str, Any]] = []
        self.deployed: dict[int, dict[str, Any]] = {}  # ranger -> its deployment as it ended (deployment_report)
        self.comm: dict[int, dict[str, Any]] = {}  # robot -> its RDPSO routing layer's latest counters (comm_report)
        self.rssi_pwm = [0.0] * self.n
        self.ideal_pose = {r for r, rp in enumerate(robots) if rp.pose_source == "ground_truth"}
        self.uwb_log_err: dict[int, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
        self.connectivity: list[tuple[float, float]] = []  # (t s, lambda2)
        # partitions: how many pieces the live swarm's radio graph is in, and each ranger's subgroup's (by sample)
        self.pieces: list[int] = []
        self.group_of = {rp.id: rp.carrier for rp in robots if rp.carrier is not None}  # scout -> its ranger
        self.carriers = set(self.group_of.values())  # robots with scouts on board
        self.group_pieces: dict[int, list[int]] = defaultdict(list)
        # each deployed subgroup's radio graph after its START, per sample (Table 5.2; link_stats)
        self.mission_links: list[dict[str, Any]] = []
        self.q_min = {rp.carrier: float(rp.params["q_min_dbm"]) for rp in robots if rp.carrier is not None
                      and rp.params.get("link_mode") == "rssi" and "q_min_dbm" in rp.params}  # ranger -> its scouts'
        # battery deaths to come: (time, robot)
        self.battery_deaths = sorted((round(f.at_s * 1e9), f.robot) for f in cfg.faults if f.kind == "battery_depleted")
        self.module_stats: dict[str, dict] = {}
        self.addr_robot: dict[tuple[str, int], int] = {}  # ("64" | "16", address) -> robot, from the modules
        self.tx_dst: dict[tuple[int, int], tuple] = {}  # (robot, frame handle) -> (addressed robot, MAC seq)
        self.node_sens: dict[int, float] = {}  # each module's receiver sensitivity, as it reported it
        self.node_net: dict[int, tuple[int, int]] = {}  # each module's (channel, PAN id)
        m = cfg.mavlink
        self.mavlink = None
        if m.endpoint:  # pymavlink only for a session that has an endpoint
            from bridge.mavlink_gateway import MavlinkGateway

            self.mavlink = MavlinkGateway(m.endpoint, {r: m.system_id_base + r for r, rp in enumerate(robots)
                                                       if rp.has_logic and rp.vehicle is None}, m.per_robot)

    def _can_bus(self, r: int, rp: Any) -> CanMedium:
        """Robot ``r``'s CAN bus: its nodes (the LLC's MCP2515 recovers from bus-off by itself; the companion
        computer's adapter restarts after ``can.host_restart_ms``), and the faults injected into it."""
        cfg = self.cfg
        bus = CanMedium(f"r{r:03d}/can0", cfg.can.bitrate, seed=stream_seed(cfg.session.seed, "can", r))
        host_ms = cfg.can.host_restart_ms
        host_restart = None if host_ms is None else round(host_ms * 1e6)
        for role in rp.can_nodes():
            bus.add_node(entity(r, role), host_restart if role == "logic" else 0)
        for f in cfg.faults:
            if f.robot != r or f.kind in ("firmware_crash", "battery_depleted"):
                continue
            start = round(f.at_s * 1e9)
            end = None if f.duration_s is None else start + round(f.duration_s * 1e9)
            if f.kind == "can_bus_off":
                bus.inject(entity(r, rp.host_node if f.node == "host" else f.node), "tx_error", start, end)
            else:
                bus.inject("*", "noise", start, end, f.probability)
        return bus

    # -- lifecycle ---------------------------------------------------------------------------------
    def open(self) -> None:
        listen = self.cfg.session.listen  # remote logic joins there (swarm-sitl join), besides the unix socket
        self.session = transport.open_session(self.endpoint, self.namespace, listen=True,
                                              extra_listen=[listen] if listen else None)
        s = self.session
        self._subs = [
            transport.queue_subscriber(s, "done/*", self.q),
            transport.queue_subscriber(s, "hello/*", self.q),
            transport.queue_subscriber(s, "control", self.q),
        ]
        self.status_pub = transport.publisher(s, "status")
        self.tick_pub = {p: transport.publisher(s, f"tick/{p}") for p in self.procs}
        # the remote procs that may still join (None: started); the plan's answer tells a joiner, who refuses to
        # join twice or late
        self.joinable: frozenset[str] | None = frozenset(p for p, pp in self.procs.items() if pp.remote)
        if listen:
            from bridge.join import plan_offer

            def offer(query: Any) -> None:  # a zenoh thread: reads the plan and a frozenset (or None)
                query.reply(transport.PLAN_KEY, plan_offer(self.plan, self.joinable))

            self._subs.append(s.declare_queryable(transport.PLAN_KEY, offer))
            self._world_token = s.liveliness().declare_token(transport.WORLD_KEY)  # a joiner sees the world go

    def status(self, **msg: Any) -> None:
        """Tell the launcher (nothing to tell before ``open``, e.g. a hub driven directly by tests)."""
        if self.status_pub is not None:
            self.status_pub.put(transport.pack(msg))

    def wait_for_participants(self) -> None:
        t0 = time.monotonic()
        timeout = self.cfg.session.startup_timeout_s
        remote = {p for p, pp in self.procs.items() if pp.remote}  # they join from other computers, maybe later
        self.status(op="listening", listen=self.cfg.session.listen, remote=sorted(remote))
        missing = set(self.procs)
        try:
            while missing:
                left = timeout - (time.monotonic() - t0)
                if left <= 0:
                    hint = (" (remote logic: run the swarm-sitl join command the launcher printed on the other "
                            "computer, or raise session.startup_timeout_s)" if missing & remote else "")
                    raise TimeoutError(f"processes did not join within {timeout:.0f} s: {', '.join(sorted(missing))}"
                                       + hint)
                if self.abort or os.getppid() != self.parent_pid:
                    raise KeyboardInterrupt
                try:
                    key, data = self.q.get(timeout=min(left, 0.2))
                except queue.Empty:
                    continue
                msg = _unpack_dict(data)
                if msg is None:
                    self.counts["malformed_control"] += 1
                    continue
                if key.startswith("hello/"):
                    p = key.split("/", 1)[1]
                    if p in missing and isinstance(msg.get("pid"), int):
                        if p in remote:  # its pid is on another computer: never ours to kill
                            self.joinable = frozenset((missing & remote) - {p})
                            self.status(op="notice", joined=p, text=f"robot {self.procs[p].robots[0]}'s logic joined "
                                                                    f"from another computer ({p})")
                        else:
                            self.pids[p] = msg["pid"]
                        transport.wait_matched(self.tick_pub[p], timeout, f"tick/{p}")
                        missing.discard(p)
                elif key == "control":
                    if msg.get("op") == "dead" and msg.get("proc") in remote:  # a joiner left: it may join again
                        p = msg["proc"]
                        missing.add(p)
                        self.joinable = frozenset(missing & remote)
                        self.status(op="notice", left=p, text=f"{p} left before the start ({msg.get('detail')}); "
                                                              "waiting for it again")
                    elif msg.get("op") == "dead":
                        raise RuntimeError(f"process {msg.get('proc')} exited during start-up ({msg.get('detail')})")
                    if msg.get("op") == "stop":
                        raise KeyboardInterrupt
        except BaseException:
            self.live_procs -= missing & remote  # they never joined: nobody to say stop to
            self.unjoined = set(missing)  # nor a goodbye to wait for (the launcher ends them)
            raise
        self.startup_wall_s = time.monotonic() - t0
        self.joinable = None  # started: a late joiner is refused
        self.status(op="started", startup_s=self.startup_wall_s,
                    mavlink=self.mavlink.endpoints if self.mavlink is not None else None)

    # -- failures ------------------------------------------------------------------------------------
    def robot_failed(self, r: int, t_ns: int, kind: str, detail: str, proc: str | None = None) -> None:
        if r in self.dead:
            return
        self.dead.add(r)
        self.world.kill(r)
        for role in self.roles[r]:
            e = entity(r, role)
            self.next_wake[e] = None
            self.wom[e] = False
            self.inbox[e].clear()
        rec = {"robot": r, "t_s": t_ns / 1e9, "kind": kind, "detail": detail[-2000:]}
        self.rec.write(t_ns, "/session/events", "swarm_sitl.Event", {"kind": kind, "robot": r, "detail": rec["detail"]})
        if proc:  # which process is a packing detail: reported, not recorded
            rec["process"] = proc
        self.failures.append(rec)
        self.status(op="event", **rec)
        if self.cfg.session.on_robot_failure == "stop":
            self.failed_stop = True
            self.stop_reason = f"robot {r} failed ({kind}) and on_robot_failure = stop"

    def proc_failed(self, proc: str, t_ns: int, kind: str, detail: str) -> None:
        if proc not in self.live_procs:
            return
        self.live_procs.discard(proc)
        pid = self.pids.get(proc)
        if pid and kind == "hung":
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        for r in self.procs[proc].robots:
            self.robot_failed(r, t_ns, kind, detail, proc)

    # -- one quantum ---------------------------------------------------------------------------------
    def _deliver(self, t: int) -> None:
        items = self.deliveries.pop(t, None)
        if not items:
            return
        rec, world = self.rec, self.world
        for item in items:
            kind = item[0]
            if kind == "can":
                _, r, d = item
                topic = self._topics[r][0]
                rec.write_json(t, topic, "swarm_sitl.CanFrame", (
                    f'{{"id":{d.arbitration_id},"data":"{d.data.hex()}","src":"{d.src}",'
                    f'"name":"{self._names.get(d.arbitration_id, "")}","wire_end_ns":{d.wire_end_ns}}}').encode())
                self.counts["can_frames"] += 1
                if r in self.dead:
                    continue
                for node in d.receivers:
                    self.inbox[node].append(["can0", d.arbitration_id, d.data, d.extended, d.wire_end_ns])
                if d.src in self.can_echo:
                    self.inbox[d.src].append(["can0", d.arbitration_id, d.data, d.extended, d.wire_end_ns, OWN])
            elif kind == "can_event":
                _, r, ev = item
                self._can_event(t, r, ev)
            elif kind == "ent":  # radio events, UART bytes: to one entity's inbox
                _, e, msg = item
                if robot_of(e) not in self.dead:
                    self.inbox[e].append(msg)
            elif kind == "rec":
                _, topic, schema, payload = item
                rec.write(t, topic, schema, payload)
            else:  # pin writes of the LLC's previous loop
                _, r, pins = item
                self.counts["pin_writes"] += 1
                if r in self.dead:
                    continue
                world.set_pwm(r, *pins["pwm"])
                world.set_led(r, tuple(pins["led"]))
                if "belt_steps" in pins:
                    world.set_belt(r, pins["belt_steps"])

    def _can_event(self, t: int, r: int, ev: Any) -> None:
        """An error frame or a node's change of fault-confinement state on robot ``r``'s bus: to the recording, to
        the node (its controller's error register; socketcan-style error frames for a logic's python-can bus), and
        a bus-off or recovery to the launcher and the summary."""
        node = ev.node
        if ev.kind == "error_frame":
            name = self._names.get(ev.arbitration_id, "")
            self.rec.write_json(t, self._topics[r][0], "swarm_sitl.CanFrame", (
                f'{{"id":{ev.arbitration_id},"data":"","src":"{node}","name":"{name}",'
                f'"wire_end_ns":{ev.wire_ns},"error":true}}').encode())
            self.counts["can_error_frames"] += 1
            logic = entity(r, "logic")  # the only node that shows error frames to its program (python-can)
            if r not in self.dead and "logic" in self.roles[r]:
                state, tec, rec = self.can[r].node_state(logic)
                if state != "bus_off":
                    self.inbox[logic].append(error_frame(CAN_ERR_PROT, 0, tec, rec, ev.wire_ns))
            return
        self.rec.write(t, f"/r{r:03d}/can0/state", "swarm_sitl.CanState",
                       {"node": node, "state": ev.state, "tec": ev.tec, "rec": ev.rec, "wire_ns": ev.wire_ns})
        if r in self.dead:
            return
        self.inbox[node].append(["can0_state", ev.state, ev.tec, ev.rec])
        if node.endswith("/logic"):  # socketcan reports its own controller's state changes as error frames
            klass, ctrl = {"bus_off": (CAN_ERR_BUSOFF, 0), "passive": (CAN_ERR_CRTL, 0x30),
                           "active": (CAN_ERR_RESTARTED if ev.arbitration_id is None else CAN_ERR_CRTL, 0x40)}[ev.state]
            self.inbox[node].append(error_frame(klass, ctrl, ev.tec, ev.rec, ev.wire_ns))
        if ev.state == "bus_off" or (ev.state == "active" and ev.arbitration_id is None):
            what = "bus-off" if ev.state == "bus_off" else "recovered from bus-off"
            rec = {"robot": r, "t_s": round(ev.wire_ns / 1e9, 6), "node": node[node.index("/") + 1:],
                   "event": "bus_off" if ev.state == "bus_off" else "recovered", "tec": ev.tec}
            self.can_events.append(rec)
            if ev.state == "bus_off":
                self.rec.write(t, "/session/events", "swarm_sitl.Event",
                               {"kind": "can_bus_off", "robot": r, "detail": f"CAN node {node} is bus-off"})
            # a node that keeps failing goes bus-off every restart: tell the user at once, then every 10 s at most
            last, quiet = self.can_noticed.get(node, (None, 0))
            if last is None or ev.wire_ns - last >= 10_000_000_000:
                more = f"; {quiet} more bus-off/recovery events since the last notice" if quiet else ""
                self.status(op="notice", text=f"robot {r}: CAN node {rec['node']} {what} at sim t={rec['t_s']:.3f} s "
                                              f"(TEC {ev.tec}){more}")
                self.can_noticed[node] = (ev.wire_ns, 0)
            else:
                self.can_noticed[node] = (last, quiet + 1)

    def _lines(self, t: int) -> None:
        """Bytes that finished crossing a host-to-module serial line by ``t`` go to the module."""
        for (r, dev), line in self.lines.items():
            if line.pending and r not in self.dead:
                data = line.arrived(t)
                if data:
                    self.inbox[entity(r, dev)].append(["uart", data])

    def _ground_station(self, t: int) -> None:
        """What ground stations sent since the last quantum: to the robots' faces now, and to the recording (it
        comes from outside the session, in wall time)."""
        for r, data, kind in self.mavlink.poll():
            if r in self.dead:
                continue
            self.inbox[entity(r, "logic")].append(["uart:mavlink", data])
            self.rec.write(t, "/mavlink/from_gcs", "swarm_sitl.MavlinkIn",
                           {"robot": r, "type": kind, "data": data.hex()})

    def _due(self, t: int) -> dict[str, list[str]]:
        due: dict[str, list[str]] = defaultdict(list)
        nw, wom, inbox, proc_of = self.next_wake, self.wom, self.inbox, self.proc_of
        for e in self.ents:
            w = nw[e]
            if (w is not None and w <= t) or (wom[e] and inbox[e] and (
                    wom[e] is True or any(item[0] in wom[e] for item in inbox[e]))):
                due[proc_of[e]].append(e)
        return due

    def _collect(self, waiting: set[str], t: int) -> dict[str, dict]:
        """Wait for every ticked process's answer. Deaths reported meanwhile take effect after the
        outputs of this quantum are routed, so a late notice never discards answers already in."""
        results: dict[str, dict] = {}
        hang = self.cfg.session.hang_timeout_s
        deadline = time.monotonic() + hang
        while waiting:
            if self.abort or os.getppid() != self.parent_pid:
                self.abort = True
                break
            left = deadline - time.monotonic()
            if left <= 0:
                for p in sorted(waiting):
                    self.proc_failed(p, t, "hung", f"no answer for the quantum at t={t / 1e9:.3f} s within {hang} s")
                break
            try:
                key, data = self.q.get(timeout=min(0.2, left))
            except queue.Empty:
                continue
            if key.startswith("done/"):
                p = key[5:]
                if p not in waiting:
                    continue
                msg = _unpack_dict(data)
                if msg is None or not isinstance(msg.get("ents"), dict):
                    self.counts["malformed_done"] += 1
                    continue
                if msg.get("k") != self.k:
                    self.counts["stale_done"] += 1
                    continue
                results[p] = msg
                waiting.discard(p)
            elif key == "control":
                dead = self._control(data, t)
                if dead in waiting:
                    waiting.discard(dead)
                    self.proc_failed(dead, t, "died", self._dead_detail.pop(dead, ""))
        return results

    def _control(self, data: bytes, t: int) -> str | None:
        """Handle a launcher message; a death is queued (applied at the end of the quantum) and returned."""
        msg = _unpack_dict(data)
        if msg is None:
            self.counts["malformed_control"] += 1
            return None
        op = msg.get("op")
        if op == "stop":
            self.stop_reason = self.stop_reason or str(msg.get("reason", "stop requested"))
        elif op == "dead":
            p = msg.get("proc")
            if p in self.live_procs:
                self._dead_detail[str(p)] = str(msg.get("detail", ""))
                return str(p)
            # already handled (e.g. the world killed it as hung, then the launcher saw it exit)
        else:
            self.counts["malformed_control"] += 1
        return None

    def _apply_deaths(self, t: int) -> None:
        for p in sorted(self._dead_detail):
            self.proc_failed(p, t, "died", self._dead_detail.pop(p))

    def _outputs(self, t: int, results: dict[str, dict], sensed: dict[str, dict],
                 due: dict[str, list[str]]) -> None:
        q = self.q_ns
        merged: dict[str, dict] = {}
        for p, res in results.items():
            for e, v in res["ents"].items():
                if e in due[p] and isinstance(v, dict):
                    merged[e] = v
                else:
                    self.counts["malformed_done"] += 1
        touched: set[int] = set()
        for e in sorted(merged):
            r = robot_of(e)
            if r in self.dead:
                continue
            res = merged[e]
            if not _valid_reply(res):
                self.counts["malformed_done"] += 1
                self.robot_failed(r, t, "malformed", f"unusable reply from {e}: {str(res)[:300]}")
                continue
            pins = res.get("pins")
            pins_ok = pins is None or _valid_pins(pins)
            if e in sensed:  # one record per LLC loop: what its pins read, and what it wrote
                pins_io = dict(sensed[e])
                if pins is not None and pins_ok:
                    pins_io.update(pins)
                self.rec.write(t, self._topics[r][1], "swarm_sitl.LlcPins", pins_io)
            if res.get("err"):
                self.robot_failed(r, t, "raised", res["err"])
                continue
            w = res.get("wake")
            self.next_wake[e] = None if w is None else max(t + q, -(-w // q) * q)
            wm = res.get("wom")
            self.wom[e] = wm if isinstance(wm, list) and all(isinstance(x, str) for x in wm) else bool(wm)
            for item in res.get("out", ()):
                if not (isinstance(item, list | tuple) and item):
                    self.counts["malformed_items"] += 1
                elif item[0] == "can0":
                    if not _valid_can(item):
                        self.counts["malformed_frames"] += 1
                        continue
                    self.seq[e] += 1
                    if len(item) == 5:  # validated: it asks for its echo
                        self.can_echo.add(e)
                    if self.can[r].offer(e, self.seq[e], item[1], item[2], item[3]):
                        touched.add(r)
                    else:  # the node is bus-off: its controller cannot send
                        self.counts["can_dropped_bus_off"] += 1
                else:
                    self._route(e, r, t, item)
            if pins is not None:
                if pins_ok:
                    self.deliveries[t + q].append(("pins", r, pins))
                else:
                    self.counts["malformed_pins"] += 1
        for r in range(self.n):
            bus = self.can[r]
            if r in touched or bus.busy(t, q):
                for d in bus.transmit(t, q):
                    self.deliveries[d.t_ns].append(("can", r, d))
                for ev in bus.drain_events():
                    self.deliveries[ev.t_ns].append(("can_event", r, ev))

    def _media(self, t: int) -> None:
        """Let the radio resolve the air up to the earliest time a new frame could start (t+2q: this quantum's
        submissions start at t+q or later), and sample the radio graph's connectivity."""
        q = self.q_ns
        if self.radio is None:
            return
        for t_ev, r, ev in self.radio.advance(t + 2 * q):
            self._radio_event(t_ev, r, ev)
        if t % CONNECTIVITY_EVERY_NS < q and all(r in self.node_net for r in self.swarm_radios
                                                 if r not in self.dead):
            lam = self.algebraic_connectivity()
            self.connectivity.append((t / 1e9, lam))
            self._partitions()
            self.rec.write(t, "/radio/connectivity", "swarm_sitl.Connectivity", {"lambda2": round(lam, 6)})

    def radio_graph(self) -> tuple[list[int], np.ndarray]:
        """The live robots' radio graph: a link where the mean link budget (no fast fading) clears the receiver's
        sensitivity both ways, on the same channel and PAN."""
        live = [r for r in self.swarm_radios if r not in self.dead]
        rssi = self.radio.mean_rssi()[np.ix_(live, live)]  # row: sender, column: receiver
        sens = np.array([self.node_sens.get(r, -94.0) for r in live])
        net = [self.node_net.get(r) for r in live]  # modules hear only their own channel and PAN
        same = np.array([[a is not None and a == b for b in net] for a in net]).reshape(len(live), len(live))
        up = rssi >= sens[None, :]
        adj = (up & up.T & same).astype(float)
        np.fill_diagonal(adj, 0.0)
        return live, adj

    def algebraic_connectivity(self) -> float:
        """lambda2 of the radio graph: above zero exactly when the radio network is connected."""
        live, adj = self.radio_graph()
        if len(live) < 2:
            return 0.0
        lap = np.diag(adj.sum(axis=1)) - adj
        return float(max(0.0, np.sort(np.linalg.eigvalsh(lap))[1]))

    def _partitions(self) -> None:
        """Sample how many pieces the swarm's radio graph is in, and each ranger's subgroup's (its live scouts)."""
        live, adj = self.radio_graph()
        self.pieces.append(graph.components(adj))
        if self.group_of:
            idx = {r: i for i, r in enumerate(live)}
            for g in sorted(self.carriers):
                members = [idx[r] for r, c in self.group_of.items() if c == g and r in idx
                           and r not in self.world.carried]
                self.group_pieces[g].append(graph.components(adj[np.ix_(members, members)]) if members else 0)
                if g in self.deployed and members:  # the mission has begun for this subgroup (its START)
                    rssi = self.radio.mean_rssi()[np.ix_(live, live)][np.ix_(members, members)]
                    # links as the scouts judge them: the mean RSSI clears their q_min both ways (else: any link)
                    q = self.q_min.get(g)
                    sub = adj[np.ix_(members, members)] if q is None else (rssi >= q) & (rssi >= q).T
                    self.mission_links.append({"group": g, **link_stats(sub, rssi)})

    def _route(self, e: str, r: int, t: int, item: list) -> None:
        """One output item other than a CAN frame: UART bytes, an air frame, a node setting, a ranging request,
        the RSSI PWM level, a log record. Anything malformed is counted and dropped."""
        q = self.q_ns
        kind = item[0]
        role = e[e.index("/") + 1:]
        try:
            if kind in ("uart", "baud") and role == "logic" and item[1] == "mavlink":  # a network link, no line
                if kind == "uart" and self.mavlink is not None and isinstance(item[2], bytes):
                    self.mavlink.from_robot(r, item[2])
                elif kind == "uart":
                    self.counts["uart_unrouted_writes"] += 1
            elif kind == "baud" and role == "logic":  # the host set its port's rate
                _, dev, baud = item
                if (r, dev) not in self.host_baud or type(baud) is not int or baud <= 0:
                    raise ValueError
                self.host_baud[(r, dev)] = baud
            elif kind == "uart" and role == "logic":
                _, dev, data, baud = item
                line = self.lines.get((r, dev))
                if line is None or not isinstance(data, bytes) or type(baud) is not int or baud <= 0:
                    self.counts["uart_unrouted_writes"] += 1
                    return
                self.host_baud[(r, dev)] = baud
                line.offer(t + q, data, baud)
                self.rec.write(t, f"/r{r:03d}/{dev}/uart", "swarm_sitl.Uart", {"dir": "to_module", "data": data.hex()})
            elif kind == "uart" and role in ("xbee", "uwb"):
                _, dev, data, baud = item
                if not isinstance(data, bytes) or dev != role:
                    raise ValueError
                if "logic" not in self.roles[r]:  # nobody in the session listens on that line
                    self.counts["uart_unrouted_writes"] += 1
                    return
                if baud != self.host_baud.get((r, dev), baud):  # the host listens at another rate: garbage
                    self.counts["uart_garbled_bytes"] += len(data)
                    data = garble(data)
                self.deliveries[t + q].append(("ent", entity(r, "logic"), [f"uart:{dev}", data]))
                self.deliveries[t + q].append(("rec", f"/r{r:03d}/{dev}/uart", "swarm_sitl.Uart",
                                               {"dir": "to_host", "data": data.hex()}))
            elif kind == "baud" and role in ("xbee", "uwb"):
                _, dev, baud = item
                if dev != role or type(baud) is not int or baud <= 0:
                    raise ValueError
                if (r, dev) in self.lines:
                    self.lines[(r, dev)].baud = baud
            elif kind == "air" and role == "xbee" and self.radio is not None and valid_air_frame(item[1]):
                f = item[1]
                self.radio.submit(r, t + q, f)
                self.counts["air_frames"] += 1
                dst = f.get("dst")
                self.tx_dst[(r, f["handle"])] = (self.addr_robot.get((dst, f["dst_addr"])) if dst != "bcast" else None,
                                                 f["seq"])
            elif kind == "node" and role == "xbee" and self.radio is not None and _valid_node(item[1]):
                node = item[1]
                self.radio.set_node(r, node)
                self.addr_robot[("64", int(node["addr64"]))] = r
                self.addr_robot[("16", int(node["addr16"]))] = r
                self.node_sens[r] = float(node["sensitivity_dbm"])
                self.node_net[r] = (node["channel"], node["pan_id"])
            elif kind == "rssi_pwm" and role == "xbee":
                self.rssi_pwm[r] = min(1.0, max(0.0, float(item[1])))
            elif kind == "uwb" and role == "uwb" and self.uwb is not None and isinstance(item[1], dict):
                req = item[1]
                peer, t_req = req.get("peer"), req.get("t_ns", 0)
                if type(peer) is not int or type(t_req) is not int or not (0 <= peer < self.n) or peer == r:
                    raise ValueError
                start = max(t + q, min(t_req, t + 2 * q))
                for t_ev, rr, ev in self.uwb.exchange(start, r, peer):
                    if "uwb" in self.roles[rr]:
                        self.deliveries[max(t + q, -(-t_ev // q) * q)].append(("ent", entity(rr, "uwb"), ["uwb", ev]))
            elif kind == "log" and role == "logic":
                _, topic, values = item
                if not (isinstance(topic, str) and topic.isidentifier() and isinstance(values, dict)):
                    raise ValueError
                json.dumps(values, allow_nan=False)  # strict JSON only: NaN would make the recording unreadable
                self.rec.write(t, f"/r{r:03d}/log/{topic}", "swarm_sitl.Log", values)
                if topic == "uwb_ranges":
                    self._uwb_log(r, values)
                elif topic == "deployment" and values.get("event") == "done" and r in self.carriers:
                    self._deployed(r, t)
                elif topic == "rdpso" and isinstance(values.get("comm"), dict):
                    self.comm[r] = values["comm"]
            else:
                raise ValueError
        except (ValueError, TypeError, KeyError, IndexError, OverflowError):
            self.counts["malformed_items"] += 1

    def _deployed(self, carrier: int, t: int) -> None:
        """A ranger says it has deployed its scouts (and broadcast START): where they are, by ground truth."""
        scouts = [r for r, c in self.group_of.items() if c == carrier and r not in self.world.carried]
        pts = self.world.pos[scouts] if scouts else np.zeros((0, 2))
        self.deployed[carrier] = {"t_s": t / 1e9, "scouts": scouts, "dispersion_m": round(dispersion(pts), 3),
                                  "positions": np.round(pts, 3).tolist()}
        if self.cfg.session.end_after_deployment and len(self.deployed) == len(self.carriers):
            self.end_ns = min(self.end_ns, t + 1_000_000_000)

    def deployment_report(self) -> dict[str, Any] | None:
        """Per ranger: when it was done, its scouts' dispersion (eq. 5.11) and positions then; over all, the share
        of the arena within 1 m of a deployed scout (each where it was when its ranger was done)."""
        if not self.carriers:
            return None
        pts = [p for d in self.deployed.values() for p in d["positions"]]
        a = self.cfg.arena
        return {"rangers": {str(c): self.deployed.get(c) for c in sorted(self.carriers)},
                "done": len(self.deployed), "rangers_total": len(self.carriers),
                "time_s_max": max((d["t_s"] for d in self.deployed.values()), default=None),
                "covered_share": round(covered_share(np.array(pts), a.width_m, a.length_m), 4) if pts else 0.0,
                "left_on_board": sorted(self.world.carried)}

    def _radio_event(self, t_ev: int, r: int, ev: dict) -> None:
        """A reception or a transmit result from the medium: to the module at the next quantum boundary, and
        to the recording (with the ground-truth distance, for surveys)."""
        q = self.q_ns
        t_del = -(-t_ev // q) * q
        if "xbee" in self.roles[r]:
            self.deliveries[t_del].append(("ent", entity(r, "xbee"), ["air", ev]))
        if ev.get("ev") == "rx":
            f = ev["frame"]
            src = self.addr_robot.get(("64", f.get("src64")), -1)
            d = float(np.hypot(*(self.world.pos[r] - self.world.pos[src]))) if 0 <= src < self.n else None
            self.deliveries[t_del].append(("rec", "/radio/rx", "swarm_sitl.RadioRx", {
                "t_ns": t_ev, "dst": r, "src": src, "handle": f.get("handle"), "rssi_dbm": ev.get("rssi_dbm"),
                "len": len(f.get("payload", b"")), "distance_m": None if d is None else round(d, 3)}))
        elif ev.get("ev") == "done":
            dst, seq = self.tx_dst.pop((r, ev.get("handle")), (None, None))
            d = walls = None
            if dst is not None and dst != r:
                d = round(float(np.hypot(*(self.world.pos[r] - self.world.pos[dst]))), 3)
                walls = int(self.world.walls(r, np.array([dst]))[0])
            self.deliveries[t_del].append(("rec", "/radio/tx", "swarm_sitl.RadioTx", {
                "t_ns": t_ev, "src": r, "handle": ev.get("handle"), "status": ev.get("status"),
                "attempts": ev.get("attempts"), "dst": dst, "seq": seq, "distance_m": d, "walls": walls}))

    def _uwb_log(self, r: int, values: dict) -> None:
        """The logic's own ranges (raw and filtered) against the ground truth now: the error it lives with."""
        peers, raw, filt = values.get("peers"), values.get("raw"), values.get("filtered")
        if not (isinstance(peers, list) and isinstance(raw, list) and isinstance(filt, list)
                and len(peers) == len(raw) == len(filt)):
            raise ValueError
        acc = self.uwb_log_err[r]
        pairs = [(self.uwb_robot.get(a), x, f) for a, x, f in zip(peers, raw, filt, strict=True)]
        pairs = [(p, x, f) for p, x, f in pairs if p is not None and p not in self.dead and p != r]
        if not pairs:
            return
        walls = self.world.walls(r, np.array([p for p, _, _ in pairs]))
        for (p, x, f), w in zip(pairs, walls.tolist(), strict=True):
            true_m = float(np.hypot(*(self.world.pos[r] - self.world.pos[p])))
            sight = "nlos" if w else "los"
            if isinstance(x, int | float) and isinstance(f, int | float):  # compared on the same samples
                acc[f"raw_{sight}"].append(float(x) - true_m)
                acc[f"filtered_{sight}"].append(float(f) - true_m)

    def run(self) -> dict[str, Any]:
        q = self.q_ns
        world, rec = self.world, self.rec
        speed = self.cfg.session.speed
        poses_every = self.cfg.session.poses_every_quanta
        wall0 = time.monotonic()
        next_status = 0
        while self.stop_reason is None and not self.abort:
            t = self.k * q
            if t >= self.end_ns:
                break
            while self.battery_deaths and self.battery_deaths[0][0] <= t:  # injected: the battery is empty
                at, r = self.battery_deaths.pop(0)
                self.world.deplete(r)
                self.robot_failed(r, t, "battery_depleted", f"battery exhausted at {at / 1e9:g} s: motors stopped, "
                                                            "radio silent")
            self._deliver(t)
            if world.mapping is not None and world.mapping.tick(t, world.pos, world.alive):  # scan, then sense
                rec.write(t, "/world/mapping", "swarm_sitl.Mapping", world.mapping.record())
            self._lines(t)
            if self.mavlink is not None:
                self._ground_station(t)
            due = self._due(t)
            for p in list(due):
                if p not in self.live_procs:
                    del due[p]
            t_pub = time.perf_counter()
            sensed: dict[str, dict] = {}
            for p in sorted(due):
                run: dict[str, Any] = {}
                for e in due[p]:
                    self.wakeups[e[e.index("/") + 1:]] += 1
                    entry: dict[str, Any] = {"in": self.inbox[e]}
                    self.inbox[e] = []
                    if e.endswith("/llc"):
                        r = robot_of(e)
                        s = world.sensors(r)
                        entry["sens"] = {"enc": list(s.encoders), "sonar_m": s.sonar_m, "lux": s.lux,
                                         "battery_v": s.battery_v}
                        if s.side_sonars_m:
                            entry["sens"]["sides"] = list(s.side_sonars_m)
                        if "xbee" in self.roles[r]:
                            entry["sens"]["rssi_pwm"] = self.rssi_pwm[r]
                        sensed[e] = entry["sens"]  # recorded as the pins' values; the pose is in /world/poses
                        if r in self.ideal_pose:  # its mocap receiver: the true pose in the world frame
                            entry["sens"] = {**entry["sens"], "pose": [
                                float(world.pos[r, 0]), float(world.pos[r, 1]), float(world.yaw[r])]}
                    run[e] = entry
                self.tick_pub[p].put(transport.pack({"k": self.k, "t": t, "run": run}))
                self.proc_ticks += 1
            if self.k % poses_every == 0:
                poses = {"x": np.round(world.pos[:, 0], 5).tolist(), "y": np.round(world.pos[:, 1], 5).tolist(),
                         "yaw": np.round(world.yaw, 5).tolist(), "alive": world.alive.tolist(),
                         "led": world.led.tolist()}
                if self.carriers:
                    poses["carried"] = [r in world.carried for r in range(self.n)]
                rec.write(t, "/world/poses", "swarm_sitl.Poses", poses)
            world.step_quantum(t, q)
            for ev in world.released:  # scouts that dropped off a carrier's conveyor in this quantum
                rel = {k: ev[k] for k in ("robot", "carrier", "slot", "pose")}
                self.deliveries[ev["t_ns"]].append(("rec", "/world/releases", "swarm_sitl.Release", rel))
                self.releases.append({"t_s": ev["t_ns"] / 1e9, **rel})
            world.released.clear()
            if due:
                results = self._collect(set(due), t)
                self.barrier_us.append((time.perf_counter() - t_pub) * 1e6)
                self._outputs(t, results, sensed, due)
                self._apply_deaths(t)
                self.ticks += 1
            else:
                self._drain_control(t)
            self._media(t)
            self.k += 1
            lag = None
            if speed != "max":
                ahead = (t + q) / 1e9 / float(speed) - (time.monotonic() - wall0)
                lag = max(0.0, -ahead)
                self.lag_s.append(lag)
            if t >= next_status:
                next_status += 1_000_000_000
                self.status(op="progress", t=(t + q) / 1e9, alive=self.n - len(self.dead), ticks=self.k, lag_s=lag)
            if lag == 0.0:
                time.sleep(ahead)
        self.sim_end_ns = self.k * q
        self.wall_s = time.monotonic() - wall0
        return self.result()

    def _drain_control(self, t: int) -> None:
        while True:
            try:
                key, data = self.q.get_nowait()
            except queue.Empty:
                break
            if key == "control":
                self._control(data, t)
        self._apply_deaths(t)

    def shutdown(self) -> None:
        """Tell every live process to stop and wait for their goodbyes (with their counters): a process that joined
        answers its stop as it answers a tick, so ``hang_timeout_s`` bounds the wait, as it bounds a quantum's."""
        stop = transport.pack({"k": self.k, "stop": True})
        waiting = set() if self.abort else set(self.live_procs)
        for p in sorted(waiting):
            self.tick_pub[p].put(stop)
        waiting -= self.unjoined
        deadline = time.monotonic() + self.cfg.session.hang_timeout_s
        while waiting and time.monotonic() < deadline:
            try:
                key, data = self.q.get(timeout=0.05)
            except queue.Empty:
                continue
            if key.startswith("done/"):
                msg = _unpack_dict(data)
                if not (msg and msg.get("bye")):  # a late answer to a quantum, not the goodbye
                    continue
                waiting.discard(key[5:])
                if isinstance(msg.get("stats"), dict):  # the modules' own counters
                    self.module_stats.update({str(k): v for k, v in msg["stats"].items() if isinstance(v, dict)})

    def radio_report(self) -> dict[str, Any]:
        """The session's radio figures: per robot from the media and the modules, and the network's
        connectivity over time. Filled in after ``shutdown`` (the modules report their counters then)."""
        out: dict[str, Any] = {"per_robot": {}}
        if self.radio is not None:
            stats = self.radio.stats()
            lam = [v for _, v in self.connectivity]
            share = round(sum(v > 1e-9 for v in lam) / len(lam), 4) if lam else None
            out["connectivity"] = {
                "samples": len(lam), "connected_share": share,
                "lambda2_min": round(min(lam), 4) if lam else None,
                "lambda2_median": round(statistics.median(lam), 4) if lam else None,
                # a partition event: the graph falls into more pieces than at the previous sample
                "partition_events": _splits(self.pieces), "pieces_max": max(self.pieces, default=0)}
            if self.group_pieces:
                out["connectivity"]["subgroups"] = {str(g): {"partition_events": _splits(v), "pieces_max": max(v)}
                                                    for g, v in sorted(self.group_pieces.items())}
            if self.mission_links:  # each ranger's live scouts after its START, once a second (mean, sd)
                ml = self.mission_links
                out["connectivity"]["mission"] = {
                    "q_min_dbm": {str(g): q for g, q in sorted(self.q_min.items())},
                    **{k: mean_sd([s[k] for s in ml]) for k in ("rssi_dbm", "hops", "relays", "lambda2")},
                    "partition_events": sum(_splits([s["pieces"] for s in ml if s["group"] == g])
                                            for g in sorted({s["group"] for s in ml}))}
            out["totals"] = stats.get("totals", {})
            out["rssi_hist_bins_dbm"] = [stats.get("rssi_hist_lo_dbm"), stats.get("rssi_hist_bin_db")]
            for r in range(self.n):
                if "xbee" in self.roles[r]:
                    out["per_robot"].setdefault(r, {})["radio"] = stats["robots"][r]
                    out["per_robot"][r]["xbee_module"] = self.module_stats.get(entity(r, "xbee"))
        for r in range(self.n):
            for role in ("slcan", "can_bridge"):  # the USB-CAN adapter's own counters; the real board's bridge's
                if role in self.roles[r]:
                    out["per_robot"].setdefault(r, {})[role] = self.module_stats.get(entity(r, role))
        if self.uwb is not None:
            ustats = self.uwb.stats()
            out["uwb_medium"] = ustats.get("all", {})
            for r in range(self.n):
                if "uwb" not in self.roles[r]:
                    continue
                d = out["per_robot"].setdefault(r, {})
                d["uwb_raw"] = ustats["robots"][r]
                d["uwb_module"] = self.module_stats.get(entity(r, "uwb"))
                logged = self.uwb_log_err.get(r)
                if logged:
                    d["uwb_logic_error"] = {k: _rms_summary(v) for k, v in logged.items()}
            allerr: dict[str, list[float]] = defaultdict(list)
            for acc in self.uwb_log_err.values():
                for k, v in acc.items():
                    allerr[k] += v
            out["uwb_logic_error"] = {k: _rms_summary(v) for k, v in sorted(allerr.items())}
        return out

    def result(self) -> dict[str, Any]:
        lat = sorted(self.barrier_us)
        return {
            "sim_time_s": self.sim_end_ns / 1e9,
            "world_wall_s": self.wall_s,
            "quanta": self.k,
            "ticks": self.ticks,
            "messages": self.rec.count,
            "message_counts": dict(self.counts),
            "wakeups": dict(self.wakeups),
            "process_ticks": self.proc_ticks,
            "digest": self.rec.digest,
            "barrier_us_median": statistics.median(lat) if lat else None,
            "barrier_us_p99": lat[min(len(lat) - 1, int(0.99 * len(lat)))] if lat else None,
            "wall_lag": _lag_summary(self.lag_s),
            "can_events": self.can_events,
            "releases": self.releases if self.carriers else None,
            "deployment": self.deployment_report(),
            "comm": comm_report(self.comm, self.sim_end_ns / 1e9) if self.comm else None,
            "mapping": self.world.mapping.summary() if self.world.mapping is not None else None,
            "mavlink": self.mavlink.stats() if self.mavlink is not None else None,
            "startup_s": getattr(self, "startup_wall_s", None),
            "failures": self.failures,
            "stop_reason": self.stop_reason,
            "failed_stop": self.failed_stop,
            "robots": [
                {"id": r, "alive": bool(self.world.alive[r]), "distance_m": round(float(self.world.odometer[r]), 3),
                 "final_pose": [round(float(self.world.pos[r, 0]), 3), round(float(self.world.pos[r, 1]), 3),
                                round(float(self.world.yaw[r]), 3)],
                 "battery_v": round(float(self.world.battery_v[r]), 3),
                 "pose_source": self.plan.robots[r].pose_source,
                 "kind": "xbee_gateway" if self.plan.robots[r].gateway is not None else "robot",
                 "profile": self.plan.robots[r].profile,
                 "on_board": self.world.carried[r][0] if r in self.world.carried else None,
                 "motion": self.plan.robots[r].motion["kind"] if self.plan.robots[r].scripted else "simulated",
                 "can_frames": self.can[r].frames,
                 "can_bus_load": round(self.can[r].bits / self.can[r].bitrate / max(self.sim_end_ns / 1e9, 1e-9), 4),
                 "can": _can_summary(self.can[r])}
                for r in range(self.n)
            ],
        }


class _Geometry:
    """What the radio and UWB media ask of the world: where robots are, which live, and walls between them."""

    def __init__(self, world: World) -> None:
        self.world = world

    def positions(self) -> np.ndarray:
        return self.world.pos

    def alive(self) -> np.ndarray:
        return self.world.alive

    def walls(self, src: int, dsts: np.ndarray) -> np.ndarray:
        return self.world.walls(src, dsts)


def _can_summary(bus: CanMedium) -> dict[str, Any]:
    """A robot's bus in the summary: error frames, and each node's final state and counters (by role)."""
    st = bus.stats()
    return {"error_frames": st["error_frames"],
            "nodes": {name[name.index("/") + 1:]: v for name, v in st["nodes"].items()}}


def _splits(pieces: list[int]) -> int:
    """Partition events in a series of component counts: the times it rose (a piece broke off)."""
    return sum(max(0, b - a) for a, b in itertools.pairwise(pieces) if a > 0)


def _lag_summary(lag_s: list[float]) -> dict[str, Any] | None:
    """How far a paced session's simulated clock fell behind wall time: quanta that ended late, and by how much."""
    if not lag_s:
        return None
    a = np.asarray(lag_s)
    return {"quanta": len(a), "late_share": round(float(np.mean(a > 0)), 4), "max_ms": round(float(a.max()) * 1e3, 2),
            "p99_ms": round(float(np.quantile(a, 0.99)) * 1e3, 2), "mean_ms": round(float(a.mean()) * 1e3, 3),
            "final_ms": round(float(a[-1]) * 1e3, 2)}


def _rms_summary(errors: list[float]) -> dict[str, Any]:
    a = np.asarray(errors, dtype=float)
    if not len(a):
        return {"n": 0}
    return {"n": len(a), "rms_m": round(float(np.sqrt(np.mean(a * a))), 4), "mean_m": round(float(a.mean()), 4),
            "p95_abs_m": round(float(np.quantile(np.abs(a), 0.95)), 4)}


def _unpack_dict(data: bytes) -> dict | None:
    try:
        msg = transport.unpack(data)
    except Exception:
        return None
    return msg if isinstance(msg, dict) else None


def _valid_reply(res: dict) -> bool:
    """The shape of one entity's answer: ``out`` a list, ``wake`` an int or None, ``err`` a str or None."""
    return (isinstance(res.get("out", []), list) and (res.get("wake") is None or type(res.get("wake")) is int)
            and (res.get("err") is None or isinstance(res.get("err"), str)))


def _valid_can(item: Any) -> bool:
    """[bus, arbitration id, data, extended] as the participants send it, optionally with a fifth element True to
    have the frame echoed back (python-can's receive_own_messages); anything else is dropped."""
    if not (isinstance(item, list | tuple) and len(item) in (4, 5) and item[0] == "can0"
            and (len(item) == 4 or item[4] is True)):
        return False
    arb, data, ext = item[1:4]
    return (isinstance(arb, int) and isinstance(data, bytes) and isinstance(ext, bool)
            and frame_fault(arb, data, ext) is None)


def _valid_node(node: Any) -> bool:
    """A module's radio settings, as the medium uses them."""
    if not isinstance(node, dict):
        return False
    ints = {"channel": (11, 26), "pan_id": (0, (1 << 64) - 1), "addr64": (0, (1 << 64) - 1), "addr16": (0, 0xFFFF),
            "series": (1, 2)}
    nums = {"tx_power_dbm": (-40.0, 30.0), "sensitivity_dbm": (-130.0, -40.0)}
    return (all(type(node.get(k)) is int and lo <= node[k] <= hi for k, (lo, hi) in ints.items())
            and all(isinstance(node.get(k), int | float) and lo <= node[k] <= hi for k, (lo, hi) in nums.items()))


def _valid_pins(pins: Any) -> bool:
    if not isinstance(pins, dict):
        return False
    pwm, led, belt = pins.get("pwm"), pins.get("led"), pins.get("belt_steps", 0)
    return (isinstance(pwm, list) and len(pwm) == 2 and all(isinstance(v, int) and -255 <= v <= 255 for v in pwm)
            and isinstance(led, list) and len(led) == 3 and all(isinstance(v, int) and 0 <= v <= 255 for v in led)
            and type(belt) is int and belt >= 0)
