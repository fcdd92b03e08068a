"""The radios' glue: the RSSI PWM path to the LLC's CAN bus, serial lines, the sitl:// port, configs, the hub's
routing of radio items, and the survey's bookkeeping."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
import serial

from bridge.core.config import Config, ConfigError, load_config, to_toml
from bridge.core.entities import entity, xbee_serial64
from bridge.core.hub import Hub
from bridge.core.plan import make_plan
from bridge.media.uart import SerialLine
from bridge.tools.radio_survey import calibration, survey_config
from firmware_sim.board.arduino import Board
from firmware_sim.modules.xbee import rssi_dbm_from_pwm, rssi_pwm_formula
from firmware_sim.robots.eswarbot.llc import PIN_RSSI, RSSI_PWM_HZ, LlcParams, LowLevelController
from swarm_logic.robots.eswarbot import eswarbot_llc_db

DB = eswarbot_llc_db()
RADIO_RSSI = DB.get_message_by_name("RADIO_RSSI")
Q = 10_000_000


@pytest.mark.parametrize("dbm", [-94, -85, -75, -72, -60])
def test_pwm_duty_of_the_module_reads_back_as_dbm(dbm: int) -> None:
    """Eq. 3.9 forward in the XBee, inverse in the LLC: the same dBm within the pulse timer's resolution."""
    duty = rssi_pwm_formula(dbm, -94.0)
    assert rssi_dbm_from_pwm(duty, -94.0) == pytest.approx(dbm, abs=1e-9)
    b = Board()
    b.pwm_inputs[PIN_RSSI] = (duty, RSSI_PWM_HZ)
    high = b.pulse_in(PIN_RSSI)
    assert high % 4 == 0 and abs(high - duty / RSSI_PWM_HZ * 1e6) < 4
    assert rssi_dbm_from_pwm(high * RSSI_PWM_HZ / 1e6, -94.0) == pytest.approx(dbm, abs=0.2)


def test_thesis_duty_values() -> None:
    """Couceiro (2013) section 3.2.3: -94 dBm is about 28.8 % duty, -75 dBm about 61.3 %."""
    assert rssi_pwm_formula(-94, -94) == pytest.approx(0.288, abs=0.001)
    assert rssi_pwm_formula(-75, -94) == pytest.approx(0.613, abs=0.001)
    assert rssi_pwm_formula(-40, -94) == 1.0


def _llc_rssi_frames(duties: list[tuple[float, float]]) -> list[dict]:
    """Run the LLC with its RSSI pin fed ``(duty, seconds)`` in turn; the RADIO_RSSI frames it sent."""
    b = Board()
    llc = LowLevelController(b, LlcParams(loop_hz=50, rssi_pwm_input=True))
    llc.setup()
    out = []
    for duty, seconds in duties:
        b.pwm_inputs[PIN_RSSI] = (duty, RSSI_PWM_HZ)
        for _ in range(round(seconds * 50)):
            llc.loop()
            for f in b.can.take_tx():
                if f.arbitration_id == RADIO_RSSI.frame_id:
                    out.append({**RADIO_RSSI.decode(f.data), "t": b.time_us / 1e6})
            b.time_us += 20_000
    return out


def test_llc_reports_rssi_on_change_and_once_a_second() -> None:
    frames = _llc_rssi_frames([(0.0, 2.0), (rssi_pwm_formula(-75, -94), 3.0), (0.0, 1.0)])
    assert frames[0]["valid"] == 0
    on = [f for f in frames if f["valid"]]
    assert on and all(f["rssi_dbm"] == -75 for f in on)
    assert 1.5 <= on[0]["t"] <= 2.2  # seen within a sampling period of the change
    assert 3 <= len(on) <= 4  # then kept alive at 1 Hz, not repeated at 10 Hz
    assert frames[-1]["valid"] == 0 and frames[-1]["t"] >= 5.0  # the output going off is reported too


def test_llc_without_a_radio_sends_no_rssi() -> None:
    b = Board()
    llc = LowLevelController(b, LlcParams(loop_hz=50))
    llc.setup()
    for _ in range(100):
        llc.loop()
        assert all(f.arbitration_id != RADIO_RSSI.frame_id for f in b.can.take_tx())
        b.time_us += 20_000


def test_serial_line_paces_bytes_at_the_senders_baud() -> None:
    line = SerialLine(9600)
    line.offer(0, bytes(range(100)), 9600)  # 100 bytes x 10 bits at 9600 bit/s: 104.2 ms
    got = b""
    for t in range(Q, 130 * 1_000_000, Q):
        got += line.arrived(t)
        if t == 50 * 1_000_000:
            assert len(got) == 48  # 50 ms / 1.0417 ms a byte
    assert got == bytes(range(100)) and not line.pending
    line.offer(200 * 1_000_000, b"ab", 9600)
    line.offer(200 * 1_000_000, b"cd", 9600)  # queues behind the first chunk
    assert line.arrived(202 * 1_000_000) == b"a" and line.arrived(210 * 1_000_000) == b"bcd"


def test_serial_line_garbles_at_the_wrong_baud() -> None:
    line = SerialLine(115200)
    line.offer(0, b"\x7e\x00\x04", 9600)
    got = line.arrived(Q)
    assert len(got) == 3 and got != b"\x7e\x00\x04" and line.garbled == 3


def test_sitl_url_outside_a_session_is_a_clear_error() -> None:
    from bridge import sitl as urlhandler

    urlhandler.register()
    with pytest.raises(serial.SerialException, match="no SITL robot in this thread"):
        serial.serial_for_url("sitl://xbee", baudrate=9600)
    with pytest.raises(serial.SerialException, match=r"expected sitl://DEVICE with DEVICE one of xbee, uwb, mavlink, "
                                                     r".*uwb_radio"):  # a robot model's own port is named too
        serial.serial_for_url("sitl://gps", baudrate=9600)
    with pytest.raises(serial.SerialException, match="no SITL robot in this thread"):  # a model's port is known
        serial.serial_for_url("sitl://uwb_radio", baudrate=115200)


def test_xbee_config_errors_name_the_field(tmp_path: Path) -> None:
    p = tmp_path / "bad.toml"
    p.write_text('[[robots]]\ncount = 2\nxbee = { baud = 14400 }\n')
    with pytest.raises(ConfigError, match=r"bad.toml: robots\[0\]\.xbee\.baud: .*14400 is not an XBee BD rate"):
        load_config(p)
    p.write_text('[[robots]]\ncount = 2\nxbee = { pty = "x" }\n')
    with pytest.raises(ConfigError, match=r"robots\[0\]: .*'\{id\}'"):
        load_config(p)
    p.write_text('[[robots]]\ncount = 1\n[radio]\npath_loss_exponent = -1\n')
    with pytest.raises(ConfigError, match=r"radio\.path_loss_exponent"):
        load_config(p)


@pytest.fixture
def radio_hub(tmp_path: Path) -> Hub:
    cfg = Config.model_validate({"robots": [{"count": 3, "xbee": {"series": 2}, "uwb": True}]})
    h = Hub(make_plan(cfg), str(tmp_path), str(tmp_path), "test")
    yield h
    h.rec.finish()
    h.world.close()


def test_plan_places_modules_in_the_firmware_process(radio_hub: Hub) -> None:
    assert radio_hub.proc_of[entity(1, "xbee")] == radio_hub.proc_of[entity(1, "llc")] == "fw1"
    assert radio_hub.proc_of[entity(1, "uwb")] == "fw1"


FRAME = {"handle": 1, "src64": 1, "src16": 2, "dst": "bcast", "dst_addr": 0xFFFF, "pan_id": 1, "channel": 12,
         "ack": False, "mac_retries": 0, "psdu_len": 40, "seq": 0, "payload": b"x", "opts": 0}


@pytest.mark.parametrize("item", [
    ["air", "not a frame"], ["air"], ["uart", "xbee", "text", 9600], ["uart", "xbee", b"x"], ["node", 3],
    ["uwb", {"peer": 99}], ["uwb", {"peer": 0}], ["uwb", {"peer": 1, "t_ns": float("inf")}], ["rssi_pwm", "high"],
    ["log", "x", {}], ["teleport", 1],
    ["air", {**FRAME, "channel": "x"}], ["air", {**FRAME, "payload": 5}], ["air", {**FRAME, "handle": [1]}],
    ["air", {**FRAME, "psdu_len": float("inf")}], ["air", {**FRAME, "psdu_len": 300}],
    ["node", {"channel": 2**63, "pan_id": 1, "addr64": 1, "addr16": 1, "series": 2, "tx_power_dbm": 3,
              "sensitivity_dbm": -94}],
])
def test_malformed_module_items_are_counted_not_fatal(radio_hub: Hub, item: list) -> None:
    e = entity(0, "xbee") if item[0] != "uwb" else entity(0, "uwb")
    res = {"out": [item], "wake": Q, "wom": True}
    radio_hub._outputs(0, {"fw0": {"k": 0, "ents": {e: res}}}, {}, {"fw0": [e]})
    assert radio_hub.counts["malformed_items"] == 1 and not radio_hub.dead


def test_a_valid_air_frame_goes_on_the_air_and_is_heard(radio_hub: Hub) -> None:
    e = entity(0, "xbee")
    node = {"channel": 12, "pan_id": 1, "addr64": 1, "addr16": 2, "series": 2, "tx_power_dbm": 3.0,
            "sensitivity_dbm": -94.0}
    res = {"out": [["node", node], ["air", FRAME]], "wake": None, "wom": True}
    radio_hub._outputs(0, {"fw0": {"k": 0, "ents": {e: res}}}, {}, {"fw0": [e]})
    assert radio_hub.counts["malformed_items"] == 0 and radio_hub.counts["air_frames"] == 1


def test_nan_in_a_log_record_is_refused_not_recorded(radio_hub: Hub) -> None:
    e = entity(1, "logic")
    res = {"out": [["log", "x", {"v": float("nan")}]], "wake": None}
    radio_hub._outputs(0, {"lg1": {"k": 0, "ents": {e: res}}}, {}, {"lg1": [e]})
    assert radio_hub.counts["malformed_items"] == 1


def test_saturated_rssi_pwm_reads_as_its_floor_not_as_silence() -> None:
    frames = _llc_rssi_frames([(1.0, 1.0)])
    assert frames[-1]["valid"] == 1 and frames[-1]["duty_permille"] == 1000
    assert frames[-1]["rssi_dbm"] == round(rssi_dbm_from_pwm(1.0, -94.0))  # about -52 dBm: stronger looks alike


def test_logic_bytes_reach_the_module_paced_by_the_line(radio_hub: Hub) -> None:
    e = entity(2, "logic")
    frame = b"\x7e\x00\x04\x08\x01SH\x5b"
    res = {"out": [["uart", "xbee", frame, 9600]], "wake": None, "wom": True}
    radio_hub._outputs(0, {"lg2": {"k": 0, "ents": {e: res}}}, {}, {"lg2": [e]})
    radio_hub.medium("uart").start_quantum(Q)  # the bytes start at the next quantum: nothing yet
    assert radio_hub.inbox[entity(2, "xbee")] == []
    radio_hub.medium("uart").start_quantum(2 * Q)  # 8 bytes at 9600 baud: 8.3 ms
    assert radio_hub.inbox[entity(2, "xbee")] == [["uart", frame]]
    # the module switched to 115200 (ATBD 7): a host still at 9600 now garbles its bytes
    mod = entity(2, "xbee")
    radio_hub._outputs(2 * Q, {"fw2": {"k": 0, "ents": {mod: {"out": [["baud", "xbee", 115200]], "wake": None}}}},
                       {}, {"fw2": [mod]})
    radio_hub.inbox[mod].clear()
    radio_hub._outputs(2 * Q, {"lg2": {"k": 0, "ents": {e: res}}}, {}, {"lg2": [e]})
    radio_hub.medium("uart").start_quantum(5 * Q)
    assert len(radio_hub.inbox[mod][0][1]) == 8 and radio_hub.inbox[mod][0][1] != frame


def test_uwb_log_is_scored_against_ground_truth(radio_hub: Hub) -> None:
    w = radio_hub.world
    d01 = float(np.hypot(*(w.pos[0] - w.pos[1])))
    radio_hub.medium("uwb").on_log(0, "uwb_ranges", {"peers": [0x1001], "raw": [d01 + 0.3], "filtered": [d01 - 0.1]}, 0)
    acc = radio_hub.medium("uwb").log_err[0]
    sight = "los" if "raw_los" in acc else "nlos"
    raw, filt = acc[f"raw_{sight}"].summary(), acc[f"filtered_{sight}"].summary()
    assert raw["n"] == filt["n"] == 1
    assert raw["mean_m"] == pytest.approx(0.3) and filt["mean_m"] == pytest.approx(-0.1)
    assert raw["p95_abs_m"] == pytest.approx(0.3, rel=0.012) and filt["rms_m"] == pytest.approx(0.1)


def test_range_errors_are_summarised_in_fixed_memory() -> None:
    """A soak's hours of ranges keep counters, not a float per range (the world's memory grew 20 MiB an hour by
    them): the summary's RMS and mean are exact, its 95th percentile of |error| within its 1.2 % bin."""
    from bridge.media.uwb import ErrorStats

    errors = np.random.default_rng(5).normal(0.05, 0.1, size=20_000)
    a, b = ErrorStats(), ErrorStats()
    for i, e in enumerate(errors):
        (a if i % 2 else b).add(float(e))
    a.merge(b)
    s = a.summary()
    assert s["n"] == 20_000 and a.abs.counts.size == 1401
    assert s["rms_m"] == pytest.approx(float(np.sqrt(np.mean(errors**2))), abs=1e-4)
    assert s["mean_m"] == pytest.approx(float(errors.mean()), abs=1e-4)
    assert s["p95_abs_m"] == pytest.approx(float(np.quantile(np.abs(errors), 0.95)), rel=0.013)


def test_survey_config_keeps_the_arena_and_swaps_the_robots(tmp_path: Path) -> None:
    raw = survey_config(Path(__file__).resolve().parents[2] / "hil_configs" / "demo.toml", 100.0, 2.0, 4, None)
    text = to_toml(raw)
    back = tomllib.loads(text)
    assert back == raw
    cfg = Config.model_validate(back)
    assert cfg.robot_count == 2 and cfg.robots[0].behaviour == "radio_survey" and cfg.robots[0].xbee.series == 2
    assert len(cfg.obstacles) == 9 and cfg.session.duration_s == 100.0 and cfg.session.seed == 4


def test_calibration_figures_from_rows() -> None:
    rows = [{"distance_m": 3.0, "delivered": 1, "rssi_dbm": -75},
            {"distance_m": 2.5, "delivered": 1, "rssi_dbm": -73},
            {"distance_m": 12.0, "delivered": 1, "rssi_dbm": -93},
            {"distance_m": 14.0, "delivered": 0, "rssi_dbm": ""},
            {"distance_m": 11.0, "delivered": 1, "rssi_dbm": -90}]
    cal = calibration(rows, -94.0)
    assert cal["median_rssi_2_4m_dbm"]["ours"] == -74.0 and cal["median_rssi_2_4m_dbm"]["pass"]
    assert cal["delivery_beyond_10m"]["ours"] == pytest.approx(2 / 3) and cal["delivery_beyond_10m"]["pass"]
    assert cal["weakest_received_dbm"]["ours"] == -93.0 and cal["furthest_delivery_m"]["ours"] == 12.0


def test_serial_numbers_are_digi_oui_and_unique() -> None:
    nums = {xbee_serial64(r) for r in range(5000)}
    assert len(nums) == 5000 and all(n >> 32 == 0x0013A200 for n in nums)
