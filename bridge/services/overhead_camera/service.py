"""The overhead camera localisation service (docs/localisation.md): each frame, every robot's pose from the camera
(tracking: rendered and tracked; noise: drawn from the fitted error model), fused with the odometry the robots send,
broadcast to every node as one pose packet (``swarm_logic.robots.sonpi.pose_packet``).

It scores itself against the ground truth it is given (``senses = ("poses",)``): position and heading error of every
pose it broadcast, and the robot-frames it had no pose for, into its ``summary.json`` entry; with ``log_frames``,
every frame's errors are also recorded (``/svc/NAME/log/frame``: what ``noise.py`` fits its model to).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from bridge.core.config import BoxObstacle
from bridge.core.services import Service, ServiceContext
from bridge.services.overhead_camera.camera import Occluder, OverheadCamera
from bridge.services.overhead_camera.fusion import PoseFilter, wrap
from bridge.services.overhead_camera.noise import NoiseModel
from swarm_logic.robots.sonpi import pose_packet as pp
from swarm_logic.robots.sonpi.interfaces import OdometryReading

MARKER_SHARE = 0.8  # a marker's radius, as a share of the robot's, unless the options say


def default_eye(width: float, length: float, fov_deg: float, aspect: float, top: float) -> tuple[float, float, float]:
    """Above the arena's centre, just high enough that the image covers the arena floor with a 5 % margin."""
    t = math.tan(math.radians(fov_deg) / 2)
    h = 1.05 * max(length / 2 / t, width / 2 / (t * aspect))
    return (width / 2, length / 2, h + top)


def build_camera(ctx: ServiceContext) -> OverheadCamera:
    """The camera an overhead_camera service's options describe, over the session's arena and robots."""
    o, cfg = ctx.options, ctx.config
    a = cfg.arena
    boxes = [
        (ob.x, ob.y, ob.size[0], ob.size[1], ob.size[2], math.radians(ob.yaw_deg))
        for ob in cfg.obstacles
        if isinstance(ob, BoxObstacle) and ob.motion is None
    ]
    # moving obstacles (toy cars) are not drawn: lower than the markers, they never hide one and never stand still
    cylinders = [
        (ob.x, ob.y, ob.radius, ob.height)
        for ob in cfg.obstacles
        if not isinstance(ob, BoxObstacle) and ob.motion is None
    ]
    top = max([r.height_m for r in ctx.robots] + [0.0])
    eye = (
        tuple(o.eye)
        if o.eye is not None
        else default_eye(a.width_m, a.length_m, o.fov_deg, o.width_px / o.height_px, top)
    )
    radii = [o.marker_radius_m or r.marker_radius_m or MARKER_SHARE * r.radius_m for r in ctx.robots]
    return OverheadCamera(
        a.width_m,
        a.length_m,
        a.wall_height_m,
        a.wall_thickness_m,
        boxes,
        cylinders,
        [Occluder(c.x, c.y, c.z, c.size, math.radians(c.yaw_deg)) for c in o.occluders],
        [(r.radius_m, r.height_m) for r in ctx.robots],
        radii,
        eye,
        o.fov_deg,
        o.width_px,
        o.height_px,
    )


def _stats(values: list[float], scale: float = 1.0) -> dict[str, float | None]:
    if not values:
        return {"mean": None, "p95": None, "max": None}
    a = np.asarray(values) * scale
    return {
        "mean": round(float(a.mean()), 6),
        "p95": round(float(np.quantile(a, 0.95)), 6),
        "max": round(float(a.max()), 6),
    }


class OverheadCameraService(Service):
    def __init__(self, ctx: ServiceContext) -> None:
        super().__init__(ctx)
        o = ctx.options
        self.o = o
        self.period_ns = round(1e9 / o.fps)
        self.frame = 0
        self.camera = build_camera(ctx)
        self.tracker = None
        if o.mode == "tracking":
            from bridge.services.overhead_camera.tracker import MarkerTracker

            self.tracker = MarkerTracker(self.camera)
        self.noise = (
            NoiseModel.load(o.noise_model)
            if o.mode == "noise" and o.noise_model
            else (NoiseModel.load() if o.mode == "noise" else None)
        )
        self.rngs = [ctx.rng("noise", r.id) for r in ctx.robots]
        self.ids = [r.id for r in ctx.robots]
        self.index = {r.id: k for k, r in enumerate(ctx.robots)}
        self.address = {r.address: r.id for r in ctx.robots}
        self.filters = [
            PoseFilter(o.position_gain, o.heading_gain, o.odometry_timeout_s, o.velocity_smoothing) for _ in ctx.robots
        ]
        self.counts = {"frames": 0, "pose_packets": 0, "odometry": 0, "ignored": 0, "malformed": 0, "fused": 0}
        # per robot, what to add to its readings' times to put them on the session's clock: 0 for a robot whose clock
        # is the session's; for one that runs on its own (a program outside the session on the wall clock, a real
        # SonPI's Pi), how far behind the session its first reading was when it was taken in
        self.clock_offset: list[float | None] = [None] * len(ctx.robots)
        self.fused_by_robot = [0] * len(ctx.robots)
        self.pos_err: list[float] = []
        self.yaw_err: list[float] = []
        self.fix_pos_err: list[float] = []
        self.fix_yaw_err: list[float] = []
        self.robot_frames = 0
        self.without_pose = 0
        self.hidden = 0
        self.cost_s: list[float] = []

    def _datagram(self, src: str, data: bytes, t_s: float) -> None:
        """A robot's odometry (taken in at ``t_s``, the service's time); another SonPI packet is ignored; what is not
        one, or odometry naming another robot than its sender, is malformed (counted, dropped)."""
        verdict, head, content = pp.accept(data, pp.Odometry, self.address.get(src))
        if verdict != "ok":
            self.counts[verdict] += 1
            return
        assert isinstance(content, pp.Odometry) and head is not None
        self.counts["odometry"] += 1
        k = self.index[content.id]
        offset = self.clock_offset[k]
        if offset is None:  # its first reading says whether the robot's clock is the session's
            gap = t_s - head.t_s
            offset = self.clock_offset[k] = gap if abs(gap) > self.o.odometry_timeout_s else 0.0
        self.filters[k].odometry(
            OdometryReading(
                head.t_s + offset, content.x_m, content.y_m, content.yaw_rad, content.v_mps, content.w_radps,
                content.left, content.right,
            )
        )

    def step(self, t_ns: int, datagrams: list[tuple[str, bytes]], sensed: dict[str, Any]) -> int | None:
        for src, data in datagrams:
            self._datagram(src, data, t_ns / 1e9)
        due = self.frame * self.period_ns
        if t_ns < due:
            return due
        wall0 = time.perf_counter()  # the bench's figure only: nothing simulated depends on it
        truth = sensed["poses"]
        xs, ys, yaws, alive = truth["x"], truth["y"], truth["yaw"], truth["alive"]
        cam = self.camera
        cam.place(xs, ys, yaws, alive)
        visible = cam.visible(xs, ys, yaws, alive)
        fixes: list[tuple[float, float, float] | None]
        if self.tracker is not None:
            fixes = [None if f is None else (f.x, f.y, f.yaw) for f in self.tracker.track(cam.render())]
        else:
            assert self.noise is not None
            fixes = []
            for k in range(len(xs)):
                seen, ex, ey, eyaw = self.noise.draw(self.rngs[k])
                ok = visible[k] and seen
                fixes.append((xs[k] + ex, ys[k] + ey, wrap(yaws[k] + eyaw)) if ok else None)
        t_s = t_ns / 1e9
        entries: list[pp.PoseEntry] = []
        keys = ("valid", "visible", "ex", "ey", "eyaw", "fix", "fx", "fy", "fyaw")
        rec: dict[str, list] = {key: [] for key in keys}
        for k, rid in enumerate(self.ids):
            est = self.filters[k].update(t_s, fixes[k] if alive[k] else None)
            if est is not None and self.filters[k].odom_used is not None:
                self.counts["fused"] += 1
                self.fused_by_robot[k] += 1
            valid = est is not None
            entries.append(
                pp.PoseEntry(rid, True, est.x, est.y, est.yaw, est.vx, est.vy)
                if est is not None
                else pp.PoseEntry(rid, False)
            )
            ex = ey = eyaw = fx = fy = fyaw = 0.0
            fix = fixes[k] if alive[k] else None
            if alive[k]:
                self.robot_frames += 1
                self.hidden += not visible[k]
                if est is None:
                    self.without_pose += 1
                else:
                    ex, ey, eyaw = est.x - xs[k], est.y - ys[k], wrap(est.yaw - yaws[k])
                    self.pos_err.append(math.hypot(ex, ey))
                    self.yaw_err.append(abs(eyaw))
                if fix is not None:  # the camera's own fix, before the comparator's correction
                    fx, fy, fyaw = fix[0] - xs[k], fix[1] - ys[k], wrap(fix[2] - yaws[k])
                    self.fix_pos_err.append(math.hypot(fx, fy))
                    self.fix_yaw_err.append(abs(fyaw))
            for key, v in zip(keys, (valid, visible[k], ex, ey, eyaw, fix is not None, fx, fy, fyaw), strict=True):
                rec[key].append(round(v, 6) if isinstance(v, float) else v)
        self.send(pp.encode_poses(self.frame, t_s, entries))
        self.counts["pose_packets"] += 1
        self.counts["frames"] += 1
        if self.o.log_frames:
            self.log("frame", {"mode": self.o.mode, "frame": self.frame, **rec})
        self.cost_s.append(time.perf_counter() - wall0)
        self.frame = t_ns // self.period_ns + 1  # the next frame after this one (a late wake skips none twice)
        return self.frame * self.period_ns

    def summary(self) -> dict[str, Any]:
        cost = np.asarray(self.cost_s) * 1e3 if self.cost_s else np.zeros(0)
        return {
            "mode": self.o.mode,
            "fps": self.o.fps,
            "robots": len(self.ids),
            **self.counts,
            "robot_frames": self.robot_frames,
            "frames_without_pose": self.without_pose,
            "robot_frames_hidden": self.hidden,
            "position_error_m": _stats(self.pos_err),
            "heading_error_deg": _stats(self.yaw_err, 180 / math.pi),
            # the camera's own fixes, before fusion with odometry (in noise mode, the drawn ones)
            "fix_position_error_m": _stats(self.fix_pos_err),
            "fix_heading_error_deg": _stats(self.fix_yaw_err, 180 / math.pi),
            "tracker": dict(self.tracker.counts) if self.tracker is not None else None,
            "fused_by_robot": {str(rid): n for rid, n in zip(self.ids, self.fused_by_robot, strict=True)},
            # the robots whose odometry came on a clock of their own, and how far it was from the session's (s)
            "clock_offsets_s": {
                str(rid): round(off, 3) for rid, off in zip(self.ids, self.clock_offset, strict=True) if off
            },
            # wall-clock cost of a frame in this process (render, track, fuse, encode): a speed figure, not simulated
            "frame_cost_ms": {"mean": round(float(cost.mean()), 3), "p95": round(float(np.quantile(cost, 0.95)), 3)}
            if len(cost)
            else None,
        }

    def close(self) -> None:
        self.camera.close()
