"""``ConvergePlanner`` (region planner ``converge``): chapter 4's convergence phase on its own (Roy 2022 §4.3, eqs.
4.6 and 4.16): one circular region of radius ``r_c`` at a fixed centre, every agent pulled to it by the formation
law over a graph at rho = 2 r_s, done when every agent is inside. It needs no obstacle logic, so it is what a user
runs to assemble the swarm before a mission.

The graph is Delta_tri (the triangular formation, §2.2.2) when there are six agents, else all pairs. The centre is
the agents' centroid at the first observation unless given. The convergence gain k_c, which the thesis never gives
(erratum 13), follows from Theorem 1's containment radius (eq. 4.16: r_c = N k_f rho e^-1 / k_c) unless given.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from swarm_logic.families.roy.regions.formation import DELTA_TRI, desired_distances
from swarm_logic.families.roy.regions.laws import Safety, theorem1_kc
from swarm_logic.families.roy.regions.planner import Observation, Plan, Region, RegionPlanner
from swarm_logic.families.roy.regions.records import check_fields
from swarm_logic.families.roy.regions.shapes import Ellipse

GRAPHS = ("auto", "tri", "all")


@dataclass(frozen=True)
class ConvergeParams:
    """The convergence phase's settings, in thesis units. ``centre`` None: the centroid at the first observation;
    ``k_c`` None: Theorem 1's gain for the agents present (erratum 13); ``rho`` = 2 ``r_s`` (erratum 14); ``graph``
    "auto" (Delta_tri for six agents, else all pairs), "tri" or "all"; ``safety`` the formation law's safety term
    (erratum 16: its fields, {} for their defaults; None: the law as printed)."""

    r_c: float = 3.0
    centre: tuple[float, float] | None = None
    r_s: float = 1.0
    k_f: float = 5.0
    k_c: float | None = None
    graph: str = "auto"
    safety: dict[str, float] | None = field(default_factory=dict)
    period_s: float = 0.25

    def __post_init__(self) -> None:
        check_fields(self, ("r_c", "r_s", "k_f", "period_s"))
        if self.k_c is not None and not (math.isfinite(self.k_c) and self.k_c > 0):
            raise ValueError(f"k_c: must be finite and > 0 (or None: Theorem 1's), got {self.k_c}")
        if self.graph not in GRAPHS:
            raise ValueError(f"graph: expected one of {', '.join(GRAPHS)}, got {self.graph!r}")
        if self.centre is not None and (len(self.centre) != 2 or not all(math.isfinite(c) for c in self.centre)):
            raise ValueError(f"centre: expected two finite coordinates, got {self.centre}")
        if self.safety is not None:
            try:
                Safety(**self.safety)
            except TypeError as e:
                raise ValueError(f"safety: {e}") from None

    @property
    def rho(self) -> float:
        return 2.0 * self.r_s


class ConvergePlanner(RegionPlanner):
    """Every period: the region (a circle), each agent's goal (its centre), the formation law with rho o Delta over
    the agents present, and the events: ``region`` once, ``inside`` when an agent enters, ``outside`` if one leaves,
    ``all_inside`` the first time every agent present is inside (the plan is done from then on)."""

    def __init__(self, **params: Any) -> None:
        if isinstance(params.get("centre"), list):
            params["centre"] = tuple(params["centre"])
        self.p = ConvergeParams(**params)
        self.period_s = self.p.period_s
        self.centre: np.ndarray | None = None if self.p.centre is None else np.array(self.p.centre, float)
        self.inside: set[int] = set()
        self.all_inside_t: float | None = None
        self.plans = 0
        self.entered: dict[int, float] = {}

    def graph(self, n: int) -> tuple[str, np.ndarray]:
        """The formation graph for ``n`` agents (in id order) and its name."""
        if self.p.graph == "tri" or (self.p.graph == "auto" and n == 6):
            if n != 6:
                raise ValueError(f"graph: Delta_tri has 6 agents, {n} reported")
            return "tri", DELTA_TRI
        return "all", np.ones((n, n), int) - np.eye(n, dtype=int)

    def k_c(self, n: int) -> float:
        return self.p.k_c if self.p.k_c is not None else theorem1_kc(max(n, 1), self.p.k_f, self.p.rho, self.p.r_c)

    def plan(self, obs: Observation) -> Plan:
        order = np.argsort(obs.ids, kind="stable")
        ids = np.asarray(obs.ids)[order]
        x = np.asarray(obs.positions, float)[order]
        n = len(ids)
        events: list[dict[str, Any]] = []
        if self.centre is None:
            if n == 0:
                return Plan(obs.t, ids, np.zeros((0, 2)), "formation", events=({"kind": "held", "reason": "no agent"},))
            self.centre = x.mean(axis=0)
        cx, cy = (float(c) for c in self.centre)
        region = Region(0, Ellipse.circle(cx, cy, self.p.r_c))
        name, adjacency = self.graph(n)
        k_c = self.k_c(n)
        if self.plans == 0:
            events.append({"kind": "region", "centre": [cx, cy], "r_c": self.p.r_c, "k_c": k_c, "graph": name})
        self.plans += 1
        inside = region.ellipse.contains(x) if n else np.zeros(0, bool)
        now = {int(i) for i, yes in zip(ids, inside, strict=True) if yes}
        for i in sorted(now - self.inside):
            events.append({"kind": "inside", "agent": i})
            self.entered.setdefault(i, obs.t)
        for i in sorted((self.inside - now) & {int(i) for i in ids}):
            events.append({"kind": "outside", "agent": i})
        self.inside = (self.inside - {int(i) for i in ids}) | now
        if self.all_inside_t is None and n and len(now) == n:
            self.all_inside_t = obs.t
            events.append({"kind": "all_inside", "agents": [int(i) for i in ids], "t": obs.t})
        params: dict[str, Any] = {
            "desired": desired_distances(adjacency, self.p.rho).tolist() if n else [],
            "k_c": k_c,
            "k_f": self.p.k_f,
            "safety": self.p.safety,
        }
        goals = np.tile(self.centre, (n, 1))
        return Plan(
            obs.t,
            ids,
            goals,
            "formation",
            params,
            groups=np.zeros(n, int),
            regions=(region,),
            events=tuple(events),
            done=self.all_inside_t is not None,
        )

    def summary(self) -> dict[str, Any]:
        return {
            "params": asdict(self.p),
            "centre": None if self.centre is None else [float(c) for c in self.centre],
            "plans": self.plans,
            "inside": sorted(self.inside),
            "entered": {str(k): v for k, v in sorted(self.entered.items())},
            "all_inside_t": self.all_inside_t,
        }
