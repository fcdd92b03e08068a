"""Each pseudo-terminal a session links has a path of its own: two robot groups on one ``pty`` name, or one robot's
XBee and slcan adapter on one name, are refused with the file, both fields and the path, not left to leave one
program on another robot's, or another module's, port."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.config import ConfigError, load_config


def _load(tmp_path: Path, text: str) -> object:
    p = tmp_path / "links.toml"
    p.write_text("[session]\nduration_s = 5\nspeed = 1\n" + text)
    return load_config(p)


def test_two_groups_on_one_xbee_pty_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as e:
        _load(tmp_path, '[[robots]]\ncount = 2\nxbee = { pty = "r{id}-xbee" }\n'
                        '[[robots]]\ncount = 1\nxbee = { pty = "r1-xbee" }\n')
    msg = str(e.value)
    assert "links.toml: robots[1].xbee.pty: robot 2's link 'r1-xbee' is also robots[0].xbee.pty of robot 1" in msg


def test_one_robots_xbee_and_slcan_adapter_on_one_path_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as e:
        _load(tmp_path, '[[robots]]\ncount = 1\nxbee = { pty = "port" }\ncan = { slcan_pty = "./x/../port" }\n')
    assert "robots[0].can.slcan_pty: robot 0's link 'port' is also robots[0].xbee.pty of robot 0" in str(e.value)


def test_distinct_links_load(tmp_path: Path) -> None:
    cfg = _load(tmp_path, '[[robots]]\ncount = 3\nxbee = { pty = "r{id}-xbee" }\ncan = { slcan_pty = "r{id}-can" }\n'
                          '[[robots]]\ncount = 1\nxbee = { pty = "r3-xbee" }\n')
    assert cfg.robot_count == 4
