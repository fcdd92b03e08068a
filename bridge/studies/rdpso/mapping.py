"""The mapping objective in a co-simulation (``[objective] kind = "mapping"``): the session's side of the objective
family's ``mapping`` field (``bridge.numerical.objectives.MappingField``, on the entropy map of
``bridge.numerical.entropy_map``, thesis chapter 8): the truth grid from a session config's arena, the robots'
scans from their true poses, eq. 8.1 read as lux, and the figures the session records.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bridge.numerical.entropy_map import normalised_auc
from bridge.numerical.objectives import MappingField, make_field


def config_occupancy(cfg: Any, cell_m: float) -> np.ndarray:
    """The truth grid of a session config's arena (rows along y): a cell is occupied when any of 3 x 3 points spread
    over it lies in a box (yawed), a cylinder or a dark pixel of the arena's bitmap map."""
    from bridge.core.config import BoxObstacle

    a = cfg.arena
    nx, ny = math.ceil(a.width_m / cell_m - 1e-9), math.ceil(a.length_m / cell_m - 1e-9)
    sub = (np.arange(3) + 0.5) / 3
    xs = ((np.arange(nx)[:, None] + sub[None, :]) * cell_m).ravel()
    ys = ((np.arange(ny)[:, None] + sub[None, :]) * cell_m).ravel()
    px, py = np.meshgrid(xs, ys)  # (3 ny, 3 nx)
    hit = np.zeros(px.shape, bool)
    for ob in cfg.obstacles:
        if isinstance(ob, BoxObstacle):
            c, s = math.cos(math.radians(ob.yaw_deg)), math.sin(math.radians(ob.yaw_deg))
            u, v = (px - ob.x) * c + (py - ob.y) * s, -(px - ob.x) * s + (py - ob.y) * c
            hit |= (np.abs(u) <= ob.size[0] / 2) & (np.abs(v) <= ob.size[1] / 2)
        else:
            hit |= np.hypot(px - ob.x, py - ob.y) <= ob.radius
    if a.map:
        from bridge.core.arena_map import occupancy

        occ = occupancy(a)
        rows, cols = occ.shape
        res = a.map_resolution_m
        c_ = np.clip((px / res).astype(int), 0, cols - 1)
        r_ = np.clip((rows - py / res).astype(int), 0, rows - 1)  # row 0 is the far edge
        hit |= occ[r_, c_]
    return hit.reshape(ny, 3, nx, 3).any(axis=(1, 3))


class SessionMap:
    """The mapping objective in a co-simulation (``[objective] kind = "mapping"``): every ``scan_period_s`` the live
    robots scan from their true poses; the light sensor reads eq. 8.1 as lux; eta_exp is kept per scan."""

    def __init__(self, cfg: Any) -> None:
        o = cfg.section("objective")
        self.lux_min, self.lux_max = float(o.lux_min), float(o.lux_max)
        field = make_field("mapping", (float(cfg.arena.width_m), float(cfg.arena.length_m)),
                           occupied=config_occupancy(cfg, o.cell_m), cell_m=o.cell_m, r_w_m=o.r_w_m, sigma_m=o.sigma_m)
        assert isinstance(field, MappingField)
        self.field = field
        self.map = field.map
        self.period_ns = round(o.scan_period_s * 1e9)
        self.next_ns = 0
        self.times_s: list[float] = []
        self.eta: list[float] = []

    def tick(self, t_ns: int, pos: np.ndarray, alive: np.ndarray) -> bool:
        """At the start of the quantum at ``t_ns``, before the sensors are read: scan if a scan is due (the first at
        t = 0, from the start poses); returns whether one was."""
        if t_ns < self.next_ns:
            return False
        live = np.asarray(alive, bool)
        if live.any():
            self.field.observe(pos[live, 0], pos[live, 1], len(self.eta))
        self.times_s.append(t_ns / 1e9)
        self.eta.append(self.field.eta())
        while self.next_ns <= t_ns:
            self.next_ns += self.period_ns
        return True

    def record(self) -> dict[str, Any]:
        """The last scan (call after a ``tick`` that scanned), as ``/world/mapping`` records it: eta_exp (eq. 8.3),
        the explored free cells and the map's total entropy in bits (what the swarm minimises, eq. 8.2 summed)."""
        return {"eta_exp": round(self.eta[-1], 6), "scans": len(self.eta),
                "explored_free_cells": self.map.explored_free, "free_cells": self.map.free_cells,
                "entropy_bits": round(float(self.map.entropy.sum()), 3)}

    def lux(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """What the light sensors read at (x, y): eq. 8.1's value mapped onto [lux_min, lux_max]."""
        return self.lux_min + self.field.value(x, y) * (self.lux_max - self.lux_min)

    def summary(self) -> dict[str, Any]:
        """eta_exp at the end, its normalised AUC over the scans, and the map's figures (summary.json)."""
        return {"eta_exp": round(self.eta[-1], 5) if self.eta else None,
                "auc": round(normalised_auc(self.eta), 5) if self.eta else None,
                "scans": len(self.eta), "scan_period_s": self.period_ns / 1e9,
                "eta_exp_every_10_scans": [round(v, 4) for v in self.eta[::10]],
                "cells": self.map.nx * self.map.ny, "free_cells": self.map.free_cells,
                "cell_m": self.map.cell_m, "r_w_m": self.map.r_w_m}
