"""The recording's Foxglove scene (bridge.core.scene): the channels carry Foxglove's well-known schema names and the
fields its panels read, show what the world holds (bodies, LED colours, failures, radio links), and change nothing
else in the recording."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.reader import make_reader

from bridge.core.launcher import run_session
from bridge.tools.foxglove_layout import layout_json

pytestmark = pytest.mark.session

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "hil_configs" / "demo.toml"
SHORT = {"robots.count": 4, "session.robots_per_process": 4, "session.duration_s": 3.0,
         "faults": [{"robot": 3, "at_s": 1.0, "kind": "firmware_crash"}]}


def _read(path: Path) -> list[tuple[str, str, str, str, int, dict]]:
    """(topic, schema name, schema encoding, message encoding, log time, message) of every message, CRCs checked."""
    out = []
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        for schema, ch, m in reader.iter_messages(log_time_order=False):
            out.append((ch.topic, schema.name, schema.encoding, ch.message_encoding, m.log_time, json.loads(m.data)))
        summary = reader.get_summary()
    assert summary is not None and summary.statistics.message_count == len(out)
    return out


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list]:
    out = {}
    for name, hz in (("scene", 10.0), ("none", 0.0)):
        d = tmp_path_factory.mktemp(name)
        res = run_session(str(DEMO), {**SHORT, "session.scene_hz": hz}, str(d), progress=None, plot=False)
        assert res.code == 0
        out[name] = _read(d / "session.mcap")
    return out


def test_the_scene_channels_use_foxglove_schemas(recordings: dict[str, list]) -> None:
    names = {topic: (schema, enc, menc) for topic, schema, enc, menc, _, _ in recordings["scene"]}
    assert names["/scene/arena"] == ("foxglove.SceneUpdate", "jsonschema", "json")
    assert names["/scene/robots"] == ("foxglove.SceneUpdate", "jsonschema", "json")
    assert names["/tf"] == ("foxglove.FrameTransforms", "jsonschema", "json")
    assert names["/log"] == ("foxglove.Log", "jsonschema", "json")
    robots = [m for topic, *_, m in recordings["scene"] if topic == "/scene/robots"]
    assert len(robots) == 30  # 10 Hz over 3 s
    arena = [m for topic, *_, m in recordings["scene"] if topic == "/scene/arena"]
    assert len(arena) == 1 and {e["id"] for e in arena[0]["entities"]} >= {"floor", "static/box0", "static/cylinder0"}


def test_the_scene_shows_the_world(recordings: dict[str, list]) -> None:
    rec = recordings["scene"]
    poses = {t: m for topic, *_, t, m in rec if topic == "/world/poses"}
    for topic, *_, t, m in rec:
        if topic != "/scene/robots":
            continue
        bodies = {e["id"]: e for e in m["entities"] if e["id"][1:].isdigit()}
        assert sorted(bodies) == ["r000", "r001", "r002", "r003"]
        p = poses[t]
        for r in range(4):
            cyl = bodies[f"r{r:03d}"]["cylinders"][0]
            assert cyl["pose"]["position"]["x"] == pytest.approx(p["x"][r], abs=1e-4)
            if p["alive"][r] and any(p["led"][r]):
                assert [round(cyl["color"][k] * 255) for k in "rgb"] == p["led"][r]
            if not p["alive"][r]:
                assert cyl["color"]["a"] < 1.0
    last = next(m for topic, *_, m in reversed(rec) if topic == "/scene/robots")
    links = next(e for e in last["entities"] if e["id"] == "radio/links")["lines"][0]
    assert links["type"] == 2 and len(links["points"]) == len(links["colors"]) >= 2
    tf = next(m for topic, *_, m in reversed(rec) if topic == "/tf")
    assert [x["child_frame_id"] for x in tf["transforms"]] == ["r000", "r001", "r002", "r003"]


def test_logs_and_events_go_to_the_log_panel(recordings: dict[str, list]) -> None:
    rec = recordings["scene"]
    logs = [m for topic, *_, m in rec if topic == "/log"]
    robot_logs = [m for topic, *_, m in rec if topic.startswith("/r") and "/log/" in topic]
    assert len([m for m in logs if m["level"] == 2]) == len(robot_logs)
    crash = [m for m in logs if m["name"] == "session/raised"]
    assert len(crash) == 1 and crash[0]["level"] == 3 and '"robot":3' in crash[0]["message"]


def test_the_scene_changes_nothing_else(recordings: dict[str, list]) -> None:
    scene_topics = {"/scene/arena", "/scene/robots", "/tf", "/log"}
    others = [(topic, t, m) for topic, *_, t, m in recordings["scene"] if topic not in scene_topics]
    assert others == [(topic, t, m) for topic, *_, t, m in recordings["none"]]
    assert not {topic for topic, *_ in recordings["none"]} & scene_topics


def test_the_committed_layout_is_the_one_built() -> None:
    assert (ROOT / "docs" / "foxglove-layout.json").read_text() == layout_json()
    layout = json.loads(layout_json())
    panels = json.dumps(layout)
    assert '"panelType": "ThreeDee"' in panels and '"topicToRender": "/log"' in panels
