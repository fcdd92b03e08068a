"""``swarm-sitl bench``: the demo behaviour at several robot counts and process packings; with ``--study NAME``, that
study's own figures (its ``Study.bench``).

Prints, per case: robots, processes, real-time factor, and beside it the physical limits of this machine for that
case: the bare lock-step barrier over as many participant processes (no physics, no firmware: ``barrier_limit``)
and the bare physics of the same world stepped alone (no process, no firmware: ``physics_limit``), each as the
real-time factor it would allow, and the share of the lower one the session reached; then the per-tick barrier
latency (median and p99: from sending a quantum's ticks to the last answer, physics overlapped), CPU per robot (all
processes, start-up included), resident memory per robot, and start-up time. Figures only, never pass/fail: the
machine is shared and noisy.
"""

from __future__ import annotations

import os
import pstats
import queue
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge.core import transport
from bridge.core.launcher import ZENOH_RUNTIME, run_session

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "hil_configs" / "demo.toml"
SCALE = ROOT / "hil_configs" / "bench" / "scale.toml"  # the scale goals' cases (--scale)



@dataclass(frozen=True)
class Case:
    """One benchmark case: a session config with its robot count (None: the config's own) and packing, and the goal
    set for it (an RTF)."""

    label: str
    robots: int | None
    per_process: int
    config: Path = DEMO
    goal: float | None = None


# the demo (XBee Series 2 and UWB on every robot): (robots, robots per process)
FULL = [Case("radio demo", n, k) for n, k in ((1, 1), (10, 1), (10, 5), (25, 5), (50, 10), (50, 25), (100, 25))]
QUICK = [Case("radio demo", 10, 1)]


class CasesError(ValueError):
    """A cases file that cannot be used: the message names the file, the case and the field."""


def load_cases(path: str | Path) -> list[Case]:
    """The cases of a TOML file (``[[cases]]`` with ``label``, ``config`` relative to the project or absolute,
    ``robots`` (optional), ``per_process``, ``goal`` (optional))."""
    import tomllib

    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise CasesError(f"{path}: {e}") from None
    cases = []
    for i, c in enumerate(data.get("cases", [])):
        where = f"{path}: cases[{i}]"
        unknown = set(c) - {"label", "config", "robots", "per_process", "goal"}
        if unknown:
            raise CasesError(f"{where}: unknown field(s) {', '.join(sorted(unknown))}")
        config = Path(c.get("config", DEMO))
        config = config if config.is_absolute() else ROOT / config
        if not config.exists():
            raise CasesError(f"{where}.config: no such file {config}")
        robots, k, goal = c.get("robots"), c.get("per_process", 1), c.get("goal")
        if not (robots is None or (isinstance(robots, int) and robots > 0)) or not (isinstance(k, int) and k > 0):
            raise CasesError(f"{where}: robots and per_process must be positive integers")
        if goal is not None and not (isinstance(goal, int | float) and goal > 0):
            raise CasesError(f"{where}.goal: must be a positive real-time factor")
        cases.append(Case(str(c.get("label", config.stem)), robots, k, config, goal))
    if not cases:
        raise CasesError(f"{path}: no [[cases]]")
    return cases


def run_study_bench(name: str, quick: bool = False, duration: float | None = None, out_dir: str = "runs/bench") -> int:
    """The benchmark study ``name`` declares (``Study.bench``)."""
    import importlib

    from bridge.core.registry import STUDIES
    from swarm_logic.plugins import PluginError

    try:
        study = STUDIES.get(name)
    except PluginError as e:
        raise SystemExit(f"swarm-sitl bench --study: {e}") from None
    if not study.bench:
        have = ", ".join(n for n, st in STUDIES.items() if st.bench) or "none"
        raise SystemExit(f"swarm-sitl bench: study {name!r} has no benchmark (studies with one: {have})")
    module, _, fn = study.bench.partition(":")
    return int(getattr(importlib.import_module(module), fn)(quick=quick, duration=duration, out_dir=out_dir))


def run_bench(quick: bool = False, duration: float | None = None, out_dir: str = "runs/bench",
              markdown: bool = False, profile: bool = False, config: str | None = None, scale: bool = False,
              cases_file: str | None = None) -> int:
    """The cases (``scale``: the scale goals' cases; ``cases_file``: a file's; ``quick``: one), each beside its
    limits, in one table."""
    if cases_file or scale:
        try:
            cases = load_cases(cases_file or SCALE)
        except CasesError as e:
            raise SystemExit(f"swarm-sitl bench: {e}") from None
        cases = cases[:1] if quick else cases
    else:
        cases = QUICK if quick else FULL
    if config:
        cases = [Case(Path(config).stem, c.robots, c.per_process, Path(config)) for c in cases]
    dur = duration or (10.0 if quick else 30.0)
    rows = []
    for case in cases:
        n, k, cfg = case.robots, case.per_process, str(case.config)
        out = Path(out_dir) / f"{case.config.stem}_n{n or 'cfg'}_k{k}"
        overrides: dict[str, Any] = {"session.robots_per_process": k, "session.duration_s": dur, "session.speed": "max"}
        if n is not None:
            overrides["robots.count"] = n
        env_before = os.environ.get("SWARM_SITL_PROFILE")
        if profile:
            (out / "profile").mkdir(parents=True, exist_ok=True)
            os.environ["SWARM_SITL_PROFILE"] = str((out / "profile").resolve())
        try:
            res = run_session(cfg, overrides, str(out), progress=None, plot=False)
        finally:
            if env_before is None:
                os.environ.pop("SWARM_SITL_PROFILE", None)
        s = res.summary
        limits = (barrier_limit(int(s["processes"]) - 1, quantum_s(cfg, overrides)),
                  physics_limit(cfg, overrides)) if s.get("processes") else (None, None)
        rows.append((case, s, limits))
        print(f"  ran {case.label}, {s.get('robots')} robots, {k} per process: rtf {s['rtf']}x (exit {res.code}); "
              f"bare barrier {_fmt(limits[0], '.1f', 'x')}, bare physics {_fmt(limits[1], '.1f', 'x')}",
              file=sys.stderr)
        if profile:
            _print_profile(out / "profile" / "world.prof")
    _print_table(rows, dur, markdown)
    rate, median_us = barrier_yardstick()
    print(f"machine yardstick: bare lock-step barrier over zenoh, world + 6 participant processes, no physics or "
          f"firmware: {rate:.0f} quanta/s, median {median_us:.0f} us (compare machines and moments by this)")
    _print_round_trip(rows)
    failed = [r for r in rows if r[1]["exit_code"] != 0]
    return 1 if failed else 0


class _EchoHost:
    """A participant that does nothing but answer: wakes every quantum."""

    def run(self, ent: str, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        return {"out": [], "wake": t_ns + 1, "wom": False}

    def stop(self) -> None:
        pass


def _echo_main(proc: str, endpoint: str, namespace: str, parent_pid: int, mode: str = "peer") -> None:
    from bridge.hosts.parent import die_with_parent
    from bridge.hosts.participant import serve

    die_with_parent()
    session = None
    if mode != "peer":  # a client of a router (the yardstick's routed variant)
        import json

        import zenoh

        c = transport.make_config(endpoint, namespace, listen=False)
        c.insert_json5("mode", json.dumps(mode))
        session = zenoh.open(c)
    code = serve(proc, endpoint, namespace, _EchoHost(), parent_pid, session=session)
    os._exit(code)


def quantum_s(config: str, overrides: dict[str, Any]) -> float:
    """The session's quantum (s)."""
    from bridge.core.config import load_config

    return load_config(config, overrides).session.quantum_ms / 1000


def barrier_limit(procs: int, q_s: float, quanta: int = 2000) -> float:
    """The real-time factor the bare lock-step barrier over ``procs`` participant processes allows at quantum
    ``q_s``: what a session of that many processes could reach with no physics and no firmware."""
    return barrier_yardstick(procs, quanta)[0] * q_s


def physics_limit(config: str, overrides: dict[str, Any], quanta: int = 1000) -> float:
    """The real-time factor the session's world allows alone: its arena, obstacles and robots built as the world
    process builds them, stepped ``quanta`` quanta in this process with no firmware and no logic (the robots idle)."""
    from bridge.core.config import load_config
    from bridge.core.plan import make_plan
    from bridge.core.world import World

    cfg = load_config(config, overrides)
    world = World(cfg, make_plan(cfg).robots)
    q = round(cfg.session.quantum_ms * 1e6)
    t0 = time.perf_counter()
    for k in range(quanta):
        world.step_quantum(k * q, q)
    wall = time.perf_counter() - t0
    world.close()
    return quanta * q / 1e9 / wall


def barrier_yardstick(procs: int = 6, quanta: int = 3000, link_delay_ms: float | None = None,
                      router: bool = False) -> tuple[float, float]:
    """Quanta per second and median barrier of the bare tick/done protocol, with our participant loop. With
    ``link_delay_ms`` the participants reach the world over TCP through a delay relay (``bridge.tools.delay_relay``;
    a negative delay: directly, no relay), each on its own connection, or with ``router`` through one zenoh router (a
    host's single connection; the participants its clients over a unix socket)."""
    d = tempfile.mkdtemp(prefix="swarm-sitl-bench-")
    ns = f"swarm-sitl-bench/{uuid.uuid4().hex[:12]}"
    ep = transport.endpoint_for(d)
    tcp = [f"tcp/127.0.0.1:{_free_port()}"] if link_delay_ms is not None else None
    s = transport.open_session(ep, ns, listen=True, extra_listen=tcp)
    q: queue.SimpleQueue = queue.SimpleQueue()
    subs = [transport.queue_subscriber(s, "done/*", q), transport.queue_subscriber(s, "hello/*", q)]
    names = [f"e{i}" for i in range(procs)]
    pubs = {n: transport.publisher(s, f"tick/{n}") for n in names}
    env = {"ZENOH_RUNTIME": ZENOH_RUNTIME, **os.environ}
    helpers: list[subprocess.Popen] = []
    mode = "peer"
    if tcp:
        from bridge.tools.delay_relay import start_relay

        port = int(tcp[0].rpartition(":")[2])
        if link_delay_ms is not None and link_delay_ms >= 0:
            helpers.append(start_relay(("127.0.0.1", port), link_delay_ms))
            port = helpers[-1].port  # type: ignore[attr-defined]
        ep = f"tcp/127.0.0.1:{port}"
        if router:
            helpers.append(_router(ep, f"unixsock-stream/{d}/router.sock", env))
            ep, mode = f"unixsock-stream/{d}/router.sock", "client"
    children = [subprocess.Popen([sys.executable, "-c", f"from bridge.tools.bench import _echo_main; "
                                  f"_echo_main({n!r}, {ep!r}, {ns!r}, {os.getpid()}, {mode!r})"], env=env,
                                 start_new_session=True) for n in names]
    try:
        for _ in names:
            q.get(timeout=60)
        for p in pubs.values():
            transport.wait_matched(p, 60, "tick")
        lat = []
        t0 = time.perf_counter()
        for k in range(quanta):
            a = time.perf_counter()
            for n in names:
                pubs[n].put(transport.pack({"k": k, "t": k, "run": {f"{n}/x": {"in": []}}}))
            for _ in names:
                q.get(timeout=30)
            lat.append(time.perf_counter() - a)
        rate = quanta / (time.perf_counter() - t0)
        for n in names:
            pubs[n].put(transport.pack({"k": quanta, "stop": True}))
        for c in children:
            c.wait(timeout=10)
    finally:
        for c in [*children, *helpers]:
            if c.poll() is None:
                os.killpg(c.pid, signal.SIGKILL)
                c.wait()
        del subs
        s.close()
        shutil.rmtree(d, ignore_errors=True)
    lat.sort()
    return rate, lat[len(lat) // 2] * 1e6


_ROUTER = """
import json, sys, zenoh
from bridge.core import transport
c = transport.make_config(sys.argv[1], None, listen=False)
c.insert_json5("mode", '"router"')
c.insert_json5("listen/endpoints", json.dumps([sys.argv[2]]))
z = zenoh.open(c)
print("up", flush=True)
sys.stdin.read()
"""


def _router(world: str, listen: str, env: dict[str, str]) -> subprocess.Popen:
    """A zenoh router connected to ``world``, listening on ``listen`` (scouting off, as every session)."""
    p = subprocess.Popen([sys.executable, "-c", _ROUTER, world, listen], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         text=True, env=env, start_new_session=True)
    if p.stdout is None or p.stdout.readline().strip() != "up":
        p.kill()
        p.wait()
        raise RuntimeError("the zenoh router did not start")
    return p


def _free_port() -> int:
    """A TCP port free on loopback now."""
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _fmt(v: float | None, spec: str, unit: str = "") -> str:
    return "-" if v is None else format(v, spec) + unit


def _print_table(rows: list, dur: float, markdown: bool) -> None:
    head = ["case", "robots", "robots/proc", "processes", "RTF", "goal", "bare barrier", "bare physics",
            "of the limit", "barrier median", "barrier p99", "CPU per robot", "RSS per robot", "start-up"]
    lines = []
    for case, s, (bar, phys) in rows:
        limit = min((v for v in (bar, phys) if v), default=None)
        lines.append([
            case.label, str(s.get("robots", case.robots)), str(case.per_process), str(s["processes"]),
            _fmt(s["rtf"], ".2f", "x"),
            f">= {case.goal:g}x" if case.goal else "",
            _fmt(bar, ".1f", "x"), _fmt(phys, ".1f", "x"),
            _fmt(s["rtf"] and limit and 100 * s["rtf"] / limit, ".0f", " %"),
            _fmt(s["barrier_us_median"], ".0f", " us"), _fmt(s["barrier_us_p99"], ".0f", " us"),
            _fmt(s["cpu_s_per_robot_per_sim_s"] and s["cpu_s_per_robot_per_sim_s"] * 1000, ".0f", " ms/sim-s"),
            _fmt(s["rss_mb_per_robot"], ".0f", " MB"), _fmt(s["startup_s"], ".1f", " s"),
        ])
    print(f"\nswarm-sitl bench: {dur:g} s simulated per case, {os.cpu_count()} cores")
    print_table(head, lines, markdown)
    configs = sorted({(case.label, str(case.config.relative_to(ROOT)) if case.config.is_relative_to(ROOT)
                       else str(case.config)) for case, _, _ in rows})
    print("cases: " + "; ".join(f"{label}: {cfg}" for label, cfg in configs))
    print("bare barrier: the lock-step barrier alone over as many participant processes; bare physics: the same world "
          "stepped alone; both as the RTF they allow. of the limit: RTF / the lower of the two.")


def print_table(head: list[str], lines: list[list[str]], markdown: bool) -> None:
    """A table of figures: Markdown, or columns aligned right."""
    if markdown:
        print("| " + " | ".join(head) + " |")
        print("|" + "|".join("---" for _ in head) + "|")
        for line in lines:
            print("| " + " | ".join(line) + " |")
    else:
        widths = [max(len(h), *(len(r[i]) for r in lines)) for i, h in enumerate(head)]
        print("  ".join(h.rjust(w) for h, w in zip(head, widths, strict=True)))
        for line in lines:
            print("  ".join(c.rjust(w) for c, w in zip(line, widths, strict=True)))


def _print_round_trip(rows: list) -> None:
    """The bare zenoh round trip (one participant process, nothing to compute), and each 10-robot case's barrier
    median as a multiple of it: what waking many processes costs beyond one message each way."""
    cases = [(case, s) for case, s, _ in rows if case.robots == 10 and s.get("barrier_us_median")]
    if not cases:
        return
    _, rtt_us = barrier_yardstick(1, 2000)
    print(f"bare zenoh round trip (world and one participant process): median {rtt_us:.0f} us")
    for case, s in cases:
        print(f"  {case.label}, 10 robots, {case.per_process} per process: barrier median {s['barrier_us_median']:.0f} "
              f"us = {s['barrier_us_median'] / rtt_us:.1f}x the round trip")


def _print_profile(path: Path, top: int = 12) -> None:
    if not path.exists():
        return
    print(f"\nworld process profile ({path}), by cumulative time:")
    st = pstats.Stats(str(path), stream=sys.stdout)
    st.sort_stats("cumulative").print_stats(top)
