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

import base64
import bisect
import contextlib
import fnmatch
import json
import os
import queue
import signal
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bridge.core import foxglove as fx
from bridge.core import transport
from bridge.core.config import Config, FaultCfg
from bridge.core.entities import entity, robot_of
from bridge.core.faults import ROBOT_FAULTS, RobotFaults
from bridge.core.loop_functions import LoopFunctions
from bridge.core.medium import Medium, route_table
from bridge.core.plan import Plan, plan_offer
from bridge.core.recorder import SCHEMAS, Recorder
from bridge.core.registry import MEDIA, SERVICES, STUDIES, robot_spec
from bridge.core.scene import Scene
from bridge.core.services import SENSES, SERVICE_ROLE
from bridge.core.stats import LogHistogram, Moments
from bridge.core.world import World


class AwakeDeadline:
    """A wall-clock deadline that counts only the time this process was awake to see answers arrive.

    The world waits in steps of at most ``step_s``; a step that took far longer means the world itself was not
    running (paused with SIGSTOP, suspended, starved of CPU), not that the others were late: that gap is added to
    the deadline, so a participant whose answer is already on its way is never declared hung for the world's own
    pause."""

    def __init__(self, seconds: float, step_s: float = 0.2, stall_s: float = 1.0) -> None:
        self.seconds, self.step_s, self.stall_s = seconds, step_s, stall_s
        self._last = time.monotonic()
        self._end = self._last + seconds
        self.stalled_s = 0.0  # how long the world was away, in all

    def left(self) -> float:
        """Seconds left, the world's own stalls not counted; call once per wait step."""
        now = time.monotonic()
        gap = now - self._last
        if gap > self.step_s + self.stall_s:
            self._end += gap
            self.stalled_s += gap
        self._last = now
        return self._end - now

LOGIC_BOOT_SPREAD_NS = 100_000_000  # companion computers start their programs within 100 ms of each other
# What one participant may send before it is failed for flooding (it fails alone; the world and the others go on):
# answers to one quantum that are not its answer (stale, malformed), the bytes of one answer, the items of one run
MAX_WRONG_ANSWERS = 100  # a sound process sends one answer per tick
MAX_ANSWER_BYTES = 16 << 20
MAX_RUN_ITEMS = 10_000  # a run's outputs: frames, bytes written, logs (a busy controller: tens)


class Hub:
    def __init__(self, plan: Plan, session_dir: str, out_dir: str, namespace: str) -> None:
        self.plan = plan
        self.cfg = cfg = Config.from_plan(plan.config)
        self.q_ns = cfg.session.quantum_ns
        self.end_ns = -(-round(cfg.session.duration_s * 1e9) // self.q_ns) * self.q_ns
        self.out = Path(out_dir)
        self.endpoint = transport.endpoint_for(session_dir)
        self.namespace = namespace
        self.world = World(cfg, plan.robots)
        self.geometry = _Geometry(self.world)  # what the media ask of the world
        self.rec = Recorder(self.out / "session.mcap", {"config": json.dumps(plan.config, sort_keys=True),
                                                        "robots": str(len(plan.robots))})
        self.scene: Scene | None = None  # the Foxglove scene channels (session.scene_hz), built with the media
        self.n = len(plan.robots)
        self._entities(plan)
        self._sensed_robots = [r for r, rp in enumerate(plan.robots) if rp.gateway is None]
        self._failure_state(cfg)
        self._wiring(plan)
        self._plugins(cfg)

    def _entities(self, plan: Plan) -> None:
        """Every process and entity, and when each first wakes."""
        self.procs = {p.name: p for p in plan.procs}
        self.proc_of: dict[str, str] = {}
        for p in plan.procs:
            for e in p.entities(plan.robots):
                self.proc_of[e] = p.name
        self.ents = sorted(self.proc_of)
        # the session's services (bridge.core.services): name -> entity, and each one's senses
        self.service_entities = {p.service: e for p in plan.procs if p.kind == "service"
                                 for e in p.entities(plan.robots)}
        self.service_of = {e: name for name, e in self.service_entities.items()}
        kinds = {s["name"]: s["kind"] for s in plan.config.get("services", [])}
        self.service_senses = {e: SERVICES.get(kinds[name]).senses for name, e in self.service_entities.items()}
        self.dead_services: set[str] = set()
        # each entity's robot (-1: a service) and role, as its id says
        self.ent_robot = {e: -1 if e in self.service_of else robot_of(e) for e in self.ents}
        self.ent_role = {e: SERVICE_ROLE if e in self.service_of else e[e.index("/") + 1:] for e in self.ents}
        # every entity of a robot: its firmware's, and its logic when the session runs it
        self.roles = {r: rp.modules() + (("logic",) if rp.has_logic else ()) for r, rp in enumerate(plan.robots)}
        self.next_wake: dict[str, int | None] = dict.fromkeys(self.ents, 0)
        for r, rp in enumerate(plan.robots):
            # Robots power up one quantum apart (cyclically), as real ones never boot in the same 10 ms; this
            # spreads LLC loops and controller steps evenly over quanta instead of waking everyone at once.
            period = round(1e9 / self.robot_spec(r).profile.llc_loop_hz)
            boot = (r * self.q_ns) % max(period, self.q_ns) // self.q_ns * self.q_ns
            for role in rp.modules():
                self.next_wake[entity(r, role)] = boot
            if rp.has_logic:
                self.next_wake[entity(r, "logic")] = (r * self.q_ns) % max(LOGIC_BOOT_SPREAD_NS, self.q_ns)
        # wake on message: False, True (any input), or the input kinds that wake it (item[0] of inbox items)
        self.wom: dict[str, Any] = dict.fromkeys(self.ents, False)
        self.inbox: dict[str, list] = {e: [] for e in self.ents}
        # what is due at a time: (handler, args), run in the order scheduled (which the schedule fixes)
        self.deliveries: dict[int, list[tuple]] = defaultdict(list)

    def _failure_state(self, cfg: Config) -> None:
        """Deaths, failures and the stop, the session's counters, and the control queue."""
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
        self.barrier = LogHistogram()  # each quantum's barrier time (us), in bounded memory for any session length
        self.lag = WallLag()  # paced sessions: how far the simulated clock is behind wall time, per quantum
        self.wakeups: dict[str, int] = defaultdict(int)  # entity runs by role (llc, xbee, uwb, logic)
        self.ticks = 0
        self.proc_ticks = 0  # tick messages sent (one per due process per quantum)
        self.k = 0
        self.q: queue.SimpleQueue = queue.SimpleQueue()
        self.status_pub: Any = None
        # battery deaths to come: (time, robot)
        self.battery_deaths = sorted((round(f.at_s * 1e9), f.robot) for f in cfg.faults if f.kind == "battery_depleted")
        self.module_stats: dict[str, dict] = {}
        self.crashes: dict[int, int] = {}  # firmware crashes injected while running: robot -> time
        # session.record_ticks: this quantum's inputs per entity (msgpack), recorded with its answer
        self._ticks_in: dict[str, bytes] | None = {} if cfg.session.record_ticks else None
        self.unplugged: set[str] = set()  # modules pulled out (unplugged faults): they run and hear no more
        self.faults = RobotFaults(self)  # freezes, reboots, brown-outs, faulty sensors and wheels, drifting clocks

    def _wiring(self, plan: Plan) -> None:
        """Each LLC's wiring in the world, and the robots carried on board."""
        self.pin_inputs: list[dict[str, Any]] = [{} for _ in range(self.n)]  # values media put on an LLC's pins
        self.ideal_pose = {r for r, rp in enumerate(plan.robots) if rp.pose_source == "ground_truth"}
        # each board's wiring in the world, by entity: an LLC's (RobotSpec.pins), a model's own modules'
        # (RobotSpec.wiring, e.g. a leg module's motor and leg sensor); its pins' record topic
        self.wiring: dict[str, Any] = {}
        for r, rp in enumerate(plan.robots):
            spec = self.robot_spec(r)
            if rp.llc_role == "llc" and spec.pins is not None:
                self.wiring[entity(r, "llc")] = spec.pins
            for role in rp.modules():
                w = spec.wiring(role) if spec.wiring is not None else None
                if w is not None:
                    self.wiring[entity(r, role)] = w
        self._pins_topics = {e: f"/{e}/pins" for e in self.wiring}  # the CAN medium keeps its own
        self.releases: list[dict[str, Any]] = []
        self.carriers = {rp.carrier for rp in plan.robots if rp.carrier is not None}  # robots with robots on board

    def _plugins(self, cfg: Config) -> None:
        """The studies' loop functions and the media this session uses, and the route table."""
        # the studies' loop functions first (a medium may call them), then the media the session uses, in order
        self.loop_functions: list[LoopFunctions] = [
            lf(self) for lf in (study.loop_functions_class() for _, study in STUDIES.items())
            if lf is not None and lf.wanted(cfg)]
        self.media: dict[str, Medium] = {}
        for name, cls in sorted(MEDIA.items(), key=lambda kv: (kv[1].order, kv[0])):
            if cls.wanted(self):
                self.media[name] = cls(self)
        self._media = list(self.media.values())
        if cfg.session.scene_hz > 0:
            self.scene = Scene(self)
        self.routes = route_table(self._media)
        self.routes[("log", "logic")] = self._log
        self.routes[("log", SERVICE_ROLE)] = self._service_log
        self.routes[("stop", SERVICE_ROLE)] = self._service_stop
        self.routes[("fault", SERVICE_ROLE)] = self._service_fault
        self._taps(cfg)
        for f in cfg.faults:
            if f.kind == "unplugged" or (f.kind in ROBOT_FAULTS and not (f.kind == "sensor" and f.sensor == "uwb")):
                self.inject_fault(f, 0)  # (the media read the faults they carry from the config themselves)
        self._log_hooks = self._media + self.loop_functions

    def robot_spec(self, r: int) -> Any:
        """Robot ``r``'s plugin (its profile, its CAN interface)."""
        return robot_spec(self.plan.robots[r].profile)

    def medium(self, name: str) -> Any:
        """The session's medium ``name`` (KeyError if this session does not use it)."""
        return self.media[name]

    def deliver_at(self, t_ns: int, handler: Callable[..., None], *args: Any) -> None:
        """Run ``handler(t, *args)`` at the start of the quantum at ``t_ns``, after what was scheduled there before."""
        self.deliveries[t_ns].append((handler, args))

    def to_inbox(self, t: int, e: str, msg: list) -> None:
        """A delivery: ``msg`` into entity ``e``'s inbox (nothing for a dead robot)."""
        if not self.is_dead(e):
            self.inbox[e].append(msg)

    def is_dead(self, e: str) -> bool:
        """Entity ``e``'s robot is dead, or ``e`` is a service that failed."""
        r = self.ent_robot.get(e)
        if r is None:  # not one of this session's entities: its id names its robot
            r = robot_of(e)
        return r in self.dead if r >= 0 else e in self.dead_services

    def record(self, t: int, topic: str, schema: str, payload: Any) -> None:
        """A delivery: a message to the recording at its time."""
        self.rec.write(t, topic, schema, payload)

    def event(self, t: int, payload: dict[str, Any]) -> None:
        """A session event (a failure, a fault, a stop) to ``/session/events``, and to the scene's log."""
        self.rec.write(t, "/session/events", "swarm_sitl.Event", payload)
        if self.scene is not None:
            self.scene.log(t, "session", str(payload.get("kind", "event")), payload, fx.LOG_WARNING)

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
        if self.cfg.session.live and self.scene is not None:  # the scene, served while the session runs
            from bridge.core.live import LiveScene

            self.scene.live = LiveScene(self.cfg.session.live, self.cfg.session.name)
        self.tick_pub = {p: transport.publisher(s, f"tick/{p}") for p in self.procs}
        # the remote procs that may still join (None: started); the plan's answer tells a joiner, who refuses to
        # join twice or late
        self.joinable: frozenset[str] | None = frozenset(p for p, pp in self.procs.items() if pp.remote)
        if listen:
            def offer(query: Any) -> None:  # a zenoh thread: reads the plan and a frozenset (or None)
                query.reply(transport.PLAN_KEY, plan_offer(self.plan, self.joinable))

            self._subs.append(s.declare_queryable(transport.PLAN_KEY, offer))
            self._world_token = s.liveliness().declare_token(transport.WORLD_KEY)  # a joiner sees the world go
            self._subs.append(transport.on_gone(s, transport.JOINED_KEY, self._remote_gone))

    def _remote_gone(self, p: str) -> None:
        """A zenoh thread: the computer running remote process ``p`` went away (its joiner's token is gone): a death,
        told as the launcher tells one, so its robots fail at once rather than after hang_timeout_s."""
        if p in self.procs and self.procs[p].remote:
            where = f"host {self.procs[p].host}" if self.procs[p].host else "the other computer"
            self.q.put(("control", transport.pack({"op": "dead", "proc": p, "lost": True, "detail": f"lost {where}: "
                                                   "its swarm-sitl join ended or its network failed"})))

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
        deadline = AwakeDeadline(timeout)
        try:
            while missing:
                left = deadline.left()
                if left <= 0:
                    hint = (" (remote processes: run the swarm-sitl join commands the launcher printed on the other "
                            "computers, or raise session.startup_timeout_s)" if missing & remote else "")
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
                        if self.procs[p].inproc:  # served by the launcher itself: never ours to kill
                            pass
                        elif p in remote:  # its pid is on another computer: never ours to kill
                            self.joinable = frozenset((missing & remote) - {p})
                            pp = self.procs[p]
                            who = f"host {pp.host}'s {p}" if pp.host else f"robot {pp.robots[0]}'s logic"
                            self.status(op="notice", joined=p, text=f"{who} joined from another computer ({p})")
                        else:
                            self.pids[p] = msg["pid"]
                        transport.wait_matched(self.tick_pub[p], timeout, f"tick/{p}")
                        missing.discard(p)
                elif key == "control":
                    if msg.get("op") == "dead" and msg.get("proc") in remote:  # a joiner left: it may join again
                        p = msg["proc"]
                        if msg.get("lost") and p in missing:  # its token went after it left, or before it joined
                            continue
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
        info: dict[str, Any] = {}
        for m in self._media:
            info.update(m.started())
        if self.scene is not None and self.scene.live is not None:
            info["live"] = self.scene.live.url
        self.status(op="started", startup_s=self.startup_wall_s, **info)

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
        self.event(t_ns, {"kind": kind, "robot": r, "detail": rec["detail"]})
        if proc:  # which process is a packing detail: reported, not recorded
            rec["process"] = proc
        self.failures.append(rec)
        self.status(op="event", **rec)
        if self.cfg.session.on_robot_failure == "stop":
            self.failed_stop = True
            self.stop_reason = f"robot {r} failed ({kind}) and on_robot_failure = stop"

    def service_failed(self, e: str, t_ns: int, kind: str, detail: str) -> None:
        """Service entity ``e`` raised, hung or lost its process: it runs no more (the robots no longer hear from
        it), recorded and reported as a robot's failure is; with ``on_robot_failure = "stop"`` the session ends."""
        if e in self.dead_services:
            return
        self.dead_services.add(e)
        self.next_wake[e] = None
        self.wom[e] = False
        self.inbox[e].clear()
        name = self.service_of[e]
        rec = {"service": name, "t_s": t_ns / 1e9, "kind": kind, "detail": detail[-2000:]}
        self.event(t_ns, {"kind": kind, "service": name,
                                                                      "detail": rec["detail"]})
        self.failures.append(rec)
        last = detail.strip().splitlines()[-1] if detail.strip() else ""
        self.status(op="notice", text=f"service {name} failed at sim t={t_ns / 1e9:.2f} s: {kind} ({last})")
        if self.cfg.session.on_robot_failure == "stop":
            self.failed_stop = True
            self.stop_reason = f"service {name} failed ({kind}) and on_robot_failure = stop"

    def _entity_failed(self, e: str, r: int, t_ns: int, kind: str, detail: str) -> None:
        """Entity ``e`` failed: its robot (``r``) or, for a service (``r`` < 0), the service."""
        if r >= 0:
            self.robot_failed(r, t_ns, kind, detail)
        else:
            self.service_failed(e, t_ns, kind, detail)

    def proc_failed(self, proc: str, t_ns: int, kind: str, detail: str) -> None:
        if proc not in self.live_procs:
            return
        self.live_procs.discard(proc)
        pid = self.pids.get(proc)
        if pid and kind in ("hung", "flooding"):  # it may go on sending: stop it
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        for r in self.procs[proc].robots:
            self.robot_failed(r, t_ns, kind, detail, proc)
        if self.procs[proc].kind == "service":
            for e in self.procs[proc].entities(self.plan.robots):
                self.service_failed(e, t_ns, kind, detail)

    # -- one quantum ---------------------------------------------------------------------------------
    def _deliver(self, t: int) -> None:
        items = self.deliveries.pop(t, None)
        if items:
            for handler, args in items:
                handler(t, *args)

    def _pins(self, t: int, e: str, pins: dict[str, Any]) -> None:
        """A delivery: the pin writes of a board's previous loop take effect, as its robot is wired."""
        self.counts["pin_writes"] += 1
        r = robot_of(e)
        if r in self.dead:
            return
        self.wiring[e].actuate(self.world, r, pins)

    def _due(self, t: int) -> dict[str, list[str]]:
        due: dict[str, list[str]] = defaultdict(list)
        for e in self.unplugged:  # what reached a module that is gone is lost
            self.inbox[e].clear()
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
        deadline = AwakeDeadline(hang)
        procs = self.procs
        wrong: dict[str, int] = defaultdict(int)  # answers of this quantum that were not the process's answer
        while waiting:
            if self.abort or os.getppid() != self.parent_pid:
                self.abort = True
                break
            # a process the launcher serves itself (a test driving the session) is waited for as long as it takes
            left = deadline.left() if any(not procs[p].inproc for p in waiting) else 0.2
            if left <= 0:
                for p in sorted(waiting):
                    if not procs[p].inproc:
                        away = (f" (not counting {deadline.stalled_s:.1f} s the world itself was stopped)"
                                if deadline.stalled_s else "")
                        self.proc_failed(p, t, "hung", f"no answer for the quantum at t={t / 1e9:.3f} s within "
                                                       f"{hang} s{away}")
                        waiting.discard(p)
                if waiting:
                    continue
                break
            try:
                key, data = self.q.get(timeout=min(0.2, left))
            except queue.Empty:
                continue
            if key.startswith("done/"):
                p = key[5:]
                if p not in waiting:
                    continue
                msg = _unpack_dict(data) if len(data) <= MAX_ANSWER_BYTES else None
                if msg is None or not isinstance(msg.get("ents"), dict) or msg.get("k") != self.k:
                    self.counts["malformed_done" if msg is None or not isinstance(msg.get("ents"), dict)
                                else "stale_done"] += 1
                    wrong[p] += 1
                    if wrong[p] > MAX_WRONG_ANSWERS or len(data) > MAX_ANSWER_BYTES:
                        waiting.discard(p)
                        why = (f"an answer of {len(data)} bytes" if len(data) > MAX_ANSWER_BYTES
                               else f"{wrong[p]} answers to the quantum at t={t / 1e9:.3f} s that were not its own")
                        self.proc_failed(p, t, "flooding", f"it sent {why}: failed alone, the others go on")
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
        if self._ticks_in:  # each entity's run: what it was given and what it answered (swarm-sitl replay)
            for e in sorted(self._ticks_in):
                reply = merged.get(e)
                self.rec.write(t, f"/ticks/{e}", "swarm_sitl.Tick", {
                    "k": self.k, "in": base64.b64encode(self._ticks_in[e]).decode(),
                    "out": None if reply is None else base64.b64encode(transport.pack(reply)).decode()})
            self._ticks_in.clear()
        for e in sorted(merged):
            r = self.ent_robot[e]
            if self.is_dead(e):
                continue
            res = merged[e]
            if not _valid_reply(res):
                self.counts["malformed_done"] += 1
                self._entity_failed(e, r, t, "malformed", f"unusable reply from {e}: {str(res)[:300]}")
                continue
            pins = res.get("pins")
            wiring = self.wiring.get(e)
            pins_ok = pins is None or (wiring is not None and wiring.valid(pins))
            if e in sensed:  # one record per board loop: what its pins read, and what it wrote
                pins_io = dict(sensed[e])
                if pins is not None and pins_ok:
                    pins_io.update(pins)
                self.rec.write(t, self._pins_topics[e], wiring.schema, pins_io)
            if res.get("err"):
                self._entity_failed(e, r, t, "raised", res["err"])
                continue
            if len(res.get("out", ())) > MAX_RUN_ITEMS:
                self.counts["flooded_runs"] += 1
                self._entity_failed(e, r, t, "flooding", f"{len(res['out'])} outputs in one run (at most "
                                                         f"{MAX_RUN_ITEMS}): failed alone, the others go on")
                continue
            w = res.get("wake")
            self.next_wake[e] = None if w is None else max(t + q, -(-w // q) * q)
            wm = res.get("wom")
            self.wom[e] = wm if isinstance(wm, list) and all(isinstance(x, str) for x in wm) else bool(wm)
            for item in res.get("out", ()):
                if not (isinstance(item, list | tuple) and item):
                    self.counts["malformed_items"] += 1
                else:
                    self._route(e, r, t, item)
            if pins is not None:
                if pins_ok:
                    self.deliver_at(t + q, self._pins, e, pins)
                else:
                    self.counts["malformed_pins"] += 1
        for m in self._media:
            m.end_outputs(t)

    def _route(self, e: str, r: int, t: int, item: list) -> None:
        """One output item to the medium that carries it, by (kind, sender role), then (kind, any role); an item no
        medium carries, or one its medium finds malformed, is counted and dropped."""
        kind = item[0]
        handler = self.routes.get((kind, self.ent_role[e])) if isinstance(kind, str) else None
        if handler is None and isinstance(kind, str):
            handler = self.routes.get((kind, "*"))
        if handler is None:
            self.counts["malformed_items"] += 1
            return
        try:
            handler(e, r, t, item)
        except (ValueError, TypeError, KeyError, IndexError, OverflowError):
            self.counts["malformed_items"] += 1

    def _log(self, e: str, r: int, t: int, item: list) -> None:
        """``["log", topic, {values}]`` from a robot's logic (``Robot.log``): recorded under ``/rNNN/log/<topic>``,
        then shown to the media and loop functions that score it."""
        _, topic, values = item
        if not (isinstance(topic, str) and topic.isidentifier() and isinstance(values, dict)):
            raise ValueError
        json.dumps(values, allow_nan=False)  # strict JSON only: NaN would make the recording unreadable
        self.rec.write(t, f"/r{r:03d}/log/{topic}", "swarm_sitl.Log", values)
        if self.scene is not None:
            self.scene.log(t, f"r{r:03d}", topic, values)
        for hook in self._log_hooks:
            hook.on_log(r, topic, values, t)

    def _service_log(self, e: str, r: int, t: int, item: list) -> None:
        """``["log", topic, {values}]`` from a service (``Service.log``): recorded under ``/svc/<name>/log/<topic>``;
        a fourth field names the registered schema to record it with (``register_schema``; unknown: malformed); then
        shown to the loop functions (``on_service_log``)."""
        _, topic, values, *schema = item
        name = schema[0] if schema else "swarm_sitl.Log"
        if not (isinstance(topic, str) and topic.isidentifier() and isinstance(values, dict)):
            raise ValueError
        if len(schema) > 1 or name not in SCHEMAS:
            raise ValueError
        json.dumps(values, allow_nan=False)
        self.rec.write(t, f"/{e}/log/{topic}", name, values)
        if self.scene is not None and name == "swarm_sitl.Log":  # a scene a service draws is not a log line
            self.scene.log(t, e, topic, values)
        service = e.removeprefix("svc/")
        for lf in self.loop_functions:
            lf.on_service_log(service, topic, values, t)

    def _service_stop(self, e: str, r: int, t: int, item: list) -> None:
        """``["stop", reason]`` from a service (``Service.stop_session``): the session ends after this quantum, as
        at its duration's end (a mission that is over, a test that has seen what it waited for)."""
        _, reason = item
        if not isinstance(reason, str):
            raise ValueError
        service = e.removeprefix("svc/")
        self.event(t, {"kind": "stopped", "service": service,
                                                                   "detail": reason[:2000]})
        self.stop_reason = self.stop_reason or f"service {service}: {reason[:200]}"

    def _service_fault(self, e: str, r: int, t: int, item: list) -> None:
        """``["fault", {fields of a [[faults]] entry}]`` from a service (a test's probe): injected at ``at_s``, no
        earlier than the next quantum, recorded as an event."""
        _, fields = item
        f = FaultCfg.model_validate(fields)  # a pydantic ValidationError is a ValueError: counted, dropped
        if any(r >= self.n for r in f.robot_ids()) or round(f.at_s * 1e9) < t + self.q_ns:
            raise ValueError
        self.inject_fault(f, t)
        detail = json.dumps({**f.model_dump(exclude_defaults=True), "kind": f.kind})
        who = {} if f.robot is None else {"robot": f.robot}
        self.event(t, {"kind": "fault_injected", **who, "service": e.removeprefix("svc/"), "detail": detail})

    def inject_fault(self, f: FaultCfg, t: int) -> None:
        """Fault ``f`` from ``f.at_s`` on, as if the config had listed it: a battery death, a firmware crash (its
        firmware raises at its first run from then on), or a fault a medium carries (CAN bus-off, CAN noise).
        ValueError if nothing in this session can carry it."""
        at = round(f.at_s * 1e9)
        if f.robot is not None and (why := self.plan.robots[f.robot].fault_problem(f)):
            raise ValueError(why)
        if f.kind == "battery_depleted":
            bisect.insort(self.battery_deaths, (at, f.robot))
        elif f.kind == "firmware_crash":
            self.crashes[f.robot] = min(at, self.crashes.get(f.robot, at))
            for role in self.plan.robots[f.robot].modules():
                ent = entity(f.robot, role)
                w = self.next_wake.get(ent)
                if ent in self.next_wake and f.robot not in self.dead:
                    self.next_wake[ent] = at if w is None else min(w, at)
        elif f.kind == "unplugged":
            self.deliver_at(-(-at // self.q_ns) * self.q_ns, self._unplug, f.robot, f.device)
        elif f.kind in ROBOT_FAULTS and not (f.kind == "sensor" and f.sensor == "uwb"):
            self.faults.inject(f, t)
        elif not any([m.inject_fault(f, t) for m in self._media]):  # every medium that carries it (a list, not any)
            on = "" if f.robot is None else f" on robot {f.robot}"
            raise ValueError(f"nothing in this session carries a {f.kind} fault{on}")

    def end_fault(self, f: FaultCfg, t: int) -> None:
        """End fault ``f`` (an entry given to ``inject_fault``) at ``t`` (ns) if it would last longer (a ground
        station's FAILURE_TYPE_OK): a robot's faulty sensor or wheel, or a fault a medium can end. ValueError if
        nothing can end it early."""
        if f.kind in ROBOT_FAULTS and not (f.kind == "sensor" and f.sensor == "uwb"):
            self.faults.end(f, t)
        elif not any([m.end_fault(f, t) for m in self._media]):
            raise ValueError(f"a {f.kind} fault cannot be ended early")

    def _unplug(self, t: int, r: int, device: str) -> None:
        """A delivery: robot ``r``'s ``device`` module is pulled out. It runs and hears no more (gone from the air and
        from its line), and its robot program's port learns the device is gone (``["uart:DEVICE", None]``: the
        ``sitl://`` port then raises ``SerialException``, as pyserial's does for a disconnected device)."""
        e = entity(r, device)
        if r in self.dead or e in self.unplugged:
            return
        self.unplugged.add(e)
        self.next_wake[e] = None
        self.wom[e] = False
        self.inbox[e].clear()
        for m in self._media:  # off the air
            m.unplug(r, device)
        if self.plan.robots[r].has_logic:
            self.to_inbox(t, entity(r, "logic"), [f"uart:{device}", None])
        self.event(t, {"kind": "unplugged", "robot": r, "detail": f"its {device} module was unplugged"})

    def _taps(self, cfg: Config) -> None:
        """Services that hear records (``ServiceSpec.hears``): every record whose topic matches one of their
        patterns also goes into their inbox, ``["rec", t, topic, values]``, for their next run."""
        kinds = {s.name: s.kind for s in cfg.services}
        self._heard: dict[str, list[tuple[str, bool]]] = {}  # topic -> the services that hear it (newest only?)
        self._latest: dict[str, dict[str, list]] = defaultdict(dict)  # service -> topic -> its newest record
        specs = {e: SERVICES.get(kinds[name]) for name, e in self.service_entities.items()}
        self._tapping = [(e, spec.hears, spec.hears_latest) for e, spec in specs.items()
                         if spec.hears or spec.hears_latest]
        if not self._tapping:
            return
        write_json = self.rec.write_json  # every record goes through it (``write`` encodes, then calls it)

        def tapped(t: int, topic: str, schema: str, data: bytes) -> None:
            write_json(t, topic, schema, data)
            if self._hearers(topic):
                self.overhear(t, topic, json.loads(data))

        self.rec.write_json = tapped  # type: ignore[method-assign]

    def _hearers(self, topic: str) -> list[tuple[str, bool]]:
        ents = self._heard.get(topic)
        if ents is None:
            ents = self._heard[topic] = []
            for e, every, latest in self._tapping:
                if any(fnmatch.fnmatchcase(topic, p) for p in every):
                    ents.append((e, False))
                elif any(fnmatch.fnmatchcase(topic, p) for p in latest):
                    ents.append((e, True))
        return ents

    def overhear(self, t: int, topic: str, payload: Any) -> None:
        """A record for the services that hear ``topic`` (``ServiceSpec.hears``, or only its newest record for
        ``hears_latest``); what the recorder passes on, and what a medium passes on without recording it (the faces'
        MAVLink to a ground station)."""
        if not self._tapping:
            return
        for e, latest in self._hearers(topic):
            if e in self.dead_services:
                continue
            if latest:
                self._latest[e][topic] = ["rec", t, topic, payload]
            else:
                self.inbox[e].append(["rec", t, topic, payload])

    def run(self) -> dict[str, Any]:
        q = self.q_ns
        world = self.world
        speed = self.cfg.session.speed
        poses_every = self.cfg.session.poses_every_quanta
        wall0 = time.monotonic()
        next_status = 0
        while self.stop_reason is None and not self.abort:
            t = self.k * q
            if t >= self.end_ns:
                break
            self._battery_deaths(t)
            self._deliver(t)
            for lf in self.loop_functions:
                lf.pre_step(t)
            for m in self._media:
                m.start_quantum(t)
            due = {p: ents for p, ents in self.faults.due_filter(t, self._due(t)).items() if p in self.live_procs}
            t_pub = time.perf_counter()
            sensed = self._publish_ticks(t, due)
            if self.k % poses_every == 0:
                self._record_poses(t)
            if self.scene is not None:
                self.scene.tick(t)
            world.step_quantum(t, q)
            self._take_releases()
            if due:
                results = self._collect(set(due), t)
                self.barrier.add((time.perf_counter() - t_pub) * 1e6)
                self._outputs(t, results, sensed, due)
                self._apply_deaths(t)
                self.ticks += 1
            else:
                self._drain_control(t)
            for m in self._media:
                m.advance(t)
            self.k += 1
            lag = None
            if speed != "max":
                ahead = (t + q) / 1e9 / float(speed) - (time.monotonic() - wall0)
                lag = max(0.0, -ahead)
                self.lag.add(lag)
            if t >= next_status:
                next_status += 1_000_000_000
                self.status(op="progress", t=(t + q) / 1e9, alive=self.n - len(self.dead), ticks=self.k, lag_s=lag)
            if lag == 0.0:
                time.sleep(ahead)
        self.sim_end_ns = self.k * q
        self.wall_s = time.monotonic() - wall0
        return self.result()

    def _battery_deaths(self, t: int) -> None:
        """Injected faults: the batteries that are empty by ``t``."""
        while self.battery_deaths and self.battery_deaths[0][0] <= t:
            at, r = self.battery_deaths.pop(0)
            self.world.deplete(r)
            self.robot_failed(r, t, "battery_depleted", f"battery exhausted at {at / 1e9:g} s: motors stopped, "
                                                        "radio silent")

    def _publish_ticks(self, t: int, due: dict[str, list[str]]) -> dict[str, dict]:
        """One tick to each due process: its entities' inboxes, and an LLC's pins as its robot is wired. Returns
        what each LLC's pins sensed (for its record)."""
        sensed: dict[str, dict] = {}
        for p in sorted(due):
            run: dict[str, Any] = {}
            for e in due[p]:
                self.wakeups[self.ent_role[e]] += 1
                entry: dict[str, Any] = {"in": self.inbox[e]}
                self.inbox[e] = []
                if self._latest and e in self._latest:  # a service that hears the newest record of each topic
                    newest = self._latest.pop(e)
                    entry["in"] = entry["in"] + [newest[k] for k in sorted(newest)]
                senses = self.service_senses.get(e)
                if senses:  # a service: the ground truth its kind is entitled to, at t
                    entry["sens"] = {k: SENSES[k](self.world, self._sensed_robots) if k in SENSES
                                     else self.radio_report() for k in senses}
                if self.faults.to_firmware and (items := self.faults.take_for(e)):  # a reboot, a drifting clock
                    entry["faults"] = items
                if self.crashes:  # a firmware crash injected while running reaches the robot's boards
                    at = self.crashes.get(self.ent_robot[e])
                    if at is not None and t >= at and self.ent_role[e] != "logic":
                        entry["crash_ns"] = at
                wiring = self.wiring.get(e)
                if wiring is not None:
                    r = robot_of(e)
                    entry["sens"], sensed[e] = wiring.sense(self.world, r, self.pin_inputs[r], r in self.ideal_pose)
                run[e] = entry
                if self._ticks_in is not None and e not in self.service_of:
                    self._ticks_in[e] = transport.pack(entry)
            self.tick_pub[p].put(transport.pack({"k": self.k, "t": t, "run": run}))
            self.proc_ticks += 1
        return sensed

    def _record_poses(self, t: int) -> None:
        world = self.world
        poses = {"x": np.round(world.pos[:, 0], 5).tolist(), "y": np.round(world.pos[:, 1], 5).tolist(),
                 "yaw": np.round(world.yaw, 5).tolist(), "alive": world.alive.tolist(), "led": world.led.tolist()}
        if self.carriers:
            poses["carried"] = [r in world.carried for r in range(self.n)]
        self.rec.write(t, "/world/poses", "swarm_sitl.Poses", poses)

    def _take_releases(self) -> None:
        """Robots that went down from their carriers in this quantum: recorded at their own time."""
        world = self.world
        for ev in world.released:
            rel = {k: ev[k] for k in ("robot", "carrier", "slot", "pose")}
            self.deliver_at(ev["t_ns"], self.record, "/world/releases", "swarm_sitl.Release", rel)
            self.releases.append({"t_s": ev["t_ns"] / 1e9, **rel})
        world.released.clear()

    def service_report(self) -> dict[str, Any]:
        """Each service's entry of ``summary.json``'s ``services``: its kind, whether it ran to the end, and its own
        figures (its ``summary()``). After ``shutdown``: the service processes report them then."""
        kinds = {s["name"]: s["kind"] for s in self.plan.config.get("services", [])}
        return {name: {"kind": kinds[name], "failed": e in self.dead_services, **self.module_stats.get(e, {})}
                for name, e in self.service_entities.items()}

    def firmware_report(self, robots: list[dict[str, Any]]) -> None:
        """Each robot model's own firmware entities' counters into its ``robots`` entry (``firmware``: role ->
        counters), for robots that have some. After ``shutdown``: the modules report their counters then."""
        for r, entry in enumerate(robots):
            rp = self.plan.robots[r]
            roles = () if rp.gateway is not None else self.robot_spec(r).own_roles(rp)
            if roles:
                entry["firmware"] = {role: self.module_stats.get(entity(r, role)) for role in roles}

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
        deadline = AwakeDeadline(self.cfg.session.hang_timeout_s, step_s=0.05)
        while waiting and not self.abort and deadline.left() > 0:  # abort: SIGTERM, they are gone
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
        """The session's radio figures, per robot and over all, from the media. Filled in after ``shutdown`` (the
        modules report their counters then)."""
        out: dict[str, Any] = {"per_robot": {}}
        for m in self._media:
            m.radio_report(out)
        return out

    def result(self) -> dict[str, Any]:
        out = {
            "sim_time_s": self.sim_end_ns / 1e9,
            "world_wall_s": self.wall_s,
            "quanta": self.k,
            "ticks": self.ticks,
            "messages": self.rec.count,
            "message_counts": dict(self.counts),
            "wakeups": dict(self.wakeups),
            "process_ticks": self.proc_ticks,
            "digest": self.rec.digest,
            "barrier_us_median": _round1(self.barrier.quantile(0.5)),
            "barrier_us_p99": _round1(self.barrier.quantile(0.99)),
            "wall_lag": self.lag.summary(),
            "releases": self.releases if self.carriers else None,
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
                 "motion": self.plan.robots[r].motion["kind"] if self.plan.robots[r].scripted else "simulated"}
                for r in range(self.n)
            ],
        }
        if self.faults.rows:
            out["faults"] = self.faults.report()
        sections: list[str] = []
        for lf in self.loop_functions:
            part = lf.summary()
            sections += list(part)
            out.update(part)
        out["study_sections"] = sections
        for m in self._media:
            m.report(out)
        return out

    def close(self) -> None:
        """Finish the recording and release the world and the media."""
        try:
            self.rec.finish()
        finally:
            if self.scene is not None and self.scene.live is not None:
                self.scene.live.close()
            self.world.close()
            for m in self._media:
                m.close()


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


def _round1(v: float | None) -> float | None:
    return None if v is None else round(v, 1)


class WallLag:
    """How far a paced session's simulated clock fell behind wall time, per quantum, in fixed memory."""

    def __init__(self) -> None:
        self.moments = Moments()
        self.late = 0
        self.hist = LogHistogram(lo=1e-6, decades=8)  # 1 us to 100 s

    def add(self, lag: float) -> None:
        self.moments.add(lag)
        self.late += lag > 0
        self.hist.add(lag)

    def summary(self) -> dict[str, Any] | None:
        """Quanta that ended late, and by how much (None for an unpaced session)."""
        m = self.moments
        if not m.n:
            return None
        p99 = self.hist.quantile(0.99) if self.late > m.n * 0.01 else 0.0
        return {"quanta": m.n, "late_share": round(self.late / m.n, 4), "max_ms": round(m.max * 1e3, 2),
                "p99_ms": round(float(p99 or 0.0) * 1e3, 2), "mean_ms": round(m.mean * 1e3, 3),
                "final_ms": round(m.last * 1e3, 2)}


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
