"""``swarm-sitl campaign``: flake (N runs of a pytest selection, half beside a busy core, a table, exit 1 if any run
failed, naming it and its log); orphans (signals at random moments: no process left, the recording reads, its digest
is recomputed), concurrency (sessions at once record what one alone does) and soak (RSS and fds stay flat)."""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import get_args

import psutil
import pytest

from bridge.core.config import ConfigError, FaultCfg, load_config
from bridge.core.recorder import Recorder
from bridge.tools.campaign import (
    ACTIONS,
    FAULT_MAKERS,
    SOAK_FAULTS,
    Proc,
    Sample,
    Soak,
    _counts,
    alive,
    check_recording,
    describe,
    fault_schedule,
    flatness,
    identify,
    judge_soak,
    leftovers,
    mcap_readable,
    plan_hits,
    session_processes,
    soak_config,
    soak_verdict,
    to_toml,
)


def _campaign(tmp_path: Path, body: str, runs: int) -> subprocess.CompletedProcess:
    (tmp_path / "suite").mkdir()
    (tmp_path / "suite" / "test_it.py").write_text(body)
    return subprocess.run([sys.executable, "-m", "bridge.tools.cli", "campaign", "flake", "--runs", str(runs),
                           "--workers", "1", "--out", str(tmp_path / "logs"), "--", str(tmp_path / "suite")],
                          capture_output=True, text=True)


def test_a_clean_selection_passes_every_run(tmp_path: Path) -> None:
    p = _campaign(tmp_path, "def test_a():\n    assert True\n\ndef test_b():\n    assert 1 + 1 == 2\n", 1)
    assert p.returncode == 0, p.stderr
    assert "| 1 | no | 0 | 2 | 0 |" in p.stdout
    assert "1 runs (0 beside a busy core): 1 passed, 0 failed" in p.stdout
    assert sorted(x.name for x in (tmp_path / "logs").iterdir()) == ["run-001.log"]


def test_a_failing_run_fails_the_campaign_and_is_named(tmp_path: Path) -> None:
    # fails on its second run only: the file it leaves says it ran before
    mark = tmp_path / "ran"
    p = _campaign(tmp_path, f"from pathlib import Path\n\ndef test_once():\n    m = Path({str(mark)!r})\n"
                            "    seen = m.exists()\n    m.touch()\n    assert not seen\n", 2)
    assert p.returncode == 1
    assert "| 1 | no | 0 | 1 | 0 |" in p.stdout
    assert "2 runs (1 beside a busy core): 1 passed, 1 failed (runs 2)" in p.stdout
    assert "| 2 | yes | 1 | 0 | 1 |" in p.stdout and "run-002.log" in p.stdout


def test_pytest_summaries_are_counted() -> None:
    assert _counts("...\n== 3 passed, 1 failed, 2 errors in 4.5s ==\n") == (3, 3)
    assert _counts("....\n4 passed in 0.1s\n") == (4, 0)
    assert _counts("collected nothing") == (0, 0)


# --- orphans, concurrency, soak: their checkers on fabricated cases, then short real campaigns ----------------------

ROOT = Path(__file__).resolve().parents[2]
SMALL = ROOT / "hil_configs" / "demos" / "random_walk.toml"  # no radios: the quickest start
RADIO = ROOT / "hil_configs" / "demo.toml"


def _cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bridge.tools.cli", *args], capture_output=True, text=True, cwd=ROOT,
                          stdin=subprocess.DEVNULL, timeout=timeout)


def _sleeper(*extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)", *extra], stdin=subprocess.DEVNULL)


def test_a_process_left_running_is_reported_and_a_gone_one_is_not(tmp_path: Path) -> None:
    p = _sleeper(str(tmp_path / "run"))
    try:
        me = describe(psutil.Process(p.pid))
        assert me is not None and me.kind == "other"
        assert leftovers([me], grace_s=0.2) == [me]  # the grace only bounds the wait: it is still there after it
        assert [x.pid for x in session_processes(tmp_path / "run")] == [p.pid]  # found by the directory it names
    finally:
        p.kill()
        p.wait()
    assert leftovers([me], grace_s=30) == []  # gone (and reaped): no wait at all
    assert session_processes(tmp_path / "run") == []


def test_a_reused_pid_is_not_the_process_that_was_seen() -> None:
    me = describe(psutil.Process(os.getpid()))
    assert me is not None and alive(me)
    assert not alive(Proc(me.pid, me.created - 1.0, me.name, me.kind))


def test_processes_are_named_by_their_command_line() -> None:
    assert identify(["python", "-m", "bridge.hosts.proc", "firmware", "--plan", "p", "--proc", "fw3"]) == (
        "fw3", "firmware")
    assert identify(["python", "-m", "bridge.hosts.proc", "world", "--plan", "p"]) == ("world", "world")
    assert identify(["python", "-m", "bridge.tools.cli", "run", "c.toml"]) == ("launcher", "launcher")
    assert identify(["/usr/bin/sleep", "9"]) == ("sleep", "other")


def _recording(out: Path, n: int = 4000) -> tuple[str, int]:
    """A finished recording of ``n`` messages in ``out`` (several chunks: the payloads do not compress)."""
    out.mkdir(parents=True, exist_ok=True)
    rec = Recorder(out / "session.mcap", {"config": "{}"}, chunk_bytes=64 * 1024)
    for i in range(n):
        rec.write(i * 1000, "/r000/can0", "swarm_sitl.CanFrame",
                  {"id": i, "data": os.urandom(64).hex(), "src": "x", "name": ""})
    rec.finish()
    return rec.digest, rec.count


def _cut(path: Path, share: float = 0.6) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * share)])


def test_a_whole_recording_reads_and_its_digest_is_recomputed(tmp_path: Path) -> None:
    digest, n = _recording(tmp_path)
    (tmp_path / "summary.json").write_text(json.dumps({"digest": digest, "messages": n}))
    c = check_recording(tmp_path)
    assert (c.readable, c.read_note, c.digest_ok, c.digest_note) == (True, "yes", True, "ok")
    (tmp_path / "summary.json").write_text(json.dumps({"digest": "0" * 64, "messages": n}))
    c = check_recording(tmp_path)
    assert c.readable is True and c.digest_ok is False and c.digest_note.startswith("MISMATCH")


def test_a_truncated_recording_is_unreadable(tmp_path: Path) -> None:
    digest, n = _recording(tmp_path)
    _cut(tmp_path / "session.mcap")
    assert mcap_readable(tmp_path / "session.mcap") is not None  # the mcap library's reader refuses it
    (tmp_path / "summary.json").write_text(json.dumps({"digest": digest, "messages": n}))
    c = check_recording(tmp_path)  # the launcher wrote its summary yet left the file cut: a defect
    assert c.readable is False and "unfinished" in c.read_note
    (tmp_path / "session.mcap").write_bytes(b"")
    assert check_recording(tmp_path).readable is False


def test_a_truncated_recording_without_a_summary_is_recovered_then_read(tmp_path: Path) -> None:
    _recording(tmp_path)
    _cut(tmp_path / "session.mcap")
    c = check_recording(tmp_path)  # the launcher died: the campaign runs swarm-sitl recover, as a user would
    assert (c.readable, c.read_note, c.digest_ok) == (True, "yes (recovered here)", True)
    assert (tmp_path / "session.mcap.damaged").exists()
    assert check_recording(tmp_path / "nothing").readable is None


def test_hits_are_drawn_from_the_seed() -> None:
    a = plan_hits(50, seed=4)
    assert a == plan_hits(50, seed=4) and a != plan_hits(50, seed=5)
    assert {h.action for h in a} == set(ACTIONS) and {h.phase for h in a} == {"start-up", "spawned", "running"}
    assert not any(h.to_child for h in a if h.action == "close-stdout")  # the launcher's pipe only
    assert all(h.to_child for h in plan_hits(20, 4, ["SIGTERM"], target="child"))
    assert not any(h.to_child for h in plan_hits(20, 4, target="launcher"))
    with pytest.raises(ValueError, match="unknown action"):
        plan_hits(1, 0, ["SIGFOO"])


def test_a_trial_s_launcher_gets_the_campaign_s_signals_with_their_default_meaning() -> None:
    """A campaign run under ``nohup`` inherits SIGHUP ignored, and so would every launcher it starts (an ignored
    signal stays ignored across exec): its SIGHUP trials would test nothing. Each trial's launcher starts with the
    default meaning of the signals the campaign sends."""
    probe = "import signal; print(int(signal.getsignal(signal.SIGHUP)), int(signal.getsignal(signal.SIGTERM)))"
    code = ("import signal, subprocess, sys; from bridge.tools.campaign import _default_signals; "
            "signal.signal(signal.SIGHUP, signal.SIG_IGN); signal.signal(signal.SIGTERM, signal.SIG_IGN); "
            f"run = lambda **k: subprocess.run([sys.executable, '-c', {probe!r}], capture_output=True, text=True, "
            "**k); "
            "print(run().stdout.strip(), '/', run(preexec_fn=_default_signals).stdout.strip())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["1", "1", "/", "0", "0"]  # (SIG_IGN inherited; SIG_DFL in a trial's launcher)


@pytest.mark.session
def test_two_trials_leave_no_process_and_a_readable_recording(tmp_path: Path) -> None:
    # seed 4: SIGTERM to a child, then SIGSTOP and SIGCONT to the launcher, both while the session runs
    assert [(h.action, h.to_child, h.phase) for h in plan_hits(2, 4)] == [
        ("SIGTERM", True, "running"), ("SIGSTOP+SIGCONT", False, "running")]
    p = _cli("campaign", "orphans", "--trials", "2", "--seed", "4", "--config", str(SMALL), "--duration", "3",
             "--out", str(tmp_path))
    assert p.returncode == 0, p.stdout + p.stderr
    rows = [ln.split(" | ") for ln in p.stdout.splitlines() if ln.startswith(("| 1 |", "| 2 |"))]
    assert len(rows) == 2, p.stdout
    assert rows[0][1:3] == ["SIGTERM", rows[0][2]] and rows[0][2] not in ("launcher", "-"), rows
    assert rows[1][1:3] == ["SIGSTOP+SIGCONT", "launcher"], rows
    assert all(r[5:8] == ["0", "yes", "ok |"] for r in rows), rows  # no orphan, readable, the same digest
    assert "orphans: 0 trials left 0 processes; unreadable recordings: 0; digest mismatches: 0; recordings " \
           "checked: 2, digests compared: 2" in p.stdout
    assert sorted(x.name for x in tmp_path.iterdir()) == ["trial-001", "trial-002"]


@pytest.mark.session
def test_a_launcher_killed_while_its_session_runs_takes_every_process_with_it(tmp_path: Path) -> None:
    # the special case: SIGKILL leaves the launcher no say; its children die with it (PR_SET_PDEATHSIG), the world
    # finishing its recording first. A seed whose moment lands early in the run, so the session is certain to run
    seed = next(s for s in range(100) if (h := plan_hits(1, s, ["SIGKILL"], "launcher")[0]).phase == "running"
                and h.delay_s < 0.5)
    p = _cli("campaign", "orphans", "--trials", "1", "--seed", str(seed), "--signals", "SIGKILL", "--target",
             "launcher", "--config", str(SMALL), "--duration", "3", "--out", str(tmp_path))
    assert p.returncode == 0, p.stdout + p.stderr
    row = next(ln for ln in p.stdout.splitlines() if ln.startswith("| 1 |"))
    assert "| SIGKILL | launcher | running" in row and "| -9 | 0 | yes | ok |" in row, row
    assert not (tmp_path / "trial-001" / "summary.json").exists()  # the launcher never wrote it: the world's result
    assert (tmp_path / "trial-001" / "world_result.json").exists()


@pytest.mark.session
def test_two_sessions_at_once_record_what_one_alone_does(tmp_path: Path) -> None:
    """Sessions at once do not see each other (each its own namespace and socket): each records the solo run's
    digest. The suite's one test of it, through the campaign that checks it at scale."""
    p = _cli("campaign", "concurrency", "--sessions", "2", "--config", str(SMALL), "--duration", "3", "--out",
             str(tmp_path))
    assert p.returncode == 0, p.stdout + p.stderr
    solo = json.loads((tmp_path / "solo" / "summary.json").read_text())["digest"]
    for i in (1, 2):
        assert f"| {i} | 0 | {solo[:16]} |" in p.stdout and p.stdout.count("| yes |") == 2
    assert "2 sessions at once: 2 exited 0, 2 recorded the solo run's digest" in p.stdout


def test_the_fault_schedule_takes_its_kinds_and_each_fault_ends_before_the_next(tmp_path: Path) -> None:
    faults = fault_schedule(["partition", "burst_loss"], robots=4, duration_s=100, every_s=5, seed=2)
    assert len(faults) == 19 and {f["kind"] for f in faults} == {"partition", "burst_loss"}
    assert all(f["at_s"] + f["duration_s"] < g["at_s"] for f, g in itertools.pairwise(faults))
    assert faults[-1]["at_s"] + faults[-1]["duration_s"] < 100
    assert faults == fault_schedule(["partition", "burst_loss"], 4, 100, 5, seed=2)
    cfg = tmp_path / "soak.toml"
    cfg.write_text(soak_config(RADIO, 4, 100, fault_schedule(SOAK_FAULTS, 4, 100, 5, 0)))
    loaded = load_config(str(cfg))  # what the schedule makes, the config accepts
    assert loaded.session.duration_s == 100 and len(loaded.faults) == 19
    cfg.write_text(soak_config(RADIO, 4, 100, fault_schedule(["no_such_fault"], 4, 100, 5, 0)))
    with pytest.raises(ConfigError, match="faults"):  # a kind without a maker: the generic one, checked
        load_config(str(cfg))


def test_every_fault_maker_makes_faults_the_config_accepts(tmp_path: Path) -> None:
    known = set(get_args(FaultCfg.model_fields["kind"].annotation))
    kinds = [k for k in FAULT_MAKERS if k in known]  # a maker for a kind still to come waits for it
    assert {"can_noise", "partition", "burst_loss"} <= set(kinds)
    cfg = tmp_path / "all.toml"
    cfg.write_text(soak_config(RADIO, 3, 200, fault_schedule(kinds, 3, 200, 2, 1)))
    assert {f.kind for f in load_config(str(cfg)).faults} == set(kinds)


@pytest.mark.parametrize("config", sorted((ROOT / "hil_configs").rglob("*.toml")), ids=lambda p: p.name)
def test_every_config_is_written_back_as_the_same_toml(config: Path) -> None:
    raw = tomllib.loads(config.read_text())
    assert tomllib.loads(to_toml(raw)) == raw


def test_the_flatness_rule_flags_growth_and_passes_a_flat_series() -> None:
    growing = [(float(t), 100.0 + 0.05 * t) for t in range(0, 3600, 60)]  # +1.5 MiB per simulated minute
    f = flatness("rss", growing, 3600)
    assert f.ok is False and f.change is not None and f.change > 0.1
    flat = [(float(t), 100.0 + (3 if t % 120 else -3)) for t in range(0, 3600, 60)]  # noise, no trend
    assert flatness("rss", flat, 3600).ok is True
    warm = [(0.0, 10.0), *((float(t), 100.0) for t in range(60, 3600, 60))]  # the start-up is not held against it
    assert flatness("rss", warm, 3600).ok is True
    assert flatness("rss", [(5.0, 1.0), (400.0, 1.0), (3599.0, 9.0)], 3600).ok is False
    assert flatness("rss", [(5.0, 1.0)], 3600).ok is None  # nothing after warm-up: not judged
    samples = [Sample(t, t, {"world": v, "logic": 5000.0}, {"world": 40, "logic": 16}, {"world": 1, "logic": 2})
               for t, v in growing]
    judged = {j.name: j.ok for j in judge_soak(samples, 3600)}
    assert judged == {"RSS total (MiB)": True, "RSS world (MiB)": False, "RSS logic (MiB)": True, "fds world": True,
                      "fds logic": True}
    r = Soak(Path("x"), 3600, 0, samples, code=0, robots=2, alive=2, judged=judge_soak(samples, 3600))
    assert not r.ok and "RSS world (MiB): " in soak_verdict(r) and "NOT FLAT" in soak_verdict(r)


@pytest.mark.session
def test_a_short_soak_samples_its_processes_and_judges_them(tmp_path: Path) -> None:
    p = _cli("campaign", "soak", "--config", str(RADIO), "--robots", "2", "--sim-hours", "0.01",
             "--fault-every-s", "4", "--sample-every-s", "10", "--out", str(tmp_path))
    assert p.returncode in (0, 1), p.stderr
    lines = p.stdout.splitlines()
    head = lines.index(next(ln for ln in lines if ln.startswith("| sim t (s) |")))
    assert "fds (world / firmware / logic / launcher)" in lines[head]
    rows = [ln for ln in lines[head + 2:] if ln.startswith("| ")]
    assert len(rows) >= 3 and rows[-1].split(" | ")[-1] == "1 / 2 / 2 / 1 |", p.stdout  # the processes, per kind
    assert "soak: 2 robots, 36 simulated s, 8 faults" in p.stdout and "exit 0; robots alive at the end: 2" in p.stdout
    assert "fds firmware: " in p.stdout and "verdict: " in p.stdout
    assert len(load_config(str(tmp_path / "soak.toml")).faults) == 8
    assert json.loads((tmp_path / "session" / "summary.json").read_text())["exit_code"] == 0
