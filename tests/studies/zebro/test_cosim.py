"""The six setups in co-simulation: the versioned configs are what the scenario generator gives, the decision's
figures (components, A-13's split) are counted right, and a session of Zebros records its decision the same at any
packing and speed."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from bridge.core.config import ConfigError, load_config, to_toml
from bridge.core.recorder import iter_messages
from bridge.studies.zebro.cosim import SETUPS, scenario_config
from bridge.studies.zebro.decision import SplitWatch, components
from tests.conftest import ROOT

CONFIGS = ROOT / "hil_configs" / "zebro"


@pytest.mark.parametrize("setup", list(SETUPS))
def test_the_versioned_setups_are_the_generators(setup: str) -> None:
    path = CONFIGS / f"{setup.lower()}.toml"
    assert tomllib.loads(path.read_text()) == scenario_config(setup, "mature", "realistic", 1,
                                                              name=f"zebro-{setup.lower()}")
    cfg = load_config(path)
    n, p, long_range = SETUPS[setup]
    assert cfg.robot_count == n and len(cfg.section("particles")) == p
    assert (cfg.uwb.max_range_m == 60.0) == long_range  # LRC: the radios' own range; SRC: turned down


def test_scenario_names_are_checked() -> None:
    with pytest.raises(ValueError, match="setup: expected one of E1"):
        scenario_config("E7", "mature", "faithful", 1)
    with pytest.raises(ValueError, match="algorithm: expected one of silent"):
        scenario_config("E1", "greedy", "faithful", 1)
    with pytest.raises(ValueError, match="sensing: expected one of faithful"):
        scenario_config("E1", "mature", "noisy", 1)


def test_a_bad_decision_section_names_the_field(tmp_path: Path) -> None:
    raw = scenario_config("E1", "silent", "faithful", 1)
    raw["decision"]["split_s"] = -1
    p = tmp_path / "z.toml"
    p.write_text(to_toml(raw))
    with pytest.raises(ConfigError, match=r"decision.split_s: Input should be greater than 0"):
        load_config(p)


def test_components_of_the_disc_graph() -> None:
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [5.0, 0.0], [5.5, 0.0]])
    alive = np.ones(5, dtype=bool)
    assert components(pos, alive, 1.0) == 2
    assert components(pos, alive, 0.9) == 4
    assert components(pos, alive, 3.0) == 1
    alive[1] = False  # a dead robot relays nothing
    assert components(pos, alive, 1.0) == 3
    assert components(pos, np.zeros(5, dtype=bool), 1.0) == 0


def test_a13_split_is_pieces_for_split_s_in_a_row_or_at_the_end() -> None:
    w = SplitWatch(10.0)
    for t in range(30):
        w.sample(float(t), 2 if 5 <= t < 14 else 1)  # apart for 9 s: not a split
    assert w.report() == {"split": False, "components_max": 2, "components_end": 1, "first_apart_s": 5.0}
    for t in range(30, 41):
        w.sample(float(t), 3)  # apart from 30 to 40: 10 s in a row
    assert w.split
    end = SplitWatch(10.0)
    end.sample(0.0, 1)
    end.sample(1.0, 2)  # in pieces at the end
    assert end.report()["split"] and not end.split


@pytest.mark.long
@pytest.mark.session
def test_a_zebro_session_records_its_decision_the_same_at_any_packing_and_speed(tmp_path: Path) -> None:
    raw = scenario_config("E4", "mature", "faithful", 1)
    raw["session"] |= {"duration_s": 14.0, "robots_per_process": 1}
    cfg = tmp_path / "e4.toml"
    cfg.write_text(to_toml(raw))

    def run(out: str, *extra: str) -> dict:
        cmd = [sys.executable, "-m", "bridge.tools.cli", "run", str(cfg), "--out", str(tmp_path / out), "--quiet",
               *extra]
        r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stdout + r.stderr
        return json.loads((tmp_path / out / "summary.json").read_text())

    s = run("one")
    d = s["decision"]
    assert not s["failures"]
    # a particle lies in a finder's cone at launch; the controllers wait for their radios' first neighbourhood
    assert d["first_sensed"]["t_s"] == 0.0
    assert d["first_meal"] is not None and d["first_meal"]["t_s"] > 1.0
    consumed = s["particles"]["consumed"]
    assert consumed[0] == d["first_meal"]
    assert d["best"] == (d["first_meal"]["utility"] == 95)
    # the mature election ended with one leader before the meal, the swarm stayed whole (a 60 m radio)
    assert len(d["leaders"]) >= 1 and d["leaders"][0]["t_s"] < d["first_meal"]["t_s"]
    assert d["components_max"] == 1 and not d["split"]
    # the frames on the air by type: the STOP flood, the wave, the acks, EOE, the beacons and the link lists
    byt = d["frames_by_type"]
    assert {"stop", "n2", "n4", "eoe", "n1", "links"} <= set(byt)
    assert all(v["bytes"] >= v["frames"] > 0 for v in byt.values())
    # the session ended 10 s after the first meal
    assert s["sim_time_s"] == pytest.approx(min(14.0, d["first_meal"]["t_s"] + 10.0), abs=0.011)
    counted = [t for topic, t, _ in iter_messages(tmp_path / "one" / "session.mcap") if topic == "/world/components"]
    assert counted == [k * 1_000_000_000 for k in range(math.ceil(round(s["sim_time_s"], 2)))]  # once a second
    # the same seed, five robots in one process, paced at 20x real time: the same recording
    packed = run("packed", "--robots-per-process", "5", "--speed", "20")
    assert packed["digest"] == s["digest"]
