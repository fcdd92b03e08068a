"""``swarm-sitl join ENDPOINT --session NAME [--robot R | --host H]``: one robot's swarm logic, or all the processes
of a host of ``[[hosts]]``, run on this computer for a session that runs on another one (its config sets
``session.listen`` and gives the robot ``logic = "remote"``, or places robot groups and services on the host).

The joiner connects to the world over zenoh (peer mode, TCP, no scouting), asks it for the session's plan (the
``plan`` queryable), and is then the robot's logic process ``remote<R>`` as a local one would be
(``bridge.hosts.participant.serve``): it computes quantum k when the world's tick for k arrives, in simulated time, so
the robot behaves exactly as with its logic on the world's computer, and the recording is the same byte for byte.
The only wall-clock times here are the network's timeouts. A host's joiner starts the host's participant processes
(``python -m bridge.hosts.proc ... --endpoint``: each connects to the world itself, as a launcher's child connects to
its unix socket), supervises them as the launcher does its own, and holds a liveliness token per process
(``joined/<proc>``), so the world sees at once when this computer's join goes away.

Both ends of the exchange live here: the world's answer (``plan_offer``) and the joiner's checks of it.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from typing import Any, TextIO

import zenoh
from pydantic import ValidationError

from bridge.core import transport
from bridge.core.config import SessionCfg
from bridge.core.launcher import child_env, end_group, id_ranges
from bridge.core.plan import PROTOCOL, Plan, ProcPlan, code_fingerprint


class JoinError(Exception):
    """The joiner cannot join: the message says why, naming the endpoint, the session or the robot."""


def choose(offer: dict[str, Any], endpoint: str, session: str, robot: int | None) -> tuple[Plan, int, str]:
    """Check the world's offer against this joiner: the plan, the robot to run and its process name, or a
    ``JoinError`` saying why not (another version, a robot that is not remote, already joined, too late)."""
    plan, where = _offered_plan(offer, endpoint, session)
    remote = {p.robots[0]: p.name for p in plan.procs if p.remote and p.host is None}
    listed = ", ".join(map(str, sorted(remote)))
    if not remote:
        hosts = _hosts(plan)
        raise JoinError(f"{where} has no robot whose logic is remote (logic = \"remote\" in its config)"
                        + (f"; its hosts are {', '.join(hosts)}: join one with --host" if hosts else ""))
    if robot is None:
        if len(remote) > 1:
            raise JoinError(f"{where} has several remote robots ({listed}): choose one with --robot")
        robot = next(iter(remote))
    elif robot not in remote:
        raise JoinError(f"robot {robot} is not a remote robot of {where} (remote robots: {listed})")
    joinable = offer.get("joinable")
    if joinable is None:
        raise JoinError(f"{where} has already started: remote logic joins before the start "
                        "(within its session.startup_timeout_s)")
    if remote[robot] not in joinable:
        raise JoinError(f"robot {robot}'s logic has already joined {where} (a join on another computer?)")
    return plan, robot, remote[robot]


def choose_host(offer: dict[str, Any], endpoint: str, session: str, host: str) -> tuple[Plan, list[ProcPlan]]:
    """Check the world's offer against a host's joiner: the plan and the host's processes, or a ``JoinError`` saying
    why not (another version, not a host of the session, already joined, too late)."""
    plan, where = _offered_plan(offer, endpoint, session)
    procs = [p for p in plan.procs if p.host == host]
    if not procs:
        hosts = _hosts(plan)
        raise JoinError(f"{host!r} is not a host of {where} (hosts: {', '.join(hosts) or 'none'})")
    joinable = offer.get("joinable")
    if joinable is None:
        raise JoinError(f"{where} has already started: a host joins before the start (within its "
                        "session.startup_timeout_s)")
    if any(p.name not in joinable for p in procs):
        raise JoinError(f"host {host!r} has already joined {where} (a join on another computer?)")
    return plan, procs


def _offered_plan(offer: dict[str, Any], endpoint: str, session: str) -> tuple[Plan, str]:
    """The plan of a world's offer from this version and session (a ``JoinError`` otherwise), and how to name it."""
    where = f"session {session!r} at {endpoint}"
    if offer.get("version") != code_fingerprint() or offer.get("protocol") != PROTOCOL:
        raise JoinError(f"{where} runs swarm-sitl {offer.get('version')} (protocol {offer.get('protocol')}), this "
                        f"computer has {code_fingerprint()} (protocol {PROTOCOL}): install the same version, the "
                        "same code, on both (the part after + is a hash of the code)")
    if offer.get("session") != session:
        raise JoinError(f"the session at {endpoint} is {offer.get('session')!r}, not {session!r}")
    try:
        return Plan.from_json(offer["plan"]), where
    except (KeyError, TypeError, ValueError) as e:
        raise JoinError(f"{where} sent an unusable plan ({e!r})") from None


def _hosts(plan: Plan) -> list[str]:
    """The session's hosts, in the order of its ``[[hosts]]``."""
    return list(dict.fromkeys(p.host for p in plan.procs if p.host is not None))


def fetch_offer(endpoint: str, session: str, timeout_s: float) -> tuple[zenoh.Session, dict[str, Any]]:
    """Connect to the world at ``endpoint`` in the session's namespace and ask for the plan, retrying until
    ``timeout_s`` (wall time: the session may still be starting). The open session and the world's offer."""
    deadline = time.monotonic() + timeout_s
    ns = transport.namespace_for(session)
    try:
        zs = transport.open_session(endpoint, ns, listen=False, connect_timeout_s=timeout_s)
    except zenoh.ZError:
        raise JoinError(f"nobody answers at {endpoint} within {timeout_s:g} s: is `swarm-sitl run` running there, "
                        "with that session.listen (and the port open in the firewall)?") from None
    deadline = max(deadline, time.monotonic() + 2.0)  # connected late: still give the world time to answer
    try:
        others: list[str] = []
        while True:
            left = deadline - time.monotonic()
            for reply in zs.get(transport.PLAN_KEY, timeout=max(0.2, min(2.0, left))):
                if reply.ok is not None:
                    try:
                        offer = json.loads(reply.ok.payload.to_bytes())
                    except ValueError:
                        raise JoinError(f"the session at {endpoint} sent an unreadable plan") from None
                    if isinstance(offer, dict):
                        return zs, offer
            # Nobody by that name: which sessions are there? Asked again until some session answers, as the world
            # accepts connections a moment before it answers (it listens, then declares its plan's queryable).
            if not others:
                others = sessions_at(endpoint)
                if others and session not in others:  # (ours among them: its answer was late, ask again)
                    raise JoinError(f"no session {session!r} at {endpoint}: the session there is "
                                    f"{' and '.join(map(repr, others))} (--session)")
            if time.monotonic() >= deadline:
                raise JoinError(f"{endpoint} accepts connections but no swarm-sitl session {session!r} answers there "
                                f"within {timeout_s:g} s")
            time.sleep(0.2)
    except BaseException:
        zs.close()
        raise


def sessions_at(endpoint: str) -> list[str]:
    """The names of the sessions answering at ``endpoint`` (for a clear error when --session names another)."""
    try:
        zs = transport.open_session(endpoint, None, listen=False, connect_timeout_s=2.0)
    except zenoh.ZError:
        return []
    try:
        names = set()
        for reply in zs.get(f"swarm-sitl/*/{transport.PLAN_KEY}", timeout=2.0):
            if reply.ok is not None:
                try:
                    names.add(str(json.loads(reply.ok.payload.to_bytes())["session"]))
                except (ValueError, KeyError, TypeError):
                    continue
        return sorted(names)
    finally:
        zs.close()


class _Tracked:
    """The logic host, noting how often and until when it ran (for the joiner's last line)."""

    def __init__(self, host: Any) -> None:
        self.host = host
        self.runs = 0
        self.t_ns: int | None = None

    def run(self, ent: str, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        self.runs += 1
        self.t_ns = t_ns
        return self.host.run(ent, t_ns, inputs)

    def stats(self) -> dict[str, dict]:
        return self.host.stats()

    def stop(self) -> None:
        self.host.stop()


INTERRUPTED, DROPPED, WORLD_GONE, ENDED = 130, 4, 5, 6  # why a joiner left, besides the world's stop (0)


class _Watch:
    """What ends a joiner besides the world's stop, polled by ``serve`` after every tick and idle second (a host's
    joiner polls it itself): Ctrl-C or SIGTERM, the world dropping one of its processes (it hung or died, as the world
    saw it), the session's end, or the world unreachable for longer than ``world_timeout_s``. It holds the joiner's
    liveliness token per process (``joined/<proc>``: the world sees this computer go), and prints the line saying the
    world accepted the join once it has accepted every process."""

    def __init__(self, zs: zenoh.Session, procs: dict[str, tuple[int, ...]], world_timeout_s: float, out: TextIO,
                 joined_line: str) -> None:
        self.procs, self.world_timeout_s, self.out = procs, world_timeout_s, out
        self.robots = {r for robots in procs.values() for r in robots}
        self.joined_line = joined_line
        self.waiting = set(procs)  # processes the world has not said joined yet
        self.joined = False
        self.signal: int | None = None
        self.dropped: dict[str, dict[str, Any]] = {}  # process -> the world's failure event naming it
        self.failed: dict[int, dict[str, Any]] = {}  # our robot -> its failure; its process goes on until the stop
        self.started = False  # the world said every process has joined
        self.ended = False
        self.left = False  # the world took our leaving before the start (its notice naming our process)
        self.world_lost_at: float | None = None
        self._lock = threading.Lock()
        self.control = transport.publisher(zs, "control")  # to tell the world we leave (it fails the robot at once)
        self._tokens = [zs.liveliness().declare_token(f"{transport.JOINED_KEY}/{p}") for p in procs]
        self._subs = [zs.declare_subscriber("status", self._status),
                      zs.liveliness().declare_subscriber(transport.WORLD_KEY, self._world, history=True)]

    def _status(self, sample: zenoh.Sample) -> None:
        try:
            msg = transport.unpack(sample.payload.to_bytes())
        except Exception:
            return
        if not isinstance(msg, dict):
            return
        op = msg.get("op")
        if op == "notice" and msg.get("joined") in self.procs:
            with self._lock:
                self.waiting.discard(msg["joined"])
                if not self.waiting and not self.joined:
                    self.joined = True
                    print(self.joined_line, file=self.out, flush=True)
        elif op == "notice" and msg.get("left") in self.procs:
            self.left = True
        elif op == "event" and msg.get("robot") in self.robots:
            if msg.get("process") in self.procs:
                self.dropped[msg["process"]] = msg
            else:
                self.failed[msg["robot"]] = msg
        elif op == "started":
            self.started = True
        elif op == "end":
            self.ended = True

    def leave(self, procs: list[str], why: str) -> None:
        """Tell the world these processes leave, and wait until it took it (an event or notice naming one of them), so
        that it fails their robots at once rather than as hung; ``world_timeout_s`` bounds the wait on a lost world."""
        for p in procs:
            self.control.put(transport.pack({"op": "dead", "proc": p, "detail": why}))
        until = time.monotonic() + self.world_timeout_s
        while (not any(p in self.dropped for p in procs) and not any(r in self.failed for p in procs
                                                                      for r in self.procs[p])
               and not self.left and not self.ended and self.world_lost_at is None and time.monotonic() < until):
            time.sleep(0.02)

    def _world(self, sample: zenoh.Sample) -> None:
        self.world_lost_at = time.monotonic() if sample.kind == zenoh.SampleKind.DELETE else None

    def on_signal(self, signum: int, frame: Any) -> None:
        self.signal = signum

    def __call__(self) -> int | None:
        if self.signal is not None:
            return INTERRUPTED
        if self.dropped:
            return DROPPED
        if self.ended:
            return ENDED
        if self.world_gone():
            return WORLD_GONE
        return None

    def world_gone(self) -> bool:
        """The world has been unreachable for longer than ``world_timeout_s``."""
        lost = self.world_lost_at
        return lost is not None and time.monotonic() - lost > self.world_timeout_s


def join(endpoint: str, session: str, robot: int | None = None, timeout_s: float = 10.0,
         world_timeout_s: float = 10.0, out: TextIO = sys.stdout, host: str | None = None) -> int:
    """Join the session as robot ``robot``'s logic, or as host ``host`` (all its processes), and run until the session
    ends. The exit code: 0 the world said stop, 1 the world dropped a process of ours, went away or the session ended
    without us, 130 interrupted. A ``JoinError`` when it cannot join (nobody answers, another session or version, not
    a remote robot or host)."""
    try:
        SessionCfg(listen=endpoint)
    except ValidationError as e:
        raise JoinError(f"ENDPOINT: {e.errors()[0]['msg'].removeprefix('Value error, ')}") from None
    try:
        ns = transport.namespace_for(session)
    except ValueError:
        raise JoinError("--session: the session's name (its config's session.name) must not be empty") from None
    if host is not None and robot is not None:
        raise JoinError("--robot and --host: a join runs one remote robot's logic or one host's processes")
    zs, offer = fetch_offer(endpoint, session, timeout_s)
    if host is not None:
        try:
            plan, procs = choose_host(offer, endpoint, session, host)
            return _run_host(zs, endpoint, ns, session, host, plan, procs, world_timeout_s, out)
        finally:
            zs.close()
    code = 1
    try:
        plan, robot, proc = choose(offer, endpoint, session, robot)
        rp = plan.robots[robot]
        from bridge.hosts.logic import LogicHost

        try:
            logic = _Tracked(LogicHost(plan, (robot,)))
        except Exception as e:
            raise JoinError(f"robot {robot}'s logic ({rp.behaviour!r}) does not start on this computer: {e}") from None
        watch = _Watch(zs, {proc: (robot,)}, world_timeout_s, out,
                       f"swarm-sitl join: robot {robot}'s logic ({rp.behaviour}) joined session {session!r} at "
                       f"{endpoint}; it runs in the session's simulated time until the session ends")
        old = {s: signal.signal(s, watch.on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            from bridge.hosts.participant import serve

            code = serve(proc, endpoint, ns, logic, session=zs, watch=watch)
        except TimeoutError as e:
            raise JoinError(f"session {session!r} at {endpoint} stopped answering while joining ({e})") from None
        finally:
            for s, h in old.items():
                signal.signal(s, h)
        if code != 0:  # the world will not say stop: end the robot's thread here
            with contextlib.suppress(Exception):
                logic.stop()
        ran = (f"{logic.runs} runs, the last at sim t={logic.t_ns / 1e9:.3f} s" if logic.t_ns is not None
               else "it never ran")
        if code == 0:
            print(f"swarm-sitl join: session {session!r} ended (the world said stop); robot {robot}'s logic: {ran}"
                  + (f"; the robot failed at sim t={watch.failed[robot]['t_s']:.2f} s "
                     f"({watch.failed[robot]['kind']})" if watch.failed else ""), file=out, flush=True)
        elif code == INTERRUPTED:
            name = signal.Signals(watch.signal or signal.SIGINT).name
            watch.leave([proc], f"swarm-sitl join on another computer stopped ({name})")
            print(f"swarm-sitl join: interrupted ({name}); robot {robot} fails in session {session!r}; its logic: "
                  f"{ran}", file=out, flush=True)
        elif code == DROPPED:
            d = watch.dropped[proc]
            print(f"swarm-sitl join: the world dropped robot {robot}'s logic at sim t={d.get('t_s', 0):.2f} s "
                  f"({d.get('kind')}: {str(d.get('detail', '')).strip()}); the session goes on without it",
                  file=out, flush=True)
        elif code == WORLD_GONE:
            print(f"swarm-sitl join: lost the world at {endpoint} for more than {world_timeout_s:g} s: session "
                  f"{session!r} ended without a stop for robot {robot}, or the network is down; its logic: {ran}",
                  file=out, flush=True)
        else:
            print(f"swarm-sitl join: session {session!r} ended without a stop for robot {robot}; its logic: {ran}",
                  file=out, flush=True)
        return {0: 0, INTERRUPTED: 130}.get(code, 1)
    finally:
        zs.close()


def _run_host(zs: zenoh.Session, endpoint: str, ns: str, session: str, host: str, plan: Plan, procs: list[ProcPlan],
              world_timeout_s: float, out: TextIO) -> int:
    """Start the host's processes here, each connecting to the world at ``endpoint``, and supervise them as the
    launcher does its own: a process that dies is reported to the world (its robots fail at once), one the world
    dropped is ended; all of them end on Ctrl-C or SIGTERM (the world is told), or when the world is gone. Returns
    when every process has ended: 0 all ended on the world's stop, 1 one did not, 130 interrupted."""
    import shutil
    import tempfile
    from pathlib import Path

    work = Path(tempfile.mkdtemp(prefix=f"swarm-sitl-join-{host}-"))
    (work / "plan.json").write_text(json.dumps(plan.to_json()))
    robots = sorted(r for p in procs for r in p.robots)
    what = ", ".join(f"{p.name} ({p.kind}" + (f": robots {id_ranges(p.robots)})" if p.robots else ")") for p in procs)
    watch = _Watch(zs, {p.name: p.robots for p in procs}, world_timeout_s, out,
                   f"swarm-sitl join: host {host!r} joined session {session!r} at {endpoint} with {len(procs)} "
                   f"processes ({what}); they run in the session's simulated time until the session ends")
    old = {s: signal.signal(s, watch.on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    children: dict[str, subprocess.Popen] = {}
    try:
        for p in procs:
            with open(work / f"{p.name}.log", "wb") as log:
                children[p.name] = subprocess.Popen(
                    [sys.executable, "-m", "bridge.hosts.proc", p.kind, "--plan", str(work / "plan.json"),
                     "--endpoint", endpoint, "--namespace", ns, "--out", str(work), "--proc", p.name,
                     "--parent-pid", str(os.getpid())],
                    stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True,
                    env=child_env())
        exits = _supervise_host(watch, children, work)
    finally:
        for p in children.values():
            end_group(p)
        for s, h in old.items():
            signal.signal(s, h)
    ended_here = [p for p, c in exits.items() if c is None]  # still running: ended above
    exits = {p: children[p].returncode if c is None else c for p, c in exits.items()}
    if watch.signal is not None:
        name = signal.Signals(watch.signal).name
        watch.leave(ended_here, f"swarm-sitl join on host {host} stopped ({name})")
        print(f"swarm-sitl join: interrupted ({name}); host {host!r}'s robots ({id_ranges(robots)}) fail in session "
              f"{session!r}", file=out, flush=True)
        return 130
    bad = {p: c for p, c in exits.items() if c != 0}
    if bad and not watch.started:  # a process died before the start: the host leaves whole (the world waits again)
        watch.leave([p.name for p in procs], f"a process of host {host} did not start on its computer")
        print(f"swarm-sitl join: host {host!r}: " + ", ".join(f"{p} exited {c}" for p, c in sorted(bad.items())
                                                                if p not in ended_here)
              + f" before the session started; see {work}", file=out, flush=True)
        return 1
    failed = sorted(watch.failed) + sorted(r for p in watch.dropped for r in watch.procs[p])
    if not bad:
        shutil.rmtree(work, ignore_errors=True)
        print(f"swarm-sitl join: session {session!r} ended (the world said stop); host {host!r} ran "
              f"{len(procs)} processes" + (f"; robots {id_ranges(failed)} failed" if failed else ""), file=out,
              flush=True)
        return 0
    why = ("the world dropped " + ", ".join(sorted(watch.dropped)) if watch.dropped else
           f"lost the world at {endpoint} for more than {world_timeout_s:g} s" if watch.world_gone() else
           "processes ended without the world's stop")
    print(f"swarm-sitl join: host {host!r}: {why}; exits " + ", ".join(f"{p} {c}" for p, c in sorted(bad.items()))
          + f"; logs in {work}", file=out, flush=True)
    return 1


def _supervise_host(watch: _Watch, children: dict[str, subprocess.Popen], work: Any) -> dict[str, int | None]:
    """Until every child has ended (or Ctrl-C, or the world is gone): report a child that died to the world, end one
    it dropped. Each child's exit code (None: still running, ended by the caller)."""
    exits: dict[str, int | None] = dict.fromkeys(children)
    while any(c is None for c in exits.values()):
        if watch.signal is not None or watch.world_gone():
            break
        for p, child in children.items():
            if exits[p] is not None:
                continue
            if p in watch.dropped:  # the world no longer waits for it (hung): it will never hear a stop
                exits[p] = end_group(child)
            elif (code := child.poll()) is not None:
                exits[p] = code
                if code != 0 and not watch.started:  # the host cannot start: leave, to be joined again whole
                    return exits
                if code != 0 and not watch.ended:  # it died: its robots fail at once
                    watch.control.put(transport.pack({"op": "dead", "proc": p, "detail": f"exit code {code} on "
                                                      f"another computer; see {work}/{p}.log there"}))
        time.sleep(0.05)
    return exits

