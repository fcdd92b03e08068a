"""The world itself may stall or fail, and the rest must not lie about it: a world paused longer than the hang
timeout kills no healthy robot (the time it was away is not counted against the others)."""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import pytest

from bridge.core import hub
from tests.core.test_session import config, session_procs, start, wait_running, wait_started

pytestmark = pytest.mark.session


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
