"""Graph maths every part of the swarm uses: how many pieces a network of robots is in.

Families add their own (the RDPSO's MANET tools are ``swarm_logic.families.rdpso.graph``); the simulator's radio
medium counts partitions with the same function.
"""

from __future__ import annotations

from collections import deque

import numpy as np


def components(a: np.ndarray) -> int:
    """How many pieces the MANET is in: connected components of the graph (a link counts if it works either way;
    0 for no robots)."""
    am = np.asarray(a) != 0
    am = am | am.T
    n = am.shape[0]
    seen = np.zeros(n, dtype=bool)
    count = 0
    for src in range(n):
        if seen[src]:
            continue
        count += 1
        seen[src] = True
        q = deque([src])
        while q:
            u = q.popleft()
            for v in np.flatnonzero(am[u] & ~seen).tolist():
                seen[v] = True
                q.append(v)
    return count
