"""A legged robot given an LLC's or a wheeled robot's options: the config error names the file, the field and why."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.config import ConfigError, load_config

BASE = """
[[robots]]
profile = "decizebro"
count = 2
"""


@pytest.mark.parametrize(("extra", "match"), [
    ('xbee = { series = 2 }\n', r"robots\[0\]: xbee: a decizebro has no XBee: its radio is the DWM1001"),
    ("uwb = true\n", r"robots\[0\]: uwb: a decizebro always has its DWM1001 UWB radio"),
    ('can = { slcan_pty = "r{id}-can" }\n', r"robots\[0\]: can: a decizebro has no LLC on CAN"),
    ('pose_source = "ground_truth"\n', r"robots\[0\]: pose_source: a decizebro has no LLC to report a pose"),
    ("conveyor_slots = 3\n", r"robots\[0\].conveyor_slots: Extra inputs are not permitted"),
    ('motion = { kind = "fixed" }\n', r"robots\[0\]: motion.kind = 'fixed': the session drives this robot's body "
                                      r"through its simulated boards \(wheels, legs\)"),
])
def test_options_a_decizebro_does_not_have_are_refused(tmp_path: Path, extra: str, match: str) -> None:
    p = tmp_path / "zebros.toml"
    p.write_text(BASE + extra)
    with pytest.raises(ConfigError, match=match) as e:
        load_config(p)
    assert str(e.value).startswith(str(p))


def test_a_plain_decizebro_group_is_fine(tmp_path: Path) -> None:
    p = tmp_path / "zebros.toml"
    p.write_text(BASE)
    assert load_config(p).robots[0].profile == "decizebro"
