"""Developing the graph (thesis Algorithm 11): link lists gossiped into an adjacency matrix.

A robot's own links are (me, j) for each neighbour j of its list N1; when j leaves N1 the robot negates both (me, j)
and (j, me), since links are symmetric and j may be unable to tell anyone. It broadcasts its link list M when it
changed (its own links, or links learnt from a neighbour's M); a receiver merges M into its adjacency list and, when
that grew, sends the merged list on. A broken link travels with its negation bit: a receiver deletes it and keeps
the deletion (a tombstone) so that stale copies of the link from third parties do not bring it back; only the
link's owner (robot i of (i, j)) can assert it again. The list is complete when the matrix equals its transpose,
which proves every robot has reported only because links are symmetric (equal radii). It is never used to decide.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

Link = tuple[int, int]


class LinkGossip:
    """One robot's adjacency list and what it has yet to tell."""

    def __init__(self, me: int) -> None:
        self.me = me
        self.links: set[Link] = set()
        self.deleted: set[Link] = set()
        self.own: set[int] = set()
        self.changed = True

    def update_own(self, neighbours: Iterable[int]) -> None:
        """UPDATING M: new links added, broken ones negated, from the current neighbour list N1."""
        now = set(neighbours)
        for j in now - self.own:
            self.links.add((self.me, j))
            self.deleted.discard((self.me, j))
            self.changed = True
        for j in self.own - now:  # links are symmetric: the link is gone both ways
            for link in ((self.me, j), (j, self.me)):
                self.links.discard(link)
                self.deleted.add(link)
            self.changed = True
        self.own = now

    def receive(self, src: int, entries: Iterable[tuple[int, int, bool]]) -> None:
        """RECEIVE LIST OF LINKS: merge a neighbour's M (a negated link deletes, any other adds)."""
        me = self.me
        told = {(i, j) for i, j, neg in entries if not neg and i != me}
        negated = {(i, j) for i, j, neg in entries if neg and i != me}
        gone = negated - self.deleted
        if gone:
            self.links -= gone
            self.deleted |= gone
            self.changed = True
        new = told - self.links
        if new:
            new = {link for link in new if link not in self.deleted or link[0] == src}
            if new:
                self.links |= new
                self.deleted -= new
                self.changed = True

    def outgoing(self) -> list[tuple[int, int, bool]] | None:
        """SEND LIST OF LINKS: the list to broadcast when it changed since the last time, else None."""
        if not self.changed:
            return None
        self.changed = False
        return [(i, j, False) for i, j in sorted(self.links)] + [(i, j, True) for i, j in sorted(self.deleted)]

    def matrix(self, n: int) -> np.ndarray:
        """CONVENE ADJACENCY MATRIX over robots 0..n-1 (links naming others left out)."""
        a = np.zeros((n, n), dtype=bool)
        for i, j in self.links:
            if i < n and j < n:
                a[i, j] = True
        return a

    def complete(self) -> bool:
        """Algorithm 11's test: the adjacency matrix equals its transpose (every link reported from both ends)."""
        return bool(self.links) and all((j, i) in self.links for i, j in self.links)
