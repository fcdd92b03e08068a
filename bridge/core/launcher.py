"""The launcher: starts one session's processes, supervises them, shows progress, writes the summary.

It owns the terminal: Ctrl-C (or SIGTERM, or SIGHUP when the terminal closes, unless under ``nohup``) asks the world
to stop at the end of the current quantum and finish the recording; a second Ctrl-C kills everything at once (the
world gets SIGTERM, so it still finishes the recording, as when the launcher dies) and skips the plot. A closed
stdout or stderr never stops it. A child that
dies is reported to the world, which applies the failure policy. Children are in their own process groups and die
with the launcher (PR_SET_PDEATHSIG), so no process of a session outlives it. A remote logic process
(``logic = "remote"``) or a host's (``[[hosts]]``) is not its child: it joins from another computer (``swarm-sitl
join``, whose command the launcher prints, or for a host with a ``launch`` command runs it: that command is its
child, ended with the session or with the launcher (``bridge.hosts.tethered``), and its failure fails the host's
processes), and the world watches it (its
timeouts, ``startup_timeout_s`` and ``hang_timeout_s``, and the joiner's liveliness).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import queue
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from bridge.core import transport
from bridge.core.config import ConfigError, config_warnings, load_config
from bridge.core.plan import Plan, make_plan
from bridge.core.recorder import NotARecording, Recovered, recover_in_place
from bridge.core.registry import PREFLIGHT, STUDIES

# One worker thread per zenoh runtime: a session runs tens of processes on a few cores, and fewer
# runtime threads mean fewer context switches per quantum (about 5% faster at 10 robots, measured).
ZENOH_RUNTIME = ("(rx: (worker_threads: 1), tx: (worker_threads: 1), app: (worker_threads: 1), "
                 "acc: (worker_threads: 1), net: (worker_threads: 1))")


@dataclass
class Child:
    name: str
    kind: str
    popen: subprocess.Popen
    robots: tuple[int, ...] = ()
    procs: tuple[str, ...] = ()  # a host's launch command ("host"): the session's processes it runs there
    exit_code: int | None = None
    cpu_s: float = 0.0
    maxrss_kb: int = 0
    expected_exit: bool = False


@dataclass
class SessionResult:
    code: int
    summary: dict[str, Any]
    out_dir: Path
    children: list[Child] = field(default_factory=list)


def say(stream: TextIO | None, text: str) -> bool:
    """Write ``text`` for the user and flush it; False if the stream is gone (a closed pipe: ``| tee`` died with
    the same Ctrl-C; a hung-up terminal). Then it, and stdout or stderr if they are the same file, are pointed at
    /dev/null, so no later write (nor Python's flush of sys.stdout at exit) raises again. A lost line must never
    cost a session its stop, its summary or its recording."""
    if stream is None:
        return False
    try:
        stream.write(text)
        stream.flush()
    except (OSError, ValueError):  # EPIPE, EIO; ValueError: the stream was closed
        output_gone(stream)
        return False
    return True


def output_gone(stream: TextIO) -> None:
    """Point the file descriptor behind ``stream`` (and behind sys.stdout and sys.stderr, if the same file) at
    /dev/null: what is still buffered, and whatever is written later, goes nowhere instead of failing."""
    try:
        fd = stream.fileno()
        gone = os.fstat(fd)
    except (OSError, ValueError, AttributeError):
        return
    fds = {fd}
    for std in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError, AttributeError):
            st = os.fstat(std.fileno())
            if (st.st_dev, st.st_ino) == (gone.st_dev, gone.st_ino):
                fds.add(std.fileno())
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for f in fds:
            os.dup2(devnull, f)
    finally:
        os.close(devnull)


class _Progress:
    def __init__(self, stream: TextIO | None, name: str, duration: float, robots: int) -> None:
        self.stream = stream
        self.tty = bool(stream and stream.isatty())
        self.name, self.duration, self.robots = name, duration, robots
        self.last_line_t = -1e9

    def _write(self, text: str) -> None:
        if not say(self.stream, text):
            self.stream = None  # gone: no more lines

    def update(self, sim_t: float, rtf: float, alive: int, lag_s: float | None = None) -> None:
        if not self.stream:
            return
        line = (f"[{self.name}] sim {sim_t:7.1f} / {self.duration:.1f} s   rtf {rtf:6.2f}x   "
                f"robots alive {alive}/{self.robots}")
        if lag_s is not None:  # a paced session: how far the simulated clock is behind wall time
            line += f"   lag {lag_s * 1e3:5.1f} ms"
        if self.tty:
            self._write("\r" + line)
        elif sim_t - self.last_line_t >= 10 or sim_t >= self.duration:
            self.last_line_t = sim_t
            self._write(line + "\n")

    def note(self, text: str) -> None:
        if self.stream:
            self._write(("\n" if self.tty else "") + text + "\n")


class _Hurry(BaseException):  # like KeyboardInterrupt, which `except Exception` lets through
    """Raised by a Ctrl-C (or SIGTERM) that comes while the launcher draws the plot: be done at once."""


class _Stops:
    """The launcher's Ctrl-C and SIGTERM handler, from the session's start until its summary is written.

    The first asks the world to stop (``used`` = 1 once asked); any further one ("Ctrl-C again") means be done at
    once: stop the session's processes now, skip the plot, or abandon it (``raising``: while it is drawn)."""

    def __init__(self, stop: Callable[[], bool] | None = None) -> None:
        self.count = 0
        self.used = 0
        self.last: int | None = None
        self.raising = False
        self.stop = stop

    def asked(self) -> bool:
        """Whether a stop was asked: a Ctrl-C, or the ``stop`` hook saying so (taken as a first Ctrl-C)."""
        if not self.count and self.stop is not None and self.stop():
            self.count = 1
        return bool(self.count)

    def __call__(self, signum: int, frame: Any) -> None:
        self.count += 1
        self.last = signum
        if self.raising:
            self.raising = False
            raise _Hurry

    def hurry(self) -> bool:
        return self.count > self.used


# the stop hook of the sessions run in this context that are given none (``stopping_when``)
_STOP_WHEN: ContextVar[Callable[[], bool] | None] = ContextVar("session_stop", default=None)


@contextlib.contextmanager
def stopping_when(stop: Callable[[], bool]) -> Iterator[None]:
    """Give ``stop`` to the sessions run in this context (thread) that are not given one: code that runs a session
    for someone else (an experiment's trial on a cluster's worker) stops it without reaching into that code."""
    token = _STOP_WHEN.set(stop)
    try:
        yield
    finally:
        _STOP_WHEN.reset(token)


def _stop_signals() -> tuple[int, ...]:
    """The signals that stop a session: Ctrl-C, SIGTERM, and SIGHUP unless it is ignored (``nohup``: the user asked
    the session to outlive the terminal)."""
    hup = () if signal.getsignal(signal.SIGHUP) is signal.SIG_IGN else (signal.SIGHUP,)
    return (signal.SIGINT, signal.SIGTERM, *hup)


def on_main_thread() -> bool:
    """Whether this is the main thread: the only one that can take Ctrl-C and SIGTERM (install signal handlers)."""
    return threading.current_thread() is threading.main_thread()


def run_session(config_path: str, overrides: dict[str, Any] | None = None, out_dir: str = "runs/latest",
                progress: TextIO | None = sys.stderr, plot: bool = True,
                stop: Callable[[], bool] | None = None, hosted: dict[str, Any] | None = None) -> SessionResult:
    """Run the session of ``config_path`` into ``out_dir``. ``stop`` (default: the one ``stopping_when`` set, if
    any), polled while the session runs, acts as a first Ctrl-C once it returns true: the session stops cleanly and
    writes its summary (interrupted).

    ``hosted`` (process name -> a participant host, ``bridge.hosts.participant.Host``) serves those processes of the
    plan in this process, each in a thread of its own, instead of starting them: a test that drives a session (the
    pytest plugin's probe). The world waits for their answers without a hang timeout; a host with an ``ended()``
    method is told when its process stops serving."""
    cfg = load_config(config_path, overrides)
    plan = make_plan(cfg, config_path)
    hosted = dict(hosted or {})
    if hosted:
        names = {p.name for p in plan.procs if not p.remote}
        if unknown := sorted(set(hosted) - names):
            raise ValueError(f"hosted: the plan has no local process {', '.join(unknown)}")
        plan.procs = [dataclasses.replace(p, inproc=True) if p.name in hosted else p for p in plan.procs]
    try:  # random, or for a session that remote logic joins, its name's (the joiner knows only that)
        namespace = transport.namespace_for(cfg.session.name if cfg.session.listen else None)
    except ValueError as e:
        raise ConfigError(f"{config_path}: {e}") from None
    if progress is not None:
        for w in config_warnings(cfg):
            say(progress, f"{config_path}: warning: {w}\n")
    for _, check in PREFLIGHT.items():  # e.g. a real device that does not answer stops the session before it starts
        check(cfg, config_path)
    if cfg.session.listen and (why := _cannot_listen(cfg.session.listen)):  # before anything starts, as devices
        raise ConfigError(f"{config_path}: session.listen: cannot listen on {cfg.session.listen}: {why}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for stale in ("session.mcap", "session.mcap.damaged", "summary.json", "world_result.json", "trajectories.png",
                  "plan.json"):
        (out / stale).unlink(missing_ok=True)
    logs = out / "logs"
    shutil.rmtree(logs, ignore_errors=True)
    logs.mkdir()
    ports: list[str] = []  # a pseudo-terminal link is a path the user chose, relative to the output directory
    for i, rp in enumerate(plan.robots):
        if rp.xbee and rp.xbee.get("pty"):
            rp.xbee["pty"] = str((out / rp.xbee["pty"].replace("{id}", str(rp.id))).absolute())
            ports.append(f"{rp.name} XBee (API {rp.xbee['api_mode']}, {rp.xbee['baud']} baud): {rp.xbee['pty']}")
        if rp.slcan_pty:
            plan.robots[i] = rp = dataclasses.replace(
                rp, slcan_pty=str((out / rp.slcan_pty.replace("{id}", str(rp.id))).absolute()))
            ports.append(f"{rp.name} CAN bus (slcan, {cfg.can.bitrate} bit/s): {rp.slcan_pty}")
        ptys = {k: v for k, v in rp.options.items() if k.endswith("_pty") and isinstance(v, str) and v}
        if ptys:  # a robot model's own modules on pseudo-terminals (RobotGroup.model_ptys)
            ptys = {k: str((out / v.replace("{id}", str(rp.id))).absolute()) for k, v in ptys.items()}
            plan.robots[i] = rp = dataclasses.replace(rp, options={**rp.options, **ptys})
            ports += [f"{rp.name} {k.removesuffix('_pty')}: {v}" for k, v in ptys.items()]
    plan_path = out / "plan.json"
    plan_path.write_text(json.dumps(plan.to_json(), indent=1))
    session_dir = tempfile.mkdtemp(prefix="swarm-sitl-")
    endpoint = transport.endpoint_for(session_dir)
    prog = _Progress(progress, cfg.session.name, cfg.session.duration_s, len(plan.robots))
    remote = sum(p.remote or p.inproc for p in plan.procs)  # processes that are not the launcher's children

    def spawn(role: str, name: str) -> subprocess.Popen:
        log = open(logs / f"{name}.log", "wb")  # noqa: SIM115 - owned by the child
        cmd = [sys.executable, "-m", "bridge.hosts.proc", role, "--plan", str(plan_path), "--session-dir", session_dir,
               "--namespace", namespace, "--out", str(out), "--proc", name, "--parent-pid", str(os.getpid())]
        p = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                             start_new_session=True, env=child_env())
        log.close()
        return p

    stops = _Stops(stop if stop is not None else _STOP_WHEN.get())
    # Ctrl-C, SIGTERM and SIGHUP (its terminal closed; not under nohup, which ignores it) stop the session; a session
    # run from another thread (an experiment's trial on a Dask worker) cannot take them: it ends with the process it
    # runs in, or when its stop hook says so
    old = {s: signal.signal(s, stops) for s in _stop_signals()} if on_main_thread() else {}
    try:
        res = _supervise(cfg, plan, out, logs, spawn, stops, endpoint, namespace, session_dir, prog, ports, remote,
                         plot, hosted)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    _pass_on(stops.last, old)
    return res


@dataclass
class _Watch:
    """What the launcher knows of a running session: its processes, when it started, how it ended."""

    t_launch: float
    children: list[Child] = field(default_factory=list)  # the world first
    served: _Served | None = None  # the processes the launcher serves itself
    t_started: float | None = None  # when the world said every process had joined
    last_sim: float = 0.0  # the simulated time of the last progress report
    world_code: int | None = None
    interrupted: bool = False
    startup_error: str | None = None
    stopped_since: dict[str, float] = field(default_factory=dict)  # children seen stopped (SIGSTOP) in start-up
    next_state_check: float = 0.0


def _supervise(cfg, plan: Plan, out: Path, logs: Path, spawn, stops: _Stops, endpoint: str, namespace: str,
               session_dir: str, prog: _Progress, ports: list[str], remote: int, plot: bool,
               hosted: dict[str, Any]) -> SessionResult:
    """Start the session's processes, supervise them until the world ends, tear down, write the summary."""
    w = _Watch(time.monotonic())
    session = None
    status_q: queue.SimpleQueue = queue.SimpleQueue()
    served = w.served = _Served()
    try:
        world = Child("world", "world", spawn("world", "world"))
        w.children.append(world)
        w.startup_error = _await_endpoint(cfg, w, Path(session_dir) / "zenoh.sock", w.t_launch, logs, stops)
        if w.startup_error or stops.asked():
            raise _Abort
        session = transport.open_session(endpoint, namespace, listen=False)
        _sub = transport.queue_subscriber(session, "status", status_q)
        control = transport.publisher(session, "control")
        for line in join_commands(cfg.session.name, cfg.session.listen, plan, cfg.hosts):  # the world listens now
            prog.note(f"[{cfg.session.name}] {line}")
        for h in cfg.hosts:
            if h.launch is not None:  # started by its command; otherwise by the user, as printed
                w.children.append(_launch_host(cfg, h, plan, logs))
        for p in plan.procs:
            if p.inproc:  # served here, by the caller's host
                served.start(p.name, hosted[p.name], endpoint, namespace)
            elif not p.remote:  # a remote process is started on its own computer; the world watches it
                w.children.append(Child(p.name, p.kind, spawn(p.kind, p.name), p.robots))
        _watch(cfg, w, status_q, control, logs, stops, prog, ports, remote)
    except _Abort:
        w.interrupted = bool(stops.count)
        stops.used = min(stops.count, 1)
    finally:
        try:
            _teardown(w, stops, session, session_dir)
        finally:
            served.end()
    wall = time.monotonic() - w.t_launch
    if w.world_code is None and w.children:
        w.world_code = w.children[0].exit_code  # the world, reaped during teardown
    return _finish(cfg, plan, out, w.children, w.world_code, w.interrupted, wall, w.t_started, w.t_launch, prog,
                   plot, w.startup_error, stops)


class _Served:
    """The processes the launcher serves itself (``run_session(hosted=...)``), each answering the world's ticks in a
    thread of its own until the session is over."""

    def __init__(self) -> None:
        self.over = threading.Event()
        self.threads: list[threading.Thread] = []
        self.told: set[str] = set()
        self.why: dict[str, str] = {}  # a served process's thread that raised: what it raised

    def died(self) -> list[str]:
        """The served processes whose thread ended while the session runs (their host raised), once each."""
        gone = [t.name.removeprefix("swarm-sitl-") for t in self.threads if not t.is_alive()]
        new = [p for p in gone if p not in self.told]
        self.told.update(new)
        return [] if self.over.is_set() else new

    def start(self, proc: str, host: Any, endpoint: str, namespace: str) -> None:
        from bridge.hosts.participant import serve

        def run() -> None:
            try:
                serve(proc, endpoint, namespace, host, watch=lambda: 0 if self.over.is_set() else None)
            except Exception as e:  # told to the world (``died``) with what went wrong, not as a traceback
                self.why[proc] = f"{type(e).__name__}: {e}"
            finally:
                if hasattr(host, "ended"):
                    host.ended()

        t = threading.Thread(target=run, name=f"swarm-sitl-{proc}", daemon=True)
        t.start()
        self.threads.append(t)

    def end(self) -> None:
        """After the teardown: every served process stops (within a second of its idle poll)."""
        self.over.set()
        for t in self.threads:
            t.join()


def _await_endpoint(cfg, w: _Watch, sock: Path, t_launch: float, logs: Path, stops: _Stops) -> str | None:
    """Wait for the world to open its endpoint (or a Ctrl-C); why it did not, if it failed or timed out."""
    world = w.children[0]
    while not sock.exists():
        if world.popen.poll() is not None or time.monotonic() - t_launch > cfg.session.startup_timeout_s:
            return f"the world process did not open its endpoint; see {logs / 'world.log'}"
        if _frozen_at_startup(w, cfg) is not None:
            world.popen.kill()
            return f"{_frozen_note(world, cfg)}; see {logs / 'world.log'}"
        if stops.asked():
            break
        time.sleep(0.01)
    return None


def _watch(cfg, w: _Watch, status_q: queue.SimpleQueue, control, logs: Path, stops: _Stops, prog: _Progress,
           ports: list[str], remote: int) -> None:
    """Until the world ends (or Ctrl-C again): show its status, report dead processes to it, pass a Ctrl-C on."""
    world = w.children[0]
    sent_stop = False
    while True:
        while True:  # status from the world
            try:
                _, data = status_q.get_nowait()
            except queue.Empty:
                break
            _on_status(cfg, w, transport.unpack(data), prog, ports, remote)
        _reap_running(w.children, world, control, logs)
        for proc in w.served.died() if w.served else ():  # what drives the session is gone: so is the session
            why = w.served.why.get(proc, "it stopped serving")
            control.put(transport.pack({"op": "dead", "proc": proc,
                                        "detail": f"its host in the launcher stopped: {why}"}))
            control.put(transport.pack({"op": "stop", "reason": f"{proc}, served by the launcher, stopped"}))
        if w.t_started is None and not w.startup_error and (frozen := _frozen_at_startup(w, cfg)):
            w.startup_error = f"{_frozen_note(frozen, cfg)}; see {logs / frozen.name}.log"
            prog.note(f"[{cfg.session.name}] {w.startup_error}")
            control.put(transport.pack({"op": "stop", "reason": w.startup_error}))
            frozen.popen.kill()
        if w.t_started is None and not w.startup_error and (
                gone := [c for c in w.children if c.kind == "host" and c.exit_code not in (None, 0)]):
            w.startup_error = (f"host {gone[0].name.removeprefix('host-')}'s launch command exited (code "
                               f"{gone[0].exit_code}) before the session started; see {logs / gone[0].name}.log")
            prog.note(f"[{cfg.session.name}] {w.startup_error}")
            control.put(transport.pack({"op": "stop", "reason": w.startup_error}))
        if world.exit_code is not None:
            w.world_code = world.exit_code
            return
        if stops.asked() and not sent_stop:
            sent_stop = w.interrupted = True
            stops.used = 1
            prog.note(f"stopping at sim t={w.last_sim:.1f} s (Ctrl-C again to kill at once)")
            control.put(transport.pack({"op": "stop", "reason": "interrupted"}))
        if stops.hurry():
            return
        time.sleep(0.02)


def _on_status(cfg, w: _Watch, msg: dict[str, Any], prog: _Progress, ports: list[str], remote: int) -> None:
    """Show one status message of the world: the session started, its progress, a notice, a robot's failure."""
    op = msg.get("op")
    if op == "started":
        w.t_started = time.monotonic()
        procs = sum(c.kind != "host" for c in w.children) + remote  # a host's launch command is none of them
        prog.note(f"[{cfg.session.name}] started: {procs} processes joined in {w.t_started - w.t_launch:.1f} s")
        for line in ports:
            prog.note(f"[{cfg.session.name}] port: {line}")
        if msg.get("mavlink"):
            prog.note(f"[{cfg.session.name}] MAVLink: " + ", ".join(
                f"{who} {ep}" for who, ep in msg["mavlink"].items()))
        if msg.get("live"):
            prog.note(f"[{cfg.session.name}] live scene: {msg['live']} (Foxglove: open connection, Foxglove "
                      "WebSocket; layout docs/foxglove-layout.json)")
        for who, ep in (msg.get("wifi_udp") or {}).items():
            prog.note(f"[{cfg.session.name}] port: {who} Wi-Fi (UDP): {ep}")
    elif op == "progress" and w.t_started is not None and msg["t"] >= 1.0:
        w.last_sim = msg["t"]
        prog.update(msg["t"], msg["t"] / max(time.monotonic() - w.t_started, 1e-9), msg["alive"],
                    msg.get("lag_s"))
    elif op == "notice":  # something the user should know that is not a failure (a CAN bus-off)
        prog.note(f"[{cfg.session.name}] {msg.get('text', '')}")
    elif op == "event":
        prog.note(f"robot {msg['robot']} failed at sim t={msg['t_s']:.2f} s: {msg['kind']} "
                  f"({msg['detail'].strip().splitlines()[-1] if msg['detail'].strip() else ''})")


def _frozen_note(c: Child, cfg) -> str:
    return (f"process {c.name} was stopped (SIGSTOP, or a debugger) for {cfg.session.hang_timeout_s:g} s during "
            "start-up (session.hang_timeout_s), so it was killed")


def _frozen_at_startup(w: _Watch, cfg) -> Child | None:
    """A process of this computer stopped (SIGSTOP, a debugger's break) for ``hang_timeout_s`` before the session
    started: in a quantum, the hang timeout finds it; in start-up, nothing would before ``startup_timeout_s``. A
    process waiting for the others sleeps, which is not stopped: only the stopped state counts."""
    import psutil

    now = time.monotonic()
    if now < w.next_state_check:
        return None
    w.next_state_check = now + 0.25
    for c in w.children:
        if c.kind == "host" or c.exit_code is not None:
            continue
        try:
            stopped = psutil.Process(c.popen.pid).status() in (psutil.STATUS_STOPPED, psutil.STATUS_TRACING_STOP)
        except psutil.Error:
            stopped = False
        if not stopped:
            w.stopped_since.pop(c.name, None)
        elif now - w.stopped_since.setdefault(c.name, now) >= cfg.session.hang_timeout_s:
            return c
    return None


def _reap_running(children: list[Child], world: Child, control, logs: Path) -> None:
    """Reap the children that ended; tell the world of a participant that died while it runs (its failure policy)."""
    for c in children:
        if c.exit_code is None:
            _reap(c)
            unexpected = c.kind != "world" and not c.expected_exit and world.exit_code is None
            if c.kind == "host" and c.exit_code == 0:
                unexpected = False  # its join ended when the world said stop to all its processes
            if c.exit_code is not None and unexpected:
                for proc in c.procs or (c.name,):  # a host's: every process it ran there
                    control.put(transport.pack({"op": "dead", "proc": proc,
                                                "detail": _ended(c, logs)}))


def _ended(c: Child, logs: Path) -> str:
    """Why the processes of a child that ended failed: its exit code (a host's: its launch command's), its log."""
    why = f"exit code {c.exit_code}; see {logs / c.name}.log"
    return f"host {c.name.removeprefix('host-')}'s launch command ended ({why})" if c.kind == "host" else why


def _teardown(w: _Watch, stops: _Stops, session, session_dir: str) -> None:
    """End every process of the session, close the launcher's zenoh session, remove the session directory."""
    for c in w.children:
        c.expected_exit = True
    # Once started, every process was told to stop and leaves by itself: the grace only bounds a stuck one, and
    # is generous so that a loaded machine does not turn a clean exit into a kill. A process that never joined
    # (start-up failed) waits for nothing: it gets the short grace; a second Ctrl-C hurries them all.
    _terminate(w.children, grace_s=10.0 if w.t_started is not None else 2.0, hurry=stops.hurry)
    if session is not None:
        session.close()
    shutil.rmtree(session_dir, ignore_errors=True)


def _pass_on(signum: int | None, handlers: dict[int, Any]) -> None:
    """A session run inside another program (an experiment's trial) took that program's Ctrl-C or SIGTERM to stop
    itself: now that the session is over and written, hand the signal to the handler the program had installed,
    so the program stops too. A default handler is left alone: the command line reports exit code 130 itself."""
    h = handlers.get(signum) if signum is not None else None
    if callable(h) and h is not signal.default_int_handler:
        h(signum, None)


class _Abort(Exception):
    pass


def _cannot_listen(listen: str) -> str | None:
    """Why the world could not listen on ``tcp/HOST:PORT`` (the port is taken, the address is not this machine's),
    or None. A trial bind, closed at once (SO_REUSEADDR as zenoh's listener, so a port in TIME_WAIT is free)."""
    host, _, port = listen.removeprefix("tcp/").rpartition(":")
    try:
        family, _, _, _, addr = socket.getaddrinfo(host.strip("[]"), int(port), type=socket.SOCK_STREAM)[0]
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind(addr)
    except OSError as e:
        return e.strerror or str(e)
    return None


def join_commands(name: str, listen: str | None, plan: Plan, hosts: list | None = None) -> list[str]:
    """For each robot whose logic joins from another computer, and each host without a ``launch`` command, the line
    telling the user how: ``swarm-sitl join`` with an address of this machine (a wildcard listen address is not one
    another computer can connect to)."""
    remote = [p for p in plan.procs if p.remote and p.host is None]
    manual = [h.name for h in hosts or () if h.launch is None]
    if not (remote or manual) or listen is None:
        return []
    endpoint, lines = public_endpoint(listen)
    for p in remote:
        lines.append(f"robot {p.robots[0]}'s logic: swarm-sitl join {endpoint} --session {shlex.quote(name)} "
                     f"--robot {p.robots[0]}")
    for h in manual:
        lines.append(f"host {h} ({host_share(plan, h)}): {host_join(endpoint, name, h)}")
    return lines


def public_endpoint(listen: str) -> tuple[str, list[str]]:
    """The world's endpoint as another computer reaches it: ``listen``, a wildcard address replaced by one of this
    machine's (with a line saying which others there are, if several)."""
    host, _, port = listen.removeprefix("tcp/").rpartition(":")
    lines = []
    if host in ("0.0.0.0", "[::]"):
        import psutil

        mine = [a.address for addrs in psutil.net_if_addrs().values() for a in addrs
                if a.family == socket.AF_INET and not a.address.startswith("127.")]
        host = mine[0] if mine else "127.0.0.1"
        if len(mine) > 1:
            lines.append(f"listening on {listen}: this machine's addresses are {', '.join(mine)}; use one the other "
                         "computer reaches")
    return f"tcp/{host}:{port}", lines


def host_join(endpoint: str, session: str, host: str) -> str:
    """The command that runs host ``host``'s processes on it."""
    return f"swarm-sitl join {endpoint} --session {shlex.quote(session)} --host {shlex.quote(host)}"


def host_share(plan: Plan, host: str) -> str:
    """What host ``host`` runs: its processes and their robots, e.g. "fw2, lg2: robots 5-9"."""
    procs = [p for p in plan.procs if p.host == host]
    robots = sorted({r for p in procs for r in p.robots})
    return ", ".join(p.name for p in procs) + (f": robots {id_ranges(robots)}" if robots else "")


def id_ranges(ids: Any) -> str:
    """Robot ids as a short list: "0-4, 7"."""
    ids = sorted(ids)
    runs: list[str] = []
    i = 0
    while i < len(ids):
        j = i
        while j + 1 < len(ids) and ids[j + 1] == ids[j] + 1:
            j += 1
        runs.append(str(ids[i]) if i == j else f"{ids[i]}-{ids[j]}")
        i = j + 1
    return ", ".join(runs)


def launch_command(template: str, endpoint: str, session: str, host: str) -> str:
    """A host's ``launch`` template with its placeholders filled in, each shell-quoted (``HostCfg.launch``)."""
    q = shlex.quote
    return template.format(name=q(host), endpoint=q(endpoint), session=q(session),
                           join=host_join(endpoint, session, host))


def _launch_host(cfg, h, plan: Plan, logs: Path) -> Child:
    """Run host ``h``'s launch command (a shell command line, in a process group of its own, its output in
    logs/host-NAME.log): a child of the launcher like the session's own processes."""
    endpoint, _ = public_endpoint(str(cfg.session.listen))
    cmd = launch_command(h.launch, endpoint, cfg.session.name, h.name)
    name = f"host-{h.name}"
    with open(logs / f"{name}.log", "wb") as log:
        # tethered: the command and what it starts end with this launcher, even should it be killed
        p = subprocess.Popen([sys.executable, "-m", "bridge.hosts.tethered", str(os.getpid()), "--", "/bin/sh", "-c",
                              cmd], stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                             start_new_session=True, env=child_env())
    procs = tuple(p.name for p in plan.procs if p.host == h.name)
    robots = tuple(sorted({r for pp in plan.procs if pp.host == h.name for r in pp.robots}))
    return Child(name, "host", p, robots, procs)


def child_env() -> dict[str, str]:
    """The environment of a session's process: this one's, without python-can's config (``CAN_*``), with one zenoh
    worker thread per runtime (unless set), unbuffered output and MAVLink 2."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("CAN_")}
    return {"ZENOH_RUNTIME": ZENOH_RUNTIME, **env, "PYTHONUNBUFFERED": "1", "MAVLINK20": "1"}


def end_group(p: subprocess.Popen) -> int:
    """End ``p`` and its process group (SIGKILL) if it still runs; its exit code."""
    if p.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, signal.SIGKILL)
    return p.wait()


def _reap(c: Child) -> None:
    try:
        pid, status, ru = os.wait4(c.popen.pid, os.WNOHANG)
    except ChildProcessError:
        c.exit_code = c.popen.returncode if c.popen.returncode is not None else -1
        return
    if pid == 0:
        return
    c.exit_code = os.waitstatus_to_exitcode(status)
    c.popen.returncode = c.exit_code
    c.cpu_s = ru.ru_utime + ru.ru_stime
    c.maxrss_kb = ru.ru_maxrss


def _terminate(children: list[Child], grace_s: float, hurry=lambda: False, world_grace_s: float = 5.0) -> None:
    """Reap the children; kill those still running after ``grace_s``.

    ``hurry()`` (Ctrl-C again) cuts the wait short, as if the launcher had died: the participants are killed at
    once, and the world gets SIGTERM, on which it finishes its recording without waiting for anyone; it is killed
    only if it has not ended ``world_grace_s`` later (a safety net: the recording stays whole)."""
    deadline = time.monotonic() + grace_s
    hurried = False
    while any(c.exit_code is None for c in children):
        for c in children:
            if c.exit_code is None:
                _reap(c)
        if time.monotonic() >= deadline:
            break
        if not hurried and hurry():
            hurried = True
            deadline = time.monotonic() + world_grace_s
            for c in children:
                if c.exit_code is None:
                    with contextlib.suppress(ProcessLookupError):
                        os.killpg(c.popen.pid, signal.SIGTERM if c.kind == "world" else signal.SIGKILL)
        time.sleep(0.02)
    for c in children:
        if c.exit_code is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(c.popen.pid, signal.SIGKILL)
    for c in children:
        while c.exit_code is None:
            _reap(c)
            if c.exit_code is None:
                time.sleep(0.01)


def _draw(out: Path, plan: Plan, prog: _Progress, stops: _Stops) -> bool:
    """Draw trajectories.png (whole: drawn aside, then renamed); False if it was not drawn. A Ctrl-C (or SIGTERM)
    not used to stop the session, before or while it is drawn, skips it: "Ctrl-C again kills at once"."""
    png, part = out / "trajectories.png", out / "trajectories.partial.png"
    try:
        stops.raising = True
        try:
            if stops.hurry():
                raise _Hurry
            from bridge.core.plot import plot_session

            plot_session(out / "session.mcap", plan, part)
            part.replace(png)
        finally:
            stops.raising = False
    except _Hurry:
        prog.note("trajectories.png not drawn (Ctrl-C)")
    except Exception as e:  # a plot must never cost the summary
        prog.note(f"could not draw the trajectories: {e}")
    part.unlink(missing_ok=True)
    return png.exists()


def _study_sections(world_res: dict[str, Any]) -> dict[str, Any]:
    """The summary sections of every study (null where its loop functions did not run), then any other section the
    session's loop functions wrote."""
    keys = [k for _, study in STUDIES.items() for k in study.sections]
    keys += [k for k in world_res.get("study_sections", []) if k not in keys]
    return {k: world_res.get(k) for k in keys}


def _finish(cfg, plan, out: Path, children: list[Child], world_code: int | None, interrupted: bool, wall: float,
            t_started: float | None, t_launch: float, prog: _Progress, plot: bool,
            startup_error: str | None, stops: _Stops) -> SessionResult:
    """Write the summary (and the plot) from the world's result, say how the session ended; its result."""
    res_path = out / "world_result.json"
    world_res: dict[str, Any] = json.loads(res_path.read_text()) if res_path.exists() else {}
    recovered = _recover_recording(out) if not world_res else None
    summary = _summary(cfg, plan, children, world_res, interrupted, wall, t_started, t_launch)
    if recovered is not None:  # what the world recorded before it died: the figures a reader recomputes from it
        summary.update(sim_time_s=round(recovered.last_time_ns / 1e9, 6), messages=recovered.messages,
                       digest=recovered.digest, recording=_recovery_note(recovered))
    _merge_radio(summary, world_res)
    code = _judge(summary, world_res, world_code, interrupted, t_started, startup_error, out)
    _write_outputs(summary, out, plan, prog, stops, plot)
    _report(cfg, summary, out, code, interrupted, wall, prog)
    return SessionResult(code, summary, out, children)


def _recover_recording(out: Path) -> Recovered | None:
    """The world ended without its result: its recording rewritten up to the cut (``recover_in_place``). None: no
    recording, or a finished one."""
    try:
        return recover_in_place(out / "session.mcap")
    except (OSError, NotARecording):
        return None


def _recovery_note(r: Recovered) -> dict[str, Any]:
    return {"recovered": True, "messages": r.messages, "last_time_s": round(r.last_time_ns / 1e9, 6),
            "damaged": "session.mcap.damaged",
            "note": "the world died before finishing its recording: session.mcap holds every message up to the cut "
                    "(the last chunk, still in memory, was lost), rewritten by swarm-sitl recover"}


def _summary(cfg, plan, children: list[Child], world_res: dict[str, Any], interrupted: bool, wall: float,
             t_started: float | None, t_launch: float) -> dict[str, Any]:
    """summary.json's content from the plan, the world's result and the processes' exits (no files, no exit code)."""
    n = len(plan.robots)
    hosts = [c for c in children if c.kind == "host"]  # launch commands: their processes run elsewhere
    children = [c for c in children if c.kind != "host"]
    cpu_total = sum(c.cpu_s for c in children)
    sim_t = world_res.get("sim_time_s", 0.0)
    loop_wall = world_res.get("world_wall_s") or 0.0
    summary: dict[str, Any] = {
        "name": cfg.session.name,
        "seed": cfg.session.seed,
        "robots": n,
        "processes": len(children) + sum(p.remote or p.inproc for p in plan.procs),
        "remote_processes": [p.name for p in plan.procs if p.remote],  # joined from other computers
        "hosts": _hosts_summary(cfg, plan, hosts, world_res),
        "robots_per_process": cfg.session.robots_per_process,
        "speed": cfg.session.speed,
        "sim_time_s": sim_t,
        "wall_time_s": round(wall, 3),
        "run_wall_s": round(loop_wall, 3),
        "rtf": round(sim_t / loop_wall, 3) if loop_wall else None,
        "startup_s": round(t_started - t_launch, 3) if t_started else None,
        "ticks": world_res.get("ticks"),
        "quanta": world_res.get("quanta"),
        "messages": world_res.get("messages"),
        "message_counts": world_res.get("message_counts"),
        "wakeups": world_res.get("wakeups"),
        "process_ticks": world_res.get("process_ticks"),
        "digest": world_res.get("digest"),
        "barrier_us_median": world_res.get("barrier_us_median"),
        "barrier_us_p99": world_res.get("barrier_us_p99"),
        "wall_lag": world_res.get("wall_lag"),
        "can_events": world_res.get("can_events", []),
        "releases": world_res.get("releases"),  # robots that went down from their carriers (sessions with carriers)
        **_study_sections(world_res),  # what the studies' loop functions measured (bridge/studies/<study>)
        "mavlink": world_res.get("mavlink"),
        "cpu_s_total": round(cpu_total, 3),
        "cpu_s_per_robot_per_sim_s": round(cpu_total / n / sim_t, 5) if sim_t and n else None,
        "rss_mb_per_robot": round(sum(c.maxrss_kb for c in children) / 1024 / n, 1) if n else None,
        "interrupted": interrupted,
        "stop_reason": world_res.get("stop_reason"),
        "failures": world_res.get("failures", []),
        "error": world_res.get("error"),
        "process_exits": {c.name: c.exit_code for c in children},
        "process_cpu_s": {c.name: round(c.cpu_s, 3) for c in children},
        "process_maxrss_mb": {c.name: round(c.maxrss_kb / 1024, 1) for c in children},
        "per_robot": world_res.get("robots", []),
        "files": {},  # the outputs there are (below)
    }
    for key in ("wifi", "services", "faults"):  # a Wi-Fi network, services (bridge.core.services), robot faults
        if world_res.get(key) is not None:
            summary[key] = world_res[key]
    return summary


def _hosts_summary(cfg, plan, launched: list[Child], world_res: dict[str, Any]) -> dict[str, Any] | None:
    """Per host of ``[[hosts]]``: its processes and robots, the robots that failed, its launch command's exit code
    (null: no launch command)."""
    if not cfg.hosts:
        return None
    failed = {f["robot"] for f in world_res.get("failures", []) if "robot" in f}
    exits = {c.name.removeprefix("host-"): c.exit_code for c in launched}
    out = {}
    for h in cfg.hosts:
        procs = [p for p in plan.procs if p.host == h.name]
        robots = sorted({r for p in procs for r in p.robots})
        out[h.name] = {"processes": [p.name for p in procs], "robots": robots,
                       "failed_robots": [r for r in robots if r in failed], "launch_exit": exits.get(h.name)}
    return out


def _merge_radio(summary: dict[str, Any], world_res: dict[str, Any]) -> None:
    """Add the radio medium's statistics, per robot and for the session, when it has any."""
    radio = world_res.get("radio") or {}
    if radio.get("per_robot") or len(radio) > 1:
        for rr in summary["per_robot"]:
            rr.update(radio.get("per_robot", {}).get(str(rr["id"]), {}))
        summary["radio"] = {k: v for k, v in radio.items() if k != "per_robot"}


def _how_it_ended(code: int | None) -> str:
    if code is not None and code < 0:
        try:
            return f"was killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"was killed by signal {-code}"
    return f"ended (exit {code})"


def _where_cut(summary: dict[str, Any]) -> str:
    r = summary.get("recording") or {}
    return (f" at simulated t={r['last_time_s']:.3f} s (its recording recovered up to there: {r['messages']} "
            "messages)" if r.get("recovered") else "")


def _judge(summary: dict[str, Any], world_res: dict[str, Any], world_code: int | None, interrupted: bool,
           t_started: float | None, startup_error: str | None, out: Path) -> int:
    """The session's exit code (130: interrupted; non-zero: an error, or every robot failed), with its error."""
    if not world_res:
        summary["error"] = (
            "interrupted during start-up" if interrupted and t_started is None else
            "the world was killed before it wrote its result (Ctrl-C again); the recording ends where it was cut"
            if interrupted else startup_error or
            f"the world process {_how_it_ended(world_code)}{_where_cut(summary)} without writing its result; see "
            f"{out / 'logs'}")
    code = world_code if world_code is not None and world_code >= 0 else 1  # a death by a signal is a failure: 1
    robots_alive = [r["alive"] for r in summary["per_robot"]]
    if startup_error and world_res and not interrupted:  # the launcher stopped the start (a host's launch failed)
        summary["error"] = startup_error
        code = 1
    elif interrupted:
        code = 130
    elif not world_res or world_res.get("error"):
        code = code or 1
    elif str(world_res.get("stop_reason") or "").startswith("signal "):  # not the launcher's: it signals only when
        summary["error"] = (f"the world process got {world_res['stop_reason'].removeprefix('signal ')} from outside "
                            f"the session at simulated t={summary.get('sim_time_s') or 0:.3f} s and stopped there")
        code = code or 1  # interrupted (Ctrl-C twice), handled above
    elif robots_alive and not any(robots_alive):
        code = code or 1
        summary["error"] = summary["error"] or "every robot failed"
    summary["exit_code"] = code
    return code


def _write_outputs(summary: dict[str, Any], out: Path, plan, prog: _Progress, stops: _Stops, plot: bool) -> None:
    """Write summary.json, then draw the plot and write it again listing the plot (a Ctrl-C skips the plot)."""
    outputs = {"recording": out / "session.mcap", "summary": out / "summary.json", "plot": out / "trajectories.png",
               "logs": out / "logs"}

    def write_summary() -> None:  # listing the outputs that exist; whole or not at all
        summary["files"] = {k: str(p) for k, p in outputs.items() if k == "summary" or p.exists()}
        tmp = out / "summary.json.tmp"
        tmp.write_text(json.dumps(summary, indent=1))
        tmp.replace(out / "summary.json")

    write_summary()
    if plot and (out / "session.mcap").exists() and _draw(out, plan, prog, stops):
        write_summary()  # now with the plot


def _report(cfg, summary: dict[str, Any], out: Path, code: int, interrupted: bool, wall: float,
            prog: _Progress) -> None:
    """Say how the session ended, how fast it ran and where its outputs are (and how late a paced one was)."""
    sim_t = summary["sim_time_s"]
    how = "interrupted" if interrupted else "stopped" if code else "done"
    why = f" ({summary['stop_reason'] or summary['error'].strip().splitlines()[-1]})" if code and not interrupted and (
        summary["stop_reason"] or summary["error"]) else ""
    files = "".join(f"\n  {label:<10} {path}" for label, path in (
        ("recording", out / "session.mcap"), ("summary", out / "summary.json"), ("plot", out / "trajectories.png"),
        ("logs", out / "logs")) if path.exists())
    if summary["wall_lag"]:
        lag = summary["wall_lag"]
        prog.note(f"[{cfg.session.name}] paced at speed {cfg.session.speed}: the simulated clock was behind wall time "
                  f"in {lag['late_share']:.1%} of quanta, by {lag['p99_ms']} ms at the 99th percentile, "
                  f"{lag['max_ms']} ms at most")
    prog.note(
        f"[{cfg.session.name}] {how}{why}: {sim_t:.1f} s simulated in "
        f"{wall:.1f} s wall (rtf {summary['rtf']}x), {summary['messages']} messages, digest "
        f"{str(summary['digest'])[:16]}{files}"
    )
