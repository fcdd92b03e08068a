"""Faults of the air in a session: a partition splits the swarm's radio network for a while (no frame crosses it,
lambda2 falls to 0, the start and end are events) and the swarm goes on; burst loss from the config takes frames
in bursts, counted in the summary, the same for the same seed."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.config import ConfigError, load_config
from bridge.core.launcher import run_session
from bridge.testing import SwarmSession

pytestmark = pytest.mark.session

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "hil_configs" / "demo.toml"


def test_a_partition_splits_the_radio_network_while_it_lasts(tmp_path: Path) -> None:
    with SwarmSession(DEMO, {"robots.count": 4, "session.robots_per_process": 4}, tmp_path) as s:
        s.run_for(2.0)
        before = s.radio()["connectivity"]
        assert before["connected_share"] == 1.0
        s.fault("partition", groups=[[0, 1], [2, 3]], duration_s=4.0)
        s.run_for(8.0)
        kinds = [(e.values["kind"], round(e.t_s, 2)) for e in s.events()]
        assert ("partition", 2.01) in kinds and ("partition_end", 6.01) in kinds
        c = s.radio()["connectivity"]
        assert c["lambda2_min"] == 0.0 and c["partition_events"] == 1 and 0.4 < c["connected_share"] < 0.8
        imp = s.radio()["impairments"]
        assert imp["partitioned"] > 0 and imp["burst_frames"] == 0
        assert all(s.alive(r) for r in range(4))
        with pytest.raises(ConfigError, match="no robot 7"):
            s.fault("partition", groups=[[0], [7]])
        with pytest.raises(ConfigError, match="a fault of the air"):
            s.fault("partition", 1, groups=[[0], [2]])


def test_burst_loss_from_the_config_is_counted_and_seeded(tmp_path: Path) -> None:
    over = {"robots.count": 6, "session.robots_per_process": 6, "session.duration_s": 10.0,
            "faults": [{"kind": "burst_loss", "at_s": 1.0, "p_gb": 0.2, "p_bg": 0.3}]}
    a = run_session(str(DEMO), over, str(tmp_path / "a"), progress=None, plot=False)
    b = run_session(str(DEMO), over, str(tmp_path / "b"), progress=None, plot=False)
    assert a.code == 0 and not a.summary["failures"]
    imp = a.summary["radio"]["impairments"]
    # 6 robots' hellos to 5 others for 9 s; bad 40 % of the time once mixed (links start good)
    assert imp["burst_frames"] > 200 and 0.2 < imp["burst_lost"] / imp["burst_frames"] < 0.6
    assert (a.summary["digest"], imp) == (b.summary["digest"], b.summary["radio"]["impairments"])
    with pytest.raises(ConfigError, match=r"faults\[0\]: .*p_gb, p_bg"):
        load_config(DEMO, {"faults": [{"kind": "burst_loss", "at_s": 1.0}]})
    with pytest.raises(ConfigError, match=r"faults\[0\]\.robots: no robot 12"):
        load_config(DEMO, {"faults": [{"kind": "burst_loss", "at_s": 1.0, "p_gb": 0.1, "p_bg": 0.5, "robots": [12]}]})
