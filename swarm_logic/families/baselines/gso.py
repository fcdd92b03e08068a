"""GSO, the Glowworm Swarm Optimization of Krishnanand & Ghose (2009a, 2009b), one controller per robot.

Per robot i and iteration t (2009b, eq. 1-4):

    l_i(t) = (1 - rho) l_i(t-1) + gamma J(x_i(t))                                   luciferin update
    N_i(t) = { j : |x_j - x_i| < r_d^i(t),  l_i(t) < l_j(t) }                         brighter neighbours
    p_ij = (l_j - l_i) / sum_{k in N_i} (l_k - l_i);  j drawn with probability p_ij  leader choice
    x_i(t+1) = x_i(t) + s (x_j - x_i) / |x_j - x_i|                                   step toward the leader
    r_d^i(t+1) = min(r_s, max(0, r_d^i(t) + beta (n_t - |N_i(t)|)))                  local-decision range

J is the sensed objective. A robot with no brighter neighbour in its range stays where it is (a local leader).
Neighbours and distances come from the frames of this iteration (each carries its sender's position and
luciferin), so r_s also caps what the radio hears. The step is s even when the leader is nearer (as for the
papers' points: overshooting the leader is how a cluster climbs past it). Robots differ from points in two ways:
obstacles, and the other robots the sonar sees, are handled below the algorithm by the same Braitenberg-style
deflection as EPSO's (the thesis' "low-level obstacle avoidance"), and the step is a rotate-then-go move.

The frame (``<BBHfff``, 16 bytes): magic 0x47 ("G"), robot id, iteration mod 65536, position (x, y), luciferin.
"""

from __future__ import annotations

import math
import random
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar

from swarm_logic.families.baselines.common import COMMON_DEFAULTS, COMMON_RANGES, Iterated, braitenberg

MAGIC = 0x47  # "G"
FRAME = struct.Struct("<BBHfff")
YELLOW, GREEN, RED = (255, 200, 0), (0, 255, 0), (255, 0, 0)


@dataclass(frozen=True, slots=True)
class Frame:
    robot: int
    k: int  # iteration number mod 65536
    x: float
    y: float
    luciferin: float


def encode(f: Frame) -> bytes:
    return FRAME.pack(MAGIC, f.robot, f.k & 0xFFFF, f.x, f.y, f.luciferin)


@lru_cache(maxsize=1024)
def decode(data: bytes) -> Frame | None:
    """The GSO frame in ``data``, or None (another application's frame, wrong length, non-finite numbers).
    Cached: treat the result as read-only."""
    if len(data) != FRAME.size or data[0] != MAGIC:
        return None
    _, robot, k, x, y, lum = FRAME.unpack(data)
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(lum)):
        return None
    return Frame(robot, k, x, y, lum)


def luciferin(l_prev: float, j: float, rho: float, gamma: float) -> float:
    """l(t) = (1 - rho) l(t-1) + gamma J(x(t)) (2009b, eq. 1)."""
    return (1.0 - rho) * l_prev + gamma * j


def decision_range(r_d: float, n_neighbours: int, r_s: float, beta: float, n_t: int) -> float:
    """r_d(t+1) = min(r_s, max(0, r_d(t) + beta (n_t - |N(t)|))) (2009b, eq. 4)."""
    return min(r_s, max(0.0, r_d + beta * (n_t - n_neighbours)))


def leader_probabilities(l_own: float, l_neighbours: Sequence[float]) -> list[float]:
    """p_j = (l_j - l_i) / sum_k (l_k - l_i) over the brighter neighbours (2009b, eq. 2)."""
    gaps = [lj - l_own for lj in l_neighbours]
    total = sum(gaps)
    return [g / total for g in gaps]


def pick(probabilities: Sequence[float], u: float) -> int:
    """Roulette wheel: the index whose cumulative probability first exceeds ``u`` in [0, 1)."""
    acc = 0.0
    for i, pr in enumerate(probabilities):
        acc += pr
        if u < acc:
            return i
    return len(probabilities) - 1


class Gso(Iterated):
    """One robot (glowworm) of the GSO swarm."""

    topic = "gso"
    decode = staticmethod(decode)
    defaults: ClassVar[dict[str, Any]] = {
        **COMMON_DEFAULTS,
        "rho": 0.4,  # luciferin decay constant (2009b)
        "gamma": 0.6,  # luciferin enhancement constant (2009b)
        "beta": 0.033,  # m per missing neighbour: 2009b's 0.08 in its 6-unit peaks domain, scaled to a 2.5 m arena
        "n_t": 5,  # desired number of neighbours (2009b)
        "step_m": 0.0125,  # s: 2009b's 0.03 in the 6-unit domain, scaled to a 2.5 m arena
        "l0": 5.0,  # initial luciferin (2009b), in objective units
        "r_s_m": 1.0,  # hard-limited sensor (here: hearing) range r_s (problem-dependent in the papers: chosen)
        "r_d0_m": 0.0,  # initial local-decision range; 0: r_s (as the papers start it)
        "avoid_m": 0.3,  # Braitenberg reaction radius on the sonar
        "avoid_turn_deg": 90.0,  # deflection of a move when the echo is at contact (scaled by proximity)
    }
    ranges: ClassVar[dict[str, str]] = {
        **COMMON_RANGES,
        "rho": "(0, 1)",
        "gamma": "(0, 1]",
        "beta": "[0, inf)",
        "n_t": "[1, inf)",
        "step_m": "(0, inf)",
        "l0": "(-inf, inf)",
        "r_s_m": "(0, inf)",
        "r_d0_m": "[0, inf)",  # and <= r_s_m
        "avoid_m": "(0, inf)",
        "avoid_turn_deg": "[0, 180]",
    }

    # read only at init and reset: the clock, the swarm's size, the starting luciferin and decision range
    static_params = frozenset({"iteration_s", "n_total", "l0", "r_d0_m"})

    @classmethod
    def check(cls, p: dict[str, Any]) -> None:
        if p["r_d0_m"] > p["r_s_m"]:
            raise ValueError(f"r_d0_m: the initial decision range {p['r_d0_m']} exceeds r_s_m = {p['r_s_m']}")

    def reset_algorithm(self) -> None:
        p = self.p
        self.luciferin = float(p["l0"])
        self.r_d = float(p["r_d0_m"] or p["r_s_m"])
        self.n_neighbours = 0
        self.leader: int | None = None

    def telemetry(self) -> dict[str, float | int]:
        """Iteration, luciferin, decision range, brighter neighbours, the leader followed (-1: none)."""
        return {"k": self.k, "lucif": self.luciferin, "r_d": self.r_d, "n_brighter": self.n_neighbours,
                "leader": -1 if self.leader is None else self.leader}

    def tell(self) -> bytes:
        p = self.p
        self.luciferin = luciferin(self.luciferin, self.h, p["rho"], p["gamma"])
        return encode(Frame(self.robot.id, self.k, self.x, self.y, self.luciferin))

    def decide(self) -> dict[str, Any]:
        p = self.p
        # the luciferin compared is the float32 the neighbours received, so two robots never both see the other as
        # the brighter one
        mine = FRAME.unpack(self.outgoing)[5]
        brighter = [f for f in self.heard.values()
                    if f.luciferin > mine and math.hypot(f.x - self.x, f.y - self.y) < self.r_d]
        brighter.sort(key=lambda f: f.robot)  # the draw must not depend on arrival order
        self.n_neighbours = len(brighter)
        self.leader = None
        avoided = False
        if brighter:
            rng: random.Random = self.robot.rng_py
            j = brighter[pick(leader_probabilities(mine, [f.luciferin for f in brighter]), rng.random())]
            self.leader = j.robot
            dist = p["step_m"]
            heading, avoided = braitenberg(math.atan2(j.y - self.y, j.x - self.x), self.theta, self.sonar,
                                           p["avoid_m"], math.radians(p["avoid_turn_deg"]), tie=rng.random() - 0.5)
            self.move_along(heading, dist)
        self.r_d = decision_range(self.r_d, self.n_neighbours, p["r_s_m"], p["beta"], int(p["n_t"]))
        self.show(RED if avoided else GREEN if brighter else YELLOW)
        return {"luciferin": self.luciferin, "r_d": self.r_d, "n_brighter": self.n_neighbours,
                "leader": -1 if self.leader is None else self.leader, "avoided": avoided}
