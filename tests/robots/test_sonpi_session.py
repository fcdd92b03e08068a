"""SonPIs in a session (hil_configs/sonpi/sandbox.toml): their programs wander through the Pi's ``sonpi_board``
driver on the simulated I2C bus to their Arduino boards, which fire their HC-SR04s one after the other and hand the
Pi 250 ms windows; the summary scores each board's windows against the true ranges. The same session with its robots
packed in one process each records the same; simultaneous firing shows cross-talk; the ideal profile pings at
200 Hz."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from bridge.core.recorder import iter_messages
from tests.conftest import ROOT
from tests.robots.test_zebro_bus_session import run

pytestmark = pytest.mark.session

SANDBOX = ROOT / "hil_configs" / "sonpi" / "sandbox.toml"


def test_sonpis_wander_on_their_sonar_boards_and_the_summary_scores_the_windows(tmp_path: Path) -> None:
    out = tmp_path / "run"
    s = run(SANDBOX, out, "--duration", "20")
    assert run(SANDBOX, tmp_path / "packed", "--duration", "20", "--robots-per-process", "3")["digest"] == s["digest"]
    assert not s["failures"]
    for rob in s["per_robot"]:
        i2c, board = rob["i2c"], rob["firmware"]["arduino"]
        assert i2c["slaves"] == {"0x20": "arduino"} and i2c["nacks"] == i2c["timeouts"] == 0
        assert board["transactions"] == i2c["transactions"] and board["refused_writes"] == board["bad_reads"] == 0
        assert board["malformed"] == 0 and board["watchdog_stops"] == 0 and board["crosstalk"] == 0
        assert board["ping_hz_per_sensor"] == pytest.approx(3.33, abs=0.05)  # sequential: one ping per 60 ms
        assert board["windows"] == 79  # 250 ms windows from its power-up to the end
        w = board["sonar_windows"]
        # in a 3 m pen every sensor has a surface within 4 m: nearly every window reports it, within a centimetre
        assert w["in_reach"] >= 300 and w["valid_fraction"] > 0.97 and w["phantom"] == 0
        assert 0 < w["error_mean_mm"] < 15 and w["error_rms_mm"] < 25
        assert rob["distance_m"] > 1.0  # they wandered (0.15 m/s asked)
    # the Pi read a window about every 125 ms: its log shows the readings it acted on, the same as the board's
    readings = [json.loads(d) for topic, _t, d in iter_messages(out / "session.mcap") if topic == "/r000/log/sonar"]
    assert len(readings) >= 70
    finite = [r for rec in readings for r in rec["ranges_m"] if r is not None]
    assert finite and all(0.02 <= r <= 4.0 for r in finite)
    pins = [json.loads(d) for topic, _t, d in iter_messages(out / "session.mcap") if topic == "/r000/arduino/pins"]
    assert len(pins) == 2000 and any(p.get("pwm", [0, 0]) != [0, 0] for p in pins)


FIRING = """
[session]
name = "sonpi-firing"
duration_s = 6
seed = 3
[arena]
width_m = 2
length_m = 2
[[robots]]
count = 1
profile = "sonpi"
behaviour = "sonar_wander"
params = {{ speed_mps = 0.0 }}
sonar_firing = "{firing}"
sonar_crosstalk = 1.0
placement = {{ kind = "explicit", poses = [[0.4, 1.0, 0.0]] }}
"""


def test_simultaneous_firing_cross_talks_and_the_ideal_profile_pings_at_200_hz(tmp_path: Path) -> None:
    got = {}
    for firing in ("simultaneous", "ideal"):
        cfg = tmp_path / f"{firing}.toml"
        cfg.write_text(FIRING.format(firing=firing))
        got[firing] = run(cfg, tmp_path / firing)["per_robot"][0]["firmware"]["arduino"]
    sim, ideal = got["simultaneous"], got["ideal"]
    assert sim["ping_hz_per_sensor"] == pytest.approx(1000 / 60, rel=0.02) and sim["crosstalk"] > 0
    assert ideal["ping_hz_per_sensor"] == pytest.approx(200, rel=0.01) and ideal["crosstalk"] == 0
    # cross-talk makes windows report nearer echoes than the truth: the error grows negative
    assert sim["sonar_windows"]["error_mean_mm"] < ideal["sonar_windows"]["error_mean_mm"] - 5
    assert ideal["sonar_windows"]["valid_fraction"] == 1.0 and math.isfinite(ideal["sonar_windows"]["error_rms_mm"])
