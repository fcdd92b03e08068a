"""A SonPI group's options in a config: a wrong setting names the file, the field and why; options it does not have
are refused; its profile carries the group's marker colour for the overhead camera."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.config import ConfigError, load_config
from bridge.core.registry import robot_profile
from bridge.models.marker import TopMarker
from tests.conftest import ROOT

BASE = """
[[robots]]
profile = "sonpi"
count = 2
"""


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (
            'sonar_firing = "rapid"\n',
            r"robots\[0\]\.sonar_firing: Input should be 'sequential', 'simultaneous' or "
            r"'ideal'",
        ),
        ("sonar_noise_m = -0.01\n", r"robots\[0\]\.sonar_noise_m: Input should be greater than or equal to 0"),
        ("sonar_crosstalk = 1.5\n", r"robots\[0\]\.sonar_crosstalk: Input should be less than or equal to 1"),
        ("watchdog_ms = 505\n", r"robots\[0\]\.watchdog_ms: Input should be a multiple of 10"),
        ("marker_rgb = [255, 0, 300]\n", r"robots\[0\]\.marker_rgb\[2\]: Input should be less than or equal to 255"),
        ("sonar_rate_hz = 200\n", r"robots\[0\]\.sonar_rate_hz: Extra inputs are not permitted"),
        ("xbee = { series = 2 }\n", r"robots\[0\]: xbee: a SonPI talks Wi-Fi \(802\.11\), not XBee"),
        ('can = { slcan_pty = "r{id}-can" }\n', r"robots\[0\]: can: a SonPI has no CAN bus"),
        ('pose_source = "ground_truth"\n', r"robots\[0\]: pose_source: a SonPI's board reports no pose"),
    ],
)
def test_a_wrong_sonpi_setting_names_file_field_and_reason(tmp_path: Path, extra: str, match: str) -> None:
    p = tmp_path / "sonpis.toml"
    p.write_text(BASE + extra)
    with pytest.raises(ConfigError, match=match) as e:
        load_config(p)
    assert str(e.value).startswith(str(p))


def test_an_external_sonpi_logic_needs_its_bus_on_a_port(tmp_path: Path) -> None:
    p = tmp_path / "external.toml"
    p.write_text('[session]\nspeed = 1\n[[robots]]\nprofile = "sonpi"\nlogic = "external"\n')
    with pytest.raises(
        ConfigError,
        match=r"robots\[0\]: i2c_pty: an external logic drives the SonPI through its "
        r"Arduino board on the I2C bus: expose it",
    ):
        load_config(p)


def test_the_groups_options_and_the_session_configs_load(tmp_path: Path) -> None:
    p = tmp_path / "sonpis.toml"
    p.write_text(BASE + 'sonar_firing = "simultaneous"\nmarker_rgb = [0, 128, 255]\n')
    cfg = load_config(p)
    assert cfg.profile(cfg.robots[0]).part(TopMarker).rgb == (0, 128, 255)
    assert robot_profile("sonpi").part(TopMarker).rgb == (255, 64, 0)
    for cfg in ("sonpi/sandbox.toml", "hil/sonpi_outside.toml"):
        assert load_config(ROOT / "hil_configs" / cfg).robots[0].profile == "sonpi"


def test_the_board_s_pins_are_checked_before_they_act() -> None:
    """PWM per motor, and the sonars' firing times only as five [next, period] pairs (a malformed one is dropped and
    counted by the hub, never reaching the world)."""
    from bridge.robots.sonpi.wiring import BOARD_WIRING as w

    trig = [[60_000_000 * i, 300_000_000] for i in range(5)]
    assert w.valid({"pwm": [0, 255]}) and w.valid({"pwm": [-255, 3], "trig": trig})
    for bad in (
        {"pwm": [0, 256]},
        {"pwm": [0]},
        {"trig": trig},
        {"pwm": [0, 0], "trig": trig[:4]},
        {"pwm": [0, 0], "trig": [*trig[:4], [0, 0]]},
        {"pwm": [0, 0], "trig": [*trig[:4], [-1, 5]]},
        {"pwm": [0, 0], "trig": [*trig[:4], [1.5, 5]]},
        {"pwm": [0, 0], "echo": 1},
        [0, 0],
    ):
        assert not w.valid(bad), bad
