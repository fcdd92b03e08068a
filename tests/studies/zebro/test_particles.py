"""Food particles: checked in the config (in the arena, not in an obstacle, distinct utilities), summed by the
utility sensor's cone (Z-U7's sum rule on the robot's own sensor), consumed by the robot that reaches one."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bridge.core.config import ConfigError, load_config
from bridge.core.plan import make_plan
from bridge.core.world import World
from bridge.studies.zebro.particles import Particles

BASE = """
[arena]
width_m = 10
length_m = 10

[[obstacles]]
type = "box"
x = 8.0
y = 8.0
size = [1.0, 1.0, 0.5]

[[robots]]
profile = "decizebro"
count = 1
placement = { kind = "explicit", poses = [[2.0, 5.0, 0.0]] }
"""


def write(tmp_path: Path, particles: str) -> Path:
    p = tmp_path / "zebros.toml"
    p.write_text(BASE + particles)
    return p


@pytest.mark.parametrize(("particles", "match"), [
    ("[[particles]]\nx = 8.1\ny = 7.9\nutility = 15\n", r"particles\[0\]: \(8.1, 7.9\) is inside obstacles\[0\]"),
    ("[[particles]]\nx = 12.0\ny = 5.0\nutility = 15\n", r"particles\[0\]: \(12.0, 5.0\) is outside the 10"),
    ("[[particles]]\nx = 3.0\ny = 5.0\nutility = 15\n[[particles]]\nx = 4.0\ny = 5.0\nutility = 15\n",
     r"particles\[1\].utility = 15: particles\[0\] has it already"),
    ("[[particles]]\nx = 3.0\ny = 5.0\nutility = 300\n",
     r"particles\[0\].utility: Input should be less than or equal to 127"),
    ("[[particle]]\nx = 3.0\ny = 5.0\nutility = 15\n", r"particle: Extra inputs are not permitted"),
])
def test_bad_particles_are_config_errors(tmp_path: Path, particles: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        load_config(write(tmp_path, particles))


def test_the_cone_sums_the_particles_in_it_and_the_nearest_robot_consumes() -> None:
    p = Particles([])
    assert p.in_cone(0, 0, 0, 0.5, 1) == 0
    from bridge.studies.zebro.particles import ParticleCfg

    p = Particles([ParticleCfg(x=0.75, y=0.1, utility=15), ParticleCfg(x=0.7, y=-0.1, utility=95),
                   ParticleCfg(x=0.0, y=0.7, utility=40), ParticleCfg(x=0.5, y=0.0, utility=-20)])
    assert p.in_cone(0.0, 0.0, 0.0, math.radians(30), 0.804) == 15 + 95 - 20  # the one at 90 degrees is not seen
    assert p.in_cone(0.0, 0.0, math.pi / 2, math.radians(30), 0.804) == 40
    pos = np.array([[0.45, 0.0], [0.8, 0.1]])
    assert p.reached(pos, np.array([True, True])) == [(0, 1), (3, 0)]
    assert p.reached(pos, np.array([True, True])) == []  # consumed once
    assert p.in_cone(0.0, 0.0, 0.0, math.radians(30), 0.804) == 95


def test_a_zebros_utility_sensor_reads_the_particles_a_study_put_in_the_world(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, "[[particles]]\nx = 2.5\ny = 5.1\nutility = 95\n"
                                      "[[particles]]\nx = 2.6\ny = 4.9\nutility = 15\n"
                                      "[[particles]]\nx = 1.0\ny = 5.0\nutility = 40\n"))
    w = World(cfg, make_plan(cfg).robots)
    assert w.sensors(0)["utility"] == 0  # no study has put particles in this world
    w.objects["particles"] = Particles(cfg.section("particles"))
    assert w.sensors(0)["utility"] == 110  # the two ahead, not the one behind
