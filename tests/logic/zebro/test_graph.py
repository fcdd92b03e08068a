"""Algorithm 11 (developing the graph), Z-U4: link lists gossiped over rounds give every robot the true adjacency,
symmetric; a broken link sent negated is deleted everywhere and stale copies do not bring it back."""

from __future__ import annotations

import numpy as np

from swarm_logic.families.zebro.graph import LinkGossip


def gossip(nodes: list[LinkGossip], adj: np.ndarray, rounds: int) -> None:
    """Synchronous rounds: each robot sends what changed; its neighbours merge it."""
    for _ in range(rounds):
        out = [(g.me, g.outgoing()) for g in nodes]
        for src, m in out:
            if m is None:
                continue
            for j in np.flatnonzero(adj[src]):
                nodes[j].receive(src, m)


def line(n: int) -> np.ndarray:
    a = np.zeros((n, n), bool)
    for i in range(n - 1):
        a[i, i + 1] = a[i + 1, i] = True
    return a


def test_gossip_builds_the_true_symmetric_adjacency_after_the_diameter() -> None:
    n = 7
    adj = line(n)
    nodes = [LinkGossip(i) for i in range(n)]
    for g in nodes:
        g.update_own(np.flatnonzero(adj[g.me]).tolist())
    gossip(nodes, adj, n - 1)  # diameter 6
    for g in nodes:
        assert np.array_equal(g.matrix(n), adj)
        assert g.complete()


def test_an_incomplete_list_is_not_symmetric() -> None:
    g = LinkGossip(0)
    g.update_own([1])
    assert not g.complete()
    g.receive(1, [(1, 0, False)])
    assert g.complete()


def test_a_negated_link_is_deleted_everywhere_and_stays_deleted() -> None:
    n = 6
    adj = line(n)
    nodes = [LinkGossip(i) for i in range(n)]
    for g in nodes:
        g.update_own(np.flatnonzero(adj[g.me]).tolist())
    gossip(nodes, adj, n)
    adj2 = adj.copy()
    adj2[4, 5] = adj2[5, 4] = False  # the link 4-5 breaks
    for g in nodes:
        g.update_own(np.flatnonzero(adj2[g.me]).tolist())
    gossip(nodes, adj2, 2 * n)
    for g in nodes[:5]:
        assert (4, 5) not in g.links and (5, 4) not in g.links
        assert np.array_equal(g.matrix(n)[:5, :5], adj2[:5, :5])
    # a stale copy from a third party does not revive it; its owner can
    nodes[0].receive(1, [(4, 5, False)])
    assert (4, 5) not in nodes[0].links
    nodes[3].receive(4, [(4, 5, False)])
    assert (4, 5) in nodes[3].links
