"""The Zebro's utility sensor in a session: the board on its serial line streams the cone's sum and the direction
of what it sees; a particle a robot stands on is eaten once, recorded on /world/consumptions, and the robot's
program learns it from ``consumed()``; a junk byte on the line is counted, not fatal."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bridge.core.recorder import iter_messages
from tests.core.test_session import run as session_run

pytestmark = pytest.mark.session

CFG = """
[session]
name = "zebro-utility"
duration_s = 2
seed = 4
[arena]
width_m = 10
length_m = 10
[[robots]]
profile = "decizebro"
count = 2
behaviour = "tests.support.zebro_utility_probe:Taster"
placement = { kind = "explicit", poses = [[2.0, 5.0, 0.0], [6.0, 5.0, 90.0]] }
[[particles]]
x = 2.5
y = 5.2
utility = 95
[[particles]]
x = 2.6
y = 4.8
utility = 15
[[particles]]
x = 6.05
y = 5.0
utility = 40
"""


def test_the_utility_sensor_reads_the_cone_and_reports_meals(tmp_path: Path) -> None:
    cfg = tmp_path / "u.toml"
    cfg.write_text(CFG)
    out = tmp_path / "run"
    code, s = session_run(cfg, out, timeout=900)
    assert code == 0, s.get("error")
    logs = {r: [json.loads(d) for topic, _t, d in iter_messages(out / "session.mcap")
                if topic == f"/r{r:03d}/log/taste"] for r in (0, 1)}
    meals = [json.loads(d) for topic, _t, d in iter_messages(out / "session.mcap") if topic == "/world/consumptions"]
    assert meals == [{"robot": 1, "particle": 2, "utility": 40}]  # robot 1 stands on it; robot 0's are ahead
    seen = [rec for rec in logs[0] if rec["utility"]]
    assert seen and all(rec["utility"] == 110 for rec in seen)  # the two ahead of robot 0, summed
    assert all(rec["bearing"] is not None and abs(rec["bearing"]) < 0.52 for rec in seen)  # within +-30 degrees
    assert sum(rec["ate"] for rec in logs[1]) == 40 and sum(rec["ate"] for rec in logs[0]) == 0
    assert s["particles"]["consumed"][0]["robot"] == 1 and s["particles"]["left"] == [0, 1]
    assert all(rr["firmware"]["utility"]["reports"] >= 15 for rr in s["per_robot"])  # 10 Hz for 2 s
