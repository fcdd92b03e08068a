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


def link_stats(adj: np.ndarray, rssi: np.ndarray) -> dict[str, float | int | None]:
    """One sample of a subgroup's radio graph, the figures of the thesis' Table 5.2: the mean one-hop RSSI over its
    links (``rssi[i, j]``, sender i, receiver j, both directions of each link), the mean BFS hop count between
    connected non-neighbours (and the scouts relaying, hops - 1, which is what the thesis counts), and the
    algebraic connectivity lambda2 of its Laplacian (0 when it is in pieces)."""
    from scipy.sparse.csgraph import connected_components, shortest_path

    a = (np.asarray(adj, dtype=float) > 0).astype(float)
    n = len(a)
    a = np.maximum(a, a.T)
    np.fill_diagonal(a, 0.0)
    links = a > 0
    out: dict[str, float | int | None] = {"n": n, "links": int(links.sum()) // 2}
    out["rssi_dbm"] = float(np.asarray(rssi, dtype=float)[links].mean()) if links.any() else None
    if n >= 2:
        hops = shortest_path(a, unweighted=True, directed=False)
        far = np.isfinite(hops) & (hops > 1)
        out["hops"] = float(hops[far].mean()) if far.any() else None
        lap = np.diag(a.sum(axis=1)) - a
        out["lambda2"] = float(max(0.0, np.sort(np.linalg.eigvalsh(lap))[1]))
        out["pieces"] = int(connected_components(a, directed=False)[0])
    else:
        out["hops"], out["lambda2"], out["pieces"] = None, 0.0, n
    out["relays"] = None if out["hops"] is None else out["hops"] - 1.0
    return out


def mean_sd(values: list[float]) -> dict[str, float | int | None]:
    """Mean and sample standard deviation of a list of samples (None when empty), rounded for a summary."""
    v = np.asarray([x for x in values if x is not None], dtype=float)
    if not len(v):
        return {"mean": None, "sd": None, "samples": 0}
    return {"mean": round(float(v.mean()), 4), "sd": round(float(v.std(ddof=1)) if len(v) > 1 else 0.0, 4),
            "samples": len(v)}
