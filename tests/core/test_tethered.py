"""A host's launch command is tethered to the launcher: it and what it starts end when the launcher dies, even by
SIGKILL, and its exit (a code or a signal) is the launcher's to see as the command's."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

from tests.experiments.test_experiment import wait_until

LAUNCHER = """
import subprocess, sys, os, time
p = subprocess.Popen([sys.executable, "-m", "bridge.hosts.tethered", str(os.getpid()), "--", "/bin/sh", "-c",
                      "sleep 1000 & echo $! > " + sys.argv[1] + "; wait"], start_new_session=True)
print(p.pid, flush=True)
time.sleep(1000)
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie (not yet reaped by init) is gone too
        return f.read().rsplit(")", 1)[1].split()[0] != "Z"


def test_the_command_and_its_children_end_when_the_launcher_is_killed(tmp_path: Path) -> None:
    pid_file = tmp_path / "sleep.pid"
    launcher = subprocess.Popen([sys.executable, "-c", LAUNCHER, str(pid_file)], stdout=subprocess.PIPE, text=True)
    try:
        tether = int(launcher.stdout.readline())
        wait_until(lambda: pid_file.exists() and pid_file.read_text().strip(), "the command's child started")
        sleeper = int(pid_file.read_text())
        assert _alive(tether) and _alive(sleeper)
        launcher.kill()
        launcher.wait()
        wait_until(lambda: not _alive(sleeper) and not _alive(tether), "the command and its child ended")
    finally:
        if launcher.poll() is None:
            launcher.kill()


def test_the_commands_exit_is_passed_on() -> None:
    run = [sys.executable, "-m", "bridge.hosts.tethered", str(os.getpid()), "--", "/bin/sh", "-c"]
    assert subprocess.run([*run, "exit 3"], start_new_session=True).returncode == 3
    assert subprocess.run([*run, "kill -9 $$"], start_new_session=True).returncode == -signal.SIGKILL
    bad = subprocess.run([sys.executable, "-m", "bridge.hosts.tethered", "x"], capture_output=True, text=True)
    assert bad.returncode == 2 and "usage" in bad.stderr
