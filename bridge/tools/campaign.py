"""``swarm-sitl campaign``: repeat a check many times and count what went wrong, to prove a flake is absent.

``flake`` runs a pytest selection N times, the second half of them beside a process that keeps one core busy (a
loaded CI machine), and prints a table of the runs: exit code, tests passed and failed, wall time. A failure is a
bug, not bad luck: the table names the run and its log. Bounded in count (``--runs``) and in time (``--max-wall``:
no run starts after it); the exit code is 1 if any run failed, 0 if none did.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

_SUMMARY = re.compile(r"(\d+) (passed|failed|error|errors|skipped)")


@dataclass
class Run:
    """One run of the selection: what pytest said, with or without a busy core."""

    index: int
    busy: bool
    code: int
    passed: int
    failed: int
    wall_s: float
    log: Path


def _spinner() -> subprocess.Popen:
    """A process that keeps one core busy until killed."""
    return subprocess.Popen([sys.executable, "-c", "while True: pass"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)


def _counts(text: str) -> tuple[int, int]:
    last = [ln for ln in text.strip().splitlines() if " in " in ln and _SUMMARY.search(ln)]
    found = {k: int(n) for n, k in _SUMMARY.findall(last[-1])} if last else {}
    return found.get("passed", 0), found.get("failed", 0) + found.get("error", 0) + found.get("errors", 0)


def flake(selection: list[str], runs: int, out: Path, workers: int = 2, max_wall_s: float | None = None,
          busy_share: float = 0.5, echo: bool = True) -> list[Run]:
    """Run ``pytest -n workers selection`` ``runs`` times (the last ``busy_share`` of them beside a busy core)."""
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    first_busy = runs - round(runs * busy_share)
    done: list[Run] = []
    for i in range(runs):
        if max_wall_s is not None and time.monotonic() - t0 > max_wall_s:
            break
        busy = i >= first_busy
        spin = _spinner() if busy else None
        log = out / f"run-{i + 1:03d}.log"
        start = time.monotonic()
        try:
            with open(log, "w") as f:
                cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *(
                    ["-n", str(workers)] if workers > 1 else []), *selection]
                code = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL).returncode
        finally:
            if spin is not None:
                os.killpg(spin.pid, signal.SIGKILL)
                spin.wait()
        passed, failed = _counts(log.read_text(errors="replace"))
        run = Run(i + 1, busy, code, passed, failed, round(time.monotonic() - start, 1), log)
        done.append(run)
        if echo:
            print(_row(run), flush=True)
    return done


def _row(r: Run) -> str:
    return (f"| {r.index} | {'yes' if r.busy else 'no'} | {r.code} | {r.passed} | {r.failed} | {r.wall_s} |"
            + ("" if r.code == 0 else f" {r.log} |"))


def table(runs: list[Run]) -> str:
    """The campaign's summary as a Markdown table, then one line of totals."""
    failed = [r for r in runs if r.code != 0]
    busy = sum(r.busy for r in runs)
    return "\n".join([
        f"{len(runs)} runs ({busy} beside a busy core): {len(runs) - len(failed)} passed, {len(failed)} failed"
        + (f" (runs {', '.join(str(r.index) for r in failed)})" if failed else ""),
        f"tests per run: {sorted({r.passed for r in runs})}; wall per run {min(r.wall_s for r in runs)}-"
        f"{max(r.wall_s for r in runs)} s" if runs else "no run"])


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("campaign", help="repeat a check many times and count failures (flake)")
    what = p.add_subparsers(dest="campaign", required=True)
    f = what.add_parser("flake", help="run a pytest selection N times, the second half beside a busy core")
    f.add_argument("selection", nargs="+", help="what pytest runs (paths, -k, -m ...: put them after --)")
    f.add_argument("--runs", type=int, default=20)
    f.add_argument("--workers", type=int, default=2, help="pytest -n (1: no xdist)")
    f.add_argument("--busy-share", type=float, default=0.5, help="share of the runs beside a busy core")
    f.add_argument("--max-wall", type=float, default=None, help="start no run after this many seconds")
    f.add_argument("--out", default="runs/campaign-flake", help="where each run's log goes")
    f.set_defaults(fn=cmd_campaign)


def cmd_campaign(a: argparse.Namespace) -> int:
    if a.runs < 1 or not 0 <= a.busy_share <= 1:
        print("swarm-sitl campaign: --runs must be at least 1 and --busy-share within 0..1", file=sys.stderr)
        return 2
    print("| run | busy core | exit | passed | failed | wall (s) |\n|---|---|---|---|---|---|", flush=True)
    runs = flake(a.selection, a.runs, Path(a.out), a.workers, a.max_wall, a.busy_share)
    print(table(runs))
    return 0 if runs and all(r.code == 0 for r in runs) else 1
