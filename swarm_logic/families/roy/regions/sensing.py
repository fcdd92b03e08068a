"""Range readings to obstacle points (Roy 2022 eqs. 4.26-4.29, 5.3-5.5, 6.1-6.4): every agent's beams projected to
world points, filtered by a range window, chapter 4's virtual-boundary test and the eclipse test (a beam that hit a
teammate is not an obstacle), and stacked into one set with the agent that saw each point.

Chapter-neutral: chapter 4 passes its circle for the boundary filter and no window floor, chapter 5 the window
[0.5, 5] of Table 5.1 (erratum 18: below its own 2 r_s requirement, used as printed), chapter 6 the window [2, 5].
Every dropped reading is counted under the first reason that applies, so a caller can log what the sensing lost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from swarm_logic.families.roy.regions.records import Logged, check_fields

DROP_REASONS = ("no_echo", "garbage", "out_of_window", "boundary", "eclipse")


def ring_angles(m: int) -> np.ndarray:
    """The mounting angles (j - 1) z, z = 2 pi / m, of m beams covering the full turn (simulation: m = 8, 45°)."""
    if m < 1:
        raise ValueError(f"m (beam count): must be >= 1, got {m}")
    return np.arange(m) * (2.0 * math.pi / m)


def fan_angles(count: int, spacing: float) -> np.ndarray:
    """``count`` beams ``spacing`` rad apart, centred on the heading (the SonPI: 5 front sonars at 45°: -90..90°)."""
    if count < 1:
        raise ValueError(f"count (beam count): must be >= 1, got {count}")
    return (np.arange(count) - (count - 1) / 2.0) * spacing


@dataclass(frozen=True)
class SensingParams:
    """The reading filters. ``d_min``/``d_max``: the window kept (eqs. 5.3, 6.1; chapter 4 has no floor and a 5 unit
    cap, the digest's default); ``r_robot`` + ``eclipse_eps``: a point this close to a teammate is that teammate (eq.
    4.28, resolved as a distance)."""

    d_min: float = 0.0
    d_max: float = 5.0
    r_robot: float = 0.5
    eclipse_eps: float = 0.1

    def __post_init__(self) -> None:
        check_fields(self, ("d_min", "d_max", "r_robot", "eclipse_eps"), positive=False)
        if self.d_max <= self.d_min:
            raise ValueError(f"d_max: must exceed d_min ({self.d_min}), got {self.d_max}")


@dataclass(frozen=True)
class ObstaclePoints(Logged):
    """The stacked obstacle points of eq. 4.29: ``points`` (K, 2), ``owner`` (K,) the agent whose beam gave each,
    ``beam`` (K,) its beam index, and ``dropped`` the count of readings lost per reason (``DROP_REASONS``)."""

    points: np.ndarray
    owner: np.ndarray
    beam: np.ndarray
    dropped: dict[str, int]

    def __len__(self) -> int:
        return int(self.points.shape[0])


def beam_points(
    positions: np.ndarray, headings: np.ndarray, angles: np.ndarray, owner: np.ndarray, beam: np.ndarray,
    lengths: np.ndarray | float,
) -> np.ndarray:
    """The world points (K, 2) ``lengths`` along beams (``owner``, ``beam``): x_i + d [cos(angle_j + heading_i),
    sin(angle_j + heading_i)] (eq. 5.4; eq. 4.27's "+" is a "x", erratum 9)."""
    a = np.asarray(angles, dtype=float)[beam] + np.asarray(headings, dtype=float)[owner]
    d = np.broadcast_to(np.asarray(lengths, dtype=float), a.shape)
    return np.asarray(positions, dtype=float)[owner] + d[:, None] * np.stack([np.cos(a), np.sin(a)], axis=1)


def sense(
    positions: np.ndarray,
    headings: np.ndarray,
    ranges: np.ndarray,
    angles: np.ndarray,
    params: SensingParams = SensingParams(),
    boundary: tuple[np.ndarray, float] | None = None,
) -> ObstaclePoints:
    """Project each agent's readings to world points and filter them.

    ``positions`` (N, 2), ``headings`` (N,) rad, ``ranges`` (N, m) with NaN for "no echo", ``angles`` (m,) the beams'
    angles from the heading. The world point is x_i + d [cos(angle + heading), sin(angle + heading)] (eq. 5.4; eq.
    4.27's "+" is a "x", erratum 9). ``boundary`` = (O, r_c) applies eq. 4.26: keep d >= r_c - |x_i - O| (only what
    lies beyond the virtual circle). The eclipse filter tests each point against every other agent (never its own).
    Non-finite or negative ranges, and every reading of an agent whose
    pose is not finite, count as garbage."""
    x = np.asarray(positions, dtype=float)
    h = np.asarray(headings, dtype=float)
    d = np.asarray(ranges, dtype=float)
    ang = np.asarray(angles, dtype=float)
    if x.ndim != 2 or x.shape[1] != 2:
        raise ValueError(f"positions: expected shape (N, 2), got {x.shape}")
    n = x.shape[0]
    if h.shape != (n,):
        raise ValueError(f"headings: expected shape ({n},), got {h.shape}")
    if ang.ndim != 1 or d.shape != (n, ang.shape[0]):
        raise ValueError(f"ranges: expected shape ({n}, {ang.shape[0] if ang.ndim == 1 else '?'}), got {d.shape}")
    dropped = dict.fromkeys(DROP_REASONS, 0)
    no_echo = np.isnan(d)
    pose_ok = np.isfinite(x).all(axis=1) & np.isfinite(h)
    garbage = ~no_echo & (~np.isfinite(d) | (d < 0) | ~pose_ok[:, None])
    keep = ~no_echo & ~garbage
    dropped["no_echo"] = int(no_echo.sum())
    dropped["garbage"] = int(garbage.sum())
    window = keep & (d >= params.d_min) & (d <= params.d_max)
    dropped["out_of_window"] = int((keep & ~window).sum())
    keep = window
    if boundary is not None:
        centre, r_c = np.asarray(boundary[0], dtype=float), float(boundary[1])
        inner = r_c - np.hypot(*(x - centre).T)
        beyond = keep & (d >= inner[:, None])
        dropped["boundary"] = int((keep & ~beyond).sum())
        keep = beyond
    owner, beam = np.nonzero(keep)
    pts = beam_points(x, h, ang, owner, beam, d[owner, beam])
    idx = np.nonzero(pose_ok)[0]
    if len(pts) and len(idx) > 1:
        dist, near = cKDTree(x[idx]).query(pts, k=2)
        nearest_other = np.where(idx[near[:, 0]] == owner, dist[:, 1], dist[:, 0])
        hit = nearest_other <= params.r_robot + params.eclipse_eps
        dropped["eclipse"] = int(hit.sum())
        pts, owner, beam = pts[~hit], owner[~hit], beam[~hit]
    return ObstaclePoints(pts.reshape(-1, 2), owner.astype(int), beam.astype(int), dropped)
