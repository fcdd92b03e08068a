"""A session across computers: robot groups' firmware and logic processes on hosts of ``[[hosts]]``, each host in a
network namespace of its own (``bridge.tools.netns.Lab``), started by the launcher through its ``launch`` command.

The world listens on the lab hub's address; each host reaches it only over its link. Remote processes run in the
session's lock-step, so the recording equals the same config's run on one computer byte for byte; a host that
vanishes fails its robots at once, and only those.
"""

from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
from pathlib import Path

import psutil
import pytest
from mcap.reader import make_reader

from bridge.core.config import ConfigError, load_config
from bridge.core.launcher import join_commands, launch_command
from bridge.core.plan import make_plan
from bridge.tools.netns import Lab
from tests.conftest import ROOT
from tests.hil.test_remote_logic import cli, free_port, summary, wait_line, wait_lines

CONFIG = """
[session]
name = "{name}"
duration_s = 3
seed = 9
robots_per_process = 2
hang_timeout_s = 60
startup_timeout_s = 240
{listen}
[arena]
width_m = 6
length_m = 6
{hosts}
"""
GROUP = """
[[robots]]
count = 2
behaviour = "random_walk"
{host}
[robots.placement]
kind = "random"
region = [0.5, {y0}, 5.5, {y1}]
min_separation_m = 0.6
"""

PORT = """
import socket, sys
with socket.socket() as s:
    s.bind((sys.argv[1], 0))
    print(s.getsockname()[1])
"""


def write(path: Path, name: str, listen: str | None = None, launch: dict[str, str | None] | None = None) -> Path:
    """The test's config: robots 0-1 here; 2-3 (firmware and logic) on host a, 4-5 (logic only) on host b when
    ``launch`` gives the hosts' commands (None: joined by hand); all of them here otherwise."""
    hosts = "".join(
        f'[[hosts]]\nname = "{h}"\n' + (f"launch = {json.dumps(cmd)}\n" if cmd else "")
        for h, cmd in (launch or {}).items()
    )
    text = CONFIG.format(name=name, listen=f'listen = "{listen}"' if listen else "", hosts=hosts)
    for host, y0, y1 in (("", 0.5, 2.0), ('host = "a"', 2.2, 3.8), ('host = { logic = "b" }', 4.0, 5.5)):
        text += GROUP.format(host=host if launch else "", y0=y0, y1=y1)
    path.write_text(text)
    return path


def lab_port(lab: Lab) -> int:
    """A TCP port free on the hub's address (bound in its namespace, read, closed): no fixed port."""
    p = lab.popen(lab.hub, [sys.executable, "-c", PORT, lab.hub.address], stdout=subprocess.PIPE, text=True)
    out, _ = p.communicate(timeout=60)
    return int(out)


def hosted(lab: Lab, tmp_path: Path, name: str, *extra: str, by_hand: str = "") -> tuple[subprocess.Popen, Path]:
    """The launcher in the lab's hub, with hosts a and b in namespaces of their own, each started by its launch
    command but those named in ``by_hand``; its output directory."""
    endpoint = f"tcp/{lab.hub.address}:{lab_port(lab)}"
    launch: dict[str, str | None] = {}
    for h in (lab.add_host("a"), lab.add_host("b")):
        enter = " ".join(map(shlex.quote, lab.enter_argv(h, inside=True)))
        launch[h.name] = (
            None
            if h.name in by_hand
            else (
                f"exec {enter} {shlex.quote(sys.executable)} -m bridge.tools.cli join {{endpoint}} "
                "--session {session} --host {name} --timeout 120"
            )
        )
    cfg = write(tmp_path / f"{name}.toml", name, endpoint, launch)
    out = tmp_path / name
    launcher = lab.popen(
        lab.hub,
        cli("run", str(cfg), "--out", str(out), *extra),
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    return launcher, out


def joiner_of(host: str, session: str) -> psutil.Process:
    """Host ``host``'s swarm-sitl join process for ``session`` (its launch command's), found by its command line."""
    for p in psutil.process_iter(["cmdline"]):
        cmd = p.info["cmdline"] or []
        if (
            "join" in cmd
            and "--host" in cmd
            and cmd[cmd.index("--host") + 1] == host
            and (cmd[cmd.index("--session") + 1] == session)
        ):
            return p
    raise AssertionError(f"no join process for host {host}")


pytestmark = pytest.mark.skipif(Lab.unavailable() is not None, reason=str(Lab.unavailable()))


@pytest.mark.session
def test_hosts_in_their_own_namespaces_record_what_one_computer_records(tmp_path: Path) -> None:
    local_out = tmp_path / "local"
    local = subprocess.Popen(
        cli("run", str(write(tmp_path / "local.toml", "hosted")), "--out", str(local_out), "--quiet"),
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    with Lab() as lab:
        launcher, out = hosted(lab, tmp_path, "hosted", by_hand="b")
        joiner = None
        try:  # the timeouts only bound a hang: every wait ends on a process's exit
            # b is joined by hand, in its namespace, with the command the launcher printed
            line = wait_line(launcher.stderr, "host b (lg2: robots 4-5): swarm-sitl join ", launcher)
            command = shlex.split(line.split("): ", 1)[1])
            assert command == ["swarm-sitl", "join", f"tcp/{lab.hub.address}:{command[2].rpartition(':')[2]}",
                               "--session", "hosted", "--host", "b"]  # fmt: skip
            joiner = lab.popen(lab.hosts[1], [*cli(*command[1:]), "--timeout", "120"], cwd=ROOT,
                               stdout=subprocess.PIPE, text=True)  # fmt: skip
            _, err = launcher.communicate(timeout=280)
            assert launcher.returncode == 0, err
            assert local.wait(timeout=280) == 0, local.stderr.read()
            j_out, _ = joiner.communicate(timeout=120)
            assert joiner.returncode == 0, j_out
        finally:
            for p in (launcher, local, joiner):
                if p is not None and p.poll() is None:
                    p.kill()
    s, ref = summary(out), summary(local_out)
    assert s["remote_processes"] == ["fw2", "lg1", "lg2"] and s["processes"] == ref["processes"] == 7
    assert s["hosts"] == {
        "a": {"processes": ["fw2", "lg1"], "robots": [2, 3], "failed_robots": [], "launch_exit": 0},
        "b": {"processes": ["lg2"], "robots": [4, 5], "failed_robots": [], "launch_exit": None},
    }
    assert s["failures"] == [] and all(r["alive"] and r["distance_m"] > 0.05 for r in s["per_robot"])
    assert "host 'a' joined session 'hosted' at tcp/127.77.0.1:" in (out / "logs" / "host-a.log").read_text()
    assert "session 'hosted' ended (the world said stop); host 'b' ran 1 processes" in j_out
    # the same seed gives the same bytes whether robots 2-5 run on other computers or here
    assert (s["digest"], s["messages"]) == (ref["digest"], ref["messages"])


@pytest.mark.session
def test_a_host_that_vanishes_fails_only_its_robots(tmp_path: Path) -> None:
    with Lab() as lab:
        # far longer than the test: it ends when the test says so, after the loss, never before it
        launcher, out = hosted(lab, tmp_path, "loss", "--speed", "2", "--duration", "3600")
        try:
            wait_line(launcher.stderr, "started:", launcher)
            victim = joiner_of("a", "loss")
            children = victim.children()
            assert sorted(c.cmdline()[c.cmdline().index("--proc") + 1] for c in children) == ["fw2", "lg1"]
            victim.kill()  # the join and, with it, its processes (they die with their parent)
            psutil.wait_procs([victim, *children], timeout=120)
            wait_lines(launcher.stderr, ["robot 2 failed at sim t=", "robot 3 failed at sim t="], launcher)
            wait_line(launcher.stderr, "rtf", launcher)  # the rest went on: a progress line after the loss
            leaver = joiner_of("b", "loss")
            children = leaver.children()
            leaver.send_signal(signal.SIGINT)  # b's join leaves: it ends its processes and tells the world
            psutil.wait_procs([leaver, *children], timeout=120)
            wait_lines(launcher.stderr, ["robot 4 failed at sim t=", "robot 5 failed at sim t="], launcher)
            launcher.send_signal(signal.SIGINT)
            assert launcher.wait(timeout=120) == 130
        finally:
            if launcher.poll() is None:
                launcher.kill()
    s = summary(out)
    assert sorted((f["robot"], f["kind"]) for f in s["failures"]) == [
        (2, "died"),
        (3, "died"),
        (4, "died"),
        (5, "died"),
    ]
    lost, left = s["failures"][:2], s["failures"][2:]
    assert all("host a" in f["detail"] for f in lost), lost
    assert all("swarm-sitl join on host b stopped (SIGINT)" in f["detail"] for f in left), left
    assert max(f["t_s"] for f in lost) < min(f["t_s"] for f in left)  # robots 0, 1, 4, 5 went on after a's loss
    assert [r["alive"] for r in s["per_robot"]] == [True, True, False, False, False, False]
    assert s["hosts"]["a"]["failed_robots"] == [2, 3] and s["hosts"]["b"]["failed_robots"] == [4, 5]
    assert s["hosts"]["b"]["launch_exit"] == 130  # b's join, interrupted
    assert s["sim_time_s"] > max(f["t_s"] for f in s["failures"])
    with open(out / "session.mcap", "rb") as f:  # the recording is whole: readable to its end
        poses = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=["/world/poses"])]
    assert len(poses) == round(s["sim_time_s"] * 100) and poses[-1]["alive"] == [True, True] + [False] * 4


def test_a_host_whose_launch_command_fails_stops_the_start(tmp_path: Path) -> None:
    port = free_port()
    cfg = write(
        tmp_path / "f.toml",
        "fails",
        f"tcp/127.0.0.1:{port}",
        {"a": "echo no route to {name} >&2; exit 3", "b": "exit 0"},
    )
    r = subprocess.run(cli("run", str(cfg), "--out", str(tmp_path / "f")), cwd=ROOT, capture_output=True, text=True,
                       timeout=300)  # fmt: skip
    assert r.returncode == 1, r.stderr
    s = summary(tmp_path / "f")
    assert s["error"].startswith("host a's launch command exited (code 3) before the session started; see ")
    assert (tmp_path / "f" / "logs" / "host-a.log").read_text() == "no route to a\n"


def test_host_config_errors_and_commands(tmp_path: Path) -> None:
    launch = {"a": "ssh {name}.lan {join}", "b": "ssh b {join}"}
    cfg = load_config(str(write(tmp_path / "ok.toml", "two hosts", "tcp/0.0.0.0:7447", launch)))
    plan = make_plan(cfg)
    assert [(p.name, p.robots, p.host) for p in plan.procs] == [
        ("fw0", (0, 1), None),
        ("fw1", (4, 5), None),
        ("fw2", (2, 3), "a"),
        ("lg0", (0, 1), None),
        ("lg1", (2, 3), "a"),
        ("lg2", (4, 5), "b"),
    ]
    assert launch_command(cfg.hosts[0].launch, "tcp/10.0.0.1:7447", "two hosts", "a") == (
        "ssh a.lan swarm-sitl join tcp/10.0.0.1:7447 --session 'two hosts' --host a"
    )
    assert join_commands("two hosts", "tcp/10.0.0.1:7447", plan, cfg.hosts) == []  # both launched
    cfg.hosts[1].launch = None
    assert join_commands("two hosts", "tcp/10.0.0.1:7447", plan, cfg.hosts) == [
        "host b (lg2: robots 4-5): swarm-sitl join tcp/10.0.0.1:7447 --session 'two hosts' --host b"
    ]
    text = (tmp_path / "ok.toml").read_text()
    bad = {
        'host = "a"': ('host = "c"', r"robots\[1\].host: 'c' is not a host of \[\[hosts\]\] \(hosts: a, b\)"),
        'host = { logic = "b" }': ('host = { logic = "a" }', r"hosts\[1\]: host 'b' runs no process"),
        "{join}": ("{joined}", r"hosts\[0\].launch: \{joined\} is not a placeholder"),
        'name = "b"': ('name = "a"', r"hosts\[1\].name: 'a' names another host already"),
        'listen = "tcp/0.0.0.0:7447"': ("", r"session.listen: \[\[hosts\]\] join over zenoh"),
        'logic = "b"': ('logik = "b"', r"robots\[2\].host: \{'logik': 'b'\}: a table of hosts by process kind takes"),
    }
    for old, (new, err) in bad.items():
        p = tmp_path / "bad.toml"
        p.write_text(text.replace(old, new, 1))
        with pytest.raises(ConfigError, match=err):
            load_config(str(p))
    pty = text.replace('host = "a"', 'host = "a"\nxbee = { pty = "r{id}-xbee" }', 1).replace(
        "seed = 9", "seed = 9\nspeed = 1"
    )
    p.write_text(pty)
    with pytest.raises(ConfigError, match=r"robots\[1\].host: xbee.pty is a device or port of the world's computer"):
        load_config(str(p))


def test_a_service_runs_on_a_host(tmp_path: Path) -> None:
    from bridge.core.config import read_toml, to_toml

    raw = read_toml(ROOT / "hil_configs" / "demos" / "overhead_camera.toml")
    raw["session"]["listen"] = "tcp/127.0.0.1:7447"
    raw["hosts"] = [{"name": "cam"}]
    raw["services"][0]["host"] = "cam"
    (tmp_path / "s.toml").write_text(to_toml(raw))
    cfg = load_config(str(tmp_path / "s.toml"))
    plan = make_plan(cfg)
    assert [(p.name, p.remote, p.host) for p in plan.procs if p.kind == "service"] == [
        ("svc-camera", True, "cam"),
        ("svc-controller", False, None),
    ]
    assert join_commands("s", "tcp/127.0.0.1:7447", plan, cfg.hosts) == [
        "host cam (svc-camera): swarm-sitl join tcp/127.0.0.1:7447 --session s --host cam"
    ]
    raw["services"][0]["host"] = "nowhere"
    (tmp_path / "s.toml").write_text(to_toml(raw))
    with pytest.raises(ConfigError, match=r"services\[0\].host: 'nowhere' is not a host of \[\[hosts\]\]"):
        load_config(str(tmp_path / "s.toml"))


BEHAVIOUR = '''
from swarm_logic.controller import Controller


class Idle(Controller):
    """A behaviour this computer has and the host has not."""

    def step(self):
        self.robot.llc.drive(0.0, 0.0)
'''


@pytest.mark.session
def test_a_host_whose_process_cannot_start_leaves_whole_and_the_start_stops(tmp_path: Path) -> None:
    """Host b lacks the behaviour its logic runs (a plugin installed on the world's computer only): its logic process
    dies before the start, so b's join leaves whole (exit 1) and, as its launch command failed, the start stops."""
    site = tmp_path / "site"
    (site / "onlyhere").mkdir(parents=True)
    (site / "onlyhere" / "__init__.py").write_text(BEHAVIOUR)
    info = site / "onlyhere-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: onlyhere\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[swarm_sitl.behaviours]\nidle_here = onlyhere:Idle\n")
    join = f"exec env -u PYTHONPATH {shlex.quote(sys.executable)} -m bridge.tools.cli join {{endpoint}} --session {{session}} --host {{name}} --timeout 120"  # noqa: E501
    cfg = write(tmp_path / "g.toml", "gone", f"tcp/127.0.0.1:{free_port()}", {"a": join, "b": join})
    b_group = 'behaviour = "random_walk"\nhost = { logic = "b" }'
    cfg.write_text(cfg.read_text().replace(b_group, b_group.replace("random_walk", "idle_here")))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)])}
    r = subprocess.run(cli("run", str(cfg), "--out", str(tmp_path / "g")), cwd=ROOT, capture_output=True, text=True,
                       timeout=300, env=env)  # fmt: skip
    assert r.returncode == 1, r.stderr
    s = summary(tmp_path / "g")
    assert s["error"].startswith("host b's launch command exited (code 1) before the session started; see ")
    log = (tmp_path / "g" / "logs" / "host-b.log").read_text()
    assert "swarm-sitl join: host 'b': lg2 exited 1 before the session started; see " in log, log
