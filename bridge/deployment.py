"""Deployment metrics of the marsupial deployment (Couceiro 2013, §5.1.4): how spread out a subgroup lands
(dispersion, eq. 5.11) and how much of the arena the swarm covers right after deployment (1 m discs, §5.3)."""

from __future__ import annotations

import numpy as np


def dispersion(points: np.ndarray) -> float:
    """sigma_s of eq. 5.11: the mean distance of the scouts to their centroid (m)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if not len(pts):
        return 0.0
    return float(np.mean(np.hypot(*(pts - pts.mean(axis=0)).T)))


def covered_share(points: np.ndarray, width_m: float, length_m: float, radius_m: float = 1.0,
                  cell_m: float = 0.05) -> float:
    """Share of the arena within ``radius_m`` of a scout (the union of discs, on a ``cell_m`` grid)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    xs = (np.arange(round(width_m / cell_m)) + 0.5) * cell_m
    ys = (np.arange(round(length_m / cell_m)) + 0.5) * cell_m
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    covered = np.zeros(gx.shape, dtype=bool)
    for x, y in pts:
        covered |= (gx - x) ** 2 + (gy - y) ** 2 <= radius_m * radius_m
    return float(covered.mean())
