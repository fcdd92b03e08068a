"""PPSO, the Physically-embedded PSO of Hereford & Siebold (2008, 2010): the thesis' Algorithm 8.2.

Per robot and iteration:

    h = sense();  if h > h_best: h_best = h, chi_1 = x                       (personal best)
    exchange h with the robots in range: H = {h} U {h_j heard}
    if max H == h: this robot is the local best and shares its position
    if max H > H_best: H_best = max H, chi_2 = x of that robot                (the best ever heard of)
    v = w v + rho_1 r_1 o (chi_1 - x) + rho_2 r_2 o (chi_2 - x),  |v| <= dx_max
    the move's heading is limited to a cone of +-cone_deg around the robot's heading (constrain_movement)
    while the sonar reads a collision: go back back_m, and turn right by turn_deg (go_back_turn_right)

One frame per robot per iteration carries both of the listing's exchanges: the reading h, and, from a robot that
was the local best in the previous iteration, that iteration's value and position. So a best robot's position
reaches the others one iteration late (in the listing it costs a second round of messages). Only the best
robots' frames carry a position, the traffic saving the thesis credits PPSO with (section 8.1.5); the radius R_r
of the exchange is therefore the radio's range.

The frame (little-endian): ``<BBHfB`` magic 0x50 ("P"), robot id, iteration mod 65536, h, flags (1: BEST);
with BEST set, ``<fff`` the previous iteration's h and position (x, y) follow (9 or 21 bytes).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar

from swarm_logic.families.baselines.common import (
    COMMON_DEFAULTS,
    COMMON_RANGES,
    Iterated,
    WindowBest,
    pso_stability_warnings,
    pso_velocity,
    wire,
)
from swarm_logic.geometry import clamp, wrap

MAGIC = 0x50  # "P"
HEAD = struct.Struct("<BBHfB")
BEST_BLOCK = struct.Struct("<fff")
F_BEST = 1
WHITE, GREEN, RED = (255, 255, 255), (0, 255, 0), (255, 0, 0)


@dataclass(frozen=True, slots=True)
class Frame:
    robot: int
    k: int  # iteration number mod 65536
    h: float  # this iteration's reading
    best: tuple[float, float, float] | None = None  # (h, x, y) of the previous iteration, if it was the local best


def encode(f: Frame) -> bytes:
    head = HEAD.pack(MAGIC, f.robot, f.k & 0xFFFF, wire(f.h), F_BEST if f.best is not None else 0)
    if f.best is None:
        return head
    return head + BEST_BLOCK.pack(wire(f.best[0]), f.best[1], f.best[2])


@lru_cache(maxsize=1024)
def decode(data: bytes) -> Frame | None:
    """The PPSO frame in ``data``, or None (another application's frame, a length that disagrees with its flags,
    non-finite numbers). Cached: treat the result as read-only."""
    n = len(data)
    if n < HEAD.size or data[0] != MAGIC:
        return None
    _, robot, k, h, flags = HEAD.unpack_from(data)
    if flags & ~F_BEST or n != HEAD.size + (BEST_BLOCK.size if flags & F_BEST else 0) or not math.isfinite(h):
        return None
    best = None
    if flags & F_BEST:
        best = BEST_BLOCK.unpack_from(data, HEAD.size)
        if not all(math.isfinite(v) for v in best):
            return None
    return Frame(robot, k, h, best)


def constrain_heading(heading: float, reference: float, cone_rad: float) -> float:
    """constrain_movement: ``heading`` limited to within ``cone_rad`` of ``reference`` (both arena-frame angles)."""
    off = wrap(heading - reference)
    return wrap(reference + max(-cone_rad, min(cone_rad, off)))


class Ppso(Iterated):
    """One robot of the PPSO swarm."""

    topic = "ppso"
    decode = staticmethod(decode)
    defaults: ClassVar[dict[str, Any]] = {
        **COMMON_DEFAULTS,
        "w": 0.7298,  # inertia (Clerc & Kennedy 2002 constriction set: Hereford & Siebold's values not available)
        "rho1": 1.4962,  # cognitive coefficient (chi_1, personal best)
        "rho2": 1.4962,  # social coefficient (chi_2, best position heard of)
        "cone_deg": 45.0,  # constrain_movement: largest heading change per iteration (half-angle of the cone)
        "collide_m": 0.1,  # sonar range that counts as a collision
        "back_m": 0.05,  # go_back_turn_right: how far to back off
        "turn_deg": 90.0,  # go_back_turn_right: then turn right (clockwise) by this
        "memory_iterations": 0,  # h_best and H_best are the bests of the last this many iterations (0: ever)
    }
    ranges: ClassVar[dict[str, str]] = {
        **COMMON_RANGES,
        "w": "[0, 1)",  # the inertia: >= 1 the velocity never decays
        "rho1": "[0, inf)",  # attraction coefficients
        "rho2": "[0, inf)",
        "cone_deg": "(0, 180]",
        "collide_m": "(0, inf)",
        "back_m": "(0, inf)",
        "turn_deg": "[0, 180]",
        "memory_iterations": "[0, inf)",
    }

    @classmethod
    def warnings(cls, params: dict[str, Any]) -> list[str]:
        """Stability warnings for a valid parameter set (each names the bound it breaks)."""
        p = cls.resolve(params)
        return pso_stability_warnings(p["w"], p["rho1"], p["rho2"], ("w", "rho1", "rho2"))

    def reset_algorithm(self) -> None:
        self.v = (0.0, 0.0)
        self.hbest = -math.inf
        self.chi1 = (0.0, 0.0)
        self.H_best = -math.inf
        self.chi2 = (0.0, 0.0)
        self.was_best: tuple[float, float, float] | None = None  # (h, x, y) to share in the next frame
        self.reference: float | None = None  # heading the cone is centred on; None: the robot's own heading
        self.is_best = False
        self.own = WindowBest(int(self.p["memory_iterations"]))  # h_best, chi_1 (used when the window is set)
        self.social = WindowBest(int(self.p["memory_iterations"]))  # H_best, chi_2 (same)

    def telemetry(self) -> dict[str, float | int]:
        """Iteration, neighbours heard, local best (1/0), personal and swarm bests (-3e38: none yet)."""
        return {"k": self.k, "heard": len(self.heard), "is_best": int(self.is_best), "hbest": wire(self.hbest),
                "H_best": wire(self.H_best)}

    def tell(self) -> bytes:
        if self.own.window:  # a changing objective: the best of the last memory_iterations readings
            self.own.add(self.k, self.h, (self.x, self.y))
            self.hbest, self.chi1 = self.own.best()  # type: ignore[misc]
        elif self.h > self.hbest:
            self.hbest, self.chi1 = self.h, (self.x, self.y)
        return encode(Frame(self.robot.id, self.k, self.h, self.was_best))

    def social_update(self) -> None:
        """H = {h} U heard; the local best shares its position (next frame); chi_2 from the best known position."""
        here = (self.h, self.x, self.y)
        self.is_best = all(self.h >= f.h for f in self.heard.values())
        self.was_best = here if self.is_best else None
        offers = [f.best for f in self.heard.values() if f.best is not None]
        if self.is_best:
            offers.append(here)
        if self.social.window:  # the best heard of in the last memory_iterations iterations
            for h, x, y in offers:
                self.social.add(self.k, h, (x, y))
            self.social.forget(self.k)
            best = self.social.best()
            self.H_best, self.chi2 = best if best is not None else (-math.inf, self.chi2)
            return
        for h, x, y in offers:
            if h > self.H_best:
                self.H_best, self.chi2 = h, (x, y)

    def decide(self) -> dict[str, Any]:
        p = self.p
        self.social_update()
        v = pso_velocity(self.v, (self.x, self.y), p["w"], ((p["rho1"], self.chi1), (p["rho2"], self.chi2)),
                         self.robot.rng_py.random)
        self.v = clamp(*v, p["dx_max_m"])
        reference = self.theta if self.reference is None else self.reference
        collided = self.sonar < p["collide_m"]
        if collided:  # go_back_turn_right: back off along -heading, and face right of where it was going
            self.move_along(self.theta + math.pi, p["back_m"])
            self.reference = wrap(self.theta - math.radians(p["turn_deg"]))
            self.show(RED)
        else:
            heading = constrain_heading(math.atan2(self.v[1], self.v[0]), reference, math.radians(p["cone_deg"]))
            self.move_along(heading, math.hypot(*self.v))
            self.reference = None
            self.show(GREEN if self.is_best else WHITE)
        return {"hbest": wire(self.hbest), "H_best": wire(self.H_best), "is_best": self.is_best,
                "collided": collided, "v": self.v}
