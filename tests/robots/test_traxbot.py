"""TraxBot rangers: the profile (tracked, three sonars, a conveyor of five scouts), scouts carried on board and
released one by one as the conveyor turns, in the world and in a session."""

from __future__ import annotations

import itertools
import json
import math
import subprocess
from pathlib import Path

import pytest

from bridge.core.config import ConfigError, load_config
from bridge.core.plan import make_plan
from bridge.core.recorder import iter_messages
from tests.conftest import ROOT
from tests.core.test_session import cli

RANGER = """[session]
duration_s = {duration}
seed = 4
[arena]
width_m = 5
length_m = 8
[[robots]]
profile = "traxbot"
count = {rangers}
behaviour = "tests.support.ranger_probe:Unloader"
placement = {{ kind = "explicit", poses = {poses} }}
[[robots]]
count = {scouts}
behaviour = "random_walk"
carried_by = 0
"""


# the sessions pack three robots a process (the ranger with scouts 1-2, scouts 3-5 in another): the same recording as
# one robot a process (packing never changes a session's digest), the ranger still reaching scouts in another process
PACKED = ("--robots-per-process", "3")


def ranger_config(tmp_path: Path, duration: float = 20, rangers: int = 1, scouts: int = 5) -> Path:
    poses = [[2.0, 1.5 + 3.0 * i, 90.0] for i in range(rangers)]
    p = tmp_path / "rangers.toml"
    p.write_text(RANGER.format(duration=duration, rangers=rangers, scouts=scouts, poses=poses))
    return p


def test_scouts_are_loaded_ranger_by_ranger(tmp_path: Path) -> None:
    plan = make_plan(load_config(ranger_config(tmp_path, rangers=2, scouts=7)))
    scouts = plan.robots[2:]
    assert [(r.carrier, r.slot) for r in scouts] == [(0, 1), (0, 2), (0, 3), (0, 4), (0, 5), (1, 1), (1, 2)]
    assert all(r.pose == plan.robots[r.carrier].pose for r in scouts)


@pytest.mark.parametrize(("edit", "match"), [
    (lambda t: t.replace("count = 5\n", "count = 6\n"), r"robots\[1\].count: robots\[0\] carries at most 1 x 5"),
    (lambda t: t.replace("carried_by = 0", "carried_by = 1"), r"robots\[1\].carried_by = 1: not another robot group"),
    (lambda t: t.replace('profile = "traxbot"', 'profile = "eswarbot"'), r"robots\[0\] \(eswarbot\) has no conveyor"),
    (lambda t: t + 'placement = { kind = "random" }\n', "carried robots start on board"),
])
def test_carrying_is_checked(tmp_path: Path, edit, match: str) -> None:
    p = ranger_config(tmp_path)
    p.write_text(edit(p.read_text()))
    with pytest.raises(ConfigError, match=match):
        load_config(p)


@pytest.mark.session
def test_a_ranger_unloads_its_scouts_one_by_one(tmp_path: Path) -> None:
    """The ranger asks for 2 slots at 1 s and 3 more at 8 s; the belt (0.15 m a slot at 0.05 m/s) drops a scout
    every 3 s behind the ranger, which keeps driving; on board the scouts ride along, then each drives off."""
    cfg = ranger_config(tmp_path)
    r = subprocess.run(cli("run", str(cfg), "--out", str(tmp_path / "run"), *PACKED), cwd=ROOT, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    rel = s["releases"]
    assert [e["robot"] for e in rel] == [1, 2, 3, 4, 5] and [e["slot"] for e in rel] == [1, 2, 3, 4, 5]
    times = [e["t_s"] for e in rel]
    assert times[0] == pytest.approx(4.0, abs=0.2) and times[1] == pytest.approx(7.0, abs=0.2)
    assert times[2] == pytest.approx(11.0, abs=0.3)  # the second request starts after the first is done
    assert all(b - a == pytest.approx(3.0, abs=0.2) for a, b in itertools.pairwise(times[2:]))
    poses, releases = [], []
    for topic, t, payload in iter_messages(tmp_path / "run" / "session.mcap"):
        if topic == "/world/poses":
            poses.append((t, json.loads(payload)))
        elif topic == "/world/releases":
            releases.append(json.loads(payload))
    assert releases == [{k: e[k] for k in ("robot", "carrier", "slot", "pose")} for e in rel]
    # on board until released, each where the ranger was, then behind it (the ranger drives along +y)
    at = {round(t / 1e9, 2): p for t, p in poses}
    before = at[3.5]
    assert before["carried"] == [False, True, True, True, True, True]
    assert math.hypot(before["x"][1] - before["x"][0], before["y"][1] - before["y"][0]) < 1e-3
    for e in rel:
        _, y, yaw = e["pose"]
        assert yaw == pytest.approx(math.pi / 2, abs=0.05)
        ranger_y = next(p["y"][0] for t, p in poses if t / 1e9 >= e["t_s"])
        assert ranger_y - y == pytest.approx(0.11 + 0.063 + 0.02, abs=0.03)
    end = s["per_robot"]
    assert all(r["on_board"] is None for r in end) and end[0]["profile"] == "traxbot"
    assert all(r["distance_m"] > 0.05 for r in end[1:4])  # released early, they drove off on their own
    logs = [json.loads(p) for topic, _t, p in iter_messages(tmp_path / "run" / "session.mcap")
            if topic == "/r000/log/ranger"]
    assert logs[-1]["position"] == 5 and logs[-1]["pending"] == 0
    assert any(entry["left"] is not None and entry["right"] is not None for entry in logs)  # side walls


@pytest.mark.session
def test_a_dead_ranger_keeps_its_scouts_on_board(tmp_path: Path) -> None:
    cfg = ranger_config(tmp_path, duration=10)
    cfg.write_text(cfg.read_text() + "[[faults]]\nrobot = 0\nat_s = 5.0\n")
    r = subprocess.run(cli("run", str(cfg), "--out", str(tmp_path / "run"), *PACKED), cwd=ROOT, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert [e["robot"] for e in s["releases"]] == [1]  # one dropped at 4 s, then the ranger died
    assert [r["on_board"] for r in s["per_robot"]] == [None, None, 0, 0, 0, 0]


def test_deployment_messages_round_trip_and_refuse_garbage() -> None:
    from swarm_logic.families.rdpso.est import BEACON, POSE, START, Msg, decode, encode

    for m in (Msg(POSE, 2, 7, 1.5, -2.25, 0.5), Msg(BEACON, 2, 7, 1.5, -2.25), Msg(START, 2, hops=3)):
        assert decode(encode(m)) == m
    assert decode(b"") is None and decode(b"R\x01") is None  # another protocol's frame
    assert decode(encode(Msg(POSE, 2, 7, 1.0, 2.0, 0.0))[:-1]) is None  # cut short
    assert decode(b"D\x09\x00\x00") is None  # unknown type
    nan = encode(Msg(BEACON, 2, 7, float("nan"), 0.0))
    assert decode(nan) is None


EST = RANGER.replace('behaviour = "tests.support.ranger_probe:Unloader"', 'behaviour = "est_ranger"\n'
                     'xbee = {{ series = 2, baud = 115200 }}\nparams = {{ q_min_dbm = -70.0, mode = "{mode}" }}')
EST = EST.replace('behaviour = "random_walk"\ncarried_by = 0', 'behaviour = "rdpso"\ncarried_by = 0\n'
                  'xbee = {{ series = 2, baud = 115200 }}\nparams = {{ deployed = true, first_id = 1, n_total = 5, '
                  'subgroups_init = 1, subgroups_max = 1, link_mode = "rssi", q_min_dbm = -70.0 }}')


@pytest.mark.long
@pytest.mark.session
def test_a_ranger_deploys_its_subgroup_along_the_spiral_and_starts_it(tmp_path: Path) -> None:
    """Algorithm 5.1 end to end: the ranger drops its 5 scouts one by one, each told its pose (the ranger's
    dead reckoning), each beaconing; then START, which every scout relays before its first RDPSO iteration."""
    cfg = tmp_path / "est.toml"
    # (the last scout lands at 70.7 s, START at 71.4 s, the first RDPSO iterations at 72.3 s: 80 s leaves room)
    cfg.write_text(EST.format(duration=80, rangers=1, scouts=5, poses=[[5.0, 7.0, 90.0]], mode="est")
                   .replace("width_m = 5", "width_m = 10").replace("length_m = 8", "length_m = 14"))
    r = subprocess.run(cli("run", str(cfg), "--out", str(tmp_path / "run"), *PACKED), cwd=ROOT, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    dep = s["deployment"]
    assert dep["done"] == 1 and dep["left_on_board"] == [] and len(s["releases"]) == 5
    assert dep["rangers"]["0"]["dispersion_m"] > 0.3 and dep["covered_share"] > 0.05
    logs: dict[int, list[dict]] = {}
    first_iteration: dict[int, float] = {}
    for topic, t, payload in iter_messages(tmp_path / "run" / "session.mcap"):
        if topic.endswith("/log/deployment"):
            logs.setdefault(int(topic[2:5]), []).append({**json.loads(payload), "t": t / 1e9})
        elif topic.endswith("/log/rdpso"):
            first_iteration.setdefault(int(topic[2:5]), t / 1e9)
    true = {e["robot"]: e["pose"] for e in s["releases"]}
    start_t = next(e["t"] for e in logs[0] if e["event"] == "done")
    errors = []
    for scout in range(1, 6):
        landed = next(e for e in logs[scout] if e["event"] == "landed")
        errors.append(math.hypot(landed["x"] - true[scout][0], landed["y"] - true[scout][1]))
        started = next(e for e in logs[scout] if e["event"] == "start")
        assert started["t"] <= start_t and first_iteration[scout] > started["t"]  # no iteration before START
    # the pose a scout is told is the ranger's dead reckoning, which drifts as it bumps walls: off, not lost
    assert errors[0] < 0.3 and sorted(errors)[2] < 1.0 and max(errors) < 2.0, errors
    dropped = [e for e in logs[0] if e["event"] == "dropped"]
    assert [e["scout"] for e in dropped] == [1, 2, 3, 4, 5]


@pytest.mark.long
@pytest.mark.session
def test_the_random_baseline_drops_each_scout_within_d_max_of_the_last(tmp_path: Path) -> None:
    cfg = tmp_path / "random.toml"
    # the session ends 1 s after the ranger's START (the last drop came at 62.3 s of the 100 s cap)
    cfg.write_text(EST.format(duration=100, rangers=1, scouts=5, poses=[[5.0, 7.0, 90.0]], mode="random")
                   .replace("seed = 4", "seed = 4\nend_after_deployment = true")
                   .replace("width_m = 5", "width_m = 10").replace("length_m = 8", "length_m = 14")
                   .replace('mode = "random" }', 'mode = "random", d_max_m = 2.0 }'))
    r = subprocess.run(cli("run", str(cfg), "--out", str(tmp_path / "run"), *PACKED), cwd=ROOT, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert s["deployment"]["done"] == 1 and len(s["releases"]) == 5
    drops = [json.loads(p) for topic, _t, p in iter_messages(tmp_path / "run" / "session.mcap")
             if topic == "/r000/log/deployment" and json.loads(p)["event"] == "dropped"]
    gaps = [math.hypot(b["x"] - a["x"], b["y"] - a["y"]) for a, b in itertools.pairwise(drops)]
    # where the ranger believed it dropped them: each within d_max (+ reach) of the last, never on top of it
    assert len(gaps) == 4 and all(0.4 - 1e-6 <= g <= 2.0 + 0.15 + 0.05 for g in gaps), gaps
    # the ranger steers the landing spot behind it onto each point: every leg after the first ends there
    assert [d["why"] for d in drops] == ["first_leg"] + ["reached"] * 4, drops
    assert all(math.hypot(d["x"] - d["target"][0], d["y"] - d["target"][1]) <= 0.15 for d in drops[1:])


def test_the_conveyor_command_is_checked_and_advances_whole_slots() -> None:
    """On the TraxBot's LLC: CONVEYOR_CMD with 0 slots is a bad frame; 2 slots advance the belt 2 pitches at the
    belt's speed, reported in CONVEYOR_STATUS; the stepper's steps are what the world sees."""
    from bridge.robots.eswarbot.board import llc_params
    from bridge.robots.traxbot import TRAXBOT
    from firmware_sim.board.arduino import Board
    from firmware_sim.board.can_controller import Frame
    from firmware_sim.robots.eswarbot.llc import LowLevelController
    from swarm_logic.robots.eswarbot import eswarbot_llc_db

    db = eswarbot_llc_db()
    cmd = db.get_message_by_name("CONVEYOR_CMD")
    board = Board()
    llc = LowLevelController(board, llc_params(TRAXBOT))
    llc.setup()
    board.can.on_bus_frame(Frame(cmd.frame_id, bytes([0, 1])))  # 0 slots: outside the DBC's range
    board.can.on_bus_frame(Frame(cmd.frame_id, cmd.encode({"slots": 2, "seq": 2})))
    status = []
    for _ in range(400):  # 8 s at 50 Hz: 2 x 0.15 m at 0.05 m/s takes 6 s
        board.time_us += 20_000
        llc.loop()
        status += [db.decode_message(f.arbitration_id, f.data) for f in board.can.take_tx()
                   if f.arbitration_id == db.get_message_by_name("CONVEYOR_STATUS").frame_id]
    assert llc.rx_bad == 1
    assert board.stepper_steps == round(2 * 150 / 0.5)
    assert status[-1] == {"seq": 2, "moving": 0, "position_slots": 2, "pending_slots": 0}
    assert any(s["position_slots"] == 1 and s["moving"] for s in status)


def test_the_deployment_area_keeps_the_rangers_points_inside() -> None:
    from swarm_logic.families.rdpso.est import EstRanger

    with pytest.raises(ValueError, match="area_m"):
        EstRanger.resolve({"area_m": [0, 0, 10]})
    with pytest.raises(ValueError, match="area_m"):
        EstRanger.resolve({"area_m": [0, 0, 0.5, 20], "area_margin_m": 0.4})
    with pytest.raises(ValueError, match="d_max_m: must exceed min_leg_m"):
        EstRanger.resolve({"mode": "random", "d_max_m": 0.3})
    with pytest.raises(ValueError, match="max_leg_s"):
        EstRanger.resolve({"max_leg_s": 0})
    ranger = EstRanger()
    ranger.p = EstRanger.resolve({"area_m": [0.0, 0.0, 10.0, 20.0]})
    assert ranger._clip((-3.0, 25.0)) == (0.4, 19.6)
    assert ranger._clip((5.0, 5.0)) == (5.0, 5.0)
    assert ranger._inside((5.0, 5.0)) and not ranger._inside((9.9, 5.0))
    ranger.p = EstRanger.resolve({})
    assert ranger._clip((-3.0, 25.0)) == (-3.0, 25.0)  # no area: unbounded
