"""A robot's swarm logic on another computer: ``session.listen``, ``logic = "remote"`` and ``swarm-sitl join``.

The "other computer" is a ``swarm-sitl join`` subprocess connecting over TCP on loopback, to a port picked free at
run time. The remote logic runs in simulated lock-step, so the recording equals a local logic's byte for byte.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

import psutil
import pytest
from mcap.reader import make_reader

from bridge.core.config import ConfigError, config_warnings, load_config
from bridge.core.launcher import join_commands
from bridge.core.plan import make_plan, plan_offer
from bridge.core.transport import namespace_for
from bridge.hil.join import JoinError, choose
from tests.conftest import ROOT

CONFIG = """
[session]
name = "{name}"
duration_s = 8
seed = 3
hang_timeout_s = 10
startup_timeout_s = 240
{listen}
[arena]
width_m = 6
length_m = 6
[[robots]]
count = {local}
behaviour = "random_walk"
[robots.placement]
kind = "random"
region = [0.5, 0.5, 5.5, 3.0]
min_separation_m = 0.6
[[robots]]
count = {remote}
behaviour = "random_walk"
logic = "{logic}"
[robots.placement]
kind = "explicit"
poses = {poses}
"""
POSES = [[1.5, 4.8, 0.0], [4.5, 4.8, 180.0]]


def free_port() -> int:
    """A TCP port free on loopback now (bound, read, closed): no fixed port in any test."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def write(tmp_path: Path, file: str, *, name: str = "rl", port: int | None = None, logic: str = "remote",
          local: int = 3, remote: int = 1) -> Path:
    p = tmp_path / file
    p.write_text(CONFIG.format(name=name, listen=f'listen = "tcp/127.0.0.1:{port}"' if port else "", logic=logic,
                               local=local, remote=remote, poses=json.dumps(POSES[:remote])))
    return p


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "bridge.tools.cli", *args]


def run(cfg: Path, out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen(cli("run", str(cfg), "--out", str(out), *extra), cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)


def join(port: int, *args: str) -> subprocess.Popen:
    return subprocess.Popen(cli("join", f"tcp/127.0.0.1:{port}", *args), cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def wait_line(stream, text: str, proc: subprocess.Popen) -> str:
    """Read ``stream`` until a line containing ``text`` (fails if the process ends first; pytest's timeout bounds a
    hang: no deadline here, a loaded machine may take its time)."""
    while True:
        line = stream.readline()
        if text in line:
            return line
        if not line and proc.poll() is not None:
            raise AssertionError(f"no line with {text!r}")


def wait_lines(stream, texts: list[str], proc: subprocess.Popen) -> None:
    """Read ``stream`` until it showed a line containing each of ``texts``, in any order."""
    left = set(texts)
    while left:
        line = stream.readline()
        left = {t for t in left if t not in line}
        if not line and proc.poll() is not None:
            raise AssertionError(f"no line with {sorted(left)}")


def session_procs(out: Path) -> list[psutil.Process]:
    return [p for p in psutil.process_iter(["cmdline"]) if "bridge.hosts.proc" in (p.info["cmdline"] or [])
            and str(out) in p.info["cmdline"]]


@pytest.mark.session
def test_remote_logic_runs_and_records_exactly_as_a_local_one(tmp_path: Path) -> None:
    port = free_port()
    remote_out, local_out = tmp_path / "remote", tmp_path / "local"
    launcher = run(write(tmp_path, "remote.toml", port=port), remote_out, "--quiet")
    joiner = join(port, "--session", "rl", "--timeout", "240")  # the only remote robot: no --robot needed
    local = run(write(tmp_path, "local.toml", logic="session"), local_out, "--quiet")
    try:  # the timeouts here and in the config only bound a hang: every wait ends on a process's exit
        j_out, j_err = joiner.communicate(timeout=280)
        assert launcher.wait(timeout=120) == 0, launcher.stderr.read()
        assert local.wait(timeout=280) == 0, local.stderr.read()
    finally:
        for p in (launcher, joiner, local):
            if p.poll() is None:
                p.kill()
    assert joiner.returncode == 0, j_err
    lines = j_out.splitlines()
    assert len(lines) == 2 and "robot 3's logic (random_walk) joined session 'rl'" in lines[0], j_out
    assert "session 'rl' ended (the world said stop)" in lines[1], j_out
    s, ref = summary(remote_out), summary(local_out)
    assert s["remote_processes"] == ["remote3"] and "remote3" not in s["process_exits"]
    assert s["processes"] == ref["processes"] == 9 and s["failures"] == []
    assert s["sim_time_s"] == 8.0 and all(r["alive"] for r in s["per_robot"])
    assert s["per_robot"][3]["distance_m"] > 0.1  # the remote robot drove
    with open(remote_out / "session.mcap", "rb") as f:
        sent = [json.loads(m.data) for _, c, m in make_reader(f).iter_messages(topics=["/r003/can0"])]
    assert sum(d["src"] == "r003/logic" and d["name"] == "DRIVE_CMD" for d in sent) > 50  # its logic's commands
    # the same seed gives the same bytes whether robot 3's logic runs here or joins over TCP
    assert (s["digest"], s["messages"]) == (ref["digest"], ref["messages"])


@pytest.mark.session
def test_join_errors_and_joiners_that_die_or_are_interrupted(tmp_path: Path) -> None:
    port = free_port()
    out = tmp_path / "run"
    # a session far longer than the test: it ends when the test says so, after both failures, never before them
    launcher = run(write(tmp_path, "two.toml", name="two remote", port=port, local=2, remote=2), out, "--speed", "2",
                   "--duration", "3600")
    # --timeout: a safety net; each joiner hears the world as soon as it answers
    bad = {"name": join(port, "--session", "other", "--timeout", "120"),
           "not remote": join(port, "--session", "two remote", "--robot", "0", "--timeout", "120"),
           "which": join(port, "--session", "two remote", "--timeout", "120")}
    j2 = j3 = None
    try:
        errs = {k: p.communicate(timeout=180)[1] for k, p in bad.items()}
        assert {p.returncode for p in bad.values()} == {2}, errs
        ep = f"tcp/127.0.0.1:{port}"
        assert f"no session 'other' at {ep}: the session there is 'two remote'" in errs["name"]
        assert f"robot 0 is not a remote robot of session 'two remote' at {ep} (remote robots: 2, 3)" in errs[
            "not remote"]
        assert "has several remote robots (2, 3): choose one with --robot" in errs["which"]
        j2 = join(port, "--session", "two remote", "--robot", "2", "--timeout", "120")
        j3 = join(port, "--session", "two remote", "--robot", "3", "--timeout", "120")
        for j in (j2, j3):
            wait_line(j.stdout, "joined session 'two remote'", j)
        wait_line(launcher.stderr, "started:", launcher)
        late = join(port, "--session", "two remote", "--robot", "3", "--timeout", "120")
        assert late.wait(timeout=120) == 2 and "has already started" in late.stderr.read()
        j2.send_signal(signal.SIGINT)  # leaves: tells the world, its robot fails at once
        j3.kill()  # vanishes: its connection closes, its liveliness token goes, its robot fails at once
        assert j2.wait(timeout=120) == 130
        assert "interrupted (SIGINT); robot 2 fails in session 'two remote'" in j2.stdout.read()
        wait_lines(launcher.stderr, ["robot 2 failed at sim t=", "robot 3 failed at sim t="], launcher)
        wait_line(launcher.stderr, "rtf", launcher)  # the rest went on: a progress line after both failures
        launcher.send_signal(signal.SIGINT)
        assert launcher.wait(timeout=120) == 130
    finally:
        for p in (launcher, j2, j3, *bad.values()):
            if p is not None and p.poll() is None:
                p.kill()
    s = summary(out)
    assert sorted((f["robot"], f["kind"]) for f in s["failures"]) == [(2, "died"), (3, "died")]
    died, lost = sorted(s["failures"], key=lambda f: f["robot"])
    assert "swarm-sitl join on another computer stopped (SIGINT)" in died["detail"]
    assert "lost the other computer: its swarm-sitl join ended or its network failed" in lost["detail"]
    assert [r["alive"] for r in s["per_robot"]] == [True, True, False, False]
    assert s["interrupted"] and s["sim_time_s"] > max(f["t_s"] for f in s["failures"])
    assert session_procs(out) == []


def test_a_joiner_that_asks_before_the_world_answers_asks_again() -> None:
    """The world accepts connections a moment before it declares its ``plan`` queryable: a joiner asking which
    sessions are there in that window hears nobody, and asks again until a session answers. Here the window is made
    certain: a fake world declares its queryable only after the joiner asked around (a wildcard query)."""
    from bridge.core import transport
    from bridge.hil.join import fetch_offer

    ep = f"tcp/127.0.0.1:{free_port()}"
    world = transport.open_session(ep, None, listen=True)
    asked_around = threading.Event()
    declared = []

    def spy(query) -> None:  # hears the joiner's questions, answers none
        if "*" in str(query.key_expr):
            asked_around.set()

    def answer_once_asked() -> None:
        if asked_around.wait(timeout=120):
            key = f"swarm-sitl/real/{transport.PLAN_KEY}"
            declared.append(world.declare_queryable(
                key, lambda q: q.reply(key, json.dumps({"session": "real"}).encode())))

    world_side = threading.Thread(target=answer_once_asked, daemon=True)
    try:
        declared.append(world.declare_queryable(f"swarm-sitl/*/{transport.PLAN_KEY}", spy))
        world_side.start()
        with pytest.raises(JoinError, match=f"no session 'other' at {ep}: the session there is 'real'"):
            fetch_offer(ep, "other", timeout_s=60)  # a safety net: the answer comes once the queryable is there
    finally:
        asked_around.set()
        world_side.join(timeout=60)
        world.close()


def test_join_with_nobody_listening_fails_quickly_naming_the_endpoint() -> None:
    port = free_port()
    p = subprocess.run(cli("join", f"tcp/127.0.0.1:{port}", "--session", "x", "--timeout", "1"), cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert f"swarm-sitl join: nobody answers at tcp/127.0.0.1:{port} within 1 s" in p.stderr
    p = subprocess.run(cli("join", "127.0.0.1:7447", "--session", "x"), cwd=ROOT, capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 2 and "ENDPOINT: '127.0.0.1:7447' is not tcp/HOST:PORT" in p.stderr


def test_config_errors_and_warnings(tmp_path: Path) -> None:
    no_listen = write(tmp_path, "a.toml")
    with pytest.raises(ConfigError, match=r'session.listen: robots\[1\].logic = "remote" joins over zenoh'):
        load_config(str(no_listen))
    bad = tmp_path / "b.toml"
    bad.write_text(write(tmp_path, "b.toml", port=7447).read_text().replace("tcp/127.0.0.1:7447", "tcp/host"))
    r = subprocess.run(cli("validate", str(bad)), cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and f"{bad}: session.listen: 'tcp/host' is not tcp/HOST:PORT" in r.stderr
    with socket.socket() as taken:  # the world could not listen there: refused before anything starts
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        busy = write(tmp_path, "busy.toml", port=port)
        r = subprocess.run(cli("run", str(busy), "--out", str(tmp_path / "x")), cwd=ROOT, capture_output=True,
                           text=True, timeout=60)
    assert r.returncode == 2, r.stderr
    assert f"{busy}: session.listen: cannot listen on tcp/127.0.0.1:{port}: Address already in use" in r.stderr
    cfg = load_config(str(write(tmp_path, "c.toml", port=7447)))
    assert not [w for w in config_warnings(cfg) if "session.listen" in w]  # loopback: stays on this machine
    for host in ("0.0.0.0", "192.168.1.10"):
        cfg = load_config(str(write(tmp_path, "c.toml", port=7447)), {"session.listen": f"tcp/{host}:7447"})
        (w,) = [w for w in config_warnings(cfg) if "session.listen" in w]
        assert f"tcp/{host}:7447 is reachable from other machines" in w and "anyone who can reach the port" in w


def test_namespace_join_commands_and_the_offer_checks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert namespace_for("rl") == "swarm-sitl/rl" and namespace_for("a b/*") == "swarm-sitl/a%20b%2F%2A"
    assert namespace_for(None) != namespace_for(None)  # private sessions: random
    with pytest.raises(ValueError, match=r"session\.name"):
        namespace_for("")
    cfg = load_config(str(write(tmp_path, "c.toml", name="two", port=7447, local=2, remote=2)))
    plan = make_plan(cfg)
    assert [(p.name, p.robots) for p in plan.procs if p.remote] == [("remote2", (2,)), ("remote3", (3,))]
    assert join_commands("two", "tcp/127.0.0.1:7447", plan) == [
        f"robot {r}'s logic: swarm-sitl join tcp/127.0.0.1:7447 --session two --robot {r}" for r in (2, 3)]
    offer = json.loads(plan_offer(plan, frozenset({"remote2", "remote3"})))
    got, robot, proc = choose(offer, "tcp/h:1", "two", 3)
    assert (robot, proc, got.to_json()) == (3, "remote3", plan.to_json())
    with pytest.raises(JoinError, match="robot 3's logic has already joined"):
        choose(json.loads(plan_offer(plan, frozenset({"remote2"}))), "tcp/h:1", "two", 3)
    with pytest.raises(JoinError, match="has already started"):
        choose(json.loads(plan_offer(plan, None)), "tcp/h:1", "two", 3)
    monkeypatch.setattr("bridge.hil.join.code_fingerprint", lambda: "0.0.1+0123456789abcdef")
    with pytest.raises(JoinError, match=r"runs swarm-sitl \S+\+\S+ \(protocol 2\), this computer has 0.0.1\+0123"):
        choose(offer, "tcp/h:1", "two", 3)
    other = {**offer, "version": offer["version"].split("+")[0] + "+ffffffffffffffff"}  # same release, other code
    monkeypatch.undo()
    with pytest.raises(JoinError, match="the same code, on both"):
        choose(other, "tcp/h:1", "two", 3)
