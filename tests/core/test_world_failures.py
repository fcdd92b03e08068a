"""The world itself may stall or fail, and the rest must not lie about it: a world paused longer than the hang
timeout kills no healthy robot (the time it was away is not counted against the others); a world killed outright
ends the session with exit 1, a summary that says so and how far it got, and a recording every MCAP reader opens;
a world stopped during start-up is noticed after the hang timeout, not the start-up timeout."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from bridge.core import hub
from bridge.core.recorder import file_digest
from tests.core.test_session import config, session_procs, start, wait_gone, wait_running, wait_started

pytestmark = pytest.mark.session


@pytest.mark.long
def test_a_world_paused_longer_than_the_hang_timeout_kills_no_healthy_robot(tmp_path: Path) -> None:
    out = tmp_path / "run"
    p = start(config(tmp_path, duration=3600), out, "--speed", "2")  # hang_timeout_s = 10
    try:
        wait_started(p)
        wait_running(p)
        (world,) = [q for q in session_procs(out) if "world" in q.cmdline()]
        os.kill(world.pid, signal.SIGSTOP)
        time.sleep(15)  # the stimulus, not a wait: the world away 1.5 hang timeouts while its robots answer
        os.kill(world.pid, signal.SIGCONT)
        wait_running(p)
        wait_running(p)  # two progress lines after it: the world went on, with what its robots had answered
        p.send_signal(signal.SIGINT)
        p.wait(timeout=240)
    finally:
        if p.poll() is None:
            p.kill()
    s = json.loads((out / "summary.json").read_text())
    assert p.returncode == 130 and s["interrupted"]
    assert s["failures"] == [] and all(r["alive"] for r in s["per_robot"])


def test_the_hang_deadline_does_not_count_the_worlds_own_stall(monkeypatch: pytest.MonkeyPatch) -> None:
    """A world stopped while it waits for answers (its wait steps are 0.2 s) finds, on waking, the time it was away
    added to its deadline: the answers already on their way are read before anyone is declared hung."""
    now = [100.0]
    monkeypatch.setattr(hub.time, "monotonic", lambda: now[0])
    d = hub.AwakeDeadline(10.0)
    now[0] += 0.2
    assert d.left() == pytest.approx(9.8)
    now[0] += 25.0  # SIGSTOP ... SIGCONT in one wait step
    assert d.left() == pytest.approx(9.8) and d.stalled_s == pytest.approx(25.0)
    for _ in range(49):  # awake, nothing arrives: the deadline runs out as it would have without the stall
        now[0] += 0.2
        d.left()
    assert d.left() == pytest.approx(0.0, abs=1e-9)
    now[0] += 0.2
    assert d.left() < 0


def test_a_world_killed_outright_leaves_a_summary_that_says_so_and_a_readable_recording(tmp_path: Path) -> None:
    out = tmp_path / "run"
    p = start(config(tmp_path, duration=3600), out, "--speed", "2")
    try:
        wait_started(p)
        wait_running(p)
        wait_running(p)
        (world,) = [q for q in session_procs(out) if "world" in q.cmdline()]
        os.kill(world.pid, signal.SIGKILL)
        p.wait(timeout=240)
        wait_gone(out)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 1  # the README's "1 when the world fails", not the signal's 247
    s = json.loads((out / "summary.json").read_text())
    assert "the world process was killed by SIGKILL at simulated t=" in s["error"] and "recovered" in s["error"]
    rec = s["recording"]
    assert rec["recovered"] and rec["messages"] == s["messages"] > 0 and 0 < s["sim_time_s"] == rec["last_time_s"]
    with open(out / "session.mcap", "rb") as f:  # the seeking reader needs the footer and summary section
        reader = make_reader(f)
        assert reader.get_summary() is not None
        assert sum(1 for _ in reader.iter_messages()) == s["messages"]
    assert file_digest(out / "session.mcap") == (s["digest"], s["messages"])
    assert file_digest(out / "session.mcap.damaged") == (s["digest"], s["messages"])  # the cut file, kept as it was


def test_swarm_sitl_recover_rewrites_a_cut_recording(tmp_path: Path) -> None:
    from bridge.core.recorder import Recorder

    run = tmp_path / "run"
    run.mkdir()
    r = Recorder(run / "session.mcap", metadata={"seed": "1"})
    for i in range(20000):
        r.write(i * 1_000_000, f"/r{i % 4:03d}/log", "swarm_sitl.Log", {"level": "info", "text": f"line {i}"})
    r.finish()
    whole = (run / "session.mcap").read_bytes()
    (run / "session.mcap").write_bytes(whole[: len(whole) * 3 // 5])  # the writer killed mid-file
    kept = file_digest(run / "session.mcap")
    assert 0 < kept[1] < 20000
    p = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "recover", str(run)], capture_output=True, text=True)
    assert p.returncode == 0 and f"{kept[1]} messages" in p.stdout, p.stderr
    with open(run / "session.mcap", "rb") as f:
        reader = make_reader(f)
        assert reader.get_summary().statistics.message_count == kept[1]
        assert [m.metadata for m in reader.iter_metadata()] == [{"seed": "1"}]
    assert file_digest(run / "session.mcap") == kept == file_digest(run / "session.mcap.damaged")
    again = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "recover", str(run / "session.mcap")],
                           capture_output=True, text=True)
    assert again.returncode == 0 and "a finished recording, nothing to recover" in again.stdout
    (tmp_path / "notes.txt").write_text("not a recording")
    bad = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "recover", str(tmp_path / "notes.txt")],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "not an MCAP recording" in bad.stderr and "Traceback" not in bad.stderr
    assert (tmp_path / "notes.txt").read_text() == "not a recording"  # refused, left as it was


def test_a_world_stopped_during_start_up_is_noticed_within_the_hang_timeout(tmp_path: Path) -> None:
    """Stopped before its robots could join (they need seconds to start; it is stopped as soon as it runs), the
    world is killed after hang_timeout_s (10 s here), not startup_timeout_s (120 s), and the start fails saying so."""
    out = tmp_path / "run"
    p = start(config(tmp_path, duration=3600), out)
    try:
        while not (world := [q for q in session_procs(out) if "world" in q.cmdline()]):
            assert p.poll() is None, "the launcher ended before its world ran"
            time.sleep(0.005)
        os.kill(world[0].pid, signal.SIGSTOP)
        p.wait(timeout=240)
        wait_gone(out)
    finally:
        if p.poll() is None:
            p.kill()
    s = json.loads((out / "summary.json").read_text())
    assert p.returncode == 1
    assert "was stopped (SIGSTOP, or a debugger) for 10 s during start-up" in s["error"]
    assert s["startup_s"] is None and s["sim_time_s"] == 0.0


def test_a_launcher_killed_as_its_world_starts_leaves_no_orphan(tmp_path: Path) -> None:
    """The world asks for its parent-death signal before its seconds of imports: a launcher killed the moment the
    world process exists takes the world with it (found by the orphan campaign: it lived on for 124 s)."""
    out = tmp_path / "run"
    p = start(config(tmp_path, duration=3600), out)
    try:
        while not (worlds := [q for q in session_procs(out) if "world" in q.cmdline()]):
            time.sleep(0.01)  # until the world process exists (pytest's timeout bounds a hang)
        p.kill()
        p.wait()
        # gone within seconds of the launcher; an orphan waited for its participants until its 120-s start-up
        # timeout (psutil.TimeoutExpired: the bound of a hang, far from either)
        worlds[0].wait(timeout=60)
        wait_gone(out)
    finally:
        if p.poll() is None:
            p.kill()


def test_a_world_stopped_by_a_signal_from_outside_is_an_error(tmp_path: Path) -> None:
    out = tmp_path / "run"
    p = start(config(tmp_path, duration=3600), out, "--speed", "2")
    try:
        wait_started(p)
        wait_running(p)
        (world,) = [q for q in session_procs(out) if "world" in q.cmdline()]
        world.send_signal(signal.SIGTERM)  # not the launcher's: it signals its world only after a second Ctrl-C
        p.wait(timeout=240)
    finally:
        if p.poll() is None:
            p.kill()
    s = json.loads((out / "summary.json").read_text())
    assert p.returncode == 1 and not s["interrupted"]
    assert "the world process got SIGTERM from outside the session at simulated t=" in s["error"]
