"""``swarm-sitl bench --hosts 1,2 --link-delay-ms 0.2,1``: what a quantum costs when robots' processes run on other
computers, over a LAN with a given latency.

The radio demo's robots (hil_configs/demo.toml, 10 by default) in two groups, packed ``--robots-per-process`` to a
process (5 by default), run on this computer, then with both groups' firmware and logic on one host, then on two
(one group each). A host is a ``swarm-sitl join --host`` on this computer started by the host's ``launch`` command,
connecting over TCP on loopback: directly, or through a delay relay per host (``bridge.tools.delay_relay``) that
delays each direction by the link's one-way delay. Every case runs the same robots from the same seed, so every case
records the same digest (printed: a check that distance changed nothing but time). Figures only, never pass/fail.
"""

from __future__ import annotations

import os
import shlex
import sys
from pathlib import Path
from typing import Any

from bridge.core.config import read_toml, to_toml
from bridge.core.launcher import run_session
from bridge.tools.bench import DEMO, _fmt, _free_port, barrier_yardstick, print_table
from bridge.tools.delay_relay import start_relay


def hosts_config(
    base: Path, robots: int, per_process: int, duration: float, listen: str | None, endpoints: list[str]
) -> dict[str, Any]:
    """The base config's first robot group as two groups (robots and a random placement's region split in halves),
    packed ``per_process``; with one endpoint, both groups on host h0, with two, one on h0 and one on h1, each host's
    join connecting to its endpoint (the world listens on ``listen``)."""
    raw = read_toml(base)
    raw["session"].update(name="bench-hosts", duration_s=duration, speed="max", robots_per_process=per_process)
    group = raw["robots"][0]
    half = robots // 2
    groups = [{**group, "count": half}, {**group, "count": robots - half}]
    placement = group.get("placement", {})
    if placement.get("kind", "random") == "random":  # each group in its half of the region, so none overlap
        a = raw.get("arena", {})
        x0, y0, x1, y1 = placement.get("region") or (0.0, 0.0, a.get("width_m", 10.0), a.get("length_m", 20.0))
        ym = (y0 + y1) / 2
        for g, (lo, hi) in zip(groups, ((y0, ym), (ym, y1)), strict=True):
            g["placement"] = {**placement, "region": [x0, lo, x1, hi]}
    if endpoints:
        raw["session"]["listen"] = listen
        raw["hosts"] = [
            {
                "name": f"h{i}",
                "launch": f"exec {shlex.quote(sys.executable)} -m bridge.tools.cli join "
                f"{ep} --session {{session}} --host {{name}} --timeout 120",
            }
            for i, ep in enumerate(endpoints)
        ]
        for i, g in enumerate(groups):
            g["host"] = f"h{i % len(endpoints)}"
    raw["robots"] = groups + raw["robots"][1:]
    if raw.get("arena", {}).get("map"):
        raw["arena"]["map"] = str((base.parent / raw["arena"]["map"]).resolve())
    return raw


def run_hosts_bench(
    hosts: list[int],
    delays_ms: list[float],
    robots: int = 10,
    per_process: int = 5,
    duration: float = 10.0,
    out_dir: str = "runs/bench-hosts",
    config: str | None = None,
    markdown: bool = False,
) -> int:
    """Every case (this computer alone; each host count at each delay, and without a relay), then the table."""
    base = Path(config or DEMO)
    cases: list[tuple[int, float | None]] = [(0, None)]
    cases += [(h, d) for h in hosts for d in [None, *delays_ms]]
    rows = []
    for h, d in cases:
        name = "local" if not h else f"h{h}_" + ("direct" if d is None else f"d{d:g}ms")
        out = Path(out_dir) / name
        out.mkdir(parents=True, exist_ok=True)
        port = _free_port()
        relays = [start_relay(("127.0.0.1", port), d) for _ in range(h)] if d is not None else []
        try:
            endpoints = [f"tcp/127.0.0.1:{r.port}" for r in relays] or [f"tcp/127.0.0.1:{port}"] * h
            path = out / "config.toml"
            path.write_text(
                to_toml(hosts_config(base, robots, per_process, duration, f"tcp/127.0.0.1:{port}", endpoints))
            )
            res = run_session(str(path), None, str(out / "run"), progress=None, plot=False)
        finally:
            for r in relays:
                r.kill()
                r.wait()
        s = res.summary
        rows.append((h, d, s))
        print(
            f"  ran {name}: rtf {s['rtf']}x, barrier median {_fmt(s['barrier_us_median'], '.0f', ' us')} "
            f"(exit {res.code})",
            file=sys.stderr,
        )
    _print(rows, robots, per_process, duration, markdown)
    digests = {s["digest"] for _, _, s in rows}
    print(
        f"digest: {'the same in every case' if len(digests) == 1 else 'DIFFERS: ' + ', '.join(sorted(digests))} "
        f"({next(iter(digests))[:16]})"
    )
    _routing(delays_ms, max(len(s["remote_processes"]) for _, _, s in rows), markdown)  # one host's, at most
    return 0 if all(s["exit_code"] == 0 for _, _, s in rows) and len(digests) == 1 else 1


def _routing(delays_ms: list[float], procs: int, markdown: bool, quanta: int = 2000) -> None:
    """The bare barrier (no physics, no firmware) over each link, with a host's ``procs`` processes each connecting
    to the world (as a host's do) or all through one zenoh router on the host (one connection per host)."""
    lines = []
    for d in [-1.0, *delays_ms]:
        direct = barrier_yardstick(procs, quanta, link_delay_ms=d)[1]
        routed = barrier_yardstick(procs, quanta, link_delay_ms=d, router=True)[1]
        lines.append([
            "loopback" if d < 0 else f"{d:g} ms + relay", f"{direct:.0f} us", f"{routed:.0f} us",
            f"{routed - direct:+.0f} us",
        ])  # fmt: skip
    print(f"\nbare barrier over the link, {procs} processes on one host, {quanta} quanta: each its own connection to "
          "the world, or one router on the host")  # fmt: skip
    print_table(["link (one way)", "a connection each", "one router", "router - direct"], lines, markdown)


def _print(rows: list, robots: int, per_process: int, duration: float, markdown: bool) -> None:
    head = ["hosts", "link (one way)", "processes remote", "RTF", "barrier median", "barrier p99", "quantum wall"]
    lines = []
    for h, d, s in rows:
        q_wall = s["run_wall_s"] / s["quanta"] * 1e3 if s["quanta"] else None
        lines.append(
            [
                str(h) if h else "none",
                "-" if not h else "loopback" if d is None else f"{d:g} ms + relay",
                str(len(s["remote_processes"])),
                _fmt(s["rtf"], ".2f", "x"),
                _fmt(s["barrier_us_median"], ".0f", " us"),
                _fmt(s["barrier_us_p99"], ".0f", " us"),
                _fmt(q_wall, ".2f", " ms"),
            ]
        )
    print(
        f"\nswarm-sitl bench --hosts: {robots} robots of the radio demo, {per_process} per process, {duration:g} s "
        f"simulated per case, {os.cpu_count()} cores (hosts and world on this machine)"
    )
    print_table(head, lines, markdown)
