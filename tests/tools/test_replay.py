"""``swarm-sitl replay``: one robot's logic or firmware re-run against its recorded inputs gives the same answers,
run by run; an edited controller gives the first divergence; a run without recorded ticks is refused."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from bridge.core.launcher import run_session

pytestmark = pytest.mark.session

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "hil_configs" / "demo.toml"
CONTROLLER = '''
from swarm_logic.families.demo.rssi_keeper import RssiKeeper

EDITED = {edited}


class MyKeeper(RssiKeeper):
    def step(self) -> None:
        super().step()
        if EDITED and self.robot.clock.now() >= 3.0:
            self.robot.log("edited", t=self.robot.clock.now())
'''


def replay(run: Path, robot: int, role: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bridge.tools.cli", "replay", str(run), "--robot", str(robot),
                           "--role", role], capture_output=True, text=True, env=env, cwd=ROOT)


@pytest.fixture(scope="module")
def edited_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict]:
    import os

    pkg = tmp_path_factory.mktemp("user")
    (pkg / "mykeeper.py").write_text(CONTROLLER.format(edited=False))
    env = {**os.environ, "PYTHONPATH": str(pkg)}
    sys.path.insert(0, str(pkg))
    old = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = str(pkg)
    try:
        out = tmp_path_factory.mktemp("run")
        res = run_session(str(DEMO), {"robots.count": 3, "session.robots_per_process": 3, "session.duration_s": 5.0,
                                      "session.record_ticks": True, "robots.0.behaviour": "mykeeper:MyKeeper"},
                          str(out), progress=None, plot=False)
        assert res.code == 0
    finally:
        sys.path.remove(str(pkg))
        if old is None:
            del os.environ["PYTHONPATH"]
        else:
            os.environ["PYTHONPATH"] = old
    return out, pkg, env


def test_a_replayed_process_answers_as_it_did(edited_run: tuple[Path, Path, dict]) -> None:
    run, _, env = edited_run
    for role in ("logic", "firmware"):
        p = replay(run, 1, role, env)
        assert p.returncode == 0, p.stderr
        assert p.stdout.startswith(f"identical: robot 1's {role}, ") and int(p.stdout.split(", ")[1].split()[0]) > 10


def test_an_edited_controller_gives_the_first_divergence(edited_run: tuple[Path, Path, dict]) -> None:
    run, pkg, env = edited_run
    (pkg / "mykeeper.py").write_text(CONTROLLER.format(edited=True))
    try:
        p = replay(run, 2, "logic", env)
    finally:
        (pkg / "mykeeper.py").write_text(CONTROLLER.format(edited=False))
    assert p.returncode == 1, p.stderr
    assert "first divergence at t=3.0" in p.stdout and "r002/logic" in p.stdout and "edited" in p.stdout


def test_a_run_without_ticks_is_refused(tmp_path: Path) -> None:
    res = run_session(str(DEMO), {"robots.count": 2, "session.robots_per_process": 2, "session.duration_s": 1.0},
                      str(tmp_path), progress=None, plot=False)
    assert res.code == 0
    p = replay(tmp_path, 0, "logic")
    assert p.returncode == 2 and "record_ticks" in p.stderr and "Traceback" not in p.stderr
    p = replay(tmp_path / "nowhere", 0, "logic")
    assert p.returncode == 2 and "no session.mcap" in p.stderr
