"""The camera's error model for ``mode = "noise"``: what the tracker gets wrong, drawn instead of rendered and tracked,
so swarms too large to render (or to give distinct marker colours) still see the camera's errors.

A robot the camera can see (``OverheadCamera.visible``: inside the image, nothing between it and the lens) gets a
fix with probability 1 - ``miss``, displaced by independent normal errors in x, y (m) and heading (rad) of the fitted
means and standard deviations; an unseen robot gets none, as in tracking mode.

The defaults (``noise_model.json`` beside this module) are fitted on tracking-mode sessions: every frame of such a
session logs each robot's fix error against the ground truth, before any fusion with odometry
(``/svc/NAME/log/frame``: ``fix``, ``fx``, ``fy``, ``fyaw``), and

    python -m bridge.services.overhead_camera.noise RUN_DIR [RUN_DIR ...] --out FILE

fits the model to them (means and standard deviations of the errors of every fix; ``miss`` the share of visible
robot-frames without a fix) and writes it with its provenance (the sessions, their seeds and digests, the frames).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

DEFAULT_MODEL = Path(__file__).with_name("noise_model.json")


@dataclass(frozen=True)
class NoiseModel:
    x_mean_m: float
    x_std_m: float
    y_mean_m: float
    y_std_m: float
    yaw_mean_rad: float
    yaw_std_rad: float
    miss: float  # the share of visible robot-frames without a fix

    @classmethod
    def load(cls, path: str | Path = DEFAULT_MODEL) -> NoiseModel:
        d = json.loads(Path(path).read_text())
        return cls(**d["model"])

    def draw(self, rng: np.random.Generator) -> tuple[bool, float, float, float]:
        """One fix's fate: (seen, x error, y error, heading error); a fixed number of draws whatever it is."""
        u, zx, zy, zyaw = float(rng.random()), *rng.standard_normal(3).tolist()
        return (
            u >= self.miss,
            self.x_mean_m + self.x_std_m * zx,
            self.y_mean_m + self.y_std_m * zy,
            self.yaw_mean_rad + self.yaw_std_rad * zyaw,
        )


def fit(frames: list[dict[str, Any]]) -> tuple[NoiseModel, dict[str, int]]:
    """The model that fits tracking-mode frames (each ``{fix, visible, fx, fy, fyaw}``, lists over robots: whether
    the camera had a fix, whether the robot could be seen, the fix's errors against the ground truth before any
    fusion with odometry)."""
    ex, ey, eyaw = [], [], []
    visible = missed = 0
    for f in frames:
        for valid, vis, a, b, c in zip(f["fix"], f["visible"], f["fx"], f["fy"], f["fyaw"], strict=True):
            if vis:
                visible += 1
                missed += not valid
            if valid:
                ex.append(a)
                ey.append(b)
                eyaw.append(c)
    if len(ex) < 2:
        raise ValueError(f"{len(ex)} fixes: too few to fit a model (run tracking-mode sessions longer)")
    x, y, w = np.array(ex), np.array(ey), np.array(eyaw)
    model = NoiseModel(
        round(float(x.mean()), 6),
        round(float(x.std(ddof=1)), 6),
        round(float(y.mean()), 6),
        round(float(y.std(ddof=1)), 6),
        round(float(w.mean()), 6),
        round(float(w.std(ddof=1)), 6),
        round(missed / visible, 6) if visible else 0.0,
    )
    return model, {"fixes": len(ex), "visible_robot_frames": visible, "missed": missed}


def frames_of(run_dir: Path) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The tracking-mode frames a session recorded, and what identifies it (name, seed, digest)."""
    from bridge.core.recorder import iter_messages

    frames = []
    for topic, _t, data in iter_messages(run_dir / "session.mcap"):
        if topic.startswith("/svc/") and topic.endswith("/log/frame"):
            rec = json.loads(data)
            if rec.get("mode") == "tracking":
                frames.append(rec)
    summary = json.loads((run_dir / "summary.json").read_text())
    return frames, {
        "session": summary.get("name"),
        "seed": summary.get("seed"),
        "digest": summary.get("digest"),
        "frames": len(frames),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m bridge.services.overhead_camera.noise",
        description="fit the overhead camera's noise model to tracking-mode sessions",
    )
    ap.add_argument("runs", nargs="+", help="session output directories (session.mcap, summary.json)")
    ap.add_argument("--out", default=str(DEFAULT_MODEL), help="where to write the model (JSON)")
    ap.add_argument("--source", default="", help="how the sessions were made (recorded in the provenance)")
    args = ap.parse_args(argv)
    frames: list[dict[str, Any]] = []
    sources = []
    for run in args.runs:
        try:
            f, src = frames_of(Path(run))
        except (OSError, ValueError) as e:
            print(f"{run}: {e}", file=sys.stderr)
            return 2
        frames += f
        sources.append(src)
    try:
        model, counts = fit(frames)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    out = {
        "model": asdict(model),
        "provenance": {
            "fitted_by": "python -m bridge.services.overhead_camera.noise",
            "source": args.source,
            "sessions": sources,
            **counts,
        },
    }
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    print(
        f"{args.out}: position sd {math.hypot(model.x_std_m, model.y_std_m) * 1000:.2f} mm, heading sd "
        f"{math.degrees(model.yaw_std_rad):.2f} deg, miss {model.miss:.4f} ({counts['fixes']} fixes)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
