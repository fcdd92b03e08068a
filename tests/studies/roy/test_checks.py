"""A chapter 3 target that no robot could reach is refused before anything runs: in a session config (a ConfigError
naming the file, the group's params and why, at load, before any process starts) and in a numerical scenario (a
ValueError naming the obstacle)."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.config import ConfigError, load_config
from bridge.studies.roy.checks import scenario_target_error, segment_distance
from bridge.studies.roy.numerical import SCENARIOS, Ch3Scenario, Mover
from bridge.tools.cli import main as cli_main
from tests.conftest import ROOT

ARENA = """
[session]
name = "roy-target"
duration_s = 10
[arena]
width_m = 4.5
length_m = 4.5
{obstacles}
[[robots]]
profile = "sonpi"
count = 2
behaviour = "{behaviour}"
params = {{ {params} }}
[robots.devices.sonpi_wifi]
url = "sitl://wifi"
[[services]]
kind = "overhead_camera"
name = "camera"
"""
CYLINDER = '[[obstacles]]\ntype = "cylinder"\nx = {x}\ny = {y}\nradius = 0.2\n'
BOX = '[[obstacles]]\ntype = "box"\nx = {x}\ny = {y}\nsize = [0.4, 2.0, 0.3]\nyaw_deg = {yaw}\n'


def _cfg(tmp_path: Path, obstacles: str = "", params: str = "", behaviour: str = "roy_apf") -> Path:
    """A session of two SonPIs under the camera running ``behaviour`` (roy_apf with fixed gains) with ``params``."""
    own = 'optimiser = "fixed"' if behaviour == "roy_apf" else ""
    p = tmp_path / "roy.toml"
    p.write_text(
        ARENA.format(obstacles=obstacles, params=", ".join(x for x in (own, params) if x), behaviour=behaviour)
    )
    return p


@pytest.mark.parametrize(
    ("obstacles", "params", "why"),
    [
        (CYLINDER.format(x=3.5, y=3.5), "", r"is inside obstacles\[0\], a cylinder at \(3.5, 3.5\), radius 0.2 m"),
        (CYLINDER.format(x=3.25, y=3.5), "", r"has obstacles\[0\], a cylinder .* across its goal region \(goal_tol"),
        # a wall-like box across the diagonal, turned 45 degrees: the target (2.5, 2.5) m lies on it
        (BOX.format(x=2.6, y=2.4, yaw=45), "target_x = 25.0, target_y = 25.0", r"is inside obstacles\[0\], a box"),
        ("", "target_x = 50.0", r"\(5, 3.5\) m is outside the 4.5 x 4.5 m arena"),
        ("", "target_x = 44.5", r"within goal_tol \(0.1 m\) of the arena's wall"),
        (CYLINDER.format(x=1.0, y=1.0) + CYLINDER.format(x=3.5, y=3.5), "", r"obstacles\[1\]"),
    ],
)
def test_a_session_target_in_or_across_an_obstacle_is_refused_at_load(
    tmp_path: Path, obstacles: str, params: str, why: str
) -> None:
    p = _cfg(tmp_path, obstacles, params)
    with pytest.raises(ConfigError, match=rf"roy\.toml: robots\[0\]\.params\.target_x, target_y: .*{why}"):
        load_config(p)


def test_the_launcher_refuses_it_before_any_process_starts(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    p = _cfg(tmp_path, CYLINDER.format(x=3.5, y=3.5))
    out = tmp_path / "run"
    with pytest.raises(SystemExit) as e:
        cli_main(["run", str(p), "--out", str(out), "--quiet"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "roy.toml: robots[0].params.target_x, target_y" in err and "Traceback" not in err
    assert not out.exists()  # nothing started, nothing written


def test_a_reachable_target_and_the_shipped_configs_load(tmp_path: Path) -> None:
    load_config(_cfg(tmp_path, CYLINDER.format(x=1.7, y=2.8)))  # camera_formation's pillar beside the path
    load_config(_cfg(tmp_path, CYLINDER.format(x=3.5, y=3.5), behaviour="random_walk"))  # no roy target: no check
    for name in ("sonpi/camera_formation.toml", "hil/sonpi_outside.toml"):
        load_config(ROOT / "hil_configs" / name)


def test_the_gathering_controllers_target_is_checked_too(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"robots\[0\]\.params\.target_x, target_y: .*inside obstacles\[0\]"):
        load_config(_cfg(tmp_path, CYLINDER.format(x=3.5, y=3.5), behaviour="roy_gathering"))


def test_random_obstacles_drawn_on_the_target_are_named(tmp_path: Path) -> None:
    """A box random_obstacles draws (from the seed, after the explicit obstacles were checked) on the target."""
    drawn = "[random_obstacles]\ncount = 1\nside_m = [0.6, 0.6]\n\n[[robots]]"
    text = _cfg(tmp_path).read_text().replace("[[robots]]", drawn, 1)
    box = load_config(
        _write(tmp_path, "wander.toml", text.replace("roy_apf", "random_walk").replace('optimiser = "fixed"', ""))
    ).obstacles[0]  # where the seed puts the box
    target = f'optimiser = "fixed", target_x = {box.x * 10}, target_y = {box.y * 10}'
    p = _write(tmp_path, "random.toml", text.replace('optimiser = "fixed"', target))
    with pytest.raises(ConfigError, match=r"random\.toml: robots\[0\]\.params\.target_x.*random_obstacles drew it"):
        load_config(p)


def _write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_a_numerical_scenario_refuses_a_target_its_obstacles_cross() -> None:
    assert all(
        scenario_target_error(sc.target, sc.goal_radius, sc.side, sc.lines, sc.movers) is None
        for sc in SCENARIOS.values()
    )
    with pytest.raises(ValueError, match=r"target \(6.0, 11.5\) is within goal_radius \(1\) of lines\[0\]"):
        Ch3Scenario(target=(6.0, 11.5))  # the baffle y = 11 runs through its goal region
    with pytest.raises(ValueError, match=r"on the path of movers\[0\]"):
        Ch3Scenario(target=(27.0, 27.0))  # where the moving circle crosses the diagonal
    with pytest.raises(ValueError, match=r"of the wall"):
        Ch3Scenario(target=(39.5, 20.0))
    with pytest.raises(ValueError, match=r"outside the 40 x 40 world"):
        Ch3Scenario(target=(45.0, 20.0))
    with pytest.raises(ValueError, match=r"movers\[0\]"):  # a standing circle on the target
        Ch3Scenario(lines=(), movers=(Mover((35.0, 35.0), (35.0, 35.0), 1.0, 0.0),))
    Ch3Scenario(target=(20.0, 20.0))  # in the wall's gap: reachable


def test_segment_distance() -> None:
    assert segment_distance((0.0, 1.0), (-1.0, 0.0), (1.0, 0.0)) == 1.0
    assert segment_distance((3.0, 4.0), (0.0, 0.0), (0.0, 0.0)) == 5.0
    assert segment_distance((2.0, 1.0), (-1.0, 0.0), (1.0, 0.0)) == pytest.approx(2**0.5)
