"""The pavilion field experiments' pieces: random obstacles drawn at config load, resized conveyors, the link
statistics of Table 5.2, the numerical EST of E3, and a deployment-only session."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bridge.core.config import ConfigError, load_config
from bridge.core.plan import make_plan
from bridge.experiments.runner import TrialResult
from bridge.experiments.stats import pooled_mean_sd
from bridge.studies.rdpso.deployment import link_stats, mean_sd
from bridge.studies.rdpso.field_experiments import est_subgroup, isolated_exclusions, random_subgroup
from tests.conftest import ROOT
from tests.core.test_session import cli

BASE = """[session]
seed = {seed}
duration_s = 10
[arena]
width_m = 10
length_m = 20
[[obstacles]]
type = "cylinder"
x = 3.0
y = 7.0
radius = 0.25
[random_obstacles]
{random}
[[robots]]
count = 3
placement = {{ kind = "explicit", poses = [[2.0, 1.0, 90.0], [5.0, 1.0, 90.0], [8.0, 1.0, 90.0]] }}
[[robots]]
count = 4
placement = {{ kind = "grid", origin = [1.0, 18.0], spacing_m = 0.5, columns = 4 }}
"""
RANDOM = 'count = 8\nside_m = [0.4, 1.2]\nclearance_m = 0.8\nkeep_clear = [[5.0, 10.0, 1.5]]'


def write(tmp_path: Path, seed: int = 7, random: str = RANDOM, name: str = "r.toml") -> Path:
    p = tmp_path / name
    p.write_text(BASE.format(seed=seed, random=random))
    return p


def test_random_obstacles_are_drawn_from_the_seed_clear_of_the_starts(tmp_path: Path) -> None:
    a = load_config(write(tmp_path)).obstacles
    assert len(a) == 9 and a[0].type == "cylinder"  # the fixed pillar first, then the drawn boxes
    assert load_config(write(tmp_path, name="again.toml")).obstacles == a
    assert load_config(write(tmp_path, seed=8)).obstacles[1:] != a[1:]
    starts = [(2.0, 1.0), (5.0, 1.0), (8.0, 1.0)] + [(1.0 + 0.5 * i, 18.0) for i in range(4)]
    placed = [(a[0].x, a[0].y, 0.25)]
    for box in a[1:]:
        sx, sy, _ = box.size
        assert 0.4 <= sx <= 1.2 and 0.4 <= sy <= 1.2
        r = math.hypot(sx, sy) / 2
        assert r + 0.8 <= box.x <= 10 - r - 0.8 and r + 0.8 <= box.y <= 20 - r - 0.8  # inside, off the walls
        assert all(math.hypot(box.x - x, box.y - y) >= r + 0.8 + 0.063 - 2e-3 for x, y in starts)
        assert math.hypot(box.x - 5.0, box.y - 10.0) >= r + 1.5 - 2e-3
        assert all(math.hypot(box.x - x, box.y - y) >= r + rr + 0.8 - 2e-3 for x, y, rr in placed)
        placed.append((box.x, box.y, r))
    make_plan(load_config(write(tmp_path)))  # the start poses are free


@pytest.mark.parametrize(("random", "match"), [
    ("count = 200\nside_m = [1.0, 2.0]", r"random_obstacles.count: placed only \d+ of 200"),
    ("count = 3\nside_m = [1.0, 0.5]", r"random_obstacles.side_m: need 0 < min <= max"),
    ("count = 0", r"random_obstacles.count"),
    ("count = 3\nside_m = [6.0, 8.0]", r"random_obstacles.side_m: a box of side 6.0 m .* does not fit"),
    ("count = 3\nkeep_clear = [[12.0, 1.0, 1.0]]", r"random_obstacles.keep_clear\[0\]: \(12.0, 1.0\) is outside"),
    ("count = 3\nshape = \"round\"", r"random_obstacles.shape"),
])
def test_random_obstacles_are_checked(tmp_path: Path, random: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match) as e:
        load_config(write(tmp_path, random=random))
    assert str(tmp_path / "r.toml") in str(e.value)


CARRY = """[session]
duration_s = 10
[arena]
width_m = 10
length_m = 20
[[robots]]
profile = "{profile}"
count = 3
{slots}
placement = {{ kind = "explicit", poses = [[2.0, 1.0, 90.0], [5.0, 1.0, 90.0], [8.0, 1.0, 90.0]] }}
[[robots]]
count = {scouts}
carried_by = 0
"""


def test_a_resized_conveyor_carries_more_scouts(tmp_path: Path) -> None:
    p = tmp_path / "c.toml"
    p.write_text(CARRY.format(profile="traxbot", slots="conveyor_slots = 20", scouts=60))
    plan = make_plan(load_config(p))
    scouts = plan.robots[3:]
    assert [sum(r.carrier == c for r in scouts) for c in range(3)] == [20, 20, 20]
    assert [r.slot for r in scouts[:21]] == [*range(1, 21), 1] and len(plan.robots[0].payload) == 20


@pytest.mark.parametrize(("profile", "slots", "scouts", "match"), [
    ("traxbot", "conveyor_slots = 20", 61, r"robots\[1\].count: robots\[0\] carries at most 3 x 20 = 60"),
    ("traxbot", "", 16, r"carries at most 3 x 5 = 15"),
    ("eswarbot", "conveyor_slots = 5", 3, r"robots\[0\].conveyor_slots: Extra inputs are not permitted"),
    ("traxbot", "conveyor_slots = 0", 3, r"robots\[0\].conveyor_slots: Input should be greater than or equal to 1"),
])
def test_conveyor_slots_are_checked(tmp_path: Path, profile: str, slots: str, scouts: int, match: str) -> None:
    p = tmp_path / "c.toml"
    p.write_text(CARRY.format(profile=profile, slots=slots, scouts=scouts))
    with pytest.raises(ConfigError, match=match):
        load_config(p)


def test_link_stats_of_a_path_and_of_a_split_graph() -> None:
    adj = np.zeros((4, 4))
    for i in range(3):
        adj[i, i + 1] = 1.0  # one way is enough: the radio graph is symmetric
    rssi = np.full((4, 4), -90.0)
    rssi[0, 1], rssi[1, 0], rssi[1, 2], rssi[2, 1], rssi[2, 3], rssi[3, 2] = -70, -72, -74, -76, -60, -62
    s = link_stats(adj, rssi)
    assert s["links"] == 3 and s["rssi_dbm"] == pytest.approx(-69.0)  # six directions of three links
    assert s["hops"] == pytest.approx((2 + 2 + 3) / 3) and s["relays"] == pytest.approx(4 / 3)
    assert s["lambda2"] == pytest.approx(2 - 2 * math.cos(math.pi / 4)) and s["pieces"] == 1
    adj[1, 2] = 0.0  # {0, 1} and {2, 3}: neighbours only, nothing to relay
    s = link_stats(adj, rssi)
    assert s["pieces"] == 2 and s["lambda2"] == pytest.approx(0.0, abs=1e-9) and s["hops"] is None
    full = np.ones((3, 3))
    assert link_stats(full, rssi[:3, :3])["lambda2"] == pytest.approx(3.0)  # complete graph: lambda2 = N
    assert link_stats(np.zeros((1, 1)), np.zeros((1, 1)))["rssi_dbm"] is None


def test_pooled_mean_and_sd_equal_those_of_all_samples() -> None:
    rng = np.random.default_rng(3)
    parts = [rng.normal(m, 1.0, n) for m, n in ((-70, 5), (-72, 9), (-68, 4))]
    rows = []
    for x in parts:
        s = mean_sd(list(x))
        rows.append(TrialResult({"r_mean": s["mean"], "r_sd": s["sd"], "r_n": s["samples"]}))
    m, sd, n = pooled_mean_sd(rows, "r")
    every = np.concatenate(parts)
    assert n == 18 and m == pytest.approx(every.mean(), abs=1e-3) and sd == pytest.approx(every.std(ddof=1), abs=1e-3)


def test_an_isolated_member_leaving_counts_as_a_self_exclusion() -> None:
    rec = {"sid": 1, "n_s": 3, "events": []}
    logs = {
        1: [rec, {**rec, "n_s": 1}, {**rec, "sid": 0, "events": ["dismantled"]}],  # alone, then out
        2: [rec, {**rec, "sid": 0, "events": ["punished"]}],  # punished with mates around: not isolated
        3: [rec, {**rec, "n_s": 1}, {**rec, "n_s": 1, "events": ["spared"]}],
    }
    assert isolated_exclusions(logs) == 1


def test_numerical_est_follows_the_spiral_and_spreads_wider_than_random() -> None:
    rng = np.random.default_rng(5)
    none = np.zeros((0, 4))
    pts = est_subgroup(10, 3.0, none, (30.0, 30.0), rng)
    legs = np.hypot(*np.diff(pts, axis=0).T)
    assert np.allclose(legs, 3.0, atol=0.05)  # unobstructed: every leg d_max, as eq. 5.2
    # a spiral of Theodorus: each leg turns the same way as the last, by less each time (arctan(1/sqrt m))
    heading = np.arctan2(*np.diff(pts, axis=0)[:, ::-1].T)
    turns = np.angle(np.exp(1j * np.diff(heading)))
    assert np.all(np.sign(turns) == np.sign(turns[0])) and np.all(np.diff(np.abs(turns)) < 0), turns
    rnd = random_subgroup(10, 3.0, none, (30.0, 30.0), rng)
    assert np.all(np.hypot(*np.diff(rnd, axis=0).T) <= 3.0 + 1e-9)
    box = np.array([[31.0, 29.0, 32.0, 31.0]])  # an obstacle right ahead: the ranger stops short of it
    blocked = est_subgroup(3, 3.0, box, (30.0, 30.0), np.random.default_rng(5))
    from bridge.numerical.objectives import obstacle_distance

    assert np.all(obstacle_distance(blocked[:, 0], blocked[:, 1], box) >= 0.15 - 1e-9)


SESSION = """[session]
duration_s = 150
seed = 3
end_after_deployment = true
[arena]
width_m = 10
length_m = 14
[random_obstacles]
count = 2
keep_clear = [[5.0, 7.0, 3.0]]
[[robots]]
profile = "traxbot"
count = 1
behaviour = "est_ranger"
xbee = { series = 2, baud = 115200 }
params = { q_min_dbm = -70.0 }
placement = { kind = "explicit", poses = [[5.0, 7.0, 90.0]] }
[[robots]]
count = 3
behaviour = "rdpso"
carried_by = 0
xbee = { series = 2, baud = 115200 }
[robots.params]
deployed = true
first_id = 1
n_total = 3
subgroups_init = 1
subgroups_max = 1
link_mode = "rssi"
q_min_dbm = -70.0
"""


@pytest.mark.session
def test_a_deployment_only_session_ends_after_the_start_and_reports_links(tmp_path: Path) -> None:
    cfg = tmp_path / "dep.toml"
    cfg.write_text(SESSION)
    # two robots a process: the same recording as one a process (packing never changes a session's digest)
    r = subprocess.run(cli("run", str(cfg), "--out", str(tmp_path / "run"), "--robots-per-process", "2"), cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    dep = s["deployment"]
    assert dep["done"] == 1 and dep["left_on_board"] == []
    t_done = dep["rangers"]["0"]["t_s"]
    assert t_done + 0.9 <= s["sim_time_s"] <= t_done + 1.1 < 150  # ended 1 s after the START, not at 150 s
    mission = s["radio"]["connectivity"]["mission"]
    assert mission["lambda2"]["samples"] >= 1 and mission["rssi_dbm"]["mean"] < -30
    assert mission["partition_events"] == 0


def _loop_functions(rssi: np.ndarray, carriers: dict[int, int | None]) -> Any:
    """The study's loop functions on a hub of rangers and scouts (robot -> its ranger, None for a ranger), the scouts
    judging links at -75 dBm; every ranger has broadcast its START."""
    from types import SimpleNamespace

    from bridge.studies.rdpso.loop_functions import RdpsoLoopFunctions

    robots = [SimpleNamespace(id=r, carrier=c, params={} if c is None else {"link_mode": "rssi", "q_min_dbm": -75.0})
              for r, c in carriers.items()]
    medium = SimpleNamespace(medium=SimpleNamespace(mean_rssi=lambda: rssi))
    hub = SimpleNamespace(plan=SimpleNamespace(robots=robots),
                          cfg=SimpleNamespace(section=lambda name: SimpleNamespace(kind="light")),
                          world=SimpleNamespace(carried=set()), medium=lambda name: medium)
    lf = RdpsoLoopFunctions(hub)
    for r, c in carriers.items():
        if c is None:
            lf.deployed[r] = {"t_s": 1.0}
    return lf


def test_link_statistics_follow_the_rdpso_subgroups_of_the_sample_not_the_rangers_groups() -> None:
    # scouts 1-5 on a line 2 m apart: -70 dBm to a neighbour on the line, -90 dBm to anyone farther
    n = 6
    rssi = np.full((n, n), -90.0)
    for i in range(1, 5):
        rssi[i, i + 1] = rssi[i + 1, i] = -70.0
    lf = _loop_functions(rssi, {0: None, 1: 0, 2: 0, 3: 0, 4: 0, 5: 0})
    for robot, sid in ((1, 7), (2, 7), (3, 7), (4, 0), (5, 9)):  # 4 excluded, 5 alone in subgroup 9
        lf.on_log(robot, "rdpso", {"sid": sid, "mate_rssi": [-70, -71] if sid == 7 else []}, 0)
    lf.on_radio_sample(0, list(range(n)), np.ones((n, n)))
    assert [(s["sid"], s["n"]) for s in lf.mission_links] == [(7, 3)]  # the one subgroup of two or more
    s = lf.mission_links[0]
    assert s["relays"] == 1.0 and s["lambda2"] == pytest.approx(1.0)  # 1-2-3: one relay between 1 and 3
    conn: dict[str, Any] = {}
    lf.radio_report(conn)
    mission = conn["mission"]
    assert mission["rssi_dbm"]["mean"] == pytest.approx(-70.5) and mission["rssi_dbm"]["samples"] == 6
    assert mission["relays"]["mean"] == 1.0 and mission["partition_events"] == 0  # the five are one chain
    rssi[3, 4] = rssi[4, 3] = -90.0  # the chain breaks between 3 and 4: the ranger's scouts fall in two
    lf.on_radio_sample(1, list(range(n)), np.ones((n, n)))
    lf.radio_report(conn)
    assert conn["mission"]["partition_events"] == 1


def test_a_subgroup_that_recruited_another_rangers_scout_is_sampled_whole() -> None:
    # rangers 0 and 3; scouts 1 and 2 (ranger 0's) and 4 (ranger 3's) form subgroup 7, on a chain 1-2-4
    rssi = np.full((5, 5), -90.0)
    rssi[1, 2] = rssi[2, 1] = rssi[2, 4] = rssi[4, 2] = -70.0
    lf = _loop_functions(rssi, {0: None, 1: 0, 2: 0, 3: None, 4: 3})
    for robot in (1, 2, 4):
        lf.on_log(robot, "rdpso", {"sid": 7}, 0)
    lf.on_radio_sample(0, list(range(5)), np.ones((5, 5)))
    assert [(s["sid"], s["n"], s["relays"]) for s in lf.mission_links] == [(7, 3, 1.0)]


def test_the_mission_curve_counts_each_robot_from_its_own_start() -> None:
    from bridge.studies.rdpso.sessions import mission_curve

    logs = {1: [{"t": 10.2, "sid": 1, "ledger_h": 100.0}, {"t": 12.2, "sid": 1, "ledger_h": 300.0}],
            2: [{"t": 50.0, "sid": 2, "ledger_h": 200.0}, {"t": 51.0, "sid": 0, "ledger_h": 900.0},
                {"t": 53.5, "sid": 2, "ledger_h": 400.0}]}
    assert mission_curve(logs, 5) == [200.0, 200.0, 300.0, 400.0, 400.0]
    assert mission_curve(logs, 0) == []
