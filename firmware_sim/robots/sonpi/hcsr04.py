"""The HC-SR04 ultrasonic ranger as the SonPI's board meets it at its pins: a 10 us pulse on TRIG makes it send an
8-cycle 40 kHz burst, then raise ECHO until the first echo comes back, or until its own time-out when none does.
The board times the ECHO pulse and takes half the round trip at the speed of sound as the range.

What is modelled (the figures: the module's datasheet, ``docs/sonpi.md``):

- the round trip at ``SPEED_OF_SOUND`` (dry air at 20 C) to the nearest surface in the sensor's beam (the world's
  ray cone, 15 degrees), plus the burst's own time before ECHO rises (``BURST_US``, not part of the pulse);
- ECHO stays high at most ``ECHO_TIMEOUT_US`` (38 ms, the module's own time-out without an echo);
- per-ping noise on the path (``noise_m + noise_rel * range``, 1 sigma, from a seeded stream);
- cross-talk: when neighbours fire together, each hears the others' bursts; a neighbour's echo (out along its own
  beam, back to this receiver) ends this sensor's pulse when it arrives first and is strong enough, which happens with
  probability ``crosstalk_p`` per neighbour and ping.

A ranger knows nothing of the board's schedule: ``ping`` is one trigger of a set of sensors at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

SPEED_OF_SOUND = 343.2  # m/s, dry air at 20 C
ECHO_TIMEOUT_US = 38_000  # the module ends ECHO after about 38 ms without an echo
BURST_US = 200  # 8 cycles at 40 kHz, and the module's own start-up, before ECHO rises (not timed by the board)
MAX_PATH_M = ECHO_TIMEOUT_US * 1e-6 * SPEED_OF_SOUND  # the longest path an echo can take and still be heard


@dataclass(frozen=True)
class RangerParams:
    """The sensors' mounting and their errors: ``angles_rad`` from the heading (+ left), on a circle of
    ``mount_radius_m`` around the robot's centre (the world casts its rays from just outside it)."""

    angles_rad: tuple[float, ...]
    mount_radius_m: float
    noise_m: float = 0.0
    noise_rel: float = 0.0
    crosstalk_p: float = 0.0


@dataclass(frozen=True, slots=True)
class Echo:
    """One sensor's ECHO pulse: its length (us) and whose burst ended it (None: the time-out)."""

    width_us: int
    source: int | None


class Rangers:
    """The robot's HC-SR04s. ``ping(sensors, ranges_m, rng)`` fires ``sensors`` together, the surfaces in their beams
    at ``ranges_m`` (m from each sensor, ``inf`` where there is none within reach), and returns each one's ECHO
    pulse; with one sensor there is no cross-talk."""

    def __init__(self, p: RangerParams) -> None:
        self.p = p
        self.ux = [math.cos(a) for a in p.angles_rad]
        self.uy = [math.sin(a) for a in p.angles_rad]

    def path_m(self, i: int, j: int, d_j: float) -> float:
        """The path of sensor ``j``'s burst, out ``d_j`` along its beam and back to sensor ``i``'s receiver."""
        if i == j:
            return 2.0 * d_j
        r = self.p.mount_radius_m
        hx, hy = (r + d_j) * self.ux[j], (r + d_j) * self.uy[j]
        return d_j + math.hypot(hx - r * self.ux[i], hy - r * self.uy[i])

    def ping(self, sensors: list[int], ranges_m: list[float], rng: Any) -> dict[int, Echo]:
        p = self.p
        together = set(sensors)
        out: dict[int, Echo] = {}
        for i in sensors:
            best: tuple[float, int] | None = None
            for j in (i, i - 1, i + 1):
                if j not in together:
                    continue
                d = ranges_m[j]
                if not math.isfinite(d):
                    continue
                if j != i and not (p.crosstalk_p > 0 and rng.random() < p.crosstalk_p):
                    continue
                path = self.path_m(i, j, d)
                if p.noise_m or p.noise_rel:
                    path += 2.0 * (p.noise_m + p.noise_rel * d) * float(rng.standard_normal())
                path = max(path, 0.0)
                if path <= MAX_PATH_M and (best is None or path < best[0]):
                    best = (path, j)
            if best is None:
                out[i] = Echo(ECHO_TIMEOUT_US, None)
            else:
                out[i] = Echo(min(ECHO_TIMEOUT_US, round(best[0] / SPEED_OF_SOUND * 1e6)), best[1])
        return out
