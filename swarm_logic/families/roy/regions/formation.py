"""Chapter 4's formations (Roy 2022 §4.2, eqs. 4.2, 4.38-4.40, Algorithm 1): the formation graph Delta and its
desired distances rho o Delta, Kirchhoff's spanning-tree count, the spanning-tree shape matcher that picks a new
formation when the current one does not fit the ellipse, and a name for the shape a set of positions makes.

The thesis' "cut-formation technique" and the embedding of a tree are undefined (erratum 15): a tree is embedded by
classical MDS on its weighted shortest-path distances, each agent drawn as a disc of radius ``pad`` (a line has an
area), and compared to the ellipse after centring and aligning its principal axis with the ellipse's major axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import networkx as nx
import numpy as np
from shapely.geometry import MultiPoint, Polygon

from swarm_logic.families.roy.regions.records import Logged
from swarm_logic.families.roy.regions.shapes import Ellipse

MISMATCH = ("iou", "literal")
TRIGGERS = ("area", "fit")


def graph(rows: str) -> np.ndarray:
    """An adjacency matrix from its rows of 0/1 digits separated by spaces."""
    return np.array([[int(c) for c in row] for row in rows.split()], dtype=int)


# Eq. 4.2 (Fig. 4.4): the hexagon 1-..-6 triangulated by the inner triangle 1-3-5.
DELTA_4_2 = graph("011011 101000 110110 001010 101101 100010")
# §4.6.1's initial "triangular" formation: a 3-row triangular lattice, rows {1}, {2, 3}, {4, 6, 5}.
DELTA_TRI = graph("011000 101101 110011 010001 001001 011110")


def tri_coordinates(rho: float) -> np.ndarray:
    """The triangular formation's positions (6, 2) with spacing ``rho``, agents 1..6 in order (§2.2.2)."""
    h = math.sqrt(3.0) * rho
    return np.array([[0, h], [-rho / 2, h / 2], [rho / 2, h / 2], [-rho, 0], [rho, 0], [0, 0]], dtype=float)


def check_adjacency(adjacency: np.ndarray) -> np.ndarray:
    """``adjacency`` as a symmetric 0/1 int matrix with an empty diagonal, or a ValueError saying what is wrong."""
    a = np.asarray(adjacency)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise ValueError(f"adjacency: expected a square matrix, got shape {a.shape}")
    a = (a != 0).astype(int)
    if not np.array_equal(a, a.T) or a.diagonal().any():
        raise ValueError("adjacency: must be symmetric with an empty diagonal")
    return a


def desired_distances(adjacency: np.ndarray, rho: float) -> np.ndarray:
    """rho o Delta: ``rho`` on every edge, 0 for non-neighbours (erratum 14: rho = 2 r_s; the thesis gives none)."""
    if not (math.isfinite(rho) and rho > 0):
        raise ValueError(f"rho: must be finite and > 0, got {rho}")
    return check_adjacency(adjacency) * float(rho)


def spanning_tree_count(adjacency: np.ndarray) -> int:
    """Kirchhoff's theorem (eq. 4.38): S(G) = (1 / v) prod_{k=1}^{v-1} lambda_k(L), L = D - Delta."""
    a = check_adjacency(adjacency)
    if len(a) < 2:
        return 1
    lam = np.sort(np.linalg.eigvalsh(np.diag(a.sum(axis=1)) - a))[1:]
    return round(float(np.prod(lam)) / len(a))


def spanning_trees(adjacency: np.ndarray) -> list[np.ndarray]:
    """Every spanning tree of the graph as an adjacency matrix, in a fixed order (networkx's iterator over the
    unit-weight graph); empty for a disconnected graph."""
    a = check_adjacency(adjacency)
    g = nx.from_numpy_array(a)
    if len(a) == 0 or not nx.is_connected(g):
        return []
    out = []
    for t in nx.algorithms.tree.mst.SpanningTreeIterator(g):
        m = np.zeros_like(a)
        e = np.array(list(t.edges()), dtype=int).reshape(-1, 2)
        m[e[:, 0], e[:, 1]] = m[e[:, 1], e[:, 0]] = 1
        out.append(m)
    return out


def embed(adjacency: np.ndarray, desired: np.ndarray) -> np.ndarray:
    """A graph's positions (N, 2), centred: classical MDS on its shortest-path distances weighted by ``desired``
    (rho o Delta). A path embeds as a line, a star as a compact blob."""
    a = check_adjacency(adjacency)
    n = len(a)
    g = nx.Graph()
    g.add_nodes_from(range(n))
    i, j = np.nonzero(np.triu(a))
    g.add_weighted_edges_from(zip(i.tolist(), j.tolist(), np.asarray(desired, float)[i, j].tolist(), strict=True))
    d = np.zeros((n, n))
    for s, row in nx.all_pairs_dijkstra_path_length(g):
        for t, v in row.items():
            d[s, t] = v
    c = np.eye(n) - 1.0 / n
    b = -0.5 * c @ (d * d) @ c
    w, v = np.linalg.eigh(b)
    top = np.argsort(w)[::-1][:2]
    return v[:, top] * np.sqrt(np.maximum(w[top], 0.0))


def hull(positions: np.ndarray, pad: float = 0.0) -> Polygon:
    """The convex hull of the (finite) positions, each drawn as a disc of radius ``pad`` (0: the bare hull, possibly
    empty)."""
    p = np.asarray(positions, dtype=float).reshape(-1, 2)
    mp = MultiPoint(p[np.isfinite(p).all(axis=1)])
    h = mp.convex_hull
    return h.buffer(pad) if pad > 0 else (h if isinstance(h, Polygon) else Polygon())


def aligned(positions: np.ndarray, region: Ellipse) -> np.ndarray:
    """The positions centred on the region's centre, their principal axis along the region's major axis."""
    p = np.asarray(positions, dtype=float)
    p = p - p.mean(axis=0)
    _, _, vt = np.linalg.svd(p, full_matrices=False) if len(p) > 1 else (None, None, np.eye(2))
    ax = vt[0]
    major = region.theta if region.a >= region.b else region.theta + math.pi / 2
    rot = major - math.atan2(ax[1], ax[0])
    c, s = math.cos(rot), math.sin(rot)
    return p @ np.array([[c, s], [-s, c]]) + region.centre


def formation_slots(embedding: np.ndarray, region: Ellipse, positions: np.ndarray) -> np.ndarray:
    """Each agent's place (N, 2) in the region for a chosen formation: its embedding (``embed``) aligned with the
    region (``aligned``), and of the four placements the ellipse cannot tell apart (turned by pi, mirrored across
    the major axis) the one nearest the agents' ``positions`` (least sum of squared distances). The thesis' law pulls
    every agent to the centre, so a tree's shape has nothing to form around; a per-agent centre (the laws accept an
    (N, 2) centre) is ours."""
    p = aligned(embedding, region) - region.centre
    c, s = math.cos(region.theta), math.sin(region.theta)
    along = np.array([c, s])
    across = np.array([-s, c])
    u, v = p @ along, p @ across
    x = np.asarray(positions, dtype=float)
    best, cost = None, math.inf
    for su, sv in ((1, 1), (-1, -1), (1, -1), (-1, 1)):
        q = region.centre + (su * u)[:, None] * along + (sv * v)[:, None] * across
        k = float(np.sum((q - x) ** 2))
        if k < cost:
            best, cost = q, k
    return best


def mismatch(positions: np.ndarray, region: Ellipse, mode: str = "iou", pad: float = 0.5) -> float:
    """Eq. 4.40's mismatch between the formation's hull (B, discs of radius ``pad``) and the ellipse (A), after
    centring and aligning (erratum 15). ``mode`` "iou" (default): 1 - |A n B| / |A u B|, in [0, 1], scale-free;
    "literal": Z / (Z + X) with X = |A n B|, Z = |A u B| / |A n B| as printed (depends on the scale). 1 when they do
    not overlap."""
    if mode not in MISMATCH:
        raise ValueError(f"mode: expected one of {', '.join(MISMATCH)}, got {mode!r}")
    b = hull(aligned(positions, region), pad)
    a = region.polygon()
    x = a.intersection(b).area
    if x <= 0:
        return 1.0
    u = a.union(b).area
    if mode == "iou":
        return 1.0 - x / u
    z = u / x
    return z / (z + x)


@dataclass(frozen=True)
class FormationChoice(Logged):
    """Algorithm 1's outcome: ``searched`` whether the tree search ran, ``reason`` why not (or what it chose),
    ``adjacency`` and ``desired`` (rho o Delta) the formation to use, ``mismatch`` its zeta, ``tree`` its index among
    the ``n_trees`` spanning trees (-1: unchanged), ``shape`` its embedding's shape name, ``embedding`` its positions
    (N, 2) centred (for ``formation_slots``; None when unchanged)."""

    searched: bool
    reason: str
    adjacency: np.ndarray
    desired: np.ndarray
    mismatch: float = math.nan
    tree: int = -1
    n_trees: int = 0
    shape: str = ""
    embedding: np.ndarray | None = None


def match_formation(
    positions: np.ndarray,
    graph: np.ndarray,
    current: np.ndarray,
    rho: float,
    region: Ellipse,
    mode: str = "iou",
    pad: float | None = None,
    max_agents: int = 10,
    trigger: str = "area",
) -> FormationChoice:
    """Algorithm 1: when the region is an ellipse and the current formation does not fit it, choose among the
    spanning trees of ``graph`` (the formation graph the trees are cut from) the one whose embedding mismatches the
    ellipse least; otherwise keep ``current``. Above ``max_agents`` agents the search is skipped: the scalable law
    (eq. 4.41) applies.

    ``trigger`` "area" (Algorithm 1 as printed): the hull of the agents' ``positions`` (N, 2), discs of radius
    ``pad`` (default rho / 2), is at least as large as the ellipse; "fit" (ours): some agent lies outside the
    ellipse. Under Theorem 1's gains a 6-agent formation's hull stays well below pi r_c^2, so "area" never fires,
    while its width can exceed the ellipse's and hold the region's barrier for good (see the chapter's page)."""
    if trigger not in TRIGGERS:
        raise ValueError(f"trigger: expected one of {', '.join(TRIGGERS)}, got {trigger!r}")
    pad = rho / 2 if pad is None else pad
    cur = check_adjacency(current)
    keep = FormationChoice(False, "", cur, desired_distances(cur, rho))
    n = len(cur)
    if n > max_agents:
        return FormationChoice(False, f"N = {n} > {max_agents}: the scalable law applies", cur, keep.desired)
    if region.is_circle:
        return FormationChoice(False, "region is a circle", cur, keep.desired)
    if trigger == "area":
        area = hull(positions, pad).area
        if area < region.area:
            return FormationChoice(False, f"formation hull {area:.4g} < ellipse {region.area:.4g}", cur, keep.desired)
    elif np.all(region.contains(np.asarray(positions, dtype=float))):
        return FormationChoice(False, "formation fits the ellipse", cur, keep.desired)
    trees = spanning_trees(graph)
    if not trees:
        return FormationChoice(False, "graph is not connected", cur, keep.desired)
    scores = []
    for t in trees:
        scores.append(mismatch(embed(t, desired_distances(t, rho)), region, mode, pad))
    k = int(np.argmin(scores))
    best = trees[k]
    emb = embed(best, desired_distances(best, rho))
    return FormationChoice(
        True,
        "least mismatch",
        best,
        desired_distances(best, rho),
        float(scores[k]),
        k,
        len(trees),
        shape_name(emb),
        emb,
    )


SHAPES = {3: "triangle", 4: "quadrilateral", 5: "pentagon", 6: "hexagon"}


def shape_name(positions: np.ndarray, heading: float | None = None, line_ratio: float = 0.15, tol: float = 0.1) -> str:
    """The shape the positions make, for a run's formation log: "line" when their spread across the principal axis
    is below ``line_ratio`` times the spread along it ("column" when that axis lies within 45° of ``heading``, else
    "row"), otherwise named by the hull's corners (triangle ... hexagon, else "polygon-<k>") after dropping corners
    that deviate from a straight edge by less than ``tol`` times the formation's size."""
    p = np.asarray(positions, dtype=float).reshape(-1, 2)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) < 2:
        return "point" if len(p) else "empty"
    c = p - p.mean(axis=0)
    _, sv, vt = np.linalg.svd(c, full_matrices=False)
    if len(p) == 2 or sv[-1] <= line_ratio * sv[0]:
        if heading is None:
            return "line"
        ang = math.atan2(vt[0][1], vt[0][0]) - heading
        return "column" if abs(math.cos(ang)) >= math.sqrt(0.5) else "row"
    h = MultiPoint(p).convex_hull
    size = math.sqrt(max(h.area, 1e-300))
    h = h.simplify(tol * size)
    k = len(h.exterior.coords) - 1 if isinstance(h, Polygon) else 2
    return SHAPES.get(k, f"polygon-{k}")
