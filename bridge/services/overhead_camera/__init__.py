"""``overhead_camera``: the SonPI swarm's localisation service (Roy 2022): an overhead camera over the whole arena,
markers on the robots tracked by Lucas-Kanade optical flow, fused with the robots' encoder odometry, every robot's
pose and velocity broadcast over Wi-Fi each frame (docs/localisation.md).

    [[services]]
    kind = "overhead_camera"
    name = "camera"
    options = { mode = "tracking", fps = 10 }
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from bridge.core.config import BoxObstacle
from bridge.core.services import ServiceContext, ServiceOptions, ServiceSpec

MAX_TRACKED = 12  # robots told apart by marker hue; beyond, use mode = "noise"


class OccluderCfg(BoxObstacle):
    """Something overhead that hides the floor from the camera (a lamp, a beam: robots drive under it), a box as an
    obstacle is, hanging at ``z``."""

    type: Literal["box"] = "box"
    z: float = Field(gt=0, description="its underside's height (m)")


class OverheadCameraOptions(ServiceOptions):
    mode: Literal["tracking", "noise"] = Field(
        "tracking", description="tracking: render and track the markers; noise: draw the fitted errors (large swarms)"
    )
    fps: float = Field(10.0, gt=0, le=60, description="frames per second")
    width_px: int = Field(480, ge=64, le=4096)
    height_px: int = Field(480, ge=64, le=4096)
    fov_deg: float = Field(60.0, gt=5, lt=150, description="vertical field of view")
    eye: tuple[float, float, float] | None = Field(
        None,
        description="the lens's position (m), looking straight down; "
        "default: above the arena's centre, high "
        "enough to see it whole",
    )
    marker_radius_m: float | None = Field(
        None,
        gt=0,
        description="default: the radius of the marker its profile carries (a TopMarker part), else 0.8 x "
        "the robot's radius",
    )
    occluders: list[OccluderCfg] = Field([], description="overhead things between the camera and the floor")
    position_gain: float = Field(
        0.8, gt=0, le=1, description="the comparator's correction gain on x and y (1: the camera alone)"
    )
    heading_gain: float = Field(0.3, gt=0, le=1, description="the comparator's correction gain on the heading")
    odometry_timeout_s: float = Field(0.5, gt=0, description="odometry older than this is not fused")
    velocity_smoothing: float = Field(0.5, gt=0, le=1, description="camera-only velocity: first-order smoothing")
    noise_model: str | None = Field(None, description="noise mode: a fitted model (JSON); default the one shipped")
    log_frames: bool = Field(True, description="record every frame's errors (/svc/NAME/log/frame)")


def _check(o: OverheadCameraOptions, cfg: Any) -> None:
    n = cfg.robot_count
    if o.mode == "tracking" and n > MAX_TRACKED:
        raise ValueError(
            f"mode: tracking tells robots apart by their markers' colours, at most {MAX_TRACKED}; the "
            f'session has {n} robots: use mode = "noise"'
        )
    if o.eye is not None:
        top = max((o.occluders and [c.z + c.size[2] for c in o.occluders]) or [0.0])
        if o.eye[2] <= max(top, cfg.arena.wall_height_m):
            raise ValueError(f"eye: the lens at {o.eye[2]} m is not above the walls and occluders")
    if o.noise_model is not None:
        from bridge.services.overhead_camera.noise import NoiseModel

        try:
            NoiseModel.load(o.noise_model)
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise ValueError(f"noise_model: cannot read {o.noise_model!r} as a fitted model: {e}") from None


def _make(ctx: ServiceContext) -> Any:
    from bridge.services.overhead_camera.service import OverheadCameraService

    return OverheadCameraService(ctx)


SPEC = ServiceSpec(
    "overhead_camera",
    _make,
    OverheadCameraOptions,
    senses=("poses",),
    title="overhead camera: LK marker tracking fused with odometry, poses broadcast over Wi-Fi",
    check=_check,
)
