"""An occupancy-grid entropy map, the model of the mapping objective (thesis chapter 8, eqs. 8.1-8.4;
``bridge.numerical.objectives.MappingField`` is it as a field of the objective family).

The arena is a grid of square cells of ``cell_m``; each holds the probability p that it is occupied (log-odds,
0.5 at the start: nothing known). A robot observes every cell within its sensing radius R_w that it has line of
sight to (a straight ray through no truly occupied cell; the arena's border is a wall), and each observation moves
the cell's log-odds towards what it truly is, free or occupied (an inverse sensor model that is right: ``p_free``
and ``p_occ`` are the probabilities one observation sets from the unknown 0.5).

The entropy of a cell (eq. 8.2, in bits, base 2 throughout) is H(p) = -p log2 p - (1 - p) log2(1 - p). A cell
counts as explored when H <= ``h_explored``; the exploration ratio (eq. 8.3) is eta_exp = A_e / A_a, the share of
the truly free cells that are explored, and the normalised AUC (eq. 8.4) is the mean of eta_exp over the mission's
samples (k = 0..K), so it lies in [0, 1].

What a robot senses (eq. 8.1): the value of its best frontier cell around it,

    h(x) = max_{m in F, |m - x| <= R_w + 1.5 cells}  psi(x, m) * |grad H_sigma(m)| / g_max,

- F, the frontier: unexplored cells next to (4-neighbour) an explored free cell (p < 0.5);
- psi(x, m) in [0, 1], the line-of-sight factor on the map as known: 1 - max p over the cells the ray from x to m
  crosses (m excluded): about 0.9 through explored free space, 0.5 through unknown cells, 0.1 through a known
  obstacle ("m is in line of sight, and so likely empty");
- grad H_sigma: the gradient of the entropy map smoothed by a Gaussian of ``sigma_m`` (default R_w / 2). On the raw
  grid the gradient of every frontier is the same one-cell step, so eq. 8.1 would only say "a frontier is within
  R_w"; smoothed, a frontier in front of a large unknown region reads more than a pocket behind a pillar;
- g_max = 1 / (sigma sqrt(2 pi)), the largest gradient (a straight front between explored and unknown space), so
  h lies in [0, 1].

The robots scan, then sense: h is read on the map that already holds the robot's own scan from where it stands. The
scan leaves every cell within R_w in line of sight explored, so the frontier it can rank is the unexplored rim just
outside its scan: hence the search radius of R_w plus one and a half cells (the cells bordering the scanned disc,
diagonals included). Inside explored space h = 0; on the edge of a large unknown region h is near 1; a shadow
behind a pillar reads less. Everything is vectorised over robots through precomputed disc stencils: the disc's
cell offsets and, for each, the cells its ray crosses.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import ndimage

Bounds = tuple[float, float, float, float]


def entropy(p: np.ndarray) -> np.ndarray:
    """Eq. 8.2 in bits (log base 2 for both terms): 0 for a known cell, 1 for p = 0.5."""
    q = np.clip(np.asarray(p, float), 1e-12, 1.0 - 1e-12)
    return -(q * np.log2(q) + (1.0 - q) * np.log2(1.0 - q))


def normalised_auc(eta: Sequence[float] | np.ndarray) -> float:
    """Eq. 8.4: the mean of eta_exp over the mission's samples k = 0..K (the thesis divides the sum of the 501
    samples of a 500-iteration mission by 500; dividing by the count keeps the AUC within [0, 1])."""
    e = np.asarray(eta, float)
    return float(e.mean()) if len(e) else math.nan


def _logit(p: float) -> float:
    return math.log(p / (1.0 - p))


def rasterise_rects(rects: np.ndarray, bounds: Bounds, cell_m: float, shape: tuple[int, int]) -> np.ndarray:
    """(rows = y, cols = x) cells overlapped (with positive area) by any axis-aligned rectangle (x0, y0, x1, y1)."""
    occ = np.zeros(shape, bool)
    ny, nx = shape
    for x0, y0, x1, y1 in np.asarray(rects, float).reshape(-1, 4):
        i0 = max(0, math.floor((x0 - bounds[0]) / cell_m + 1e-9))
        i1 = min(nx, math.ceil((x1 - bounds[0]) / cell_m - 1e-9))
        j0 = max(0, math.floor((y0 - bounds[1]) / cell_m + 1e-9))
        j1 = min(ny, math.ceil((y1 - bounds[1]) / cell_m - 1e-9))
        occ[j0:max(j0, j1), i0:max(i0, i1)] = True
    return occ


def disc_stencil(radius_cells: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell offsets (K, 2) as (di, dj) within ``radius_cells`` of the centre, and for each the cells its ray from the
    centre crosses before reaching it, (K, S) di and dj, padded with (0, 0) (the robot's own cell)."""
    r = math.floor(radius_cells)
    di, dj = np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1))
    keep = np.hypot(di, dj) <= radius_cells + 1e-9
    off = np.stack([di[keep], dj[keep]], axis=1)
    s = max(1, 3 * r)
    t = (np.arange(1, s + 1) / (s + 1))[None, :]  # samples strictly between the centre and the target
    ri = np.rint(off[:, :1] * t).astype(int)
    rj = np.rint(off[:, 1:] * t).astype(int)
    own = (ri == off[:, :1]) & (rj == off[:, 1:])  # the target cell itself: not on its own ray
    ri[own] = 0
    rj[own] = 0
    return off, ri, rj


_SCAN_CACHE: dict[tuple[Any, ...], _ScanTable] = {}  # by layout


class _ScanTable:
    """For every cell of a grid, filled the first time a robot scans from it: the flat indices (K) of the stencil's
    cells around it and whether a robot there scans each (in the grid, in true line of sight: no occupied cell or
    wall strictly between). The truth does not change, so maps of the same layout share one table."""

    def __init__(self, truth: np.ndarray, off: np.ndarray, ray_i: np.ndarray, ray_j: np.ndarray, pad: int) -> None:
        self.ny, self.nx = truth.shape
        self.truth_pad = np.pad(truth, pad, constant_values=True)  # the border is a wall
        self.off, self.ray_i, self.ray_j, self.pad = off, ray_i, ray_j, pad
        self.own = (ray_i == 0) & (ray_j == 0)
        n = self.ny * self.nx
        self.cells = np.zeros((n, len(off)), np.int32)
        self.ok = np.zeros((n, len(off)), bool)
        self.done = np.zeros(n, bool)

    def rows(self, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(cells, ok) rows of the flat cells ``at``, computing the missing ones."""
        need = np.unique(at[~self.done[at]])
        if len(need):
            jj, ii = np.divmod(need, self.nx)
            cols, rows = ii[:, None] + self.off[None, :, 0], jj[:, None] + self.off[None, :, 1]
            inside = (cols >= 0) & (cols < self.nx) & (rows >= 0) & (rows < self.ny)
            p = self.pad
            blocked = self.truth_pad[jj[:, None, None] + p + self.ray_j[None], ii[:, None, None] + p + self.ray_i[None]]
            blocked &= ~self.own[None]  # the robot's own cell never blocks (an obstacle may clip the cell it is in)
            self.cells[need] = np.where(inside, rows * self.nx + cols, 0)
            self.ok[need] = ~blocked.any(axis=2) & inside
            self.done[need] = True
        return self.cells[at], self.ok[at]


class EntropyMap:
    """Occupancy grid with entropy, exploration ratio and the eq. 8.1 objective (see the module docstring).

    ``occupied``: the truth, (rows along y, cols along x); cells outside the grid are walls."""

    def __init__(self, bounds: Bounds, occupied: np.ndarray, cell_m: float, r_w_m: float, *,
                 sigma_m: float | None = None, p_free: float = 0.1, p_occ: float = 0.9, h_explored: float = 0.5,
                 l_max: float = 6.0) -> None:
        if not cell_m > 0:
            raise ValueError(f"cell_m: must be > 0, got {cell_m!r}")
        if not r_w_m >= cell_m:
            raise ValueError(f"r_w_m: the sensing radius must be at least one cell ({cell_m} m), got {r_w_m!r}")
        if not (0 < p_free < 0.5 < p_occ < 1):
            raise ValueError(f"p_free, p_occ: need 0 < p_free < 0.5 < p_occ < 1, got {p_free}, {p_occ}")
        if not 0 < h_explored < 1:
            raise ValueError(f"h_explored: must lie in (0, 1) bits, got {h_explored!r}")
        self.bounds = tuple(float(b) for b in bounds)
        self.cell_m = float(cell_m)
        self.r_w_m = float(r_w_m)
        self.sigma_m = float(sigma_m) if sigma_m is not None else self.r_w_m / 2.0
        if not self.sigma_m > 0:
            raise ValueError(f"sigma_m: must be > 0, got {sigma_m!r}")
        self.truth = np.asarray(occupied, bool)
        self.ny, self.nx = self.truth.shape
        self.free_cells = int((~self.truth).sum())
        if self.free_cells == 0:
            raise ValueError("the map has no free cell")
        self.l_free, self.l_occ, self.l_max = _logit(p_free), _logit(p_occ), float(l_max)
        self.h_explored = float(h_explored)
        self.p_explored = float(_p_of_entropy(h_explored))  # explored <=> p <= this or p >= 1 - this
        self.off, self.ray_i, self.ray_j = disc_stencil(self.r_w_m / self.cell_m)  # what a scan covers
        self.s_off, self.s_ray_i, self.s_ray_j = disc_stencil(self.r_w_m / self.cell_m + 1.5)  # where h looks
        self.pad = int(np.abs(self.s_off).max()) + 1
        key = (self.truth.shape, self.truth.tobytes(), self.r_w_m / self.cell_m)
        if key not in _SCAN_CACHE:  # the trials of an experiment share their layout, and so one table
            if len(_SCAN_CACHE) >= 4:
                _SCAN_CACHE.pop(next(iter(_SCAN_CACHE)))
            _SCAN_CACHE[key] = _ScanTable(self.truth, self.off, self.ray_i, self.ray_j, self.pad)
        self._scans = _SCAN_CACHE[key]
        self.logodds = np.zeros(self.ny * self.nx)  # flat, row-major (rows along y)
        self._p = np.full(self.ny * self.nx, 0.5)
        self._known = np.zeros(self.ny * self.nx, bool)  # explored: H <= h_explored
        self._explored_free = 0
        self._free_flat = ~self.truth.ravel()
        self._g: np.ndarray | None = None  # padded objective per cell (frontier x normalised gradient), cached
        self._p_pad: np.ndarray | None = None
        self.observations = 0

    # -- geometry -----------------------------------------------------------------------------------------------
    def cell_of(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Column and row of the cells holding the points (clipped to the grid)."""
        i = np.clip(np.floor((np.asarray(x, float) - self.bounds[0]) / self.cell_m), 0, self.nx - 1).astype(int)
        j = np.clip(np.floor((np.asarray(y, float) - self.bounds[1]) / self.cell_m), 0, self.ny - 1).astype(int)
        return i, j

    # -- state --------------------------------------------------------------------------------------------------
    @property
    def p(self) -> np.ndarray:
        """Occupancy probability per cell, (rows along y, cols along x)."""
        return self._p.reshape(self.ny, self.nx)

    @property
    def explored_free(self) -> int:
        """Truly free cells explored so far (the numerator of eta_exp)."""
        return self._explored_free

    @property
    def entropy(self) -> np.ndarray:
        return entropy(self.p)

    @property
    def explored(self) -> np.ndarray:
        """Cells whose entropy is at most ``h_explored``."""
        return self._known.reshape(self.ny, self.nx)

    def eta(self) -> float:
        """Eq. 8.3: explored free cells over free cells."""
        return self._explored_free / self.free_cells

    # -- observing ----------------------------------------------------------------------------------------------
    def scanned(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Flat indices of the cells robots at (x, y) scan: within R_w, in true line of sight (no occupied cell and
        no wall strictly between), inside the grid. A cell several robots scan appears several times."""
        ci, cj = self.cell_of(np.atleast_1d(x), np.atleast_1d(y))
        cells, ok = self._scans.rows(cj * self.nx + ci)
        return cells[ok]

    def observe(self, x: np.ndarray, y: np.ndarray) -> None:
        """Every robot at (x, y) scans; each scanned cell takes one observation of what it truly is (a cell several
        robots scan in the same round takes one)."""
        flat = self.scanned(x, y)
        lo = self.logodds
        new = np.clip(lo[flat] + np.where(self.truth.ravel()[flat], self.l_occ, self.l_free), -self.l_max,
                      self.l_max)
        lo[flat] = new  # duplicates write the same value: one observation per round
        flat = np.unique(flat)
        p = 1.0 / (1.0 + np.exp(-lo[flat]))
        self._p[flat] = p
        known = (p <= self.p_explored) | (p >= 1.0 - self.p_explored)
        was = self._known[flat]
        free = self._free_flat[flat]
        self._explored_free += int((known & ~was & free).sum()) - int((~known & was & free).sum())
        self._known[flat] = known
        self._g = None
        self.observations += 1

    # -- the objective (eq. 8.1) --------------------------------------------------------------------------------
    def _objective_grid(self) -> tuple[np.ndarray, np.ndarray]:
        """Padded frontier x normalised smoothed entropy gradient, and padded p (cached until the next scan)."""
        if self._g is None:
            p = self.p
            explored = self.explored
            known_free = explored & (p < 0.5)
            near_free = ndimage.binary_dilation(known_free, structure=ndimage.generate_binary_structure(2, 1))
            frontier = ~explored & near_free
            hs = ndimage.gaussian_filter(entropy(p), self.sigma_m / self.cell_m, mode="nearest")
            gy, gx = np.gradient(hs, self.cell_m)
            g = np.hypot(gx, gy) * (self.sigma_m * math.sqrt(2.0 * math.pi))
            g = np.where(frontier, np.minimum(g, 1.0), 0.0)
            self._g = np.pad(g, self.pad, constant_values=0.0)
            self._p_pad = np.pad(p, self.pad, constant_values=1.0)
        assert self._p_pad is not None
        return self._g, self._p_pad

    def value(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Eq. 8.1's value at each point: its best frontier cell around it, psi x normalised |grad H|, in [0, 1]."""
        xa, ya = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        g, pp = self._objective_grid()
        ci, cj = self.cell_of(xa.ravel(), ya.ravel())
        ci, cj = ci + self.pad, cj + self.pad
        gm = g[cj[:, None] + self.s_off[None, :, 1], ci[:, None] + self.s_off[None, :, 0]]  # (N, K)
        out = np.zeros(len(ci))
        robot, k = np.nonzero(gm)  # the frontier cells in reach: psi only for those
        if len(robot):
            ray_p = pp[cj[robot, None] + self.s_ray_j[k], ci[robot, None] + self.s_ray_i[k]]  # (M, S)
            ray_p[(self.s_ray_i[k] == 0) & (self.s_ray_j[k] == 0)] = 0.0  # the robot's own cell: not on the ray
            score = (1.0 - ray_p.max(axis=1)) * gm[robot, k]
            np.maximum.at(out, robot, score)
        return out.reshape(xa.shape)

    def best_frontier(self) -> tuple[float, float]:
        """Centre of the frontier cell with the steepest smoothed entropy gradient (the arena centre if none)."""
        g, _ = self._objective_grid()
        core = g[self.pad:-self.pad, self.pad:-self.pad]
        if not core.any():
            return ((self.bounds[0] + self.bounds[2]) / 2, (self.bounds[1] + self.bounds[3]) / 2)
        j, i = np.unravel_index(int(np.argmax(core)), core.shape)
        return (self.bounds[0] + (i + 0.5) * self.cell_m, self.bounds[1] + (j + 0.5) * self.cell_m)


def _p_of_entropy(h: float) -> float:
    """The p in (0, 0.5) with H(p) = h (bisection; H is increasing there)."""
    lo, hi = 1e-12, 0.5
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if entropy(np.array(mid)) < h:
            lo = mid
        else:
            hi = mid
    return lo
