"""The pytest plugin and the driven session (bridge.testing): a test holds simulated time, sees the swarm, stops it;
a failing test's report says where the session stood; sessions run in parallel under ``pytest -n``."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest
from mcap.reader import make_reader

from bridge.core.config import ConfigError, load_config
from bridge.testing import SessionEnded, SimTimeout, SwarmSession

pytestmark = pytest.mark.session

ROOT = Path(__file__).resolve().parents[2]
WALK = ROOT / "hil_configs" / "demos" / "random_walk.toml"
DEMO = ROOT / "hil_configs" / "demo.toml"
SMALL = {"robots.count": 3, "session.robots_per_process": 3}


def test_the_test_holds_time_and_sees_the_swarm(tmp_path: Path) -> None:
    with SwarmSession(WALK, SMALL, tmp_path / "a") as s:
        assert s.t == 0.0 and s.robots == [0, 1, 2]
        start = s.pose(0)
        assert s.pose(0) == start  # held: nothing moves while the test looks
        assert s.run_for(1.5) == 1.5
        assert s.distance_m(0) > 0.0 and s.pose(0) != start
        assert s.alive(0) and 7.0 < s.battery_v(0) < 9.0
        t = s.run_until(lambda s: s.distance_m(1) > 0.4, timeout_s=30)
        assert s.distance_m(1) > 0.4 and 1.5 < t < 31.5
        with pytest.raises(SimTimeout, match="simulated time"):
            s.run_until(lambda s: False, timeout_s=0.5, every_s=0.1)
        assert s.t == pytest.approx(t + 0.5)
    assert s.code == 0 and s.summary["stop_reason"] == "service probe: the test stopped it"
    assert s.summary["sim_time_s"] == pytest.approx(s.t + 0.01)
    with open(s.recording, "rb") as f:  # finished and readable, with the stop as an event
        events = [json.loads(m.data) for _, ch, m in make_reader(f).iter_messages() if ch.topic == "/session/events"]
    assert events == [{"kind": "stopped", "service": "probe", "detail": "the test stopped it"}]


def test_the_same_seed_gives_the_same_swarm(tmp_path: Path) -> None:
    seen = []
    for i in range(2):
        with SwarmSession(WALK, {**SMALL, "session.seed": 11}, tmp_path / str(i)) as s:
            s.run_until(lambda s: s.distance_m(2) > 0.3, timeout_s=30, every_s=0.05)
            seen.append((s.t, [s.pose(r) for r in s.robots], [s.led(r) for r in s.robots]))
    assert seen[0] == seen[1]


def test_logs_arrive_as_the_robots_write_them(tmp_path: Path) -> None:
    with SwarmSession(DEMO, {"robots.count": 3, "session.robots_per_process": 3},
                      tmp_path) as s:
        assert s.logs() == []
        s.run_for(2.5)
        lines = s.logs(robot=1, topic="neighbours")
        assert lines and all(ln.robot == 1 and 0 < ln.t_s <= 2.5 for ln in lines)
        assert [ln.t_s for ln in s.logs()] == sorted(ln.t_s for ln in s.logs())
        radio = s.radio()
        assert radio["connectivity"]["samples"] >= 2 and radio["totals"]["tx"]["frames"] > 0
        assert radio["per_robot"][1]["uwb_raw"]["exchanges"] > 0
        report = s.describe()
        assert "at simulated t=2.500 s" in report and str(s.recording) in report and "robot 1, last" in report


def test_a_session_that_reaches_its_duration_ends(tmp_path: Path) -> None:
    with SwarmSession(WALK, {**SMALL, "session.duration_s": 1.0}, tmp_path) as s:
        with pytest.raises(SessionEnded, match="recording"):
            s.run_for(2.0)
        with pytest.raises(SessionEnded):
            s.run_for(0.1)
    assert s.summary["sim_time_s"] == 1.0 and s.summary["stop_reason"] is None


def test_a_wrong_override_is_refused_in_the_test(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"override robots\.4\.count"):
        SwarmSession(WALK, {"robots.4.count": 2}, tmp_path).start()


def test_the_probe_is_refused_outside_a_test(tmp_path: Path) -> None:
    from bridge.core.launcher import run_session

    res = run_session(str(WALK), {**SMALL, "services": [{"kind": "probe", "name": "probe"}]}, str(tmp_path),
                      progress=None, plot=False)
    assert res.code != 0
    assert "only a test drives" in (tmp_path / "logs" / "svc-probe.log").read_text()


PLUGIN_TESTS = """
    from pathlib import Path

    WALK = Path({walk!r})

    def test_walks(swarm_session):
        s = swarm_session(WALK, {{"robots.count": 2, "session.robots_per_process": 2}})
        s.run_until(lambda s: s.distance_m(0) > 0.2, timeout_s=20)
        assert s.alive(0)

    def test_fails(swarm_session):
        s = swarm_session(WALK, {{"robots.count": 2, "session.robots_per_process": 2}})
        s.run_for(1.0)
        assert s.pose(1)[0] > 1000, "robot 1 is not that far"
"""


def test_the_plugin_reports_where_a_failing_session_stood(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(textwrap.dedent(PLUGIN_TESTS.format(walk=str(WALK))))
    res = pytester.runpytest_subprocess("-p", "no:cacheprovider")
    res.assert_outcomes(passed=1, failed=1)
    out = res.stdout.str()
    assert "swarm-sitl session 0" in out and "at simulated t=1.000 s" in out
    assert "session.mcap" in out and "robot 1" in out


def test_the_plugin_runs_sessions_in_parallel(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(textwrap.dedent(PLUGIN_TESTS.format(walk=str(WALK))).replace("def test_fails",
                                                                                     "def _not_this_one"))
    pytester.makepyfile(test_more=textwrap.dedent(PLUGIN_TESTS.format(walk=str(WALK))).replace(
        "def test_fails", "def _not_this_one").replace("def test_walks", "def test_walks_too"))
    res = pytester.runpytest_subprocess("-n", "2", "-p", "no:cacheprovider")
    res.assert_outcomes(passed=2)


def test_every_fault_kind_is_injected_at_the_next_quantum(tmp_path: Path) -> None:
    with SwarmSession(WALK, {"robots.count": 4, "session.robots_per_process": 4}, tmp_path) as s:
        s.run_for(1.0)
        s.fault("firmware_crash", 1)
        s.fault("battery_depleted", 0)
        s.fault("can_bus_off", 2, node="host", duration_s=0.3)
        s.fault("can_noise", 3, probability=0.5, duration_s=0.3)
        assert all(s.alive(r) for r in s.robots)  # nothing happens before the world goes on
        s.run_for(0.01)  # at 1.01 the battery is empty; the firmware crashes in its run of that quantum
        assert [s.alive(r) for r in s.robots] == [False, True, True, True]
        s.run_for(0.01)
        assert [s.alive(r) for r in s.robots] == [False, False, True, True]
        kinds = {(e.values["kind"], e.values.get("robot")) for e in s.events() if e.t_s == 1.01}
        assert {("battery_depleted", 0), ("raised", 1)} <= kinds
        assert "robot 1's firmware crashed at 1.01 s" in next(e.values["detail"] for e in s.events()
                                                              if e.values["kind"] == "raised")
        s.run_for(0.5)
        assert ("can_bus_off", 2) in {(e.values["kind"], e.values.get("robot")) for e in s.events()}
        assert s.alive(2) and s.alive(3)
    counts = s.summary["message_counts"]
    assert counts["can_error_frames"] > 0 and "malformed_items" not in counts


def test_a_fault_the_session_cannot_carry_is_refused_in_the_test(tmp_path: Path) -> None:
    with SwarmSession(WALK, SMALL, tmp_path) as s:
        with pytest.raises(ConfigError, match="probability"):
            s.fault("can_noise", 1, probability=2.0)
        with pytest.raises(ConfigError, match="no robot 7"):
            s.fault("firmware_crash", 7)
        with pytest.raises(ConfigError, match="no slcan"):
            s.fault("can_bus_off", 1, node="slcan")
        with pytest.raises(ConfigError, match="duration_s"):
            s.fault("firmware_crash", 1, duration_s=1.0)
        with pytest.raises(ConfigError, match="no xbee module"):
            s.fault("unplugged", 0)
        s.run_for(0.1)
        assert all(s.alive(r) for r in s.robots)


def test_the_readme_example_passes(pytester: pytest.Pytester) -> None:
    text = (ROOT / "README.md").read_text()
    start = text.index("def test_robots_keep_away_from_walls")
    body = text[start:text.index("```", start)]
    pytester.makepyfile(body.replace('"hil_configs/', f'"{ROOT}/hil_configs/'))
    res = pytester.runpytest_subprocess("-p", "no:cacheprovider")
    res.assert_outcomes(passed=1)


def test_the_test_is_a_ground_station_in_the_lock_step(tmp_path: Path) -> None:
    from pymavlink.dialects.v20 import common as mavlink

    with SwarmSession(WALK, SMALL, tmp_path, mavlink=True) as s:
        g = s.mavlink
        s.run_for(1.0)
        assert g.last("HEARTBEAT", 0).custom_mode == 10  # AUTO: the behaviour runs
        g.mav.command_long_send(g.system_id(0), 1, mavlink.MAV_CMD_DO_SET_MODE, 0,
                                mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 15, 0, 0, 0, 0, 0)
        s.run_until(lambda s: g.last("COMMAND_ACK", 0) is not None, timeout_s=1.0)  # the face answers within 0.1 s
        assert g.last("COMMAND_ACK", 0).result == mavlink.MAV_RESULT_ACCEPTED and s.t <= 1.12
        x, y, _ = s.pose(0)
        gx, gy = min(max(x + 1.0, 1.0), 9.0), y
        g.mav.set_position_target_local_ned_send(0, g.system_id(0), 1, mavlink.MAV_FRAME_LOCAL_NED, 0b1101_1111_1100,
                                                 gy, gx, 0, 0, 0, 0, 0, 0, 0, 0, 0)  # north = arena y, east = x
        s.run_until(lambda s: abs(s.pose(0)[0] - gx) < 0.2 and abs(s.pose(0)[1] - gy) < 0.2, timeout_s=30)
        assert [m.text for m in g.messages("STATUSTEXT", 0)][-1].startswith("mode GUIDED")
        assert g.messages(robot=1) and not g.messages("COMMAND_ACK", 1)  # robot 1 heard nothing addressed to it
    with open(s.recording, "rb") as f:  # the test's packets are recorded as a UDP ground station's
        sent = [json.loads(m.data) for _, ch, m in make_reader(f).iter_messages() if ch.topic == "/mavlink/from_gcs"]
    assert [m["type"] for m in sent] == ["COMMAND_LONG", "SET_POSITION_TARGET_LOCAL_NED"]
    assert {m["robot"] for m in sent} == {0}


def test_a_session_without_faces_has_no_ground_station(tmp_path: Path) -> None:
    with SwarmSession(WALK, SMALL, tmp_path) as s, pytest.raises(RuntimeError, match="mavlink=True"):
        _ = s.mavlink


def test_an_unplugged_xbee_fails_only_its_robot(tmp_path: Path) -> None:
    with SwarmSession(DEMO, {"robots.count": 3, "session.robots_per_process": 3}, tmp_path) as s:
        s.run_for(2.0)
        s.fault("unplugged", 1, device="xbee")
        s.run_until(lambda s: not s.alive(1), timeout_s=5)
        assert s.t <= 2.1  # its program reads its XBee all the time: the next read raises
        failure = next(e.values for e in s.events() if e.values["kind"] == "raised")
        assert failure["robot"] == 1 and "device disconnected" in failure["detail"]
        sent = s.radio()["per_robot"][1]["radio"]["tx"]["frames"]
        s.run_for(5.0)
        assert s.alive(0) and s.alive(2) and s.radio()["per_robot"][1]["radio"]["tx"]["frames"] == sent


def test_an_unplugged_fault_from_the_config(tmp_path: Path) -> None:
    from bridge.core.launcher import run_session

    res = run_session(str(DEMO), {"robots.count": 3, "session.robots_per_process": 3, "session.duration_s": 3.0,
                                  "faults": [{"robot": 2, "at_s": 1.0, "kind": "unplugged"}]},
                      str(tmp_path), progress=None, plot=False)
    assert [(f["robot"], f["kind"], f["t_s"]) for f in res.summary["failures"]] == [(2, "raised", 1.0)]
    with pytest.raises(ConfigError, match=r"faults\[0\]\.device: robot 0 has no xbee module"):
        load_config(WALK, {"robots.count": 3, "faults": [{"robot": 0, "at_s": 1.0, "kind": "unplugged"}]})


def test_overrides_into_the_services_are_kept(tmp_path: Path) -> None:
    cam = ROOT / "hil_configs" / "demos" / "overhead_camera.toml"
    s = SwarmSession(cam, {"services.0.options.fps": 2}, tmp_path)
    cfg = load_config(cam, s.session_overrides())
    assert cfg.services[0].options["fps"] == 2 and [x.kind for x in cfg.services][-1] == "probe"
    s = SwarmSession(cam, {"services": []}, tmp_path)  # a whole list replaces the config's; the probe joins it
    assert [x.kind for x in load_config(cam, s.session_overrides()).services] == ["probe"]


def test_a_probe_that_dies_ends_the_session(tmp_path: Path) -> None:
    with SwarmSession(WALK, SMALL, tmp_path) as s:
        with pytest.raises(ValueError, match="seconds must lie"):
            s.run_for(1e11)
        with pytest.raises(SessionEnded):
            s._go(10**20)  # the probe's answer cannot be packed (beyond 64 bits): its thread dies
    assert "svc-probe, served by the launcher, stopped" in s.summary["stop_reason"]


def test_the_llc_state_is_its_pins_at_its_last_loop(tmp_path: Path) -> None:
    with SwarmSession(WALK, SMALL, tmp_path) as s:
        assert s.llc(0) == {}  # no loop yet at t = 0
        s.run_for(1.0)
        pins = s.llc(0)
        assert set(pins) >= {"enc", "sonar_m", "pwm", "led"} and pins["enc"][0] > 0
        assert list(pins["led"]) != [] and s.pins(0, "no_such_board") == {}
        s.run_for(1.0)
        assert s.llc(0)["enc"][0] > pins["enc"][0]  # the newest record, not the first
