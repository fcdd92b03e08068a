"""AFS, the Aggregations of Foraging Swarms of Gazi & Passino (2003, 2004): the thesis' Algorithm 8.4.

Per robot n and iteration (the continuous-time model integrated by one Euler step of ``dt_s`` per iteration):

    sigma_n = gamma g_n - rho h_n                      sigma-profile: repellent g (obstacles), attractant h (objective)
    J(x_n) = sum_{k in N_T} -(x_n - x_k) [a - b exp(-|x_n - x_k|^2 / c)]     attraction far, repulsion near
    x_n <- x_n + dt (-grad sigma_n + J(x_n)),   |dt (...)| <= dx_max

Two pairs sit at the equilibrium distance delta = sqrt(c ln(b / a)).

What a robot knows, and how:

- the positions of all N_T robots: every frame carries the sender's position and its table of the others (id,
  iteration the position is from, relays it came over, position), so positions flood one hop per iteration as
  RDPSO's member table does; an entry is replaced by a newer one (or as new over fewer relays), and dropped
  ``max_age`` iterations after its position was sent. A table that does not fit ``payload_max`` bytes is sent in
  turns (round-robin from iteration to iteration), so each entry still goes out every few iterations.
- grad h: a robot cannot evaluate it. It fits a plane h ~ h0 + grad h . (x - x_n) by least squares to the
  readings it has: its own last ``grad_memory`` samples (position, reading) and this iteration's readings of the
  robots heard directly within ``grad_radius_m`` (each frame carries its sender's reading). Directions in which
  the samples do not spread (all on a line, or too close) get no gradient (a pseudo-inverse).
- grad g: the repellent is g = r_w - sonar range within r_w (0 beyond), and the sonar looks along the robot's
  heading, so grad g is the heading's unit vector while an echo is within r_w.

The frame (little-endian): ``<BBHfffB`` magic 0x41 ("A"), robot id, iteration mod 65536, position (x, y), reading
h, table length m; then m entries ``<BBBhh`` (id, iteration mod 256, relays, x and y in cm as int16: positions
within +-327 m). 17 + 7 m bytes: 10 entries in a 92-byte ZigBee broadcast.
"""

from __future__ import annotations

import math
import struct
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, ClassVar

from swarm_logic.families.baselines.common import COMMON_DEFAULTS, COMMON_RANGES, Iterated, Vec, wire
from swarm_logic.geometry import clamp

MAGIC = 0x41  # "A"
HEAD = struct.Struct("<BBHfffB")
ENTRY = struct.Struct("<BBBhh")
CYAN, RED = (0, 220, 220), (255, 0, 0)
SPREAD_MIN_M = 1e-3  # samples spread less than this (standard deviation along a direction) give no gradient there


@dataclass(frozen=True, slots=True)
class Frame:
    robot: int
    k: int  # iteration number mod 65536
    x: float
    y: float
    h: float  # the sender's reading this iteration
    table: tuple[tuple[int, int, int, float, float], ...] = field(default=())  # (id, k mod 256, relays, x, y)


def _cm(v: float) -> int:
    return max(-32768, min(32767, round(v * 100.0)))


def encode(f: Frame, limit: int = 92, start: int = 0) -> bytes:
    """Bytes of ``f``; when the table does not fit in ``limit`` bytes, as many entries as fit, taken cyclically
    from index ``start`` (the caller turns it from iteration to iteration)."""
    entries = f.table
    room = max(0, (limit - HEAD.size) // ENTRY.size)
    if len(entries) > room:
        s = start % len(entries)
        entries = (entries[s:] + entries[:s])[:room]
    out = bytearray(HEAD.pack(MAGIC, f.robot, f.k & 0xFFFF, f.x, f.y, wire(f.h), len(entries)))
    for i, kk, relays, x, y in entries:
        out += ENTRY.pack(i, kk & 0xFF, min(relays, 255), _cm(x), _cm(y))
    return bytes(out)


@lru_cache(maxsize=1024)
def decode(data: bytes) -> Frame | None:
    """The AFS frame in ``data``, or None (another application's frame, a length that disagrees with its table
    length, non-finite numbers). Cached: treat the result as read-only."""
    n = len(data)
    if n < HEAD.size or data[0] != MAGIC:
        return None
    _, robot, k, x, y, h, m = HEAD.unpack_from(data)
    if n != HEAD.size + m * ENTRY.size or not (math.isfinite(x) and math.isfinite(y) and math.isfinite(h)):
        return None
    table = tuple((i, kk, relays, xc / 100.0, yc / 100.0)
                  for i, kk, relays, xc, yc in ENTRY.iter_unpack(data[HEAD.size:]))
    return Frame(robot, k, x, y, h, table)


def attraction_repulsion(x: Vec, others: Iterable[Vec], a: float, b: float, c: float) -> Vec:
    """J(x) = sum_k -(x - x_k) [a - b exp(-|x - x_k|^2 / c)] (Gazi & Passino; thesis Algorithm 8.4)."""
    jx = jy = 0.0
    for ox, oy in others:
        dx, dy = x[0] - ox, x[1] - oy
        f = a - b * math.exp(-(dx * dx + dy * dy) / c)
        jx -= dx * f
        jy -= dy * f
    return jx, jy


def equilibrium_distance(a: float, b: float, c: float) -> float:
    """delta = sqrt(c ln(b / a)): where attraction and repulsion between two robots balance."""
    return math.sqrt(c * math.log(b / a))


def plane_gradient(samples: Sequence[tuple[float, float, float]], spread_min: float = SPREAD_MIN_M) -> Vec:
    """grad h of the least-squares plane h ~ h0 + g . x through samples (x, y, h), by the pseudo-inverse of the
    samples' position covariance: only directions along which they spread at least ``spread_min`` (standard
    deviation, m) get a gradient component; (0, 0) from fewer than two samples."""
    n = len(samples)
    if n < 2:
        return 0.0, 0.0
    mx = sum(s[0] for s in samples) / n
    my = sum(s[1] for s in samples) / n
    mh = sum(s[2] for s in samples) / n
    sxx = syy = sxy = sxh = syh = 0.0
    for x, y, h in samples:
        dx, dy, dh = x - mx, y - my, h - mh
        sxx += dx * dx
        syy += dy * dy
        sxy += dx * dy
        sxh += dx * dh
        syh += dy * dh
    half_tr = 0.5 * (sxx + syy)
    disc = math.sqrt(max(0.0, half_tr * half_tr - (sxx * syy - sxy * sxy)))
    l1 = half_tr + disc
    if sxy != 0.0:
        ex, ey = l1 - syy, sxy
        norm = math.hypot(ex, ey)
        ex, ey = ex / norm, ey / norm
    else:
        ex, ey = (1.0, 0.0) if sxx >= syy else (0.0, 1.0)
    gx = gy = 0.0
    floor = n * spread_min * spread_min
    for lam, (ux, uy) in ((l1, (ex, ey)), (half_tr - disc, (-ey, ex))):
        if lam > floor:
            slope = (ux * sxh + uy * syh) / lam
            gx += slope * ux
            gy += slope * uy
    return gx, gy


def descent_step(grad_h: Vec, grad_g: Vec, j: Vec, rho: float, gamma: float, dt: float, dx_max: float) -> Vec:
    """dt (-grad sigma + J) with sigma = gamma g - rho h, clamped to dx_max."""
    vx = dt * (rho * grad_h[0] - gamma * grad_g[0] + j[0])
    vy = dt * (rho * grad_h[1] - gamma * grad_g[1] + j[1])
    return clamp(vx, vy, dx_max)


class Afs(Iterated):
    """One robot of the AFS swarm."""

    topic = "afs"
    decode = staticmethod(decode)
    defaults: ClassVar[dict[str, Any]] = {
        **COMMON_DEFAULTS,
        "a": 1.0,  # attraction (Gazi & Passino's simulations)
        "b": 20.0,  # repulsion (Gazi & Passino's simulations)
        "c_m2": 0.041,  # repulsion reach: delta = sqrt(c ln(b/a)) = 0.35 m, a spacing for the eSwarBot arena
        "dt_s": 0.02,  # Euler step of the continuous-time model per iteration (dt a N_T < 1 keeps it stable)
        "rho": 0.005,  # attractant weight, m^2 per objective unit (LDR counts): climbs ~0.05 m at 500 counts/m
        "gamma": 5.0,  # repellent weight, m per model second: dt gamma = 0.1 m away from an echo within r_w
        "r_w_m": 0.3,  # obstacle sensing radius R_w of the repellent g
        "grad_memory": 4,  # own samples (iterations) in the gradient fit
        "grad_radius_m": 0.5,  # neighbours' readings within this are in the gradient fit
        "max_age": 10,  # iterations after which a position nobody refreshed is forgotten
        "payload_max": 92,  # bytes per frame: a ZigBee broadcast's limit (the numerical runner may raise it)
    }
    ranges: ClassVar[dict[str, str]] = {
        **COMMON_RANGES,
        "a": "(0, inf)",
        "b": "(0, inf)",  # and > a
        "c_m2": "(0, inf)",
        "dt_s": "(0, inf)",
        "rho": "[0, inf)",
        "gamma": "[0, inf)",
        "r_w_m": "(0, inf)",
        "grad_memory": "[1, 1000]",
        "grad_radius_m": "[0, inf)",
        "max_age": "[1, 1000]",
        "payload_max": f"[{HEAD.size}, 65535]",
    }

    # read only at init and reset: the clock, the swarm's size, the length of the sample memory
    static_params = frozenset({"iteration_s", "n_total", "grad_memory"})

    @classmethod
    def check(cls, p: dict[str, Any]) -> None:
        if not p["b"] > p["a"]:
            raise ValueError(f"b: must exceed a = {p['a']} (else robots attract at every distance and pile up: "
                             f"no equilibrium distance sqrt(c ln(b/a))), got {p['b']!r}")

    @classmethod
    def warnings(cls, params: dict[str, Any]) -> list[str]:
        """Stability warnings for a valid parameter set: the Euler step of the attraction (each robot's offset from
        the swarm's centre shrinks by 1 - dt a N_T per iteration) diverges when dt a N_T >= 2."""
        p = cls.resolve(params)
        gain = p["dt_s"] * p["a"] * p["n_total"]
        if gain >= 2.0:
            return [f"dt_s * a * n_total = {gain:g} >= 2: the Euler step of the attraction term is unstable (it "
                    "overshoots the swarm's centre by more than it started from); only the dx_max_m clamp bounds it"]
        return []

    def reset_algorithm(self) -> None:
        self.table: dict[int, tuple[int, int, float, float]] = {}  # robot -> (iteration, relays, x, y)
        self.samples: deque[tuple[float, float, float]] = deque(maxlen=int(self.p["grad_memory"]))
        self.grad = (0.0, 0.0)
        self.best = -math.inf  # the best reading this robot has made or heard (logged)

    def telemetry(self) -> dict[str, float | int]:
        """Iteration, robots whose position is known, estimated gradient, best reading known (-3e38: none)."""
        return {"k": self.k, "known": len(self.table), "grad_x": self.grad[0], "grad_y": self.grad[1],
                "best": wire(self.best)}

    def tell(self) -> bytes:
        self.samples.append((self.x, self.y, self.h))
        self.best = max(self.best, self.h)
        table = tuple((i, *v) for i, v in sorted(self.table.items()))
        return encode(Frame(self.robot.id, self.k, self.x, self.y, self.h, table), int(self.p["payload_max"]),
                      start=self.k * max(1, (int(self.p["payload_max"]) - HEAD.size) // ENTRY.size))

    def merge(self) -> None:
        """Refresh the position table from this iteration's frames (direct) and the tables they carry (relayed)."""
        k, me = self.k, self.robot.id
        table = self.table
        for rid, f in self.heard.items():
            table[rid] = (k, 0, f.x, f.y)
            self.best = max(self.best, f.h)
        for f in self.heard.values():
            for rid, k8, relays, x, y in f.table:
                if rid == me or rid in self.heard:
                    continue
                origin = k - ((k - k8) & 0xFF)  # unwrap the iteration number (mod 256)
                old = table.get(rid)
                if old is None or origin > old[0] or (origin == old[0] and relays + 1 < old[1]):
                    table[rid] = (origin, relays + 1, x, y)
        limit = k - int(self.p["max_age"])
        for rid in [r for r, v in table.items() if v[0] < limit]:
            del table[rid]

    def decide(self) -> dict[str, Any]:
        p = self.p
        self.merge()
        here = (self.x, self.y)
        reach = p["grad_radius_m"]
        near = [(f.x, f.y, f.h) for f in self.heard.values() if math.hypot(f.x - self.x, f.y - self.y) <= reach]
        self.grad = plane_gradient([*self.samples, *near])
        echo = self.sonar < p["r_w_m"]
        grad_g = (math.cos(self.theta), math.sin(self.theta)) if echo else (0.0, 0.0)
        j = attraction_repulsion(here, ((v[2], v[3]) for v in self.table.values()), p["a"], p["b"], p["c_m2"])
        vx, vy = descent_step(self.grad, grad_g, j, p["rho"], p["gamma"], p["dt_s"], p["dx_max_m"])
        self.move_by(vx, vy)
        self.show(RED if echo else CYAN)
        return {"known": len(self.table), "grad": self.grad, "J": j, "v": (vx, vy), "echo": echo,
                "best": wire(self.best)}
