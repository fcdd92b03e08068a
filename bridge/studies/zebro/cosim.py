"""The thesis' six setups (Table 4.1) as co-simulation sessions: a scenario drawn by the numerical study's own
generator (``numerical.make_scenario``: positions, a flock's headings, particles in the finders' cones, the SRC or LRC
radius) laid out in metres in an arena, as a config of emulated DeciZebros running one of the three algorithms.

What differs from the numerical runs, and why: the robots start at least ``MIN_SEP_U`` body lengths apart (bodies
of 268 x 210 mm must not overlap; the point robots' 1 u would let two bodies touch); the short range (SRC) is the UWB
radios' range (``[uwb] max_range_m``: the modules' transmit power turned down to the radius, with the losses near the
range limit that the realistic mode brings), the long range (LRC) the DWM1001's own 60 m; and time is the robot's:
one control period of 1 s (the UWB's 1 Hz update) and the legs' walking speed, about 0.31 m/s, 1.2 u a tick where
the thesis' calibration walks 0.2 u. ``sensing`` is the robots' option: faithful (error-free ranges,
bearings, headings and delivery, as the thesis assumes) or realistic (the UWB medium's errors and losses, PDoA
bearings, the IMU's noise).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bridge.studies.zebro.numerical import U, make_scenario

SETUPS: dict[str, tuple[int, int, bool]] = {  # Table 4.1: robots, particles, long range
    "E1": (5, 1, False), "E2": (5, 1, True), "E3": (5, 2, False), "E4": (5, 2, True), "E5": (20, 2, False),
    "E6": (20, 2, True)}
# algorithm -> behaviour and its parameters; mature_resend: the mature election repeating its frames every 2 ticks,
# a repair beyond the thesis for a radio that loses frames (docs/zebro-algorithms.md)
BEHAVIOURS: dict[str, tuple[str, dict[str, Any]]] = {
    "silent": ("zebro_silent", {}), "immature": ("zebro_immature", {}), "mature": ("zebro_mature", {}),
    "mature_resend": ("zebro_mature", {"resend_ticks": 2})}
SENSING = ("faithful", "realistic")
SPACING_U = 2.0  # as the numerical study: uniform in a square of side 2 sqrt(n) u
MIN_SEP_U = 1.5  # 0.40 m: two bodies (half-diagonal 0.171 m) never overlap at the start
HEADING_SPREAD_DEG = 40.0  # a flock: headings within +-20 deg of a common one
UTILITIES = (95, 15)
ARENA_M = 40.0  # the swarm starts in the middle, 20 m from the walls: 60 s of walking at 0.31 m/s stays clear
DURATION_S = 60.0  # nothing eaten by then is ignorance (the run-length limit)
SETTLE_S = 10.0  # the session ends this long after the first meal (does the swarm stay together?)
SPLIT_S = 10.0


def scenario_config(setup: str, algorithm: str, sensing: str, seed: int, name: str | None = None,
                    robots_per_process: int | None = None) -> dict[str, Any]:
    """A session config (as a dict, ``to_toml``-ready) of setup ``setup`` drawn from ``seed``, the robots running
    ``algorithm`` (silent | immature | mature | mature_resend) with ``sensing`` (faithful | realistic)."""
    if setup not in SETUPS:
        raise ValueError(f"setup: expected one of {', '.join(SETUPS)}, got {setup!r}")
    if algorithm not in BEHAVIOURS:
        raise ValueError(f"algorithm: expected one of {', '.join(BEHAVIOURS)}, got {algorithm!r}")
    if sensing not in SENSING:
        raise ValueError(f"sensing: expected one of {', '.join(SENSING)}, got {sensing!r}")
    n, p, long_range = SETUPS[setup]
    behaviour, params = BEHAVIOURS[algorithm]
    rng = np.random.default_rng(seed)
    sc = make_scenario(n, p, long_range, rng, spacing_u=SPACING_U, min_sep_u=MIN_SEP_U, utilities=UTILITIES,
                       heading_spread_deg=HEADING_SPREAD_DEG)
    centre = sc.pos.mean(axis=0)
    ox = oy = ARENA_M / 2

    def at(x_u: float, y_u: float) -> tuple[float, float]:
        return round(float(ox + (x_u - centre[0]) * U), 4), round(float(oy + (y_u - centre[1]) * U), 4)

    poses = [[*at(x, y), round(math.degrees(float(h)), 2)] for (x, y), h in zip(sc.pos, sc.heading, strict=True)]
    radius_m = round(float(sc.r_comm) * U, 4)
    # SRC: the radios' transmit power turned down to the radius; LRC: the DWM1001 at full power (its 60 m)
    uwb = {"max_range_m": radius_m} if not long_range else {}
    return {
        "session": {"name": name or f"zebro-{setup.lower()}-{algorithm}", "duration_s": DURATION_S, "seed": seed,
                    "robots_per_process": robots_per_process or (5 if n <= 5 else 10)},
        "arena": {"width_m": ARENA_M, "length_m": ARENA_M},
        **({"uwb": uwb} if uwb else {}),
        "decision": {"end_after_meal_s": SETTLE_S, "split_s": SPLIT_S},
        "robots": [{"count": n, "profile": "decizebro", "behaviour": behaviour, "sensing": sensing,
                    "params": {"d_max_m": round(0.8 * radius_m, 4), **params},
                    "placement": {"kind": "explicit", "poses": poses}}],
        "particles": [{"x": x, "y": y, "utility": u} for x, y, u in ((*at(px, py), pu) for px, py, pu in sc.particles)],
    }
