"""Link impairments a fault puts on a wireless medium: partitions and Gilbert-Elliott burst loss.

One place for what the 2.4 GHz channel and the UWB radios both need: which of the frames a receiver would have decoded
it loses instead, for a while.

- A **partition** splits the robots into groups for ``[t0, t1)``: a frame from one group is lost at every receiver of
  another (an obstacle field, a wall of metal shelves, a jammer between two halves of the swarm).
- **Gilbert-Elliott burst loss** (Gilbert 1960, Elliott 1963): each directed link is a two-state Markov chain, stepped
  once per frame it carries: in the good state a frame is lost with ``loss_good``, in the bad one with ``loss_bad``;
  it goes bad with ``p_gb`` and recovers with ``p_bg`` per frame. Losses come in bursts of ``1 / p_bg`` frames on
  average (with ``loss_bad`` 1), a share ``p_gb / (p_gb + p_bg)`` of the time, as measured on 802.15.4 links beside
  Wi-Fi traffic. Links start in the good state; the draws come from the impairment's own seeded stream, so adding one
  never shifts another draw of the session.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bridge.core.rng import stream

#: Fault kinds of the swarm's air rather than of one robot (``[[faults]]`` given without ``robot``)
AIR_FAULTS = ("partition", "burst_loss")
#: the role of a robot model's own UWB radio that ranges and carries data (a DeciZebro's DWM1001), which
#: ``medium = "uwb"`` faults take as they take an eSwarBot's ranging module
UWB_RADIO_ROLE = "uwb_radio"


@dataclass
class Partition:
    """Robots in different ``groups`` hear nothing of each other from ``t0`` to ``t1`` (ns; None: to the end)."""

    t0: int
    t1: int | None
    groups: list[frozenset[int]]

    def active(self, t: int) -> bool:
        return self.t0 <= t and (self.t1 is None or t < self.t1)

    def group_of(self, r: int) -> int:
        """The index of robot ``r``'s group, or -1: a robot in no group hears everyone and is heard by everyone."""
        return next((i for i, g in enumerate(self.groups) if r in g), -1)


@dataclass
class BurstLoss:
    """Gilbert-Elliott loss on the links that start or end at ``robots`` (None: every link), from ``t0`` to ``t1``."""

    t0: int
    t1: int | None
    p_gb: float
    p_bg: float
    loss_good: float
    loss_bad: float
    robots: frozenset[int] | None
    rng: np.random.Generator
    bad: dict[tuple[int, int], bool] = field(default_factory=dict)  # each directed link's state; absent: good
    frames: int = 0
    lost: int = 0

    def active(self, t: int) -> bool:
        return self.t0 <= t and (self.t1 is None or t < self.t1)

    def step(self, src: int, dsts: np.ndarray) -> np.ndarray:
        """One frame from ``src`` to each of ``dsts``: which of them lose it (the links' states step first)."""
        out = np.zeros(len(dsts), dtype=bool)
        u = self.rng.random((len(dsts), 2))  # two draws per link and frame, whatever the states: reproducible
        for k, d in enumerate(dsts.tolist()):
            if self.robots is not None and src not in self.robots and d not in self.robots:
                continue
            was = self.bad.get((src, d), False)
            now = (u[k, 0] >= self.p_bg) if was else (u[k, 0] < self.p_gb)
            self.bad[(src, d)] = now
            out[k] = u[k, 1] < (self.loss_bad if now else self.loss_good)
            self.frames += 1
            self.lost += int(out[k])
        return out


class Impairments:
    """The impairments on one medium; ``lost`` says which receptions they take away."""

    def __init__(self, seed: int, medium: str) -> None:
        self.seed, self.medium = seed, medium
        self.partitions: list[Partition] = []
        self.bursts: list[BurstLoss] = []
        self.partitioned = 0  # receptions a partition took

    def partition(self, t0: int, t1: int | None, groups: list[list[int]]) -> None:
        """Split the robots into ``groups`` from ``t0`` to ``t1`` (ns)."""
        sets = [frozenset(g) for g in groups]
        if len(sets) < 2 or any(not g for g in sets) or sum(map(len, sets)) != len(frozenset().union(*sets)):
            raise ValueError("a partition needs two or more non-empty groups, no robot in two of them")
        self.partitions.append(Partition(t0, t1, sets))

    def burst_loss(self, t0: int, t1: int | None, p_gb: float, p_bg: float, loss_good: float = 0.0,
                   loss_bad: float = 1.0, robots: list[int] | None = None) -> None:
        """Gilbert-Elliott loss from ``t0`` to ``t1`` (ns) on every link, or on those of ``robots``."""
        if not (0 < p_gb <= 1 and 0 < p_bg <= 1 and 0 <= loss_good <= 1 and 0 <= loss_bad <= 1):
            raise ValueError("burst loss: p_gb and p_bg within (0, 1], loss_good and loss_bad within [0, 1]")
        rng = stream(self.seed, self.medium, "burst_loss", len(self.bursts))
        self.bursts.append(BurstLoss(t0, t1, p_gb, p_bg, loss_good, loss_bad,
                                     None if robots is None else frozenset(robots), rng))

    def lost(self, t: int, src: int, dsts: np.ndarray) -> np.ndarray:
        """Which of the receivers ``dsts`` lose a frame ``src`` sent at ``t`` (ns) to an impairment."""
        out = np.zeros(len(dsts), dtype=bool)
        for p in self.partitions:
            if p.active(t) and (g := p.group_of(src)) >= 0:
                cut = np.array([p.group_of(d) not in (-1, g) for d in dsts.tolist()], dtype=bool)
                self.partitioned += int((cut & ~out).sum())
                out |= cut
        for b in self.bursts:
            if b.active(t):
                out |= b.step(src, dsts)
        return out

    def report(self) -> dict[str, int]:
        """Counters for the summary: receptions a partition took, frames a burst-loss chain saw and lost."""
        return {"partitioned": self.partitioned, "burst_frames": sum(b.frames for b in self.bursts),
                "burst_lost": sum(b.lost for b in self.bursts)}
