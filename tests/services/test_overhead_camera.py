"""The overhead camera's parts without a session: its optics, the marker tracker on rendered frames, the hidden robot,
the comparator's fusion and the noise model's fit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bridge.services.overhead_camera.camera import Occluder, OverheadCamera
from bridge.services.overhead_camera.fusion import PoseFilter
from bridge.services.overhead_camera.noise import NoiseModel, fit
from bridge.services.overhead_camera.service import default_eye
from bridge.services.overhead_camera.tracker import MarkerTracker
from swarm_logic.robots.sonpi.interfaces import OdometryReading

N = 6
OCCLUDER = Occluder(3.2, 3.2, 0.6, (0.6, 0.6, 0.05))


@pytest.fixture
def camera():
    cam = OverheadCamera(
        4.0,
        4.0,
        0.3,
        0.1,
        [(1.0, 3.0, 0.3, 0.3, 0.3, 0.0)],
        [],
        [OCCLUDER],
        [(0.1, 0.1)] * N,
        [0.08] * N,
        default_eye(4.0, 4.0, 60.0, 1.0, 0.1),
        60.0,
        480,
        480,
    )
    yield cam
    cam.close()


def test_project_and_unproject_are_inverse(camera):
    pts = np.array([[0.3, 0.4, 0.1], [2.0, 2.0, 0.1], [3.7, 0.2, 0.1]])
    back = camera.unproject(camera.project(pts), 0.1)
    assert np.allclose(back, pts[:, :2], atol=1e-9)
    uv = camera.project(np.array([[2.0, 2.0, 0.0], [3.0, 2.0, 0.0], [2.0, 3.0, 0.0]]))
    assert uv[0] == pytest.approx([240.0, 240.0])
    assert uv[1, 0] > uv[0, 0] and uv[2, 1] < uv[0, 1]  # +x is right, +y is up in the image


def _drive(camera, tracker, xs, ys, yaws, frames, step=0.02):
    fixes = None
    for _ in range(frames):
        xs = [x + step * math.cos(a) for x, a in zip(xs, yaws, strict=True)]
        ys = [y + step * math.sin(a) for y, a in zip(ys, yaws, strict=True)]
        camera.place(xs, ys, yaws, [True] * len(xs))
        fixes = tracker.track(camera.render())
    return xs, ys, fixes


def test_tracker_follows_moving_markers_to_a_few_millimetres(camera):
    rng = np.random.default_rng(3)
    xs, ys = list(rng.uniform(0.6, 2.6, N)), list(rng.uniform(0.6, 2.4, N))
    yaws = list(rng.uniform(-math.pi, math.pi, N))
    tracker = MarkerTracker(camera)
    xs, ys, fixes = _drive(camera, tracker, xs, ys, yaws, 15)
    assert tracker.counts["flowed"] >= N * 13  # after the first frame, optical flow carries every marker
    for i, f in enumerate(fixes):
        assert f is not None
        assert math.hypot(f.x - xs[i], f.y - ys[i]) < 0.006
        assert abs(math.remainder(f.yaw - yaws[i], math.tau)) < math.radians(4)


def test_a_hidden_robot_gets_no_fix_rather_than_a_wrong_one(camera):
    """Robot 0 under the overhead occluder, robot 1 driving out of the image: neither gets a fix; the others do."""
    eye = camera.eye
    camera.close()
    cam = OverheadCamera(
        4.0,
        4.0,
        0.3,
        0.1,
        [],
        [],
        [OCCLUDER],
        [(0.1, 0.1)] * 3,
        [0.08] * 3,
        (eye[0] - 0.6, eye[1], eye[2]),
        60.0,
        480,
        480,
    )  # the image's right edge at x = 3.4 m
    try:
        tracker = MarkerTracker(cam)
        xs, ys, yaws = [3.2, 2.9, 1.0], [3.2, 1.0, 1.0], [0.0, 0.0, 1.0]
        seen = []
        for _ in range(30):
            xs[1] += 0.03  # robot 1 drives out of view at x = 3.4 m
            cam.place(xs, ys, yaws, [True] * 3)
            vis = cam.visible(xs, ys, yaws, [True] * 3)
            fixes = tracker.track(cam.render())
            seen.append((fixes[1] is not None, vis[1]))
            assert fixes[0] is None and not vis[0]
            assert fixes[2] is not None and vis[2]
        assert seen[0] == (True, True) and seen[-1] == (False, False)
        for fixed, visible in seen:
            assert not fixed or visible  # never a fix of a robot the camera cannot see whole
    finally:
        cam.close()


def test_fusion_corrects_odometry_drift_towards_the_camera():
    f = PoseFilter(position_gain=0.3, heading_gain=0.3, odometry_timeout_s=0.5, velocity_smoothing=0.5)
    # odometry in its own frame (starting at 0, 0, 0), drifting: it says 0.11 m per frame, the truth is 0.1 m
    truth = [(1.0 + 0.1 * k, 2.0, 0.0) for k in range(30)]
    for k, (x, y, yaw) in enumerate(truth):
        f.odometry(OdometryReading(0.1 * k, 0.11 * k, 0.0, 0.0, 1.1, 0.0, 0, 0))
        est = f.update(0.1 * k, (x, y, yaw))
    assert est is not None
    # the steady state: 0.01 m too far each frame, corrected by 0.3 of the comparator's error, leaves the estimate
    # d = 0.01 (1 - g) / g ahead of the fix and the error at -0.01 / g
    assert est.x - truth[-1][0] == pytest.approx(0.01 * 0.7 / 0.3, rel=1e-3)
    assert f.last_error[0] == pytest.approx(-0.01 / 0.3, rel=1e-3)
    assert est.vx == pytest.approx(1.1) and est.vy == pytest.approx(0.0, abs=1e-9)
    assert f.update(3.0, None) is None  # unseen: no pose
    again = f.update(3.1, (5.0, 5.0, 1.0))
    assert again is not None and (again.x, again.y, again.yaw) == (5.0, 5.0, 1.0)  # restarts at the fix


def test_fusion_without_odometry_is_the_camera_with_a_finite_difference_velocity():
    f = PoseFilter(position_gain=0.3, heading_gain=0.3, odometry_timeout_s=0.5, velocity_smoothing=1.0)
    f.update(0.0, (1.0, 1.0, 0.0))
    est = f.update(0.1, (1.05, 0.98, 0.1))
    assert (est.x, est.y, est.yaw) == (1.05, 0.98, 0.1)
    assert est.vx == pytest.approx(0.5) and est.vy == pytest.approx(-0.2)


def test_noise_model_fit_recovers_its_parameters():
    rng = np.random.default_rng(5)
    frames = []
    for _ in range(2000):
        vis = [True, True, False]
        valid = [bool(rng.random() > 0.1), True, False]
        frames.append(
            {
                "fix": valid,
                "visible": vis,
                "fx": [float(rng.normal(0.001, 0.002)) for _ in vis],
                "fy": [float(rng.normal(-0.001, 0.003)) for _ in vis],
                "fyaw": [float(rng.normal(0.0, 0.02)) for _ in vis],
            }
        )
    model, counts = fit(frames)
    assert counts["visible_robot_frames"] == 4000
    assert model.miss == pytest.approx(0.05, abs=0.01)
    assert model.x_mean_m == pytest.approx(0.001, abs=3e-4) and model.x_std_m == pytest.approx(0.002, rel=0.1)
    assert model.y_std_m == pytest.approx(0.003, rel=0.1) and model.yaw_std_rad == pytest.approx(0.02, rel=0.1)
    draws = [model.draw(np.random.default_rng(9)) for _ in range(3)]
    assert draws[0] == draws[1] == draws[2]  # a seeded stream gives the same errors


def test_the_shipped_noise_model_is_fitted_with_provenance():
    import json

    from bridge.services.overhead_camera.noise import DEFAULT_MODEL

    d = json.loads(DEFAULT_MODEL.read_text())
    model = NoiseModel.load()
    assert 0 < model.x_std_m < 0.02 and 0 < model.yaw_std_rad < math.radians(10)
    assert d["provenance"]["fixes"] > 1000 and d["provenance"]["sessions"]


def test_fusion_holds_when_odometry_comes_at_its_own_times_and_late():
    """Odometry every 0.1 s half a frame off the camera's, one reading in four lost, each arriving 30 ms late: the
    prediction carries the latest reading on to the frame's time, so the fused pose stays on the fixes."""
    f = PoseFilter(position_gain=0.3, heading_gain=0.3, odometry_timeout_s=0.5, velocity_smoothing=0.5)
    v = 0.15
    readings = [(0.1 * k + 0.05, 0.1 * k + 0.08) for k in range(60) if k % 4 != 3]  # (taken, arrives)
    worst = 0.0
    for frame in range(1, 60):
        t = 0.1 * frame
        for taken, arrives in readings:
            if t - 0.1 < arrives <= t:
                f.odometry(OdometryReading(taken, v * taken, 0.0, 0.0, v, 0.0, 0, 0))  # its own frame from (0, 0, 0)
        est = f.update(t, (1.0 + v * t, 2.0, 0.0))
        if frame > 5:
            worst = max(worst, abs(est.x - (1.0 + v * t)))
    assert worst < 1e-6  # slip-free odometry and exact fixes agree at every frame
