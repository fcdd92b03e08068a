"""Chapter 5's planner (region planner ``ch5``) as the SonPI swarm's global controller: a whole session of
hil_configs/sonpi/regions_ch5.toml, three SonPIs past one box, until the region reaches the target."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bridge.core.recorder import iter_messages
from tests.core.test_session import run as session_run

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "hil_configs" / "sonpi" / "regions_ch5.toml"


@pytest.mark.long
@pytest.mark.session
def test_three_sonpis_follow_the_ch5_regions_to_the_target(tmp_path: Path) -> None:
    cfg = tmp_path / "ch5.toml"
    text = CONFIG.read_text()
    assert "duration_s = 60" in text
    cfg.write_text(text.replace("duration_s = 60", "duration_s = 40"))
    code, s = session_run(cfg, tmp_path / "out")
    assert code == 0, s.get("error")
    ctl = s["services"]["controller"]
    assert not ctl["failed"] and ctl["planner"] == "ch5"
    assert ctl["malformed"] == 0 and ctl["planner_errors"] == 0 and ctl["unsendable"] == 0
    assert ctl["plans_sent"] == 160
    events = [
        json.loads(d) for topic, _, d in iter_messages(tmp_path / "out" / "session.mcap") if topic.endswith("/event")
    ]
    regions = [e for e in events if e["kind"] == "region"]
    releases = [e for e in events if e["kind"] == "barrier"]
    # a step of 0.3 m per region over 2.5 m, every region held until the three robots were in their circles
    assert 8 <= len(regions) <= 16 and len(releases) == len(regions)
    assert all(e["reason"] == "all in circles" for e in releases)
    assert all(e["circles"] >= e["n"] == 3 and e["radius"] >= 0.9 for e in regions)  # B7, circles hold a SonPI
    done = [e for e in events if e["kind"] == "done"]
    assert len(done) == 1 and 20.0 <= done[0]["t"] <= 40.0 and ctl["done_s"] == done[0]["t"]
    summary = ctl["planner_summary"]
    assert summary["updates"] == len(regions) and summary["done_t"] == done[0]["t"]
    assert np.hypot(*(np.array(regions[-1]["centre"]) - [24.0, 24.0])) <= 1.5  # the last region at T (units)
    assert max(summary["distances_to_target"]) < 6.0  # every robot within 0.6 m of T
    assert ctl["scenes"] >= len(regions)
