"""The marker tracker: pyramidal Lucas-Kanade optical flow (``cv2.calcOpticalFlowPyrLK``) carries each robot's marker
from one frame to the next, its colour pins it down, its white dot gives the heading.

Per frame and robot:

1. a tracked robot's marker centre is flowed from the previous grey frame to this one (LK, ``win`` x ``win`` window,
   ``levels`` pyramid levels); a lost one (or one whose flow failed) is looked for in the whole frame by its colour
   (re-acquisition: the largest blob of its hue);
2. in a window around that point the marker's own hue and the white dot are segmented (HSV thresholds); the disc's
   centre is the centroid of disc and dot together (the dot lies inside the disc), the heading the direction from it
   to the dot's centroid;
3. the fix counts only if the disc shows at least ``min_fill`` of its expected area, the dot at least half of its,
   and the whole disc lies inside the image: a marker partly hidden (under an overhead obstacle, at the image's
   edge) or not seen at all gives no fix, and the robot is lost until its colour is found again.

Pixel coordinates go back to the world through the camera's model (``OverheadCamera.unproject``) at the marker's
height.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from bridge.services.overhead_camera.camera import DOT_RATIO, OverheadCamera

HUE_TOL = 7  # OpenCV hue units (0..180)
SAT_MIN, VAL_MIN = 110, 90
DOT_SAT_MAX, DOT_VAL_MIN = 60, 170
# where a pixel's centroid lies in the camera model's continuous coordinates: pybullet's tiny renderer samples pixel
# column i at u = i and row j at v = j + 1 (measured on rendered frames; tests/services check the bias stays small)
U_OFFSET, V_OFFSET = 0.0, 1.0


@dataclass
class Fix:
    """One robot's camera fix: pose in the world frame, and the pixel it was found at."""

    x: float
    y: float
    yaw: float
    u: float
    v: float


class MarkerTracker:
    def __init__(self, camera: OverheadCamera, win: int = 21, levels: int = 3, min_fill: float = 0.9) -> None:
        self.cam = camera
        self.n = len(camera.hues)
        self.win, self.levels, self.min_fill = win, levels, min_fill
        self.hue_cv = [round(h * 180) % 180 for h in camera.hues]
        self.r_px = [camera.marker_radius[i] * camera.pixels_per_m(camera.marker_height(i)) for i in range(self.n)]
        self.prev_grey: np.ndarray | None = None
        self.last: list[tuple[float, float] | None] = [None] * self.n  # pixel of the last fix, None: lost
        self.counts = {"flowed": 0, "reacquired": 0, "lost": 0, "fixes": 0}

    def _hue_mask(self, hsv: np.ndarray, i: int) -> np.ndarray:
        h = self.hue_cv[i]
        lo, hi = h - HUE_TOL, h + HUE_TOL
        m = cv2.inRange(hsv, (max(lo, 0), SAT_MIN, VAL_MIN), (min(hi, 179), 255, 255))
        if lo < 0:  # red wraps round
            m |= cv2.inRange(hsv, (180 + lo, SAT_MIN, VAL_MIN), (179, 255, 255))
        if hi > 179:
            m |= cv2.inRange(hsv, (0, SAT_MIN, VAL_MIN), (hi - 180, 255, 255))
        return m

    def _reacquire(self, hsv: np.ndarray, i: int) -> tuple[float, float] | None:
        """The centre of the largest blob of robot ``i``'s hue in the whole frame, if it is big enough."""
        m = self._hue_mask(hsv, i)
        n, _, stats, cents = cv2.connectedComponentsWithStats(m, connectivity=8)
        if n <= 1:
            return None
        k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        if stats[k, cv2.CC_STAT_AREA] < 0.25 * math.pi * self.r_px[i] ** 2:
            return None
        return float(cents[k, 0]) + U_OFFSET, float(cents[k, 1]) + V_OFFSET

    def _refine(self, hsv: np.ndarray, i: int, u: float, v: float) -> Fix | None:
        """Robot ``i``'s fix from the window around pixel (u, v), or None if its marker is not seen whole."""
        r = self.r_px[i]
        half = math.ceil(2.0 * r) + 2
        h, w = hsv.shape[:2]
        u0, v0 = max(0, int(u) - half), max(0, int(v) - half)
        u1, v1 = min(w, int(u) + half + 1), min(h, int(v) + half + 1)
        if u1 <= u0 or v1 <= v0:
            return None
        roi = hsv[v0:v1, u0:u1]
        disc = self._hue_mask(roi, i) > 0
        dot = cv2.inRange(roi, (0, 0, DOT_VAL_MIN), (180, DOT_SAT_MAX, 255)) > 0
        dot_area_exp = math.pi * (r * DOT_RATIO) ** 2
        disc_area_exp = math.pi * r * r - dot_area_exp
        if disc.sum() < self.min_fill * disc_area_exp:
            return None
        # only dot pixels close to the disc (another robot's dot in the window is not ours)
        ys, xs = np.nonzero(disc)
        cu, cv_ = xs.mean(), ys.mean()
        dys, dxs = np.nonzero(dot)
        near = (dxs - cu) ** 2 + (dys - cv_) ** 2 <= (1.1 * r) ** 2
        dxs, dys = dxs[near], dys[near]
        if len(dxs) < 0.5 * dot_area_exp:
            return None
        au = (xs.sum() + dxs.sum()) / (len(xs) + len(dxs)) + u0 + U_OFFSET
        av = (ys.sum() + dys.sum()) / (len(ys) + len(dys)) + v0 + V_OFFSET
        du, dv = dxs.mean() + u0 + U_OFFSET, dys.mean() + v0 + V_OFFSET
        if not (r <= au <= w - r and r <= av <= h - r):
            return None  # cut by the image's edge: what shows may not be the whole marker
        z = self.cam.marker_height(i)
        (x, y), (xd, yd) = self.cam.unproject(np.array([[au, av], [du, dv]]), z)
        return Fix(float(x), float(y), math.atan2(yd - y, xd - x), float(au), float(av))

    def track(self, rgb: np.ndarray) -> list[Fix | None]:
        """Every robot's fix in this frame (None: not seen)."""
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
        guess: list[tuple[float, float] | None] = [None] * self.n
        tracked = [i for i in range(self.n) if self.last[i] is not None]
        if tracked and self.prev_grey is not None:
            p0 = (np.array([self.last[i] for i in tracked]) - (U_OFFSET, V_OFFSET)).astype(np.float32).reshape(-1, 1, 2)
            p1, st, _ = cv2.calcOpticalFlowPyrLK(
                self.prev_grey,
                grey,
                p0,
                None,
                winSize=(self.win, self.win),
                maxLevel=self.levels,
                criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.03),
            )
            for k, i in enumerate(tracked):
                if st[k, 0]:
                    guess[i] = (float(p1[k, 0, 0]) + U_OFFSET, float(p1[k, 0, 1]) + V_OFFSET)
        fixes: list[Fix | None] = []
        for i in range(self.n):
            fix = None
            if guess[i] is not None:
                fix = self._refine(hsv, i, *guess[i])
                if fix is not None:
                    self.counts["flowed"] += 1
            if fix is None:
                found = self._reacquire(hsv, i)
                if found is not None:
                    fix = self._refine(hsv, i, *found)
                    if fix is not None:
                        self.counts["reacquired"] += 1
            if fix is None:
                if self.last[i] is not None:
                    self.counts["lost"] += 1
                self.last[i] = None
            else:
                self.counts["fixes"] += 1
                self.last[i] = (fix.u, fix.v)
            fixes.append(fix)
        self.prev_grey = grey
        return fixes
