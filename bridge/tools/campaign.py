"""``swarm-sitl campaign``: repeat a check many times and count what went wrong, to prove a flake, an orphan, a
cross-talk or a leak absent.

``flake`` runs a pytest selection N times, the second half of them beside a process that keeps one core busy (a
loaded CI machine), and prints a table of the runs: exit code, tests passed and failed, wall time. A failure is a
bug, not bad luck: the table names the run and its log. Bounded in count (``--runs``) and in time (``--max-wall``:
no run starts after it); the exit code is 1 if any run failed, 0 if none did.

``orphans`` starts N short sessions and hits each, at a random (seeded) moment, with a random signal (SIGINT,
SIGTERM, SIGKILL, SIGHUP, SIGSTOP then SIGCONT, or its output pipe closed) sent to the launcher or to one of its
children; then checks that no process of the session is left, that its recording reads whole with the ``mcap``
library's reader (after ``swarm-sitl recover`` where the launcher died before it could recover it) and that
``swarm-sitl digest`` recomputes the digest the session reported.

``concurrency`` runs K sessions of one config at once and checks each recorded the same bytes (digest) as the
config run alone: sessions on one machine do not see each other, and lock-step makes a session deterministic.

``soak`` runs one long session of 10 robots with faults that end (injected every few simulated seconds), samples the
RSS and open file descriptors of its processes as it goes, and judges them flat: the first 10 % of the run is
warm-up, the mean of the next 15 % the reference, and the mean of the last quarter must be within 10 % of it, for
the total RSS and for the RSS and the fds of each kind of process (world, firmware, logic, launcher); every robot
must be alive at the end.

Each is bounded in count and in time, prints a Markdown table, and exits 1 if anything went wrong.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import re
import select
import signal
import subprocess
import sys
import time
import tomllib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from statistics import mean
from typing import Any

from bridge.tools.argtypes import at_least_one, positive

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




# --- a session this campaign starts and watches -------------------------------------------------------------------

_PROGRESS = re.compile(r"\] sim\s+([\d.]+) / ([\d.]+) s")
_TRACEBACK = "Traceback (most recent call last)"


def _cli(*args: str) -> list[str]:
    """A ``swarm-sitl`` command, run by this interpreter."""
    return [sys.executable, "-m", "bridge.tools.cli", *args]


@dataclass(frozen=True)
class Proc:
    """A process seen while a session ran: pid and start time (a pid alone may be reused), its name and kind."""

    pid: int
    created: float
    name: str  # the session's name for it (world, fw0, lg1 ...), "launcher", or its program
    kind: str  # launcher, world, firmware, logic, service, other


def identify(cmdline: list[str]) -> tuple[str, str]:
    """(name, kind) of a process from its command line: a session's process (``bridge.hosts.proc ROLE --proc NAME``),
    a launcher (``swarm-sitl run``), or another program."""
    if "bridge.hosts.proc" in cmdline[:-1]:
        role = cmdline[cmdline.index("bridge.hosts.proc") + 1]
        name = cmdline[cmdline.index("--proc") + 1] if "--proc" in cmdline[:-1] else role
        return name, role
    if "run" in cmdline and ("bridge.tools.cli" in cmdline or any(c.endswith("swarm-sitl") for c in cmdline[:2])):
        return "launcher", "launcher"
    return (Path(cmdline[0]).name if cmdline else "?"), "other"


def describe(p: Any) -> Proc | None:
    """``p`` (a psutil.Process) as a Proc; None if it is gone."""
    import psutil

    try:
        with p.oneshot():
            name, kind = identify(p.cmdline())
            return Proc(p.pid, p.create_time(), name, kind)
    except psutil.Error:
        return None


def alive(p: Proc) -> bool:
    """Whether ``p`` still runs (a zombie, dead but not yet reaped, does not)."""
    import psutil

    try:
        q = psutil.Process(p.pid)
        return q.create_time() == p.created and q.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def leftovers(procs: Iterable[Proc], grace_s: float) -> list[Proc]:
    """Those of ``procs`` still running after ``grace_s``: polled until every one is gone, so the wait ends as soon
    as they are; the grace only bounds it (a world finishing its recording takes a moment)."""
    deadline = time.monotonic() + grace_s
    left = [p for p in procs if alive(p)]
    while left and time.monotonic() < deadline:
        time.sleep(0.05)
        left = [p for p in left if alive(p)]
    return sorted(left, key=lambda p: p.name)


def session_processes(out: Path) -> list[Proc]:
    """Every process whose command line names ``out``, the session's output directory, which the launcher gives each
    of its processes: those a poll of its children may have missed (one started just before it died)."""
    import psutil

    found = []
    for p in psutil.process_iter(["cmdline"]):
        if p.pid != os.getpid() and str(out) in (p.info["cmdline"] or []) and (d := describe(p)) is not None:
            found.append(d)
    return found


def _kill(procs: Iterable[Proc]) -> None:
    """SIGKILL each of ``procs`` that still runs (after it was reported)."""
    import psutil

    for p in procs:
        if alive(p):
            with contextlib.suppress(psutil.Error):
                psutil.Process(p.pid).kill()


CAMPAIGN_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _default_signals() -> None:
    """In a trial's launcher, before it runs: the signals a campaign sends with their default meaning, as a terminal's
    session has them, whatever this campaign inherited (``nohup`` ignores SIGHUP, and an ignored signal stays ignored
    across exec: a SIGHUP trial would test nothing)."""
    for sig in CAMPAIGN_SIGNALS:
        signal.signal(sig, signal.SIG_DFL)


class Watched:
    """A ``swarm-sitl run`` this campaign started: its output read as it comes (the ``started:`` line, the simulated
    time of its progress lines), and every process it starts recorded while it runs, so that none may be left."""

    TAIL = 64 * 1024

    def __init__(self, run_args: list[str], out: Path) -> None:
        self.out = out
        self.t0 = time.monotonic()
        self.p = subprocess.Popen(_cli("run", *run_args, "--out", str(out)), stdin=subprocess.DEVNULL,
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
                                  preexec_fn=_default_signals)
        assert self.p.stdout is not None
        self.pipe_open = True
        self.text = ""  # its output (the last TAIL characters)
        self._partial = ""
        self.started_at: float | None = None  # when it said the session started
        self.sim_t = 0.0  # the simulated time of its last progress line
        self.lines = 0  # progress lines so far
        self.ended = False  # its last progress line came (the session reached its duration)
        self.procs: dict[int, Proc] = {}
        self.spawned_at: float | None = None  # when its first process (the world) was seen
        self._next_scan = 0.0

    def pump(self, timeout: float) -> bool:
        """Read what the launcher writes within ``timeout`` seconds (returning on the first output), note its
        processes; whether it still runs."""
        if self.pipe_open and self.p.stdout is not None:
            fd = self.p.stdout.fileno()
            if select.select([fd], [], [], max(timeout, 0.0))[0]:
                chunk = os.read(fd, 65536)
                if chunk:
                    self._take(chunk.decode(errors="replace"))
                else:
                    self.close_pipe()
        else:
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.p.wait(max(timeout, 0.0))
        self.scan()
        return self.p.poll() is None

    def _take(self, text: str) -> None:
        self.text = (self.text + text)[-self.TAIL:]
        lines = (self._partial + text).replace("\r", "\n").split("\n")
        self._partial = lines.pop()
        for ln in lines:
            if self.started_at is None and "] started: " in ln:
                self.started_at = time.monotonic()
            if m := _PROGRESS.search(ln):
                self.sim_t = float(m[1])
                self.lines += 1
                self.ended = self.ended or self.sim_t >= float(m[2])

    def scan(self, force: bool = False) -> None:
        """Record the launcher's descendants (at most ten times a second unless ``force``)."""
        import psutil

        now = time.monotonic()
        if now < self._next_scan and not force:
            return
        self._next_scan = now + 0.1
        try:
            kids = psutil.Process(self.p.pid).children(recursive=True)
        except psutil.Error:
            return
        for k in kids:
            if k.pid not in self.procs and (d := describe(k)) is not None:
                self.procs[k.pid] = d
                self.spawned_at = self.spawned_at or now

    def children(self) -> list[Proc]:
        """The launcher's descendants that run now, by name."""
        self.scan(force=True)
        return sorted((p for p in self.procs.values() if alive(p)), key=lambda p: p.name)

    def phase(self) -> str:
        if self.p.poll() is not None:
            return "after its exit"
        if self.started_at is None:
            up = sum(alive(p) for p in self.procs.values())
            return f"start-up ({up} process{'' if up == 1 else 'es'} up)"
        return "ending" if self.ended else "running"

    def close_pipe(self) -> None:
        """Close this end of the launcher's output (its stdout and stderr): what it writes next finds no reader."""
        if self.pipe_open and self.p.stdout is not None:
            self.p.stdout.close()
        self.pipe_open = False

    def wait(self, deadline: float) -> int | None:
        """Its exit code, once it exits, reading its output meanwhile; None if it still runs at ``deadline``."""
        while self.pump(min(0.2, deadline - time.monotonic())):
            if time.monotonic() >= deadline:
                return None
        end = time.monotonic() + 5.0
        while self.pipe_open and time.monotonic() < end:  # the rest of its output, to its end
            self.pump(0.1)
        return self.p.returncode

    def close(self) -> None:
        """Stop the launcher if it still runs (SIGINT: a clean stop; SIGKILL a minute later), close the pipe."""
        if self.p.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                self.p.send_signal(signal.SIGCONT)
                self.p.send_signal(signal.SIGINT)
            try:
                self.p.wait(60)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait()
        self.close_pipe()


# --- checking what a session left ---------------------------------------------------------------------------------


def mcap_readable(path: Path) -> str | None:
    """Read every message of ``path`` with the mcap library's own reader (CRCs checked): None if it reads whole,
    else what went wrong."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            for _ in make_reader(f, validate_crcs=True).iter_messages():
                pass
    except Exception as e:
        return f"{type(e).__name__}: {e}".strip().splitlines()[0][:120]
    return None


@dataclass
class RecordingCheck:
    """Whether a session's recording reads whole (None: there is none), and whether ``swarm-sitl digest`` recomputes
    the digest the session reported (None: nothing to compare with)."""

    readable: bool | None = None
    read_note: str = "none"
    digest_ok: bool | None = None
    digest_note: str = "n/a"


def _json(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def check_recording(out: Path) -> RecordingCheck:
    """Check ``out/session.mcap``. A finished file is read as it is. An unfinished one is recovered here (``swarm-sitl
    recover``) only if no summary.json exists (the launcher died before it could); one the launcher left unfinished
    beside its summary is unreadable. The digest is compared with summary.json's, else the world's result's, else
    what ``swarm-sitl recover`` reported."""
    from bridge.core.recorder import MCAP_MAGIC, is_complete

    rec = out / "session.mcap"
    c = RecordingCheck()
    if not rec.exists():
        return c
    summary = _json(out / "summary.json")
    ref = summary if summary is not None else _json(out / "world_result.json") or {}
    if rec.stat().st_size == 0:
        c.readable, c.read_note = False, "no: an empty file"
        return c
    with open(rec, "rb") as f:
        magic = f.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    if magic and not is_complete(rec):
        if summary is not None:
            c.readable, c.read_note = False, "no: unfinished, beside a summary (the launcher did not recover it)"
            return c
        r = subprocess.run(_cli("recover", str(out)), capture_output=True, text=True, stdin=subprocess.DEVNULL)
        if r.returncode != 0:
            c.readable, c.read_note = False, f"no: swarm-sitl recover: {r.stderr.strip()[-120:]}"
            return c
        if not ref.get("digest") and (m := re.search(r"(\d+) messages .* digest ([0-9a-f]{64})", r.stdout)):
            ref = {"digest": m[2], "messages": int(m[1])}
        c.read_note = "yes (recovered here)"
    if why := mcap_readable(rec):
        c.readable, c.read_note = False, f"no: {why}"
        return c
    c.readable = True
    if c.read_note == "none":
        c.read_note = "yes (recovered by the launcher)" if (summary or {}).get("recording") else "yes"
    r = subprocess.run(_cli("digest", str(rec)), capture_output=True, text=True, stdin=subprocess.DEVNULL)
    if r.returncode != 0:
        c.digest_ok, c.digest_note = False, f"swarm-sitl digest failed: {r.stderr.strip()[-120:]}"
        return c
    got = json.loads(r.stdout)
    if not ref.get("digest"):
        c.digest_note = "n/a (no digest reported)"
        return c
    c.digest_ok = got["digest"] == ref["digest"] and got["messages"] == ref.get("messages", got["messages"])
    c.digest_note = "ok" if c.digest_ok else (f"MISMATCH: {got['digest'][:12]} ({got['messages']} messages) vs "
                                              f"reported {ref['digest'][:12]} ({ref.get('messages')} messages)")
    return c


# --- orphans ------------------------------------------------------------------------------------------------------

ACTIONS = ("SIGINT", "SIGTERM", "SIGKILL", "SIGHUP", "SIGSTOP+SIGCONT", "close-stdout")


@dataclass(frozen=True)
class Hit:
    """What one trial does to its session: ``action`` to the launcher or to a child (``pick``: which, as a share of
    its children by name), ``delay_s`` after the launch (phase ``start-up``), after its first process (the world)
    appeared (``spawned``: the world starts up, the others come) or after the session started (``running``); a
    SIGSTOP lasts ``stop_s`` before the SIGCONT."""

    action: str
    to_child: bool
    pick: float
    phase: str
    delay_s: float
    stop_s: float


def plan_hits(trials: int, seed: int, actions: Iterable[str] = ACTIONS, target: str = "any",
              run_wall_s: float = 2.0, startup_s: float = 4.0) -> list[Hit]:
    """The trials' hits, drawn from ``random.Random(seed)`` (the same draws whatever the options, so a seed names the
    same moments). A sixth strike within ``startup_s`` of the launch, a sixth within ``startup_s`` of the world's
    appearance, the rest while the session runs (within 1.25 ``run_wall_s`` after it started: some land in its
    ending). Closing the output pipe is the launcher's only: its children write to their logs."""
    acts = list(actions)
    if unknown := sorted(set(acts) - set(ACTIONS)):
        raise ValueError(f"unknown action {', '.join(unknown)} (known: {', '.join(ACTIONS)})")
    rng = random.Random(seed)
    hits = []
    for _ in range(trials):
        action, child, pick, phase, d, stop = (rng.choice(acts), rng.random(), rng.random(), rng.random(),
                                               rng.random(), rng.uniform(0.2, 3.0))
        to_child = (target == "child" or (target == "any" and child < 0.5)) and action != "close-stdout"
        when = "start-up" if phase < 1 / 6 else "spawned" if phase < 1 / 3 else "running"
        hits.append(Hit(action, to_child, pick, when, round(d * (1.25 * run_wall_s if when == "running" else startup_s),
                                                            3), round(stop, 3)))
    return hits


@dataclass
class Trial:
    """One session hit by one signal, and what it left."""

    index: int
    action: str
    out: Path
    target: str = "-"
    when: str = "never (the session had ended)"
    code: int | None = None
    orphans: list[Proc] = field(default_factory=list)
    rec: RecordingCheck = field(default_factory=RecordingCheck)
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.orphans and self.rec.readable is not False and self.rec.digest_ok is not False and not (
            self.problems)


def _strike(w: Watched, hit: Hit, t: Trial) -> None:
    """Wait for ``hit``'s moment (reading the launcher's output), then strike."""
    if hit.phase == "running":
        while w.started_at is None and w.pump(0.1):
            pass
    while hit.phase == "spawned" and w.spawned_at is None and w.pump(0.02):
        pass
    at = {"running": w.started_at, "spawned": w.spawned_at}.get(hit.phase, w.t0) or w.t0
    at += hit.delay_s
    while (left := at - time.monotonic()) > 0 and w.pump(min(left, 0.1)):
        pass
    kids = w.children() if hit.to_child else []
    while hit.to_child and not kids and w.pump(0.05):  # the first child comes right after the launch
        kids = w.children()
    if w.p.poll() is not None:
        return
    import psutil

    t.when = f"{w.phase()} +{time.monotonic() - w.t0:.1f} s"
    victim: Any = w.p
    t.target = "launcher"
    if hit.to_child:
        c = kids[min(int(hit.pick * len(kids)), len(kids) - 1)]
        t.target = c.name
        try:
            victim = psutil.Process(c.pid)  # its send_signal checks the pid was not reused
        except psutil.Error:
            t.when += " (it was gone)"
            return
    try:
        if hit.action == "close-stdout":
            w.close_pipe()
        elif hit.action == "SIGSTOP+SIGCONT":
            t.when += f", {hit.stop_s:.1f} s stopped"
            victim.send_signal(signal.SIGSTOP)
            try:
                end = time.monotonic() + hit.stop_s
                while (left := end - time.monotonic()) > 0 and w.pump(min(left, 0.1)):
                    pass
            finally:
                victim.send_signal(signal.SIGCONT)
        else:
            victim.send_signal(getattr(signal, hit.action))
    except (ProcessLookupError, psutil.Error):
        t.when += " (it was gone)"


def orphan_trial(index: int, hit: Hit, run_args: list[str], out: Path, timeout_s: float = 300.0,
                 grace_s: float = 30.0) -> Trial:
    """Start a session (``swarm-sitl run RUN_ARGS --out OUT``), strike it with ``hit``, wait for the launcher to exit
    (killing it after ``timeout_s``: a hung trial), then check that no process of it is left ``grace_s`` later, that
    its recording reads whole and that its digest is recomputed."""
    out = out.absolute()
    t = Trial(index, hit.action, out)
    w = Watched(run_args, out)
    try:
        _strike(w, hit, t)
        t.code = w.wait(w.t0 + timeout_s)
        if t.code is None:
            t.problems.append(f"hung: the launcher had not exited {timeout_s:.0f} s after its start (killed)")
            with contextlib.suppress(ProcessLookupError):
                w.p.send_signal(signal.SIGCONT)
            w.p.kill()
            t.code = w.p.wait()
    finally:
        w.close()
    seen = {**w.procs, **{p.pid: p for p in session_processes(out)}}
    t.orphans = leftovers(seen.values(), grace_s)
    _kill(t.orphans)
    if _TRACEBACK in w.text:
        t.problems.append("the launcher printed a traceback")
    t.rec = check_recording(out)
    if t.rec.readable is None and t.when.startswith(("running", "ending")):
        t.rec.readable, t.rec.read_note = False, "no recording, though the session had started"
    return t


def _trial_row(t: Trial) -> str:
    orphans = ", ".join(f"{p.name} ({p.pid})" for p in t.orphans)
    return (f"| {t.index} | {t.action} | {t.target} | {t.when} | {t.code} | {len(t.orphans)}"
            f"{f': {orphans}' if orphans else ''} | {t.rec.read_note} | {t.rec.digest_note} |"
            + (f" {'; '.join(t.problems)} |" if t.problems else "") + ("" if t.ok else f" {t.out} |"))


ORPHANS_HEADER = ("| trial | signal | target | when | exit | orphans | recording readable | digest |\n"
                  "|---|---|---|---|---|---|---|---|")


def orphans(trials: int, seed: int, run_args: list[str], out: Path, actions: Iterable[str] = ACTIONS,
            target: str = "any", run_wall_s: float = 2.0, max_wall_s: float | None = None,
            echo: bool = True) -> list[Trial]:
    """``trials`` sessions, each struck by one of ``plan_hits``; no trial starts after ``max_wall_s``."""
    hits = plan_hits(trials, seed, actions, target, run_wall_s)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    done = []
    for i, hit in enumerate(hits, 1):
        if max_wall_s is not None and time.monotonic() - t0 > max_wall_s:
            break
        t = orphan_trial(i, hit, run_args, out / f"trial-{i:03d}")
        done.append(t)
        if echo:
            print(_trial_row(t), flush=True)
    return done


def orphans_table(trials: list[Trial]) -> str:
    """The totals of an orphans campaign."""
    if not trials:
        return "no trial"
    bad = [t for t in trials if not t.ok]
    by_action = {a: sum(t.action == a for t in trials) for a in ACTIONS}
    to_children = sum(t.target not in ("launcher", "-") for t in trials)
    missed = sum(t.target == "-" for t in trials)
    return "\n".join([
        f"{len(trials)} trials ({', '.join(f'{a} {n}' for a, n in by_action.items() if n)}; {to_children} to a child"
        f", {len(trials) - to_children - missed} to the launcher, {missed} after the session had ended): "
        f"{len(trials) - len(bad)} clean, {len(bad)} not" + (
            f" (trials {', '.join(str(t.index) for t in bad)})" if bad else ""),
        f"orphans: {sum(bool(t.orphans) for t in trials)} trials left {sum(len(t.orphans) for t in trials)} "
        f"processes; unreadable recordings: {sum(t.rec.readable is False for t in trials)}; digest mismatches: "
        f"{sum(t.rec.digest_ok is False for t in trials)}; recordings checked: "
        f"{sum(t.rec.readable is True for t in trials)}, digests compared: "
        f"{sum(t.rec.digest_ok is not None for t in trials)}; other problems: "
        f"{sum(bool(t.problems) for t in trials)}"])


# --- concurrency --------------------------------------------------------------------------------------------------


@dataclass
class SessionRun:
    """One session of a concurrency campaign: its exit code and digest."""

    name: str
    out: Path
    code: int | None = None
    digest: str | None = None
    messages: int | None = None


def _start_quiet(run_args: list[str], out: Path) -> subprocess.Popen:
    out.mkdir(parents=True, exist_ok=True)
    with open(out.with_name(out.name + ".log"), "wb") as log:
        return subprocess.Popen(_cli("run", *run_args, "--out", str(out), "--quiet"), stdin=subprocess.DEVNULL,
                                stdout=log, stderr=subprocess.STDOUT, start_new_session=True)


def _finish_all(runs: list[tuple[SessionRun, subprocess.Popen]], deadline: float) -> None:
    """Wait for every session until ``deadline``, then stop those still running (SIGINT, a clean stop); read their
    summaries."""
    for _, p in runs:
        try:
            p.wait(max(deadline - time.monotonic(), 0.0))
        except subprocess.TimeoutExpired:
            p.send_signal(signal.SIGINT)
    for s, p in runs:
        try:
            s.code = p.wait(120)
        except subprocess.TimeoutExpired:
            p.kill()
            s.code = p.wait()
        summary = _json(s.out / "summary.json") or {}
        s.digest, s.messages = summary.get("digest"), summary.get("messages")


def concurrency(sessions: int, run_args: list[str], out: Path, max_wall_s: float = 1800.0,
                echo: bool = True) -> tuple[SessionRun, list[SessionRun]]:
    """The config run alone, then ``sessions`` times at once (each stopped if still running ``max_wall_s`` after
    the start of all)."""
    t0 = time.monotonic()
    solo = SessionRun("solo", out / "solo")
    _finish_all([(solo, _start_quiet(run_args, solo.out))], t0 + max_wall_s)
    if echo:
        print(_session_row(solo, solo), flush=True)
    runs = [SessionRun(f"{i}", out / f"session-{i}") for i in range(1, sessions + 1)]
    procs = [(s, _start_quiet(run_args, s.out)) for s in runs]
    _finish_all(procs, t0 + max_wall_s)
    if echo:
        for s in runs:
            print(_session_row(s, solo), flush=True)
    return solo, runs


def _same(s: SessionRun, solo: SessionRun) -> bool:
    return s.code == 0 and s.digest is not None and (s.digest, s.messages) == (solo.digest, solo.messages)


def _session_row(s: SessionRun, solo: SessionRun) -> str:
    return (f"| {s.name} | {s.code} | {(s.digest or '-')[:16]} | {s.messages} | "
            f"{'-' if s is solo else 'yes' if _same(s, solo) else 'NO'} |" + ("" if s.code == 0 else f" {s.out} |"))


# --- soak ---------------------------------------------------------------------------------------------------------

#: how to make a fault of a kind: (random source, robot count, how long it lasts) -> its ``[[faults]]`` fields but
#: ``at_s``. A kind not listed gets ``_robot_fault`` (a random robot, ``duration_s``), which the config's validation
#: accepts or refuses; add a maker here for a kind that needs more.
FaultMaker = Callable[[random.Random, int, float], dict[str, Any]]


def _can_noise(rng: random.Random, robots: int, span_s: float) -> dict[str, Any]:
    # at most 5 %: the error counters fall on average (8 up per error, 1 down per frame), so no bus-off for good
    return {"kind": "can_noise", "robot": rng.randrange(robots), "probability": round(rng.uniform(0.005, 0.05), 4),
            "duration_s": span_s}


def _partition(rng: random.Random, robots: int, span_s: float) -> dict[str, Any]:
    if robots < 2:
        raise ValueError("partition: needs two robots or more")
    ids = list(range(robots))
    rng.shuffle(ids)
    cut = rng.randrange(1, robots)
    return {"kind": "partition", "groups": [sorted(ids[:cut]), sorted(ids[cut:])], "duration_s": span_s}


def _burst_loss(rng: random.Random, robots: int, span_s: float) -> dict[str, Any]:
    some = rng.random() < 0.5
    f: dict[str, Any] = {"kind": "burst_loss", "p_gb": round(rng.uniform(0.01, 0.1), 4),
                         "p_bg": round(rng.uniform(0.1, 0.5), 4), "duration_s": span_s}
    if some:
        f["robots"] = sorted(rng.sample(range(robots), rng.randint(1, robots)))
    return f


def _freeze(rng: random.Random, robots: int, span_s: float) -> dict[str, Any]:
    return {"kind": "freeze", "robot": rng.randrange(robots), "process": rng.choice(["logic", "firmware"]),
            "duration_s": span_s}


def _firmware_reboot(rng: random.Random, robots: int, span_s: float) -> dict[str, Any]:
    # it ends by itself: the board is back after boot_s
    return {"kind": "firmware_reboot", "robot": rng.randrange(robots), "boot_s": round(min(span_s, 2.0), 3)}


def _clock_drift(rng: random.Random, robots: int, span_s: float) -> dict[str, Any]:
    return {"kind": "clock_drift", "robot": rng.randrange(robots),
            "ppm": rng.choice([-1, 1]) * round(rng.uniform(50, 5000)), "duration_s": span_s}


def _robot_fault(kind: str) -> FaultMaker:
    def make(rng: random.Random, robots: int, span_s: float) -> dict[str, Any]:
        return {"kind": kind, "robot": rng.randrange(robots), "duration_s": span_s}

    return make


FAULT_MAKERS: dict[str, FaultMaker] = {"can_noise": _can_noise, "partition": _partition, "burst_loss": _burst_loss,
                                       "freeze": _freeze, "firmware_reboot": _firmware_reboot,
                                       "clock_drift": _clock_drift}
SOAK_FAULTS = ("can_noise", "partition", "burst_loss", "firmware_reboot", "freeze", "clock_drift")


def fault_schedule(kinds: Iterable[str], robots: int, duration_s: float, every_s: float, seed: int
                   ) -> list[dict[str, Any]]:
    """A fault every ``every_s`` simulated seconds (from ``every_s`` on, the last one period before the end), each
    of a kind drawn from ``kinds`` and lasting 20 to 80 % of the period: each ends before the next starts, and the
    swarm goes on. Seeded (``random.Random(seed)``)."""
    kinds = list(kinds)
    if not kinds or every_s <= 0:
        raise ValueError("fault_schedule: needs a kind and a period > 0")
    rng = random.Random(seed)
    out = []
    k = 1
    while (at := k * every_s) + every_s <= duration_s:
        kind = rng.choice(kinds)
        span = round(rng.uniform(0.2, 0.8) * every_s, 3)
        out.append({"at_s": round(at, 3), **FAULT_MAKERS.get(kind, _robot_fault(kind))(rng, robots, span)})
        k += 1
    return out


def _toml_key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k, ensure_ascii=False)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"no TOML for {type(v).__name__}")


def to_toml(d: dict[str, Any], path: tuple[str, ...] = ()) -> str:
    """``d`` (as ``tomllib`` reads a config) written back as TOML: values, then tables, then arrays of tables."""
    lines = [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in d.items()
             if not isinstance(v, dict) and not (isinstance(v, list) and v and all(isinstance(x, dict) for x in v))]
    parts = ["\n".join(lines)] if lines else []
    for k, v in d.items():
        name = ".".join(_toml_key(x) for x in (*path, k))
        if isinstance(v, dict):
            parts.append(f"[{name}]\n" + to_toml(v, (*path, k)))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            parts += [f"[[{name}]]\n" + to_toml(x, (*path, k)) for x in v]
    return "\n\n".join(p.rstrip("\n") for p in parts) + "\n"


def soak_config(base: Path, robots: int, duration_s: float, faults: list[dict[str, Any]]) -> str:
    """The soak's config: ``base`` (one ``[[robots]]`` group) with ``robots`` robots, ``duration_s`` and ``faults``
    added to its own."""
    raw = tomllib.loads(base.read_text())
    groups = raw.get("robots", [])
    if len(groups) != 1:
        raise ValueError(f"{base}: a soak's base config needs exactly one [[robots]] group, found {len(groups)}")
    groups[0]["count"] = robots
    raw.setdefault("session", {}).update(name="soak", duration_s=duration_s)
    raw["faults"] = [*raw.get("faults", []), *faults]
    text = (f"# swarm-sitl campaign soak: {base.name} with {robots} robots, {duration_s:g} simulated s, "
            f"{len(faults)} faults added\n" + to_toml(raw))
    if tomllib.loads(text) != raw:
        raise ValueError(f"{base}: could not write it back as TOML unchanged")
    return text


@dataclass
class Sample:
    """The session's processes at one simulated time: RSS (MiB), open file descriptors and count, per kind."""

    sim_t: float
    wall_s: float
    rss: dict[str, float]
    fds: dict[str, int]
    procs: dict[str, int]


def sample_processes(sim_t: float, wall_s: float, procs: Iterable[Proc]) -> Sample:
    """RSS and open fds of ``procs``, summed per kind."""
    import psutil

    s = Sample(sim_t, wall_s, {}, {}, {})
    for p in procs:
        try:
            q = psutil.Process(p.pid)
            with q.oneshot():
                if q.create_time() != p.created or q.status() == psutil.STATUS_ZOMBIE:
                    continue
                rss, fds = q.memory_info().rss, q.num_fds()
        except psutil.Error:
            continue
        s.rss[p.kind] = s.rss.get(p.kind, 0.0) + rss / 2**20
        s.fds[p.kind] = s.fds.get(p.kind, 0) + fds
        s.procs[p.kind] = s.procs.get(p.kind, 0) + 1
    return s


@dataclass
class Flatness:
    """One series judged: the mean just after warm-up (``reference``) against the mean of the last quarter."""

    name: str
    reference: float | None
    last: float | None
    tolerance: float = 0.10

    @property
    def change(self) -> float | None:
        if self.reference is None or self.last is None or not self.reference:
            return None
        return self.last / self.reference - 1

    @property
    def ok(self) -> bool | None:
        """Flat (True), grew or shrank by more than the tolerance (False), or too few samples to say (None)."""
        return None if self.change is None else abs(self.change) <= self.tolerance


def flatness(name: str, series: list[tuple[float, float]], end_s: float, tolerance: float = 0.10,
             warmup: float = 0.10, reference: float = 0.15) -> Flatness:
    """Judge ``series`` ((simulated time, value), over a run of ``end_s`` simulated seconds): the first ``warmup`` of
    the run is warm-up; the mean of the next ``reference`` of it (at least its first sample) is compared with the
    mean of its last quarter; flat if within ``tolerance`` of it. Too few samples (no sample after warm-up, or the
    last quarter holding only the reference's): not judged."""
    after = [(t, v) for t, v in series if t > warmup * end_s]
    ref = [(t, v) for t, v in after if t <= (warmup + reference) * end_s] or after[:1]
    last = [(t, v) for t, v in series if t > 0.75 * end_s]
    if not ref or not last or {t for t, _ in last} <= {t for t, _ in ref}:
        return Flatness(name, None, None, tolerance)
    return Flatness(name, mean(v for _, v in ref), mean(v for _, v in last), tolerance)


@dataclass
class Soak:
    """What a soak measured and how it ended."""

    out: Path
    duration_s: float
    faults: int
    samples: list[Sample] = field(default_factory=list)
    code: int | None = None
    cut: bool = False  # stopped at --max-wall
    robots: int = 0
    alive: int | None = None
    judged: list[Flatness] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return (not self.problems and bool(self.judged) and all(f.ok for f in self.judged)
                and self.alive == self.robots)


KIND_ORDER = ("world", "firmware", "logic", "service", "launcher", "other")


def _kinds(s: Sample) -> list[str]:
    return [k for k in KIND_ORDER if k in s.rss] + sorted(set(s.rss) - set(KIND_ORDER))


def soak_header(kinds: list[str]) -> str:
    k = " / ".join(kinds)
    return (f"| sim t (s) | wall (s) | RSS total (MiB) | RSS MiB ({k}) | fds ({k}) | processes ({k}) |\n"
            "|---|---|---|---|---|---|")


def _sample_row(s: Sample, kinds: list[str]) -> str:
    return (f"| {s.sim_t:.0f} | {s.wall_s:.0f} | {sum(s.rss.values()):.1f} | "
            f"{' / '.join(f'{s.rss.get(k, 0):.1f}' for k in kinds)} | {' / '.join(str(s.fds.get(k, 0)) for k in kinds)}"
            f" | {' / '.join(str(s.procs.get(k, 0)) for k in kinds)} |")


def judge_soak(samples: list[Sample], end_s: float) -> list[Flatness]:
    """Total RSS, and RSS and fds of each kind of process, each judged by ``flatness``."""
    if not samples:
        return []
    kinds = sorted({k for s in samples for k in s.rss}, key=lambda k: (k not in KIND_ORDER, KIND_ORDER.index(k)
                                                                         if k in KIND_ORDER else 0, k))
    out = [flatness("RSS total (MiB)", [(s.sim_t, sum(s.rss.values())) for s in samples], end_s)]
    for k in kinds:
        out.append(flatness(f"RSS {k} (MiB)", [(s.sim_t, s.rss.get(k, 0.0)) for s in samples], end_s))
    for k in kinds:
        out.append(flatness(f"fds {k}", [(s.sim_t, float(s.fds.get(k, 0))) for s in samples], end_s))
    return out


def soak(base: Path, robots: int, sim_hours: float, fault_every_s: float, sample_every_s: float, out: Path,
         kinds: Iterable[str] = SOAK_FAULTS, seed: int = 0, max_wall_s: float | None = None,
         echo: bool = True) -> Soak:
    """Write ``out/soak.toml`` (``base`` with ``robots`` robots, ``sim_hours`` and a fault every ``fault_every_s``
    simulated seconds), run it into ``out/session``, sample its processes every ``sample_every_s`` simulated seconds
    (at the launcher's progress lines, one per 10 simulated seconds) and judge the samples."""
    out = out.absolute()
    out.mkdir(parents=True, exist_ok=True)
    duration = round(sim_hours * 3600, 3)
    faults = fault_schedule(kinds, robots, duration, fault_every_s, seed)
    cfg = out / "soak.toml"
    cfg.write_text(soak_config(base, robots, duration, faults))
    validate(str(cfg))  # a fault the config refuses stops the soak before it starts (ConfigError)
    res = Soak(out, duration, len(faults), robots=robots)
    w = Watched([str(cfg)], out / "session")
    shown: list[str] = []
    next_at = 0.0
    seen_lines = 0
    latest: Sample | None = None  # taken at the last progress line: kept as the last sample if off the schedule

    def keep(s: Sample) -> None:
        res.samples.append(s)
        if echo:
            if not shown:
                shown.extend(_kinds(s))
                print(soak_header(shown), flush=True)
            print(_sample_row(s, shown), flush=True)

    asked_stop = False
    try:
        while w.pump(1.0):
            if max_wall_s is not None and not asked_stop and time.monotonic() - w.t0 > max_wall_s:
                asked_stop = True
                w.p.send_signal(signal.SIGINT)  # a clean stop: the summary is written (after the end: no plot)
            if w.lines == seen_lines:
                continue
            seen_lines = w.lines
            launcher = describe_pid(w.p.pid)
            latest = sample_processes(w.sim_t, time.monotonic() - w.t0,
                                      [*w.children(), *([launcher] if launcher else [])])
            if w.sim_t >= next_at or w.ended:
                next_at = (w.sim_t // sample_every_s + 1) * sample_every_s
                keep(latest)
        if latest is not None and (not res.samples or latest.sim_t > res.samples[-1].sim_t):
            keep(latest)
        res.code = w.wait(time.monotonic() + 600)
    finally:
        w.close()
    if res.code is None:
        res.problems.append("the launcher did not exit")
    if _TRACEBACK in w.text:
        res.problems.append("the launcher printed a traceback")
    summary = _json(out / "session" / "summary.json") or {}
    res.cut = asked_stop and bool(summary.get("interrupted"))  # a stop after the simulated end cuts only the plot
    if res.code not in ((0, 130) if res.cut else (0,)):
        res.problems.append(f"the session ended with exit code {res.code}: {summary.get('error') or ''}".strip())
    per_robot = summary.get("per_robot") or []
    res.alive = sum(bool(r.get("alive")) for r in per_robot) if per_robot else None
    if res.alive is not None and res.alive < robots:
        res.problems.append(f"{robots - res.alive} robots failed: {summary.get('failures')}")
    end = duration if not res.cut else (res.samples[-1].sim_t if res.samples else 0.0)
    res.judged = judge_soak(res.samples, end)
    return res


def describe_pid(pid: int) -> Proc | None:
    import psutil

    try:
        return describe(psutil.Process(pid))
    except psutil.Error:
        return None


def soak_verdict(r: Soak) -> str:
    """The soak's verdict: each series judged, how the session ended, flat or not."""
    lines = [f"soak: {r.robots} robots, {r.duration_s:g} simulated s{' (cut short by --max-wall)' if r.cut else ''}, "
             f"{r.faults} faults, {len(r.samples)} samples; exit {r.code}; robots alive at the end: {r.alive}"]
    for f in r.judged:
        lines.append(f"  {f.name}: " + ("too few samples to judge" if f.ok is None else
                                        f"{f.reference:.1f} -> {f.last:.1f} ({f.change:+.1%}): "
                                        f"{'flat' if f.ok else 'NOT FLAT'}"))
    lines += [f"  problem: {p}" for p in r.problems]
    rule = ("rule: mean of the last quarter of the run within 10 % of the mean of 10-25 % of it (the first 10 % is "
            "warm-up)")
    lines.append(f"verdict: {'flat' if r.ok else 'NOT flat or not judged' if not r.problems else 'FAILED'} ({rule})")
    return "\n".join(lines)


# --- command line -------------------------------------------------------------------------------------------------


def _session_flags(p: argparse.ArgumentParser, robots: int, duration: float | None) -> None:
    p.add_argument("--config", default="hil_configs/demo.toml", help="the session's config")
    p.add_argument("--robots", type=at_least_one, default=robots,
                   help="robot count (configs with one [[robots]] group)")
    p.add_argument("--duration", type=positive, default=duration, help="simulated seconds of each session")


def _run_args(a: argparse.Namespace) -> list[str]:
    args = [a.config, "--robots", str(a.robots)]
    if a.duration is not None:
        args += ["--duration", str(a.duration)]
    if getattr(a, "speed", None) is not None:
        args += ["--speed", str(a.speed)]
    return args


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("campaign", help="repeat a check many times and count failures (flake, orphans, "
                                        "concurrency, soak)")
    what = p.add_subparsers(dest="campaign", required=True)
    f = what.add_parser("flake", help="run a pytest selection N times, the second half beside a busy core")
    f.add_argument("selection", nargs="+", help="what pytest runs (paths, -k, -m ...: put them after --)")
    f.add_argument("--runs", type=at_least_one, default=20)
    f.add_argument("--workers", type=at_least_one, default=2, help="pytest -n (1: no xdist)")
    f.add_argument("--busy-share", type=float, default=0.5, help="share of the runs beside a busy core")
    f.add_argument("--max-wall", type=positive, default=None, help="start no run after this many seconds")
    f.add_argument("--out", default="runs/campaign-flake", help="where each run's log goes")
    f.set_defaults(fn=cmd_campaign)

    o = what.add_parser("orphans", help="hit N short sessions with a random signal each (launcher or a child); "
                                        "check no process is left, the recording reads and its digest matches")
    o.add_argument("--trials", type=at_least_one, default=20)
    o.add_argument("--seed", type=int, default=0, help="of the campaign's random draws (which signal, whom, when)")
    _session_flags(o, robots=2, duration=4.0)
    o.add_argument("--speed", type=positive, default=2.0, help="real-time factor of each session (paced, so that a "
                                                             "signal can land while it runs)")
    o.add_argument("--signals", default=",".join(ACTIONS), help=f"the actions drawn from (of {', '.join(ACTIONS)})")
    o.add_argument("--target", choices=("any", "launcher", "child"), default="any")
    o.add_argument("--max-wall", type=positive, default=None, help="start no trial after this many seconds")
    o.add_argument("--out", default="runs/campaign-orphans", help="where each trial's session goes")
    o.set_defaults(fn=cmd_orphans)

    c = what.add_parser("concurrency", help="K sessions of one config at once: each must exit 0 and record the "
                                            "same digest as the config run alone")
    c.add_argument("--sessions", type=at_least_one, default=4)
    _session_flags(c, robots=2, duration=5.0)
    c.add_argument("--max-wall", type=positive, default=1800.0, help="stop the sessions after this many seconds")
    c.add_argument("--out", default="runs/campaign-concurrency")
    c.set_defaults(fn=cmd_concurrency)

    s = what.add_parser("soak", help="one long session with faults that end; RSS and open fds of its processes "
                                     "must stay flat")
    s.add_argument("--config", default="hil_configs/demo.toml", help="the base config (one [[robots]] group)")
    s.add_argument("--robots", type=at_least_one, default=10)
    s.add_argument("--sim-hours", type=positive, default=2.0)
    s.add_argument("--fault-every-s", type=positive, default=5.0, help="simulated seconds between faults")
    s.add_argument("--faults", default=",".join(SOAK_FAULTS), help="the fault kinds drawn from (comma-separated)")
    s.add_argument("--sample-every-s", type=positive, default=60.0,
                   help="simulated seconds between samples (taken at progress lines, every 10 simulated s)")
    s.add_argument("--seed", type=int, default=0, help="of the fault schedule")
    s.add_argument("--max-wall", type=positive, default=None, help="stop the session (Ctrl-C) after this many seconds")
    s.add_argument("--out", default="runs/campaign-soak")
    s.set_defaults(fn=cmd_soak)


def cmd_campaign(a: argparse.Namespace) -> int:
    if not 0 <= a.busy_share <= 1:
        print("swarm-sitl campaign flake: --busy-share must be within 0..1", file=sys.stderr)
        return 2
    print("| run | busy core | exit | passed | failed | wall (s) |\n|---|---|---|---|---|---|", flush=True)
    runs = flake(a.selection, a.runs, Path(a.out), a.workers, a.max_wall, a.busy_share)
    print(table(runs))
    return 0 if runs and all(r.code == 0 for r in runs) else 1


def cmd_orphans(a: argparse.Namespace) -> int:
    actions = [x.strip() for x in a.signals.split(",") if x.strip()]
    if not actions or set(actions) - set(ACTIONS):
        print(f"swarm-sitl campaign orphans: --signals must be some of {', '.join(ACTIONS)}, got {a.signals!r}",
              file=sys.stderr)
        return 2
    validate(*_run_args(a))
    print(ORPHANS_HEADER, flush=True)
    trials = orphans(a.trials, a.seed, _run_args(a), Path(a.out), actions, a.target, a.duration / a.speed,
                     a.max_wall)
    print(orphans_table(trials))
    return 0 if trials and all(t.ok for t in trials) else 1


def validate(config: str, *args: str) -> None:
    """``swarm-sitl validate CONFIG ARGS`` once before any session: ConfigError with what it said if it refuses.
    In a process of its own, as the sessions run: this one loads no robot model (nor pybullet)."""
    from bridge.core.config import ConfigError

    r = subprocess.run(_cli("validate", config, *args), capture_output=True, text=True, stdin=subprocess.DEVNULL)
    if r.returncode != 0:
        said = [ln.removeprefix("config error: ") for ln in (r.stderr + r.stdout).splitlines()
                if ln.strip() and not ln.startswith("pybullet build time")]
        raise ConfigError("\n".join(said) or f"swarm-sitl validate {config}: exit {r.returncode}")


def cmd_concurrency(a: argparse.Namespace) -> int:
    validate(*_run_args(a))
    print("| session | exit | digest | messages | equal to solo |\n|---|---|---|---|---|", flush=True)
    solo, runs = concurrency(a.sessions, _run_args(a), Path(a.out), a.max_wall)
    same = sum(_same(s, solo) for s in runs)
    ok = solo.code == 0 and solo.digest is not None and same == len(runs)
    print(f"{len(runs)} sessions at once: {sum(s.code == 0 for s in runs)} exited 0, {same} recorded the solo run's "
          f"digest{'' if solo.code == 0 else f' (the solo run itself exited {solo.code})'}")
    return 0 if ok else 1


def cmd_soak(a: argparse.Namespace) -> int:
    kinds = [x.strip() for x in a.faults.split(",") if x.strip()]
    if not kinds:
        print("swarm-sitl campaign soak: --faults names no fault kind", file=sys.stderr)
        return 2
    r = soak(Path(a.config), a.robots, a.sim_hours, a.fault_every_s, a.sample_every_s, Path(a.out), kinds, a.seed,
             a.max_wall)
    print(soak_verdict(r))
    return 0 if r.ok else 1
