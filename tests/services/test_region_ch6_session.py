"""Chapter 6's planner (region planner ``ch6``) as the SonPI swarm's global controller, the acceptance test of the
two-lane session: a whole session of hil_configs/sonpi/regions_ch6.toml (six SonPIs, a wall with two lanes), ended
by the study's loop functions half a second after the controller's "done". From summary.json and the recording: the
swarm splits 3 + 3 at the wall, the sub-areas sum to the parent's, the sub-swarms merge behind it with the sum of
their areas, the region reaches the target with every robot near it, and the recording draws the ellipses
(``foxglove.SceneUpdate``), the formation (``/world/formation``) and the split and merge decisions."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from bridge.core.recorder import iter_messages
from tests.core.test_session import _check_messages_match_their_schemas
from tests.core.test_session import run as session_run

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "hil_configs" / "sonpi" / "regions_ch6.toml"
TARGET = np.array([3.3, 0.85])
R_S = 1.13  # units of 0.1 m
AREA = 6 * math.pi * R_S**2  # eq. 6.9's N pi r_s^2: 24.07 units^2 = 2407 cm^2 (A9)


def _logs(mcap: Path, topic: str) -> list[tuple[float, dict]]:
    return [(t / 1e9, json.loads(d)) for tp, t, d in iter_messages(mcap) if tp == topic]


def _polygon_area(pts: np.ndarray) -> float:
    return float(0.5 * abs(np.dot(pts[:, 0], np.roll(pts[:, 1], 1)) - np.dot(pts[:, 1], np.roll(pts[:, 0], 1))))


@pytest.mark.long
@pytest.mark.session
def test_six_sonpis_split_through_two_lanes_merge_and_reach_the_target(tmp_path: Path) -> None:
    out = tmp_path / "out"
    # no wall-clock deadline: the session's own simulated end (done + 0.5 s, or duration_s) bounds it
    code, s = session_run(CONFIG, out, timeout=None)
    assert code == 0, s.get("error")
    ctl = s["services"]["controller"]
    assert not ctl["failed"] and ctl["planner"] == "ch6"
    assert ctl["malformed"] == 0 and ctl["planner_errors"] == 0 and ctl["unsendable"] == 0 and ctl["went_silent"] == 0
    assert ctl["events"]["split"] == 1 and ctl["events"]["merge"] == 1 and ctl["events"]["done"] == 1
    mcap = out / "session.mcap"
    events = [e for _, e in _logs(mcap, "/svc/controller/log/event")]
    (split,) = [e for e in events if e["kind"] == "split"]
    (merge,) = [e for e in events if e["kind"] == "merge"]
    (done,) = [e for e in events if e["kind"] == "done"]
    # B9: one region of N pi r_s^2 split 3 + 3 at the wall, the sub-areas summing to the parent's
    assert sorted(split["sizes"]) == [3, 3] and len(split["swarms"]) == 2
    assert math.isclose(split["parent_area"], AREA, rel_tol=1e-6)
    assert math.isclose(sum(split["areas"]), split["parent_area"], rel_tol=1e-9)
    # B10: the two sub-swarms merged behind it into one, its area the sum of theirs, one leader
    assert sorted(merge["merged"]) == sorted(split["swarms"]) and merge["sizes"] == [3, 3]
    assert math.isclose(merge["area"], sum(merge["areas"]), rel_tol=1e-9)
    assert math.isclose(merge["area"], split["parent_area"], rel_tol=1e-9)
    assert merge["leader"] in range(6) and merge["a"] >= merge["b"] > 0
    assert 0 < split["t"] < merge["t"] < done["t"] == ctl["done_s"]
    # the goal: the planner's last region at the target, every robot within 0.3 m of it (truth, at the end)
    final = ctl["planner_summary"]["swarms"]
    assert len(final) == 1 and sorted(final[0]["members"]) == list(range(6))
    assert math.hypot(final[0]["region"]["x"] - 33.0, final[0]["region"]["y"] - 8.5) < 1.0  # within 0.1 m of T
    assert math.isclose(final[0]["area"], AREA, rel_tol=1e-6)
    t_end, last = _logs(mcap, "/world/poses")[-1]
    xy = np.array([last["x"], last["y"]]).T
    assert np.hypot(*(xy - TARGET).T).max() < 0.3
    # the loop functions ended the session half a second after "done" (not at duration_s)
    f = s["formation"]
    assert f["end_event"] == "controller/done" and math.isclose(f["end_event_s"], done["t"], abs_tol=0.02)
    assert math.isclose(s["sim_time_s"], done["t"] + 0.5, abs_tol=0.03) and t_end < s["sim_time_s"]
    # the plans: one group of six before the split, two of three between, one of six after the merge
    plans = [p for _, p in _logs(mcap, "/svc/controller/log/plan")]
    assert not plans[0]["ids"] and all(p["ids"] for p in plans[1:])  # no pose before the camera's first frame
    for p in plans[1:]:
        sizes = sorted(np.unique(p["groups"], return_counts=True)[1].tolist())
        assert sizes == ([3, 3] if split["t"] <= p["t"] < merge["t"] else [6]), (p["t"], sizes)
    # the recording draws the regions: one ellipse, then two, then one, each outline enclosing its area
    scenes = _logs(mcap, "/svc/controller/log/regions")
    assert len(scenes) == ctl["scenes"] >= 3
    drawn = {1: 0, 2: 0}
    for t, scene in scenes:
        ents = scene["entities"]
        if not ents:
            continue
        assert len(ents) == (2 if split["t"] <= t < merge["t"] else 1), t
        drawn[len(ents)] += 1
        areas = []
        for e in ents:
            assert e["frame_id"] == "world" and {"key": "kind", "value": "ellipse"} in e["metadata"]
            (line,) = e["lines"]
            pts = np.array([[p["x"], p["y"]] for p in line["points"]])
            assert line["type"] == 1 and len(pts) == 72
            areas.append(_polygon_area(pts) * 100)  # m^2 -> units^2; 72 vertices cover 99.87 % of the ellipse
        assert math.isclose(sum(areas), AREA * 0.99873, rel_tol=2e-3), (t, areas)
    assert drawn[1] > 0 and drawn[2] > 0
    with open(mcap, "rb") as fh:
        schemas = {
            c.topic: sc.name
            for sc, c, _ in make_reader(fh).iter_messages(topics=["/svc/controller/log/regions", "/world/formation"])
        }
    assert schemas == {
        "/svc/controller/log/regions": "foxglove.SceneUpdate",
        "/world/formation": "swarm_sitl.RoyFormation",
    }
    # the formation, sampled every second from the true poses until the swarm arrived
    form = _logs(mcap, "/world/formation")
    assert len(form) >= int(done["t"]) and f["samples"] >= 10 and f["fe_mean"] is not None
    assert f["nn_min_m"] > 0.175  # two SonPI bodies (0.09 m radius) at most touched (contact: 0.18 m)
    _check_messages_match_their_schemas(
        mcap, frozenset({"foxglove.SceneUpdate", "swarm_sitl.Log", "swarm_sitl.Poses", "swarm_sitl.RoyFormation"})
    )
