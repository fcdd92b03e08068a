"""Chapter 4's formations: the graphs, Kirchhoff's count and the tree enumeration (A7), the MDS embedding, the
mismatch factor, Algorithm 1's choice and the shape names a run logs (B4)."""

import json
import math

import networkx as nx
import numpy as np
import pytest

from swarm_logic.families.roy.regions.formation import (
    DELTA_4_2,
    DELTA_TRI,
    desired_distances,
    embed,
    formation_slots,
    match_formation,
    mismatch,
    shape_name,
    spanning_tree_count,
    spanning_trees,
    tri_coordinates,
)
from swarm_logic.families.roy.regions.shapes import Ellipse


@pytest.mark.parametrize("graph", [DELTA_4_2, DELTA_TRI])
def test_spanning_trees_a7(graph):
    assert graph.sum() // 2 == 9
    assert spanning_tree_count(graph) == 54
    trees = spanning_trees(graph)
    assert len(trees) == 54 and len({t.tobytes() for t in trees}) == 54
    for t in trees:
        g = nx.from_numpy_array(t)
        assert nx.is_tree(g) and g.number_of_nodes() == 6 and np.all(t <= graph)


def test_counts_of_known_graphs():
    k4 = np.ones((4, 4), int) - np.eye(4, dtype=int)
    assert spanning_tree_count(k4) == 16 and len(spanning_trees(k4)) == 16  # Cayley: 4^2
    split = np.zeros((4, 4), int)
    split[0, 1] = split[1, 0] = split[2, 3] = split[3, 2] = 1
    assert spanning_tree_count(split) == 0 and spanning_trees(split) == []
    with pytest.raises(ValueError, match="symmetric"):
        spanning_tree_count(np.triu(k4))


def test_triangular_lattice_edges_are_rho():
    rho = 2.0
    p = tri_coordinates(rho)
    d = np.hypot(*(p[:, None, :] - p[None, :, :]).transpose(2, 0, 1))
    assert np.allclose(d[DELTA_TRI == 1], rho)  # every edge of Delta_tri is one lattice spacing
    assert (np.isclose(d, rho) & (DELTA_TRI == 0)).sum() == 0  # and no other pair is
    assert desired_distances(DELTA_TRI, rho)[1, 3] == rho and desired_distances(DELTA_TRI, rho)[0, 3] == 0


def test_embedding_of_a_path_is_a_line_with_its_lengths():
    path = np.zeros((5, 5), int)
    for i in range(4):
        path[i, i + 1] = path[i + 1, i] = 1
    p = embed(path, desired_distances(path, 2.0))
    d = np.hypot(*(p[:-1] - p[1:]).T)
    assert d == pytest.approx([2.0] * 4) and np.hypot(*(p[0] - p[-1])) == pytest.approx(8.0)
    assert p.mean(axis=0) == pytest.approx([0.0, 0.0], abs=1e-6) and shape_name(p) == "line"


def test_mismatch_modes_on_a_square_in_a_circle():
    s, r = 2.0, 3.0
    square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * s / 2 + [10.0, 4.0]
    circle = Ellipse.circle(0.0, 0.0, r)  # the square is centred on it before comparing
    x, u = s * s, math.pi * r * r
    assert mismatch(square, circle, "iou", pad=0.0) == pytest.approx(1 - x / u, rel=2e-3)
    z = u / x
    assert mismatch(square, circle, "literal", pad=0.0) == pytest.approx(z / (z + x), rel=2e-3)
    # scale: the literal factor changes with the units, 1 - IoU does not
    big = Ellipse.circle(0.0, 0.0, 10 * r)
    assert mismatch(square * 10, big, "iou", pad=0.0) == pytest.approx(mismatch(square, circle, "iou", pad=0.0))
    assert mismatch(square * 10, big, "literal", pad=0.0) != pytest.approx(mismatch(square, circle, "literal", 0.0))
    assert mismatch(np.zeros((3, 2)), circle, "iou", pad=0.0) == 1.0  # a degenerate hull: no overlap


def test_algorithm1_skips_when_it_should():
    rho = 2.0
    pos = tri_coordinates(rho)
    circle = Ellipse.circle(0.0, 0.0, 2.5)
    assert match_formation(pos, DELTA_TRI, DELTA_TRI, rho, circle).reason == "region is a circle"
    roomy = Ellipse(0.0, 0.0, 8.0, 4.0)
    out = match_formation(pos, DELTA_TRI, DELTA_TRI, rho, roomy)
    assert not out.searched and out.reason.startswith("formation hull") and out.adjacency is not None
    compact = tri_coordinates(1.0)  # Theorem 1's spacing: a small hull, but wider than a thin ellipse
    thin = Ellipse(0.5, 0.8, 2.5**2 / 0.6, 0.6)
    assert match_formation(compact, DELTA_TRI, DELTA_TRI, rho, thin).reason.startswith("formation hull")
    fit = match_formation(compact, DELTA_TRI, DELTA_TRI, rho, thin, trigger="fit")
    assert fit.searched and fit.embedding.shape == (6, 2)
    inside = match_formation(compact * 0.2 + [0.5, 0.8], DELTA_TRI, DELTA_TRI, rho, thin, trigger="fit")
    assert inside.reason == "formation fits the ellipse"
    big = np.zeros((12, 12), int)
    assert "scalable law" in match_formation(np.zeros((12, 2)), big, big, rho, roomy).reason


def test_algorithm1_picks_a_line_for_a_narrow_corridor_b4():
    """B4: the triangle does not fit a long thin ellipse; the least-mismatch tree embeds as a line."""
    rho = 2.0
    pos = tri_coordinates(rho)
    assert shape_name(pos) == "triangle"
    corridor = Ellipse(0.0, 0.0, 2.5**2 / 0.8, 0.8, 0.3)
    out = match_formation(pos, DELTA_TRI, DELTA_TRI, rho, corridor)
    assert out.searched and out.n_trees == 54 and out.adjacency.sum() == 2 * 5
    assert out.shape == "line"
    logged = json.loads(json.dumps(out.as_dict(), allow_nan=False))
    assert logged["tree"] == out.tree and len(logged["embedding"]) == 6 and len(logged["adjacency"]) == 6
    scores = [
        mismatch(embed(t, desired_distances(t, rho)), corridor, "iou", rho / 2) for t in spanning_trees(DELTA_TRI)
    ]
    assert out.mismatch == pytest.approx(min(scores)) and out.tree == int(np.argmin(scores))
    assert max(scores) > out.mismatch + 0.1  # the choice matters
    wide = Ellipse(0.0, 0.0, 2.5**2 / 2.0, 2.0, 0.3)  # a mild ellipse: not the same choice
    assert match_formation(pos, DELTA_TRI, DELTA_TRI, rho, wide).shape != "line"


def ring(k: int) -> np.ndarray:
    t = np.arange(k) * 2 * np.pi / k
    return np.stack([np.cos(t), np.sin(t)], axis=1)


def test_shape_names():
    assert shape_name(np.concatenate([ring(5), [[0.0, 0.0]]])) == "pentagon"
    assert shape_name(ring(4)) == "quadrilateral" and shape_name(ring(6)) == "hexagon"
    line = np.stack([np.arange(5.0), 0.05 * np.array([0, 1, 0, -1, 0])], 1)
    assert shape_name(line) == "line"
    assert shape_name(line, heading=0.0) == "column" and shape_name(line, heading=math.pi / 2) == "row"
    assert shape_name(np.zeros((0, 2))) == "empty" and shape_name(np.ones((1, 2))) == "point"


def test_formation_slots_fit_the_ellipse_near_the_agents():
    rho = 1.0
    path = np.zeros((6, 6), int)
    for i in range(5):
        path[i, i + 1] = path[i + 1, i] = 1
    corridor = Ellipse(10.0, 10.0, 2.5**2 / 0.5, 0.5, math.pi / 4)
    agents = tri_coordinates(rho)[::-1] + np.array([10.0, 10.0])
    slots = formation_slots(embed(path, desired_distances(path, rho)), corridor, agents)
    assert np.all(corridor.contains(slots)) and shape_name(slots, heading=math.pi / 4) == "column"
    assert np.hypot(*(slots[1:] - slots[:-1]).T) == pytest.approx([rho] * 5)
    flipped = 2 * corridor.centre - slots  # the same line turned by pi: never nearer the agents than the choice
    assert np.sum((slots - agents) ** 2) <= np.sum((flipped - agents) ** 2)
