"""Monochrome bitmap maps (as MRSim and Stage use): dark pixels are obstacles.

One loader for the world (collision boxes), placement (free space) and the plot.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the config reads maps too: the dependency runs config -> arena_map at run time
    from bridge.core.config import ArenaCfg


def occupancy(a: ArenaCfg) -> np.ndarray:
    """Boolean grid, True where occupied; row 0 is the arena's far edge (y = rows * resolution)."""
    from PIL import Image

    return np.asarray(Image.open(a.map).convert("L")) < a.map_threshold


def blocked(occ: np.ndarray, res: float, x: float, y: float, clearance: float) -> bool:
    """Is any occupied cell within ``clearance`` of (x, y)?"""
    rows, cols = occ.shape
    c0, c1 = max(0, math.floor((x - clearance) / res)), min(cols, math.ceil((x + clearance) / res))
    r0, r1 = max(0, math.floor(rows - (y + clearance) / res)), min(rows, math.ceil(rows - (y - clearance) / res))
    if c0 >= c1 or r0 >= r1:
        return False
    cells = occ[r0:r1, c0:c1]
    if not cells.any():
        return False
    rr, cc = np.nonzero(cells)
    cx = (cc + c0 + 0.5) * res  # cell centres; a cell counts if its nearest point is within clearance
    cy = (rows - (rr + r0) - 0.5) * res
    dx = np.maximum(np.abs(cx - x) - res / 2, 0)
    dy = np.maximum(np.abs(cy - y) - res / 2, 0)
    return bool(np.any(dx * dx + dy * dy < clearance * clearance))
