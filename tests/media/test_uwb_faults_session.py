"""Faults on the UWB ranging in a session, as the robots' logic sees them (its logged ranges): a partition on
``medium = "uwb"`` cuts the ranges across its groups and not within; burst loss from the config loses ranging rounds,
counted; a module biased from the config gives ranges off by about its bias; a dead one gives none while the others
range on. Each fault's start and end are events."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.entities import uwb_addr16
from bridge.testing import SwarmSession

pytestmark = pytest.mark.session

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "hil_configs" / "demo.toml"  # eSwarBots with an XBee and a UWB module, logging their UWB ranges
BIAS_M = 1.0
FRESH_S = 1.6  # the logic logs the raw ranges of the last 1.5 s


def peers(s: SwarmSession, robot: int, t0: float, t1: float) -> set[int]:
    """The robots whose range ``robot``'s logic logged between ``t0`` and ``t1`` (s)."""
    robot_of = {uwb_addr16(r): r for r in s.robots}
    return {robot_of[a] for line in s.logs(robot, "uwb_ranges") if t0 <= line.t_s <= t1
            for a in line.values["peers"]}


def test_uwb_faults_cut_lose_bias_and_kill_ranges(tmp_path: Path) -> None:
    over = {"robots.count": 4, "session.robots_per_process": 4, "obstacles": [],  # every range in line of sight
            "faults": [{"kind": "sensor", "robot": 0, "at_s": 0.01, "sensor": "uwb", "mode": "bias", "bias": BIAS_M},
                       {"kind": "burst_loss", "at_s": 0.5, "medium": "uwb", "p_gb": 0.05, "p_bg": 0.5,
                        "robots": [3]}]}
    with SwarmSession(DEMO, over, tmp_path) as s:
        s.run_for(3.0)
        assert peers(s, 0, 3.0 - FRESH_S + 0.1, 3.0) == {1, 2, 3}
        s.fault("partition", groups=[[0, 1], [2, 3]], medium="uwb", duration_s=3.0)
        s.run_for(3.0)
        across = [(r, peers(s, r, 3.01 + FRESH_S, 6.0)) for r in range(4)]
        assert across == [(0, {1}), (1, {0}), (2, {3}), (3, {2})]  # within the groups only
        s.fault("sensor", 2, sensor="uwb", mode="dead")
        s.run_for(3.0)
        assert peers(s, 2, 6.01 + FRESH_S, 9.0) == set()  # it measures no range
        assert [peers(s, r, 6.01 + FRESH_S, 9.0) for r in (0, 1, 3)] == [{1, 3}, {0, 3}, {0, 1}]  # the rest range on
        radio = s.radio()
        events = {(e.values["kind"], e.values.get("robot"), round(e.t_s, 2)) for e in s.events()}
    assert {("sensor", 0, 0.01), ("burst_loss", None, 0.5), ("partition", None, 3.01), ("partition_end", None, 6.01),
            ("sensor", 2, 6.01)} <= events
    per = radio["per_robot"]
    # the biased module's own ranges are off by its bias (as the module measured them, as the logic logged them); a
    # peer's to it too (robot 1 ranges robot 0 all along, 2 and 3 not while partitioned), to the others not
    err0 = per[0]["uwb_logic_error"]["raw_los"]
    assert err0["n"] > 10 and err0["mean_m"] == pytest.approx(BIAS_M, abs=0.2)
    assert per[0]["uwb_raw"]["err_los"]["mean_m"] == pytest.approx(BIAS_M, abs=0.15)
    mean = [per[r]["uwb_logic_error"]["raw_los"]["mean_m"] for r in (1, 2, 3)]
    assert mean[0] > 0.3 and all(0.0 < m < err0["mean_m"] / 2 for m in mean[1:])
    raw = {r: per[r]["uwb_raw"] for r in range(4)}
    assert raw[0]["partitioned"] > 0 and raw[2]["sensor_dead"] + raw[0]["sensor_dead"] > 0
    assert raw[3]["burst_loss"] > 0 and raw[0]["burst_loss"] + raw[1]["burst_loss"] + raw[2]["burst_loss"] > 0
    faults = radio["uwb_faults"]
    # a round ends at its first lost frame (a frame a partition took may be a burst's loss too)
    assert faults["impairments"]["burst_lost"] >= sum(raw[r]["burst_loss"] for r in range(4))
    assert [(x["robot"], x["mode"]) for x in faults["sensors"]] == [(0, "bias"), (2, "dead")]
    assert faults["sensors"][0]["faulty_ranges"] > 10 and faults["sensors"][1]["failed"] > 0
