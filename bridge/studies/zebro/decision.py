"""The decision figures a Zebro session measures (thesis section 4.2, digest 4.2-4.4), in simulated seconds: when a
particle was first sensed, each consumption, the-leader, the frames sent by type, and the communication graph's
connected components (A-13's split), from the world's ground truth and the robots' own logs.

``[decision]`` sets how: the communication radius the components are counted at (the UWB radios' range by default),
how long the graph must stay in pieces to count as a split, and whether the session ends some time after the first
meal (as the numerical runs end ``SETTLE_TICKS`` after it).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import Field

from bridge.core.config import Section


class DecisionCfg(Section):
    """``[decision]``: how a session's collective decision is measured."""

    comm_range_m: float | None = Field(None, gt=0, description="the communication radius the components are counted "
                                                               "at (default: [uwb] max_range_m, the radios' range)")
    sample_s: float = Field(1.0, gt=0, le=60, description="how often the components are counted (the thesis' tick: "
                                                          "the UWB's 1 Hz update)")
    split_s: float = Field(10.0, gt=0, description="A-13: the graph in pieces this long in a row (or at the end) is a "
                                                   "split")
    end_after_meal_s: float | None = Field(None, gt=0, description="end the session this long after the first "
                                                                   "particle is eaten (default: run duration_s)")


def components(pos: np.ndarray, alive: np.ndarray, radius: float) -> int:
    """The connected components of the live robots' disc graph of ``radius``."""
    ids = np.flatnonzero(alive)
    n = len(ids)
    if n == 0:
        return 0
    p = pos[ids, :2]
    adj = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1]) <= radius
    seen = np.zeros(n, dtype=bool)
    count = 0
    for s in range(n):
        if seen[s]:
            continue
        count += 1
        stack = [s]
        seen[s] = True
        while stack:
            k = stack.pop()
            nxt = np.flatnonzero(adj[k] & ~seen)
            seen[nxt] = True
            stack.extend(nxt.tolist())
    return count


class SplitWatch:
    """A-13 on a sampled component count: in pieces for ``split_s`` in a row, or at the end."""

    def __init__(self, split_s: float) -> None:
        self.split_s = split_s
        self.first_apart_s: float | None = None
        self.max_components = 0
        self.last = 1
        self._since: float | None = None
        self.split = False

    def sample(self, t_s: float, count: int) -> None:
        self.max_components = max(self.max_components, count)
        self.last = count
        if count > 1:
            if self.first_apart_s is None:
                self.first_apart_s = t_s
            if self._since is None:
                self._since = t_s
            if t_s - self._since >= self.split_s:
                self.split = True
        else:
            self._since = None

    def report(self) -> dict[str, Any]:
        return {"split": self.split or self.last > 1, "components_max": self.max_components,
                "components_end": self.last, "first_apart_s": self.first_apart_s}
