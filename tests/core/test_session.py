"""Whole sessions: the world, firmware and logic processes over zenoh, as a user runs them."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
from mcap.reader import make_reader
from PIL import Image

from bridge.core.recorder import file_digest
from tests.conftest import ROOT

pytestmark = pytest.mark.session

SMALL = """
[session]
name = "small"
duration_s = {duration}
seed = {seed}
on_robot_failure = "{policy}"
hang_timeout_s = 10
[arena]
width_m = 6
length_m = 6
[[obstacles]]
type = "cylinder"
x = 3
y = 3
radius = 0.3
[[obstacles]]
type = "box"
x = 1.5
y = 4.5
size = [0.6, 0.6, 0.5]
[light]
ambient_lux = 15
[[light.sources]]
x = 4.5
y = 4.5
peak_lux = 60
sigma_m = 1.5
[[robots]]
count = 4
behaviour = "{behaviour}"
[robots.placement]
kind = "random"
min_separation_m = 0.6
"""


def config(tmp_path: Path, duration: float = 3, seed: int = 5, policy: str = "continue",
           behaviour: str = "random_walk", name: str = "small.toml") -> Path:
    p = tmp_path / name
    p.write_text(SMALL.format(duration=duration, seed=seed, policy=policy, behaviour=behaviour))
    return p


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "bridge.tools.cli", *args]


def run(cfg: Path, out: Path, *extra: str, timeout: float = 600, plot: bool = False) -> tuple[int, dict]:
    """``swarm-sitl run`` to its end: its exit code and summary (no trajectories.png unless ``plot``)."""
    r = subprocess.run(cli("run", str(cfg), "--out", str(out), "--quiet", *extra, *(() if plot else ("--no-plot",))),
                       cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    summary = json.loads((out / "summary.json").read_text())
    return r.returncode, summary


def session_procs(out: Path) -> list[psutil.Process]:
    found = []
    for p in psutil.process_iter(["cmdline"]):
        cmd = p.info["cmdline"] or []
        if "bridge.hosts.proc" in cmd and str(out) in cmd:
            found.append(p)
    return found


# the launcher as a terminal starts it: SIGHUP at its default whatever this test run inherited (``nohup`` ignores
# it, and an ignored signal stays ignored across exec); set in a fresh interpreter that then execs the CLI
_AS_FROM_A_TERMINAL = ("import os, signal, sys; signal.signal(signal.SIGHUP, signal.SIG_DFL); "
                       "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])")


def start(cfg: Path, out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", _AS_FROM_A_TERMINAL, *cli("run", str(cfg), "--out", str(out),
                                                                              *extra)[1:]],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def wait_line(p: subprocess.Popen, text: str) -> str:
    """Read the launcher's stderr until a line containing ``text`` (fails if it ends first). No deadline: a loaded
    machine may take its time, pytest's timeout bounds a hang."""
    while True:
        line = p.stderr.readline()
        if text in line:
            return line
        if not line and p.poll() is not None:
            raise AssertionError(f"the launcher ended without a line with {text!r}")


def wait_started(p: subprocess.Popen) -> None:
    wait_line(p, "started:")


def wait_running(p: subprocess.Popen) -> None:
    """Until the launcher shows progress (a line with the session's rtf): at least a simulated second ran."""
    wait_line(p, "rtf")


def wait_gone(out: Path) -> None:
    """Until no process of the session at ``out`` is left (pytest's timeout bounds a hang)."""
    while session_procs(out):
        time.sleep(0.1)


@pytest.fixture(scope="module")
def small_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, int, dict]:
    """One run of the default ``config`` (a session of its own, as ``run`` starts any), shared by the tests that only
    read its outputs or compare other runs of the same config with it: ``(config, out, exit code, summary)``."""
    tmp = tmp_path_factory.mktemp("small")
    cfg = config(tmp)
    out = tmp / "run"
    code, s = run(cfg, out, plot=True)
    return cfg, out, code, s


def test_session_writes_summary_recording_and_plot(small_run: tuple[Path, Path, int, dict]) -> None:
    _cfg, out, code, s = small_run
    assert code == 0, s
    for key in ("seed", "robots", "processes", "sim_time_s", "wall_time_s", "rtf", "ticks", "messages", "digest"):
        assert s[key] is not None, key
    assert (s["seed"], s["robots"], s["processes"], s["sim_time_s"]) == (5, 4, 9, 3.0)
    assert s["failures"] == [] and set(s["process_exits"].values()) == {0}
    with open(out / "session.mcap", "rb") as f:
        reader = make_reader(f)
        topics = {c.topic for c in reader.get_summary().channels.values()}
        n = sum(1 for _ in reader.iter_messages())
    assert {"/world/poses", "/r000/can0", "/r003/llc/pins"} <= topics
    assert n == s["messages"]
    assert file_digest(out / "session.mcap") == (s["digest"], s["messages"])
    assert Image.open(out / "trajectories.png").size[0] > 300
    _check_messages_match_their_schemas(out / "session.mcap")
    assert all(r["distance_m"] > 0.1 for r in s["per_robot"])  # every robot moved


def _check_messages_match_their_schemas(path: Path, expect: frozenset[str] = frozenset(
        {"swarm_sitl.CanFrame", "swarm_sitl.LlcPins", "swarm_sitl.Poses"})) -> None:
    """Every recorded message is a JSON object whose fields are declared in its embedded schema, with the
    declared JSON types (what Foxglove relies on to show them)."""
    types = {"integer": int, "number": (int, float), "string": str, "boolean": bool, "array": list,
             "null": type(None), "object": dict}
    seen = set()
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            props = json.loads(schema.data).get("properties")
            msg = json.loads(message.data)
            seen.add(schema.name)
            assert isinstance(msg, dict), (channel.topic, msg)
            if props is None:  # free-form (the logic's own log records)
                continue
            assert set(msg) <= set(props), (channel.topic, msg)
            for k, v in msg.items():
                spec = props[k]
                if "enum" in spec:
                    assert v in spec["enum"], (channel.topic, k, v)
                    continue
                kinds = spec["type"] if isinstance(spec["type"], list) else [spec["type"]]
                assert any(isinstance(v, types[t]) for t in kinds), (channel.topic, k, v)
    assert expect <= seen


@pytest.mark.long
def test_digest_is_the_same_across_reruns_packing_and_speed(tmp_path: Path, small_run) -> None:
    cfg, _out, code, a = small_run  # run "a": the shared one
    assert code == 0, a
    digests = {"a": a["digest"]}
    for name, extra in [("b", ()), ("packed", ("--robots-per-process", "2")),
                        ("one-process", ("--robots-per-process", "4")), ("paced", ("--speed", "4"))]:
        code, s = run(cfg, tmp_path / name, *extra)  # (--no-plot: no trajectories.png, none listed)
        assert code == 0, s
        assert "plot" not in s["files"] and not (tmp_path / name / "trajectories.png").exists()
        digests[name] = s["digest"]
    assert len(set(digests.values())) == 1, digests
    # packed as "one-process" (whose digest is "a"'s): only the seed differs
    code, s = run(cfg, tmp_path / "other-seed", "--seed", "6", "--robots-per-process", "4")
    assert code == 0 and s["digest"] != digests["a"]


def long_session_then(tmp_path: Path, out: Path, act) -> subprocess.Popen:
    """Start a session far longer than the test, let it run (a progress line), ``act(launcher, procs)``, and check
    that every process of the session goes (the waits end on events; pytest's timeout bounds a hang)."""
    p = start(config(tmp_path, duration=3600), out, "--speed", "2")
    try:
        wait_started(p)
        wait_running(p)
        procs = session_procs(out)
        assert len(procs) == 9
        act(p, procs)
        p.wait(timeout=240)
        wait_gone(out)
    finally:
        if p.poll() is None:
            p.kill()
    return p


def wait_for(stream, p: subprocess.Popen, text: str, timeout: float = 90) -> str:
    """Read the launcher's output up to a line containing ``text`` (the safety-net timeout only bounds a hang)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = stream.readline()
        if text in line:
            return line
        if not line and p.poll() is not None:
            break
    raise AssertionError(f"the launcher never printed {text!r}")


def check_stopped_cleanly(p: subprocess.Popen, out: Path) -> dict:
    """Exit 130, no process of the session left, a summary that lists only files that exist, and a whole
    recording whose digest is the summary's (a second Ctrl-C too lets the world finish it)."""
    assert p.returncode == 130
    assert session_procs(out) == []
    s = json.loads((out / "summary.json").read_text())
    assert s["interrupted"] and s["exit_code"] == 130
    assert {k: Path(v).exists() for k, v in s["files"].items()} == dict.fromkeys(s["files"], True), s["files"]
    assert ("plot" in s["files"]) == (out / "trajectories.png").exists()
    assert file_digest(out / "session.mcap") == (s["digest"], s["messages"]) and s["digest"] is not None
    with open(out / "session.mcap", "rb") as f:
        assert make_reader(f).get_summary() is not None  # the world finished the file: its summary section
    return s


def test_ctrl_c_with_the_output_pipe_gone_still_finishes_the_session(tmp_path: Path) -> None:
    """``swarm-sitl run ... 2>&1 | tee x.log`` and Ctrl-C: the terminal's SIGINT kills ``tee`` too, so every
    write to stdout and stderr fails (EPIPE) from then on; the session must still stop as on any Ctrl-C."""
    out = tmp_path / "run"
    r, w = os.pipe()
    p = subprocess.Popen(cli("run", str(config(tmp_path, duration=300)), "--out", str(out), "--speed", "2"),
                         cwd=ROOT, stdin=subprocess.DEVNULL, stdout=w, stderr=w)
    os.close(w)
    tee = os.fdopen(r, "r")
    try:
        wait_for(tee, p, "] sim ")  # the first progress line: the session runs
        tee.close()  # tee is gone: the pipe has no reader
        p.send_signal(signal.SIGINT)
        p.wait(timeout=90)
    finally:
        if p.poll() is None:
            p.kill()
        tee.close()
    s = check_stopped_cleanly(p, out)  # 1 before: a BrokenPipeError from the "stopping" note
    assert 0 < s["sim_time_s"] < 300
    assert (out / "trajectories.png").exists()


@pytest.mark.parametrize("second", ["after-stopping-note", "after-summary-appears"])
def test_second_ctrl_c_never_leaves_a_traceback_or_a_wrong_summary(tmp_path: Path, second: str) -> None:
    """The second Ctrl-C kills at once: wherever it lands (the session still stopping, its teardown, the
    summary, the plot), no traceback, exit 130, and a summary that lists only what was written."""
    out = tmp_path / "run"
    p = start(config(tmp_path, duration=300), out, "--speed", "2")
    try:
        wait_for(p.stderr, p, "] sim ")
        p.send_signal(signal.SIGINT)
        wait_for(p.stderr, p, "stopping at sim t=")  # the first one took effect
        if second == "after-summary-appears":  # the launcher is drawing the plot now
            deadline = time.monotonic() + 90
            while not (out / "summary.json").exists() and p.poll() is None and time.monotonic() < deadline:
                time.sleep(0.005)
        p.send_signal(signal.SIGINT)
        err = p.stderr.read()
        p.wait(timeout=90)
    finally:
        if p.poll() is None:
            p.kill()
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    check_stopped_cleanly(p, out)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGHUP], ids=["ctrl-c", "terminal-closed"])
def test_ctrl_c_leaves_no_process_and_a_readable_recording(tmp_path: Path, sig: int) -> None:
    """Ctrl-C, or the terminal closing (SIGHUP), stops the session as asked: exit 130, its summary and recording."""
    def ctrl_c(launcher: subprocess.Popen, procs: list[psutil.Process]) -> None:
        for proc in procs:  # network hygiene: unix sockets only, nothing on inet
            assert proc.net_connections(kind="inet") == []
        launcher.send_signal(sig)

    out = tmp_path / "run"
    p = long_session_then(tmp_path, out, ctrl_c)
    assert p.returncode == 130
    s = json.loads((out / "summary.json").read_text())
    assert s["interrupted"] and 0 < s["sim_time_s"] < 3600
    assert file_digest(out / "session.mcap") == (s["digest"], s["messages"])


def test_under_nohup_a_closed_terminal_does_not_stop_the_session() -> None:
    """``nohup swarm-sitl run ...``: SIGHUP ignored on purpose, the launcher leaves it so."""
    code = ("import signal; from bridge.core.launcher import _stop_signals; "
            "signal.signal(signal.SIGHUP, signal.SIG_DFL); a = _stop_signals(); "
            "signal.signal(signal.SIGHUP, signal.SIG_IGN); "
            "print(signal.SIGHUP in a, signal.SIGHUP in _stop_signals())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "False"]


@pytest.mark.parametrize("policy", ["continue", "stop"])
def test_kill_9_of_a_firmware_process_follows_policy(tmp_path: Path, policy: str) -> None:
    out = tmp_path / "run"
    # a session far longer than the test: the kill always comes before its end
    p = start(config(tmp_path, duration=3600, policy=policy), out, "--speed", "2")
    try:
        wait_started(p)
        (fw1,) = [q for q in session_procs(out) if "fw1" in q.cmdline()]
        wait_running(p)
        os.kill(fw1.pid, signal.SIGKILL)
        if policy == "continue":  # the failure, then the session goes on (a progress line after it); then Ctrl-C
            wait_line(p, "robot 1 failed at sim t=")
            wait_running(p)
            p.send_signal(signal.SIGINT)
        p.wait(timeout=240)
    finally:
        if p.poll() is None:
            p.kill()
    s = json.loads((out / "summary.json").read_text())
    assert [(f["robot"], f["kind"]) for f in s["failures"]] == [(1, "died")]
    assert 0 < s["failures"][0]["t_s"] < s["sim_time_s"] < 3600
    assert [r["alive"] for r in s["per_robot"]] == [True, False, True, True]
    if policy == "continue":
        assert p.returncode == 130 and s["interrupted"] and s["stop_reason"] == "interrupted"
    else:
        assert p.returncode == 1 and "on_robot_failure = stop" in s["stop_reason"]
    assert session_procs(out) == []


def test_raising_controller_fails_only_its_robot(tmp_path: Path) -> None:
    code, s = run(config(tmp_path, behaviour="tests.support.faulty:RaisesAtOneSecond"), tmp_path / "run",
                  "--robots-per-process", "2")
    assert code == 0
    (f,) = s["failures"]
    assert (f["robot"], f["kind"], f["t_s"]) == (1, "raised", 1.01)  # robot 1 boots 10 ms after robot 0
    assert "controller bug on purpose" in f["detail"]
    assert [r["alive"] for r in s["per_robot"]] == [True, False, True, True]


def test_hanging_controller_never_hangs_the_session(tmp_path: Path) -> None:
    code, s = run(config(tmp_path, behaviour="tests.support.faulty:HangsAtOneSecond"), tmp_path / "run")
    assert code == 0
    (f,) = s["failures"]
    assert (f["robot"], f["kind"]) == (1, "hung")
    assert s["sim_time_s"] == 3.0
    assert s["process_exits"]["lg1"] == -9  # the world killed it


def test_a_session_runs_from_a_thread_other_than_the_main_one(tmp_path: Path, small_run) -> None:
    """As an experiment's trial does on a Dask worker (whose tasks run in its threads): the same recording."""
    from concurrent.futures import ThreadPoolExecutor

    from bridge.core.launcher import run_session

    cfg, _out, code, main = small_run  # the same config run by the launcher from its main thread
    assert code == 0
    with ThreadPoolExecutor(1) as pool:
        res = pool.submit(run_session, str(cfg), None, str(tmp_path / "thread"), None).result()
    assert res.code == 0, res.summary.get("error")
    assert (res.summary["digest"], res.summary["messages"]) == (main["digest"], main["messages"])


def test_config_errors_exit_2_naming_file_and_field(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[session]\nduration_s = 'long'\n[[robots]]\ncount = 2\n")
    r = subprocess.run(cli("run", str(bad), "--out", str(tmp_path / "x")), cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 2
    assert f"{bad}: session.duration_s: Input should be a valid number" in r.stderr
    r = subprocess.run(cli("validate", str(config(tmp_path))), cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0 and "4 robots, 9 processes" in r.stdout


def test_killed_launcher_leaves_no_orphans_and_a_readable_recording(tmp_path: Path) -> None:
    out = tmp_path / "run"
    # SIGKILL: the launcher cannot clean up; its children must go by themselves
    long_session_then(tmp_path, out, lambda launcher, procs: launcher.kill())
    world = json.loads((out / "world_result.json").read_text())  # the world finished its recording
    assert file_digest(out / "session.mcap") == (world["digest"], world["messages"])
    assert 0 < world["sim_time_s"] < 3600
