"""The mature algorithm on co-simulated DeciZebros: with many neighbours its link-list gossip takes more than one UWB
frame, and it splits the list into frames the radio carries (a list too long for one frame once made every robot
fail)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.core.test_session import run as session_run

pytestmark = pytest.mark.session

CFG = """
[session]
name = "zebro-mature"
duration_s = 4
seed = 5
[arena]
width_m = 10
length_m = 10
[[robots]]
profile = "decizebro"
count = 9
behaviour = "zebro_mature"
placement = { kind = "grid", origin = [4.0, 4.0], spacing_m = 0.5, columns = 3, yaw_deg = 0 }
"""


def test_nine_close_zebros_gossip_their_links_in_frames_that_fit(tmp_path: Path) -> None:
    cfg = tmp_path / "m.toml"
    cfg.write_text(CFG)
    code, s = session_run(cfg, tmp_path / "run", timeout=900)
    assert code == 0, s.get("failures")
    assert not s["failures"] and all(r["alive"] for r in s["per_robot"])
    assert sum(r["firmware"]["uwb_radio"]["tx_data"] for r in s["per_robot"]) > 9 * 4  # they talked
