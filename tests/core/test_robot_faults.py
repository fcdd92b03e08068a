"""The faults a robot lives through (bridge.core.faults): each has its effect in a session, is an event at its start
and end and a row of summary.json's ``faults``, and the rest of the swarm goes on; the same seed gives the same
faulty run."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from bridge.core.config import ConfigError, FaultCfg, load_config
from bridge.core.faults import SensorFault
from bridge.core.launcher import run_session
from bridge.core.plan import make_plan
from bridge.core.recorder import iter_messages
from bridge.hosts.firmware import BoardFaults
from bridge.testing import SwarmSession

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "hil_configs" / "demo.toml"
FOUR = {"robots.count": 4, "session.robots_per_process": 4}


# -- units -------------------------------------------------------------------------------------------------------
def test_a_sensor_fault_sticks_adds_noise_dies_or_biases_only_while_it_lasts() -> None:
    stuck = SensorFault("sonar", "stuck", 10, 20)
    assert [stuck.apply(v, t) for v, t in ((1.0, 5), (2.0, 10), (3.0, 15), (4.0, 20))] == [1.0, 2.0, 2.0, 4.0]
    dead = SensorFault("light", "dead", 0, None)
    assert dead.apply(120.0, 3) == 0.0
    biased = SensorFault("sonar", "bias", 0, None, bias=0.25)
    assert biased.apply(np.array([1.0, 2.0]), 1).tolist() == [1.25, 2.25]
    noisy = SensorFault("sonar", "noisy", 0, None, sigma=0.1, rng=np.random.default_rng(1))
    again = SensorFault("sonar", "noisy", 0, None, sigma=0.1, rng=np.random.default_rng(1))
    draws = [noisy.apply(2.0, t) for t in range(200)]
    assert draws == [again.apply(2.0, t) for t in range(200)]  # seeded
    assert 0.07 < float(np.std(draws)) < 0.13 and abs(float(np.mean(draws)) - 2.0) < 0.03
    # an encoder that stops counting loses the pulses it missed, for good
    enc = SensorFault("encoder", "dead", 10, 20)
    assert [enc.apply(c, t) for c, t in (((5, 5), 5), ((8, 9), 10), ((30, 40), 15), ((50, 60), 20), ((51, 61), 25))] \
        == [(5, 5), (8, 9), (8, 9), (8, 9), (9, 10)]


def test_a_board_clock_that_drifts_maps_both_ways_and_a_reset_holds_it() -> None:
    bf = BoardFaults()
    bf.add({"kind": "drift", "at": 1_000_000_000, "until": 3_000_000_000, "ppm": 50_000.0})
    assert bf.local_ns(500_000_000) == 500_000_000
    assert bf.local_ns(2_000_000_000) == 2_050_000_000  # 5 % fast for the second it has drifted
    assert bf.local_ns(4_000_000_000) == 4_100_000_000  # the 0.1 s it gained in its 2 s stays
    for local in (2_050_000_000, 2_050_000_001, 4_100_000_000, 777):
        t = bf.world_ns(local)
        assert bf.local_ns(t) >= local > bf.local_ns(t - 1)
    bf.add({"kind": "reboot", "at": 10, "up": 50})
    assert not bf.reset_due(9) and bf.reset_due(12) and bf.in_reset(49) and not bf.in_reset(50)
    assert bf.counters["reboots"] == 1


def test_fault_fields_are_checked_against_the_kind_and_the_robot() -> None:
    with pytest.raises(ValueError, match="duration_s: a freeze needs it"):
        FaultCfg.model_validate({"kind": "freeze", "robot": 0, "at_s": 1})
    with pytest.raises(ValueError, match="sigma: a noisy sensor needs it"):
        FaultCfg.model_validate({"kind": "sensor", "robot": 0, "at_s": 1, "sensor": "sonar", "mode": "noisy"})
    with pytest.raises(ValueError, match="ppm do"):
        FaultCfg.model_validate({"kind": "motor_stall", "robot": 0, "at_s": 1, "ppm": 3})
    with pytest.raises(ValueError, match="hung_after_s"):
        FaultCfg.model_validate({"kind": "freeze", "robot": 0, "at_s": 1, "duration_s": 2, "hung_after_s": 2})
    cfg = load_config(DEMO, {**FOUR, "faults": [{"kind": "firmware_reboot", "robot": 1, "at_s": 1,
                                                 "board": "leg1"}]})
    with pytest.raises(ConfigError, match=r"faults\[0\]\.board: robot 1 has no leg1 board \(its boards: llc\)"):
        make_plan(cfg, "demo.toml")


# -- sessions ------------------------------------------------------------------------------------------------------
@pytest.mark.session
def test_each_fault_a_robot_lives_through_has_its_effect_and_the_swarm_goes_on(tmp_path: Path) -> None:
    with SwarmSession(DEMO, FOUR, tmp_path) as s:
        s.run_for(1.0)
        s.fault("freeze", 0, duration_s=2.0)  # its logic stops: the LLC's watchdog stops the motors
        s.fault("firmware_reboot", 1)  # its LLC in reset for 1 s, then setup() again
        s.fault("sensor", 2, sensor="sonar", mode="stuck", duration_s=3.0)
        s.fault("motor_stall", 3, wheel="left", duration_s=2.0)
        s.run_for(0.5)
        sonar = s.pins(2)["sonar_m"]
        left = s.pins(3)["enc"][0]
        assert s.pins(1)["pwm"] == [0, 0]  # a board in reset drives nothing
        s.run_for(1.0)
        assert s.pins(2)["sonar_m"] == sonar and s.pins(3)["enc"][0] == left  # stuck, stalled
        assert s.pins(1)["pwm"] != [0, 0]  # rebooted, driving again
        s.run_for(2.0)
        assert s.pins(2)["sonar_m"] != sonar and s.pins(3)["enc"][0] != left  # both over
        s.fault("brown_out", 0, sag_v=3.0, duration_s=0.2)  # below the 6 V its boards need: they reset
        s.fault("brown_out", 2, sag_v=0.1, duration_s=0.2)  # a dip its boards ride through
        s.run_for(0.1)
        assert s.pins(0)["pwm"] == [0, 0]
        s.run_for(2.0)
        assert s.pins(0)["pwm"] != [0, 0] and all(s.alive(r) for r in range(4))
        events = [(e.values["kind"], e.values.get("robot"), round(e.t_s, 2)) for e in s.events()
                  if e.values["kind"] != "fault_injected"]
        summary = s.stop()
    assert events == [("freeze", 0, 1.01), ("firmware_reboot", 1, 1.01), ("sensor", 2, 1.01),
                      ("motor_stall", 3, 1.01), ("firmware_reboot_end", 1, 2.01), ("motor_stall_end", 3, 3.01),
                      ("freeze_end", 0, 3.01), ("sensor_end", 2, 4.01), ("brown_out", 0, 4.51),
                      ("brown_out", 2, 4.51), ("brown_out_end", 0, 4.71), ("brown_out_end", 2, 4.71),
                      ("firmware_reboot_end", 0, 5.71)]
    faults = summary["faults"]
    assert faults["count"] == {"freeze": 1, "firmware_reboot": 1, "sensor": 1, "motor_stall": 1, "brown_out": 2}
    rows = {(f["kind"], f["robot"]): f for f in faults["list"]}
    assert rows["freeze", 0]["queued_on_resume"] > 0 and rows["sensor", 2]["faulty_readings"] > 10
    assert rows["brown_out", 0]["reset"] is True and rows["brown_out", 2]["reset"] is False
    assert summary["exit_code"] == 0 and not summary["failures"]


@pytest.mark.session
def test_faults_from_the_config_are_seeded_a_hung_freeze_kills_and_a_drifting_clock_runs_fast(tmp_path: Path) -> None:
    faults = [
        {"kind": "freeze", "robot": 0, "at_s": 1.0, "duration_s": 3.0, "hung_after_s": 1.5},
        {"kind": "clock_drift", "robot": 1, "at_s": 1.0, "ppm": 100_000},  # 10 % fast from 1 s on
        {"kind": "sensor", "robot": 2, "at_s": 1.0, "sensor": "sonar", "mode": "noisy", "sigma": 0.3},
        {"kind": "sensor", "robot": 3, "at_s": 1.0, "sensor": "light", "mode": "dead", "duration_s": 2.0},
        {"kind": "wheel_slip", "robot": 3, "at_s": 1.0, "wheel": "both", "slip": 0.9, "duration_s": 4.0},
    ]
    over = {**FOUR, "session.duration_s": 6.0, "faults": faults}
    a = run_session(str(DEMO), over, str(tmp_path / "a"), progress=None, plot=False)
    b = run_session(str(DEMO), over, str(tmp_path / "b"), progress=None, plot=False)
    assert a.summary["digest"] == b.summary["digest"] and a.summary["faults"] == b.summary["faults"]
    fails = a.summary["failures"]
    assert [(f["robot"], f["kind"], f["t_s"]) for f in fails] == [(0, "hung", 2.5)]
    assert "declared hung" in fails[0]["detail"]
    # the LLC's loop runs 10 % more often in world time once its clock drifts; a light sensor reads 0 while dead;
    # a wheel that slips 90 % turns as much but moves the robot a tenth as far
    loops = {1: 0, 2: 0}
    lux3, enc3, pose3 = [], [], []
    for topic, t, data in iter_messages(tmp_path / "a" / "session.mcap"):
        if topic in ("/r001/llc/pins", "/r002/llc/pins") and 2e9 <= t < 6e9:
            loops[int(topic[2:5])] += 1
        elif topic == "/r003/llc/pins":
            msg = json.loads(data)
            lux3.append((t, msg["lux"]))
            enc3.append((t, msg["enc"]))
        elif topic == "/world/poses":
            msg = json.loads(data)
            pose3.append((t, msg["x"][3], msg["y"][3]))
    assert 1.07 < loops[1] / loops[2] < 1.13
    assert all(v == 0.0 for t, v in lux3 if 1.02e9 <= t < 2.99e9) and all(v > 0 for t, v in lux3 if t >= 3.02e9)

    def moved(t0: float, t1: float) -> tuple[float, float]:
        """(metres the robot moved, pulses its encoders counted) from t0 to t1 (s)."""
        p = [(x, y) for t, x, y in pose3 if t0 * 1e9 <= t <= t1 * 1e9]
        e = [c for t, c in enc3 if t0 * 1e9 <= t <= t1 * 1e9]
        dist = sum(float(np.hypot(x1 - x0, y1 - y0)) for (x0, y0), (x1, y1) in itertools.pairwise(p))
        return dist, float(abs(e[-1][0] - e[0][0]) + abs(e[-1][1] - e[0][1]))

    slipping, grip = moved(1.5, 4.5), moved(5.1, 6.0)
    assert slipping[1] > 0 and grip[1] > 0
    assert slipping[0] / slipping[1] < 0.3 * grip[0] / grip[1]
    rows = {(f["kind"], f["robot"]): f for f in a.summary["faults"]["list"]}
    assert rows["freeze", 0]["declared_hung"] is True and rows["sensor", 2]["faulty_readings"] > 50
