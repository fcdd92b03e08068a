"""The global controller hosting a region planner (``region``): stepped directly with bad input (windows of the wrong
shape, missing and garbage readings, a robot that stops reporting, malformed packets, a planner that raises, a plan
too large to send), refused configs naming the field, and whole sessions of SonPIs (hil_configs/sonpi/
regions_converge.toml): converging until every robot is inside, the scene and the events recorded; robots holding
still once the controller dies."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from bridge.core.config import Config
from bridge.core.plan import make_plan
from bridge.core.recorder import iter_messages
from bridge.hosts.service import service_context
from swarm_logic.robots.sonpi import pose_packet as pp
from tests.core.test_session import _check_messages_match_their_schemas
from tests.core.test_session import run as session_run

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "hil_configs" / "sonpi" / "regions_converge.toml"
POSES = [[0.6, 0.6, 0.0], [2.4, 0.8, 0.0], [1.5, 2.4, 0.0]]


def _config(**params: object) -> dict:
    return {
        "arena": {"width_m": 3, "length_m": 3},
        "robots": [{"profile": "sonpi", "count": 3, "placement": {"kind": "explicit", "poses": POSES}}],
        "services": [
            {
                "kind": "global_controller",
                "name": "ctl",
                "options": {"controller": "region", "params": {"planner": "converge", **params}},
            }
        ],
    }


def _controller(**params: object):
    plan = make_plan(Config.model_validate(_config(**params)))
    spec, ctx = service_context(plan, "ctl")
    return spec.make(ctx)


@pytest.mark.parametrize(
    "params, where",
    [
        ({"planner": "no_such_planner"}, r"services\[0\]\.options\.params\.planner: unknown region planner"),
        ({"planner_params": {"r_c": -1.0}}, r"services\[0\]\.options\.params\.planner_params: r_c: must be finite"),
        ({"planner_params": {"radius": 3.0}}, r"services\[0\]\.options\.params\.planner_params: .*radius"),
        ({"unit_m": 0}, r"services\[0\]\.options\.params\.unit_m: Input should be greater than 0"),
        ({"beams": 5}, r"services\[0\]\.options\.params\.beams: Extra inputs"),
    ],
)
def test_a_bad_region_config_is_refused_naming_the_field(params: dict, where: str) -> None:
    with pytest.raises(ValueError, match=where):
        Config.model_validate(_config(**params))


def _window(rid: int, t: float, ranges: tuple) -> tuple[str, bytes]:
    return f"r{rid:03d}", pp.encode_sonar(0, t, pp.SonarWindow(rid, ranges))


def _camera(t: float) -> tuple[str, bytes]:
    return "camera", pp.encode_poses(0, t, [pp.PoseEntry(i, True, x, y, yaw) for i, (x, y, yaw) in enumerate(POSES)])


def test_bad_input_is_counted_and_logged_never_fatal_and_a_failing_planner_keeps_its_last_plan() -> None:
    svc = _controller(planner="tests.support.region_faults:FaultyPlanner", silent_s=0.6)
    good = (0.5, math.inf, None, 9.0, 1.0)  # an echo, no echo, no reading, garbage (beyond 4 m), an echo
    plans, events = [], []
    for k in range(17):  # 0 .. 4 s
        t = k * 0.25
        datagrams = [_camera(t), _window(0, t, good)]
        datagrams.append(_window(1, t, (1.0, 1.0, 1.0) if k == 2 else (2.0,) * 5))  # once, three beams of five
        if t <= 1.0 or t >= 3.0:  # robot 2 is silent from 1 s to 3 s
            datagrams.append(_window(2, t, (3.0,) * 5))
        if k == 3:
            datagrams += [("r000", b"\x00garbage"), ("r000", b"")]  # garbage, and an empty datagram
            datagrams.append(("r001", pp.encode_sonar(0, t, pp.SonarWindow(0, good))))  # robot 1 posing as 0
        res = svc.run(round(t * 1e9), {"in": [["wifi", list(d)] for d in datagrams]})
        assert res["wake"] == (k + 1) * 250_000_000
        sent = [pp.decode(item[2]) for item in res["out"] if item[0] == "wifi"]
        assert len(sent) == 1 and sent[0][0].type == pp.PLAN and sent[0][0].t_s == t  # a plan every period
        plans.append(sent[0][1])
        events += [item[2] for item in res["out"] if item[:2] == ["log", "event"]]
    s = svc.summary()
    assert s["malformed"] == 3 and s["windows"] == 17 + 17 + 10
    assert s["window_shape"] == 1 and s["readings_missing"] == 17 and s["readings_garbage"] == 17
    assert s["went_silent"] == 1 and s["came_back"] == 1 and s["silent"] == []
    assert s["planner_errors"] == 2 and s["unsendable"] == 1 and s["plans"] == 15 and s["plans_sent"] == 17
    # the observation: thesis units, NaN for no echo, no reading and garbage alike
    obs = svc.controller.planner.observations
    assert np.allclose(obs[4].positions, np.array(POSES)[:, :2] / 0.1)
    assert np.array_equal(obs[4].ranges[0], [5.0, np.nan, np.nan, np.nan, 10.0], equal_nan=True)
    assert np.isnan(obs[2].ranges[1]).all() and np.array_equal(obs[3].ranges[1], [20.0] * 5)
    # robot 2 leaves the observation 0.6 s after its last window (1 s) and comes back with its next one (3 s)
    assert [tuple(o.ids) for o in obs[4:13]] == [(0, 1, 2)] * 3 + [(0, 1)] * 5 + [(0, 1, 2)]
    kinds = [(e["kind"], e.get("reason"), e["t"]) for e in events if e["kind"] in ("input", "planner_error")]
    assert kinds == [
        ("input", "window_shape", 0.5),
        ("planner_error", None, 1.5),
        ("input", "silent", 1.75),
        ("planner_error", None, 1.75),
        ("input", "back", 3.0),
    ]
    err = next(e for e in events if e["kind"] == "planner_error")
    assert err["error"] == "ZeroDivisionError: planner fault" and err["kept"] == 1.25
    assert s["last_planner_error"] == {"t": 1.75, "error": "ZeroDivisionError: planner fault", "kept": 1.25}
    assert next(e for e in events if e["kind"] == "unsendable")["error"].endswith("more than one datagram (1472 bytes)")
    # while the planner fails, and when its plan cannot be sent, the last plan goes out again
    assert plans[6] == plans[7] == plans[5] and plans[10] == plans[9]
    assert [a.id for a in plans[7].agents] == [0, 1, 2] and [a.id for a in plans[8].agents] == [0, 1]


def test_the_plan_on_the_wire_is_the_planners_and_robots_without_a_pose_are_left_out() -> None:
    svc = _controller(planner_params={"r_c": 2.0})
    res = svc.run(0, {"in": [["wifi", list(_window(0, 0.0, (1.0,) * 5))], ["wifi", list(_window(1, 0.0, (1.0,) * 5))]]})
    (item,) = [i for i in res["out"] if i[0] == "wifi"]
    assert item[1] is None  # broadcast
    _, plan = pp.decode(item[2])
    assert plan.agents == ()  # reporting, but no pose known yet: no observation, and the planner holds
    res = svc.run(250_000_000, {"in": [["wifi", list(_camera(0.25))], ["wifi", list(_window(0, 0.25, (1.0,) * 5))]]})
    _, plan = pp.decode(next(i for i in res["out"] if i[0] == "wifi")[2])
    centre = np.array(POSES)[:2, :2].mean(axis=0) / 0.1  # robots 0 and 1 reported (robot 1 at 0 s)
    assert [a.id for a in plan.agents] == [0, 1] and plan.law == "formation" and not plan.done
    assert np.allclose([[a.goal_x, a.goal_y] for a in plan.agents], [centre, centre], atol=1e-4)
    assert plan.params["desired"] == [[0.0, 2.0], [2.0, 0.0]]
    scene = next(i for i in res["out"] if i[:2] == ["log", "regions"])
    assert scene[3] == "foxglove.SceneUpdate"
    (entity,) = scene[2]["entities"]
    pts = np.array([[p["x"], p["y"]] for p in entity["lines"][0]["points"]])
    assert np.allclose(np.hypot(*(pts - centre * 0.1).T), 0.2, atol=1e-4)  # r_c = 2 units = 0.2 m


def _run(tmp_path: Path, tag: str, duration: float, replace: dict[str, str] | None = None) -> tuple[Path, dict]:
    text = CONFIG.read_text().replace("duration_s = 30", f"duration_s = {duration}")
    for a, b in (replace or {}).items():
        assert a in text
        text = text.replace(a, b)
    cfg = tmp_path / f"{tag}.toml"
    cfg.write_text(text)
    out = tmp_path / tag
    code, summary = session_run(cfg, out)
    assert code == 0, summary.get("error")
    return out, summary


def _logs(out: Path, suffix: str) -> list[tuple[float, str, dict]]:
    return [
        (t / 1e9, topic, json.loads(d)) for topic, t, d in iter_messages(out / "session.mcap") if topic.endswith(suffix)
    ]


@pytest.mark.session
def test_three_sonpis_converge_until_every_one_is_inside_and_the_recording_draws_the_region(tmp_path: Path) -> None:
    out, s = _run(tmp_path, "converge", 10.0)
    ctl = s["services"]["controller"]
    assert not ctl["failed"] and ctl["planner"] == "converge"
    assert ctl["malformed"] == 0 and ctl["planner_errors"] == 0 and ctl["window_shape"] == 0
    assert ctl["plans_sent"] == 40 and ctl["windows"] >= 3 * 38
    events = [e for _, _, e in _logs(out, "/svc/controller/log/event")]
    kinds = [e["kind"] for e in events]
    assert kinds.count("region") == 1 and kinds.count("inside") == 3 and kinds.count("all_inside") == 1
    done = next(e for e in events if e["kind"] == "all_inside")
    # 0.9 to 1.2 m from the centroid at 0.15 m/s: every robot inside within 5 to 9 s of simulated time
    assert done["agents"] == [0, 1, 2] and 5.0 <= done["t"] <= 9.0 and ctl["done_s"] == done["t"]
    region = next(e for e in events if e["kind"] == "region")
    centre = np.array(region["centre"]) * 0.1
    assert np.allclose(centre, np.array(POSES)[:, :2].mean(axis=0), atol=0.03)  # the camera's first poses
    # the plans: recorded every period, done from the event on
    plans = _logs(out, "/svc/controller/log/plan")
    assert len(plans) == 40 and all(p["done"] == (p["t"] >= done["t"]) for _, _, p in plans if p["ids"])
    # the robots hold until the first plan naming them, then follow
    for r in range(3):
        holds = _logs(out, f"/r{r:03d}/log/hold")
        follows = _logs(out, f"/r{r:03d}/log/follow")
        assert holds and holds[0][2]["reason"] in ("no_plan", "not_in_plan") and len(follows) == 1
        assert follows[0][0] <= 0.6
    # the truth at the end: all three within r_c = 0.3 m of the centre, about rho = 0.3 m apart
    last = _logs(out, "/world/poses")[-1][2]
    xy = np.array([last["x"], last["y"]]).T
    assert np.hypot(*(xy - centre).T).max() < 0.3
    gaps = [math.dist(xy[i], xy[j]) for i in range(3) for j in range(i)]
    assert min(gaps) > 0.25 and max(gaps) < 0.36
    # the scene: foxglove.SceneUpdate on its own topic, the circle of radius r_c as a closed line
    scenes = _logs(out, "/svc/controller/log/regions")
    assert len(scenes) == ctl["scenes"] == 2  # the empty first plan, then the circle
    (entity,) = scenes[1][2]["entities"]
    line = entity["lines"][0]
    assert line["type"] == 1 and entity["id"] == "region/0" and entity["frame_id"] == "world"
    pts = np.array([[p["x"], p["y"]] for p in line["points"]])
    assert len(pts) == 72 and np.allclose(np.hypot(*(pts - centre).T), 0.3, atol=1e-4)
    with open(out / "session.mcap", "rb") as f:
        schemas = {c.topic: s.name for s, c, _ in make_reader(f).iter_messages(topics=["/svc/controller/log/regions"])}
    assert schemas == {"/svc/controller/log/regions": "foxglove.SceneUpdate"}
    _check_messages_match_their_schemas(
        out / "session.mcap", frozenset({"foxglove.SceneUpdate", "swarm_sitl.Log", "swarm_sitl.Poses"})
    )


@pytest.mark.session
def test_robots_hold_still_when_the_controller_dies(tmp_path: Path) -> None:
    out, s = _run(
        tmp_path,
        "dies",
        6.0,
        {'controller = "region"': 'controller = "tests.support.region_faults:DiesAtThreeSeconds"'},
    )
    assert s["services"]["controller"]["failed"]
    for r in range(3):
        holds = _logs(out, f"/r{r:03d}/log/hold")
        stale = [h for h in holds if h[2]["reason"] == "stale_plan"]
        # the last plan came at 2.75 s: stale 1 s after it arrived, within a control step
        assert len(stale) == 1 and 3.75 < stale[0][0] <= 3.85 and stale[0][2]["plan_t"] == 2.75
    # and they stand: no robot moves more than a few mm after the tracking layer has stopped them
    poses = {round(t, 2): p for t, _, p in _logs(out, "/world/poses")}
    a, b = np.array([poses[4.5]["x"], poses[4.5]["y"]]), np.array([poses[5.99]["x"], poses[5.99]["y"]])
    assert np.abs(a - b).max() < 0.005
