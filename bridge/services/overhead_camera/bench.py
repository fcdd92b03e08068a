"""The camera service's cost per frame in tracking mode, measured outside a session (the world, robots and Wi-Fi cost
nothing here): the service built as a session builds it, stepped on robots driving circles, timed per frame.

    python -m bridge.services.overhead_camera.bench [--robots 6] [--frames 100] [--fps 10] [--size 480]

It prints the mean and 95th percentile cost of a frame (render, track, fuse, encode) and the fastest real-time factor
the service alone allows at that frame rate (1 / (fps x cost)). The figure is wall time, for the bench only.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from bridge.core.config import Config
from bridge.core.plan import make_plan
from bridge.hosts.service import service_context


def measure(
    robots: int = 6,
    frames: int = 100,
    fps: float = 10.0,
    size: int = 480,
    profile: str = "eswarbot",
    arena_m: float = 4.0,
) -> dict[str, float]:
    """Cost per frame (ms) of a tracking-mode camera over ``robots`` robots in an ``arena_m`` square arena."""
    cols = math.ceil(math.sqrt(robots))
    step = (arena_m - 1.0) / max(cols - 1, 1)
    poses = [[0.5 + (i % cols) * step, 0.5 + (i // cols) * step, 0.0] for i in range(robots)]
    cfg = Config.model_validate(
        {
            "arena": {"width_m": arena_m, "length_m": arena_m},
            "robots": [{"profile": profile, "count": robots, "placement": {"kind": "explicit", "poses": poses}}],
            "services": [
                {
                    "kind": "overhead_camera",
                    "name": "cam",
                    "options": {"fps": fps, "width_px": size, "height_px": size, "log_frames": False},
                }
            ],
        }
    )
    spec, ctx = service_context(make_plan(cfg), "cam")
    svc = spec.make(ctx)
    period = 1.0 / fps
    cost = []
    try:
        for k in range(frames):
            t = k * period
            a = [0.3 * t + i for i in range(robots)]  # each robot on a circle of 0.25 m, 0.3 rad/s
            sens = {
                "poses": {
                    "x": [p[0] + 0.25 * math.cos(ai) for p, ai in zip(poses, a, strict=True)],
                    "y": [p[1] + 0.25 * math.sin(ai) for p, ai in zip(poses, a, strict=True)],
                    "yaw": [ai + math.pi / 2 for ai in a],
                    "alive": [True] * robots,
                }
            }
            t0 = time.perf_counter()
            svc.run(round(t * 1e9), {"in": [], "sens": sens})
            cost.append(time.perf_counter() - t0)
        s = svc.summary()
    finally:
        svc.close()
    c = np.asarray(cost[1:]) * 1e3  # the first frame acquires every marker in the whole image
    return {
        "robots": robots,
        "frames": frames,
        "fps": fps,
        "size_px": size,
        "mean_ms": round(float(c.mean()), 2),
        "p95_ms": round(float(np.quantile(c, 0.95)), 2),
        "max_rtf": round(1000.0 / (fps * float(c.mean())), 2),
        "position_error_p95_mm": round(s["position_error_m"]["p95"] * 1e3, 2),
        "frames_without_pose": s["frames_without_pose"],
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bridge.services.overhead_camera.bench", description=__doc__)
    ap.add_argument("--robots", type=int, default=6)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--fps", type=float, default=10.0)
    ap.add_argument("--size", type=int, default=480, help="image width and height (px)")
    ap.add_argument("--profile", default="eswarbot", help="the robot model (its body carries the marker)")
    args = ap.parse_args(argv)
    r = measure(args.robots, args.frames, args.fps, args.size, args.profile)
    print(
        f"overhead camera, tracking mode: {r['robots']} robots, {r['size_px']} x {r['size_px']} px at {r['fps']:g} "
        f"fps: {r['mean_ms']} ms a frame (p95 {r['p95_ms']}), at most {r['max_rtf']}x real time for the service "
        f"alone; position error p95 {r['position_error_p95_mm']} mm, {r['frames_without_pose']} robot-frames "
        "without a pose"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
