"""Whole sessions with the SonPI's services on eSwarBots: the overhead camera in tracking and in noise mode, a robot
hidden under an overhead lamp that gets no pose, the robots' sonpi_wifi device serving the broadcast poses, the global
controller's mission and the robots' status, and the same seed giving the same recording."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from bridge.core.config import to_toml
from bridge.core.recorder import iter_messages
from tests.core.test_session import _check_messages_match_their_schemas
from tests.core.test_session import run as session_run

pytestmark = pytest.mark.session

CFG = """
[session]
name = "camera-{mode}"
duration_s = {duration}
seed = {seed}
robots_per_process = 3
[arena]
width_m = 4
length_m = 4
wall_height_m = 0.3
[[robots]]
profile = "eswarbot"
count = 3
behaviour = "random_walk"
placement = {{ kind = "explicit", poses = [[1.0, 1.0, 0.0], [2.0, 2.2, 90.0], [3.3, 3.3, 45.0]] }}
[robots.devices.sonpi_wifi]
url = "sitl://wifi"
controller = "ctl"
log_period_s = 0.2
first_pose_timeout_s = 60
[[services]]
kind = "overhead_camera"
name = "cam"
# a lamp over the far corner: robot 2 starts under it
options = {{ mode = "{mode}", fps = 10, occluders = [{{ x = 3.3, y = 3.3, z = 0.6, size = [1.4, 1.4, 0.05] }}] }}
[[services]]
kind = "global_controller"
name = "ctl"
options = {{ target = [2.0, 2.0], start_s = 1.0, goal_radius_m = 0.5 }}
[wifi]
{wifi}
"""


def run(
    tmp_path: Path, mode: str, *, duration: float = 4.0, seed: int = 3, wifi: str = 'mode = "ideal"', tag: str = ""
) -> tuple[Path, dict]:
    cfg = tmp_path / f"{mode}{tag}.toml"
    cfg.write_text(CFG.format(mode=mode, duration=duration, seed=seed, wifi=wifi))
    out = tmp_path / f"{mode}{tag}"
    code, summary = session_run(cfg, out)
    assert code == 0, summary.get("error")
    return out, summary


def _truth(out: Path) -> list[tuple[int, dict]]:
    return [(t, json.loads(d)) for topic, t, d in iter_messages(out / "session.mcap") if topic == "/world/poses"]


def _check_localisation(out: Path, s: dict, pos_p95: float) -> None:
    cam = s["services"]["cam"]
    assert not cam["failed"] and cam["frames"] == 40 and cam["robot_frames"] == 120
    assert cam["position_error_m"]["p95"] < pos_p95
    assert cam["heading_error_deg"]["p95"] < 15
    # robot 2 stays under the lamp: the camera never gives it a pose (no wrong one either)
    frames = [json.loads(d) for topic, _, d in iter_messages(out / "session.mcap") if topic == "/svc/cam/log/frame"]
    assert len(frames) == 40
    assert not any(f["valid"][2] or f["visible"][2] for f in frames)
    assert all(f["valid"][0] and f["valid"][1] for f in frames)
    assert cam["frames_without_pose"] == 40 and cam["robot_frames_hidden"] == 40
    # the robots' devices serve the broadcast poses: their own estimate is close to the truth at the time
    truth = _truth(out)
    logs = {
        r: [
            (t, json.loads(d))
            for topic, t, d in iter_messages(out / "session.mcap")
            if topic == f"/r{r:03d}/log/wifi_pose"
        ]
        for r in range(3)
    }
    assert not logs[2]  # robot 2 never had a pose
    for r in (0, 1):
        assert len(logs[r]) >= 10
        for t, p in logs[r]:
            assert p["fresh"] and p["others"] == 1  # it sees robot 0 or 1, never the hidden one
            gt = max((tt, g) for tt, g in truth if tt <= t)[1]
            assert math.hypot(p["x"] - gt["x"][r], p["y"] - gt["y"][r]) < 0.05  # within a frame and a quantum
    ctl = s["services"]["ctl"]
    assert ctl["missions"] == 16 and ctl["robots_reporting"] == 3 and ctl["malformed"] == 0
    assert s["wifi"]["malformed"] == 0 and s["wifi"]["lost"] == 0 and s["wifi"]["nodes"] == 5


def test_tracking_mode_localises_the_robots_and_gives_a_hidden_one_no_pose(tmp_path: Path) -> None:
    out, s = run(tmp_path, "tracking")
    _check_localisation(out, s, pos_p95=0.01)
    cam = s["services"]["cam"]
    assert cam["tracker"]["flowed"] >= 70  # optical flow carried the two visible markers after their first frame
    _check_messages_match_their_schemas(out / "session.mcap")
    # the same seed gives the same recording, whatever the packing
    cfg = tmp_path / "tracking.toml"
    code, again = session_run(cfg, tmp_path / "tracking-packed", "--robots-per-process", "1")
    assert code == 0 and again["digest"] == s["digest"]


def test_noise_mode_draws_the_fitted_errors_and_is_deterministic(tmp_path: Path) -> None:
    out, s = run(tmp_path, "noise")
    _check_localisation(out, s, pos_p95=0.02)
    assert s["services"]["cam"]["tracker"] is None
    _, again = run(tmp_path, "noise", tag="-again")
    assert again["digest"] == s["digest"]


def test_a_lossy_wifi_loses_pose_packets_but_never_delivers_a_wrong_pose(tmp_path: Path) -> None:
    out, s = run(tmp_path, "noise", wifi='mode = "lossy"\nloss = 0.3\nlatency_ms = 5.0\njitter_ms = 2.0', tag="-lossy")
    assert s["wifi"]["lost"] > 20 and s["wifi"]["malformed"] == 0
    assert s["services"]["cam"]["frames"] == 40
    truth = _truth(out)
    for r in (0, 1):  # what a robot holds may be a frame or two old, never another robot's nor a made-up one
        logs = [
            (t, json.loads(d))
            for topic, t, d in iter_messages(out / "session.mcap")
            if topic == f"/r{r:03d}/log/wifi_pose"
        ]
        assert len(logs) >= 10
        for t, p in logs:
            gt = max((tt, g) for tt, g in truth if tt <= t)[1]
            assert math.hypot(p["x"] - gt["x"][r], p["y"] - gt["y"][r]) < 0.1


FAILING = """
[session]
name = "failing-service"
duration_s = 3
on_robot_failure = "{policy}"
[arena]
width_m = 4
length_m = 4
[[robots]]
profile = "eswarbot"
count = 2
behaviour = "random_walk"
[[services]]
kind = "global_controller"
name = "ctl"
options = {{ controller = "tests.support.failing_controller:FailsAtOneSecond", target = [2.0, 2.0] }}
"""


@pytest.mark.parametrize("policy, code", [("continue", 0), ("stop", 1)])
def test_a_service_that_raises_is_a_recorded_failure(tmp_path: Path, policy: str, code: int) -> None:
    cfg = tmp_path / f"{policy}.toml"
    cfg.write_text(FAILING.format(policy=policy))
    rc, s = session_run(cfg, tmp_path / policy)
    assert rc == code
    (f,) = s["failures"]
    assert f["service"] == "ctl" and f["kind"] == "raised" and "controller fault at 1 s" in f["detail"]
    assert f["t_s"] == pytest.approx(1.0)
    assert s["services"]["ctl"]["failed"] and s["services"]["ctl"]["missions"] == 4  # 0, 0.25, 0.5, 0.75 s
    assert all(r["alive"] for r in s["per_robot"])  # the robots go on without it
    assert s["sim_time_s"] == pytest.approx(3.0 if policy == "continue" else 1.01)
    events = [
        json.loads(d) for topic, _, d in iter_messages(tmp_path / policy / "session.mcap") if topic == "/session/events"
    ]
    assert events and events[0]["service"] == "ctl"


SONPIS = """
[session]
name = "sonpi-camera"
duration_s = 4
seed = 2
robots_per_process = 3
[arena]
width_m = 3
length_m = 3
[[robots]]
count = 3
profile = "sonpi"
behaviour = "roy_apf"
params = { optimiser = "fixed", target_x = 25.0, target_y = 25.0 }  # the controller's target, inside the 3 m arena
placement = { kind = "explicit", poses = [[0.6, 0.6, 0.0], [1.2, 0.6, 0.0], [0.6, 1.2, 0.0]] }
[robots.devices.sonpi_wifi]
url = "sitl://wifi"
localisation = "camera"
controller = "controller"
[[services]]
kind = "overhead_camera"
name = "camera"
[[services]]
kind = "global_controller"
name = "controller"
options = { target = [2.5, 2.5] }
"""


def test_sonpis_send_their_odometry_and_the_camera_fuses_it(tmp_path: Path) -> None:
    """Chapter 3's controller on SonPIs, its poses from the camera: every robot's Arduino odometry reaches the camera
    and corrects its fixes; the controller hears every robot."""
    cfg = tmp_path / "sonpis.toml"
    cfg.write_text(SONPIS)
    rc, s = session_run(cfg, tmp_path / "sonpis")
    assert rc == 0, s.get("error")
    cam = s["services"]["camera"]
    assert cam["frames"] == 40 and cam["frames_without_pose"] == 0 and cam["malformed"] == 0
    assert cam["odometry"] >= 3 * 36  # every robot, 10 a second once its program runs
    assert cam["fused"] >= 3 * 34
    assert cam["position_error_m"]["p95"] < 0.01 and cam["heading_error_deg"]["p95"] < 10
    assert s["services"]["controller"]["robots_reporting"] == 3
    assert all(r["alive"] for r in s["per_robot"])


HIDDEN_SONPI = {  # a beam over robot 2's start: the camera has never seen it when its program starts
    "session": {"name": "sonpi-hidden", "duration_s": 8, "seed": 4, "robots_per_process": 3},
    "arena": {"width_m": 3, "length_m": 3},
    "robots": [{
        "count": 3, "profile": "sonpi", "behaviour": "roy_apf", "params": {"optimiser": "fixed", "v_max": 1.5,
                                                                  "target_x": 25, "target_y": 25},
        "placement": {"kind": "explicit", "poses": [[0.6, 0.6, 0.0], [1.2, 0.6, 0.0], [0.6, 2.2, 0.0]]},
        "devices": {"sonpi_wifi": {"url": "sitl://wifi", "localisation": "camera", "first_pose_timeout_s": 1.0}},
    }],
    "services": [{"kind": "overhead_camera", "name": "camera", "options": {
        "mode": "noise", "occluders": [{"x": 0.6, "y": 2.2, "z": 0.6, "size": [0.9, 0.9, 0.05]}]}}],
}


def test_a_sonpi_the_camera_has_never_seen_drives_on_its_odometry(tmp_path: Path) -> None:
    """Robot 2 starts under a beam: its pose device has no pose (NoPose) after its first_pose_timeout_s; its program
    and tracking layer steer by its encoders meanwhile (no failure), it drives out from under the beam, and once the
    camera sees it, the camera's pose steers it again."""
    cfg = tmp_path / "hidden.toml"
    cfg.write_text(to_toml(HIDDEN_SONPI))
    out = tmp_path / "hidden"
    rc, s = session_run(cfg, out)
    assert rc == 0, s.get("error")
    assert all(r["alive"] for r in s["per_robot"])
    mcap = out / "session.mcap"
    sources = [json.loads(d)["source"] for topic, _, d in iter_messages(mcap) if topic == "/r002/log/pose_source"]
    assert sources[:2] == ["odometry", "camera"], sources
    assert all(
        json.loads(d)["source"] == "camera"
        for topic, _, d in iter_messages(out / "session.mcap")
        if topic in ("/r000/log/pose_source", "/r001/log/pose_source")
    )
    truth = _truth(out)
    first, last = truth[0][1], truth[-1][1]
    moved = math.hypot(last["x"][2] - first["x"][2], last["y"][2] - first["y"][2])
    assert moved > 0.4, moved
