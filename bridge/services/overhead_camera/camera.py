"""The overhead camera's scene and optics: a pybullet DIRECT client of its own holding what the camera sees (floor,
walls, obstacles, overhead occluders, each robot's body and its marker on top), posed from the ground truth each
frame and rendered from above (``ER_TINY_RENDERER``), with the pinhole model that maps pixels back to the floor.

A marker is a disc of the robot's own colour (a hue per robot: identity) with a white dot towards its front
(heading). The camera looks straight down from ``eye``; its intrinsics and extrinsics are pybullet's view and
projection matrices, which ``project`` and ``unproject`` use in both directions (pixel coordinates are continuous:
pixel (i, j) covers [i, i+1) x [j, j+1)).
"""

from __future__ import annotations

import colorsys
import math
from dataclasses import dataclass

import numpy as np
import pybullet as pb

FLOOR_GREY = 0.55
WALL_GREY = 0.3
OBSTACLE_GREY = 0.22
OCCLUDER_GREY = 0.4
BODY_GREY = 0.12
MARKER_SAT = 1.0
DOT_RATIO = 0.4  # the white dot's radius, as a share of the marker's
DOT_OFFSET = 0.5  # its centre's distance ahead of the marker's centre, as a share of the marker's radius


@dataclass(frozen=True)
class Occluder:
    """Something overhead between the camera and the floor (a lamp, a beam, a shelf) that robots drive under."""

    x: float
    y: float
    z: float  # its underside's height
    size: tuple[float, float, float]
    yaw: float = 0.0  # rad


def marker_hues(n: int) -> list[float]:
    """Each robot's marker hue (0..1), as far apart as ``n`` allows."""
    return [i / n for i in range(n)]


class OverheadCamera:
    """The camera's own world and its optics."""

    def __init__(
        self,
        arena_w: float,
        arena_l: float,
        wall_h: float,
        wall_t: float,
        boxes: list[tuple],
        cylinders: list[tuple],
        occluders: list[Occluder],
        bodies: list[tuple[float, float]],
        marker_radius: list[float],
        eye: tuple[float, float, float],
        fov_deg: float,
        width: int,
        height: int,
    ) -> None:
        # two clients: the static scene (rendered once, and what lines of sight meet) and the robots (each frame)
        self.scene = pb.connect(pb.DIRECT)
        self.cid = pb.connect(pb.DIRECT)
        self.width, self.height = width, height
        self.eye = np.asarray(eye, float)
        self._background: tuple[np.ndarray, np.ndarray] | None = None
        c = self.scene
        self._box(
            (arena_w / 2, arena_l / 2, -0.005),
            (arena_w / 2 + 2 * wall_t + 5, arena_l / 2 + 2 * wall_t + 5, 0.005),
            FLOOR_GREY,
        )
        for cx, cy, sx, sy in (
            (arena_w / 2, -wall_t / 2, arena_w + 2 * wall_t, wall_t),
            (arena_w / 2, arena_l + wall_t / 2, arena_w + 2 * wall_t, wall_t),
            (-wall_t / 2, arena_l / 2, wall_t, arena_l),
            (arena_w + wall_t / 2, arena_l / 2, wall_t, arena_l),
        ):
            self._box((cx, cy, wall_h / 2), (sx / 2, sy / 2, wall_h / 2), WALL_GREY)
        for x, y, sx, sy, sz, yaw in boxes:
            self._box((x, y, sz / 2), (sx / 2, sy / 2, sz / 2), OBSTACLE_GREY, yaw)
        for x, y, r, h in cylinders:
            v = pb.createVisualShape(
                pb.GEOM_CYLINDER, radius=r, length=h, rgbaColor=[OBSTACLE_GREY] * 3 + [1], physicsClientId=c
            )
            pb.createMultiBody(0, self._collision_cylinder(r, h), v, basePosition=[x, y, h / 2], physicsClientId=c)
        for o in occluders:
            self._box(
                (o.x, o.y, o.z + o.size[2] / 2), (o.size[0] / 2, o.size[1] / 2, o.size[2] / 2), OCCLUDER_GREY, o.yaw
            )
        self.heights = [h for _, h in bodies]
        c = self.cid
        self.marker_radius = marker_radius
        self.bodies: list[int] = []
        self.discs: list[int] = []
        self.dots: list[int] = []
        self.hues = marker_hues(len(bodies))
        for i, (r, h) in enumerate(bodies):
            rgb = colorsys.hsv_to_rgb(self.hues[i], MARKER_SAT, 1.0)
            body = pb.createVisualShape(
                pb.GEOM_CYLINDER, radius=r, length=h, rgbaColor=[BODY_GREY] * 3 + [1], physicsClientId=c
            )
            disc = pb.createVisualShape(
                pb.GEOM_CYLINDER, radius=marker_radius[i], length=0.002, rgbaColor=[*rgb, 1], physicsClientId=c
            )
            dot = pb.createVisualShape(
                pb.GEOM_CYLINDER,
                radius=marker_radius[i] * DOT_RATIO,
                length=0.002,
                rgbaColor=[1, 1, 1, 1],
                physicsClientId=c,
            )
            far = [0.0, 0.0, -100.0]  # parked below the floor until posed
            self.bodies.append(pb.createMultiBody(0, -1, body, basePosition=far, physicsClientId=c))
            self.discs.append(pb.createMultiBody(0, -1, disc, basePosition=far, physicsClientId=c))
            self.dots.append(pb.createMultiBody(0, -1, dot, basePosition=far, physicsClientId=c))
        target = [float(self.eye[0]), float(self.eye[1]), 0.0]
        self.view = pb.computeViewMatrix(self.eye.tolist(), target, [0, 1, 0])
        self.proj = pb.computeProjectionMatrixFOV(fov_deg, width / height, 0.05, float(self.eye[2]) + 1.0)
        self._pv = np.array(self.proj).reshape(4, 4).T @ np.array(self.view).reshape(4, 4).T
        self._pv_inv = np.linalg.inv(self._pv)

    def _collision_cylinder(self, r: float, h: float) -> int:
        return pb.createCollisionShape(pb.GEOM_CYLINDER, radius=r, height=h, physicsClientId=self.scene)

    def _box(
        self, pos: tuple[float, float, float], half: tuple[float, float, float], grey: float, yaw: float = 0.0
    ) -> None:
        c = self.scene
        v = pb.createVisualShape(pb.GEOM_BOX, halfExtents=list(half), rgbaColor=[grey] * 3 + [1], physicsClientId=c)
        s = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=list(half), physicsClientId=c)
        pb.createMultiBody(
            0, s, v, basePosition=list(pos), baseOrientation=pb.getQuaternionFromEuler([0, 0, yaw]), physicsClientId=c
        )

    # -- the scene, each frame -------------------------------------------------------------------------------
    def marker_height(self, i: int) -> float:
        """The height of robot ``i``'s marker's top face (m)."""
        return self.heights[i] + 0.003

    def place(self, x: list[float], y: list[float], yaw: list[float], shown: list[bool]) -> None:
        """Pose every robot's body and marker as the ground truth says (a robot not ``shown``, a dead one, is
        removed)."""
        c = self.cid
        reset = pb.resetBasePositionAndOrientation
        for i in range(len(self.bodies)):
            if not shown[i]:
                for b in (self.bodies[i], self.discs[i], self.dots[i]):
                    reset(b, [0.0, 0.0, -100.0], [0, 0, 0, 1], physicsClientId=c)
                continue
            h = self.heights[i]
            q = pb.getQuaternionFromEuler([0, 0, yaw[i]])
            reset(self.bodies[i], [x[i], y[i], h / 2], q, physicsClientId=c)
            reset(self.discs[i], [x[i], y[i], h + 0.001], q, physicsClientId=c)
            off = self.marker_radius[i] * DOT_OFFSET
            reset(
                self.dots[i],
                [x[i] + off * math.cos(yaw[i]), y[i] + off * math.sin(yaw[i]), h + 0.004],
                q,
                physicsClientId=c,
            )

    def _shoot(self, cid: int) -> tuple[np.ndarray, np.ndarray]:
        """One client's image (RGB) and depth buffer."""
        img = pb.getCameraImage(
            self.width,
            self.height,
            self.view,
            self.proj,
            renderer=pb.ER_TINY_RENDERER,
            flags=pb.ER_NO_SEGMENTATION_MASK,
            shadow=0,
            lightAmbientCoeff=0.8,
            lightDiffuseCoeff=0.2,
            lightSpecularCoeff=0.0,
            physicsClientId=cid,
        )
        rgb = np.asarray(img[2], dtype=np.uint8).reshape(self.height, self.width, 4)[:, :, :3]
        return rgb, np.asarray(img[3], dtype=np.float32).reshape(self.height, self.width)

    def render(self) -> np.ndarray:
        """The frame: an RGB image (height x width x 3, uint8). The static scene is rendered once; each frame renders
        the robots alone and puts them in front of it where they are nearer the lens (a pixel the tiny renderer
        shades costs far more than an empty one, and the floor fills every pixel)."""
        if self._background is None:
            self._background = self._shoot(self.scene)
        bg_rgb, bg_depth = self._background
        rgb, depth = self._shoot(self.cid)
        out = bg_rgb.copy()
        near = depth < bg_depth
        out[near] = rgb[near]
        return out

    # -- optics ----------------------------------------------------------------------------------------------
    def project(self, pts: np.ndarray) -> np.ndarray:
        """World points (n x 3) to pixel coordinates (n x 2: u right, v down)."""
        pts = np.atleast_2d(np.asarray(pts, float))
        clip = np.c_[pts, np.ones(len(pts))] @ self._pv.T
        ndc = clip[:, :2] / clip[:, 3:4]
        return np.c_[(ndc[:, 0] + 1) / 2 * self.width, (1 - ndc[:, 1]) / 2 * self.height]

    def unproject(self, uv: np.ndarray, z: float) -> np.ndarray:
        """Pixel coordinates (n x 2) to the world points (n x 2) on the plane at height ``z`` they show."""
        uv = np.atleast_2d(np.asarray(uv, float))
        ndc = np.c_[2 * uv[:, 0] / self.width - 1, 1 - 2 * uv[:, 1] / self.height]
        near = np.c_[ndc, -np.ones(len(uv)), np.ones(len(uv))] @ self._pv_inv.T
        far = np.c_[ndc, np.ones(len(uv)), np.ones(len(uv))] @ self._pv_inv.T
        near, far = near[:, :3] / near[:, 3:4], far[:, :3] / far[:, 3:4]
        s = (z - near[:, 2]) / (far[:, 2] - near[:, 2])
        return near[:, :2] + s[:, None] * (far[:, :2] - near[:, :2])

    def pixels_per_m(self, z: float) -> float:
        """The image scale at height ``z`` (pixels per metre, at the image centre)."""
        a = self.unproject(np.array([[self.width / 2, self.height / 2], [self.width / 2 + 100, self.height / 2]]), z)
        return 100.0 / float(np.hypot(*(a[1] - a[0])))

    def visible(self, x: list[float], y: list[float], yaw: list[float], shown: list[bool]) -> list[bool]:
        """Which robots' markers the camera sees whole, by geometry alone: the whole disc inside the image and a clear
        line of sight from the lens to its centre and its dot (nothing overhead or taller in between)."""
        n = len(x)
        out = [False] * n
        idx = [i for i in range(n) if shown[i]]
        if not idx:
            return out
        pts = []
        for i in idx:
            z = self.marker_height(i) + 0.002
            off = self.marker_radius[i] * DOT_OFFSET
            pts.append([x[i], y[i], z])
            pts.append([x[i] + off * math.cos(yaw[i]), y[i] + off * math.sin(yaw[i]), z])
        pts_a = np.array(pts)
        uv = self.project(pts_a)
        res = pb.rayTestBatch([self.eye.tolist()] * len(pts), pts_a.tolist(), physicsClientId=self.scene)
        for k, i in enumerate(idx):
            r_px = self.marker_radius[i] * self.pixels_per_m(self.marker_height(i))
            u, v = uv[2 * k]
            inside = r_px <= u <= self.width - r_px and r_px <= v <= self.height - r_px
            clear = res[2 * k][0] == -1 and res[2 * k + 1][0] == -1
            out[i] = inside and clear
        return out

    def close(self) -> None:
        for cid in (self.cid, self.scene):
            if pb.isConnected(cid):
                pb.disconnect(cid)
