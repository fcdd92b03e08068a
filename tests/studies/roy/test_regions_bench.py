"""``bench --study roy``'s virtual-regions figures: the 1000-agent chapter 6 line and the SonPI session's config."""

from __future__ import annotations

import re
from pathlib import Path

from bridge.core.config import load_config, to_toml
from bridge.studies.roy.regions_bench import CH6_AGENTS, CH6_CASES, TARGET_CH6_RTF, ch6_figures, region_session


def test_the_ch6_figure_is_a_1000_agent_mission_with_its_real_time_factor() -> None:
    (line,) = ch6_figures(quick=True, duration=1.0)
    assert CH6_CASES[0] == "ch6-case2" and CH6_AGENTS == 1000
    assert f"ch6-case2 with {CH6_AGENTS} agents" in line and f"target >= {TARGET_CH6_RTF:g}x" in line
    m = re.search(r"([\d.]+) simulated s in ([\d.]+) s wall, rtf ([\d.]+)x", line)
    assert m is not None, line
    sim, wall, rtf = (float(g) for g in m.groups())
    assert sim == 1.0 and wall > 0 and rtf > 0 and abs(rtf - sim / wall) <= 0.05 * rtf + 0.1
    assert "not arrived" in line  # one second is not a mission


def test_the_region_session_is_regions_ch6_shortened(tmp_path: Path) -> None:
    raw = region_session(7.5)
    path = tmp_path / "r.toml"
    path.write_text(to_toml(raw))
    cfg = load_config(path)
    assert cfg.session.duration_s == 7.5 and cfg.session.name == "roy-bench-regions6"
    assert sum(g.count for g in cfg.robots) == 6
    kinds = {s.kind: s for s in cfg.services}
    assert kinds["overhead_camera"].options["mode"] == "tracking"
    assert kinds["global_controller"].options["params"]["planner"] == "ch6"
