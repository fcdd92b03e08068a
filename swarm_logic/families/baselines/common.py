"""What the four baseline controllers share: the iteration clock, the radio and move plumbing, and two update rules.

``Iterated`` runs one iteration every ``iteration_s`` of the robot's clock, aligned on the clock like the RDPSO
controller's (``swarm_logic.families.rdpso.controller``) so that every robot agrees on the iteration number ``k``:

A. at ``k * iteration_s``: read the pose, the objective (the light sensor, ``state.light_raw``: LDR counts in a
   co-simulation, the field's value in the numerical runner) and the sonar; build this iteration's frame;
S. ``U(0, send_jitter_s)`` later: broadcast it, the robot's one XBee frame of the iteration;
B. ``comm_window_s`` after A: drain the radio (frames of iteration k; others counted and dropped), decide, and
   hand one rotate-then-go move to the LLC, clamped to ``dx_max_m``.

A subclass gives its frame codec (``decode``), what it says (``tell``) and what it does (``decide``). The update
rules shared by two algorithms live here too: the PSO velocity (EPSO, PPSO) and the Braitenberg-style sonar
reaction that deflects a move without touching the algorithm's own state (EPSO, GSO).
"""

from __future__ import annotations

import math
from abc import abstractmethod
from collections.abc import Callable, Iterable
from typing import Any, ClassVar

from swarm_logic.controller import MAX_SPEED_MPS, Controller
from swarm_logic.geometry import clamp, wrap
from swarm_logic.iteration import IterationSchedule
from swarm_logic.robot import Robot

Vec = tuple[float, float]

COMMON_DEFAULTS: dict[str, Any] = {
    "iteration_s": 1.0,  # iteration period (as RDPSO's A13)
    "comm_window_s": 0.25,  # phase A -> phase B: time for the frames of an iteration to arrive
    "send_jitter_s": 0.1,  # each frame goes out U(0, this) after phase A (0 in the numerical runner)
    "dx_max_m": 0.1,  # largest displacement per iteration (the robots' Delta x_max, thesis Table 4.3 arena value)
    "speed_mps": 0.2,  # wheel speed of the rotate-then-go moves
    "min_move_m": 0.003,  # shorter displacements are not sent (about one encoder pulse)
    "n_total": 12,  # N_T, the number of robots (ids travel as one byte: at most 255)
    "log_every": 1,  # iterations between log records (0: none)
}
COMMON_RANGES: dict[str, str] = {
    "iteration_s": "(0, inf)",
    "comm_window_s": "(0, inf)",  # and < iteration_s
    "send_jitter_s": "[0, inf)",  # and < comm_window_s
    "dx_max_m": "(0, inf)",
    "speed_mps": f"(0, {MAX_SPEED_MPS:g}]",
    "min_move_m": "[0, inf)",
    "n_total": "[1, 255]",
    "log_every": "[0, inf)",
}


class WindowBest:
    """The best (value, position) recorded in the last ``window`` iterations, or ever when ``window`` is 0.

    For an objective that changes as the robots act (the chapter 8 mapping task: a place's information gain falls once
    it is mapped), a PSO's memory of a best goes stale; the dynamic-PSO remedy is to forget it (Carlisle & Dozier
    2000; Blackwell 2007). Ties go to the newer record."""

    def __init__(self, window: int) -> None:
        self.window = int(window)
        self.records: list[tuple[int, float, Vec]] = []  # (iteration, value, position), oldest first

    def add(self, k: int, value: float, at: Vec) -> None:
        if self.window == 0:
            if not self.records or value > self.records[0][1]:
                self.records = [(k, value, at)]
            return
        self.records.append((k, value, at))
        self.forget(k)

    def forget(self, k: int) -> None:
        """Drop records older than ``window`` iterations before ``k`` (nothing when the window is 0)."""
        if self.window:
            self.records = [r for r in self.records if r[0] > k - self.window]

    def best(self) -> tuple[float, Vec] | None:
        if not self.records:
            return None
        _, value, at = max(self.records, key=lambda r: (r[1], r[0]))
        return value, at


def pso_velocity(v: Vec, x: Vec, w: float, pulls: Iterable[tuple[float, Vec]],
                 rand: Callable[[], float]) -> Vec:
    """v' = w v + sum_i c_i r_i o (chi_i - x): the PSO velocity update with one uniform draw per attractor and axis
    (r_1x, r_1y, r_2x, r_2y, ... in that order from ``rand``). ``pulls`` is ((c_1, chi_1), (c_2, chi_2), ...)."""
    vx, vy = w * v[0], w * v[1]
    for c, (cx, cy) in pulls:
        vx += c * rand() * (cx - x[0])
        vy += c * rand() * (cy - x[1])
    return vx, vy


def pso_stability_warnings(w: float, c1: float, c2: float, names: tuple[str, str, str]) -> list[str]:
    """Warnings for PSO coefficients outside the order-2 (mean and variance) stable region of Poli (2009):
    c1 + c2 < 24 (1 - w^2) / (7 - 5 w). Outside it the velocity clamp (dx_max) alone keeps the particle bounded."""
    bound = 24.0 * (1.0 - w * w) / (7.0 - 5.0 * w)
    if c1 + c2 >= bound:
        return [f"{names[1]} + {names[2]} = {c1 + c2:g} >= {bound:.3g} = 24 (1 - {names[0]}^2) / (7 - 5 {names[0]}) "
                f"for {names[0]} = {w:g}: outside the PSO's order-2 stable region (Poli 2009); only the dx_max_m "
                "clamp bounds the particles"]
    return []


def braitenberg(heading: float, facing: float, sonar_m: float, avoid_m: float, turn_max_rad: float,
                tie: float = 1.0) -> tuple[float, bool]:
    """The heading to drive along when the forward sonar (pointing along ``facing``) reads ``sonar_m``.

    A Braitenberg-style reaction (Braitenberg 1984, vehicle 3b with one proximity sensor): a move that heads into the
    half-plane the sonar looks at, with an echo closer than ``avoid_m``, is turned further away from the sonar's axis,
    by ``turn_max_rad * (1 - sonar_m / avoid_m)`` (more the closer the echo), to the side it already leans to
    (``tie``'s sign when it points straight at it). Returns (heading, deflected). The caller's velocity is untouched:
    the robot only drives in the new direction (thesis section 8.1.1)."""
    if not (math.isfinite(sonar_m) and sonar_m < avoid_m):
        return heading, False
    off = wrap(heading - facing)
    if abs(off) >= math.pi / 2:
        return heading, False  # moving away from what the sonar sees
    side = math.copysign(1.0, off) if off != 0.0 else math.copysign(1.0, tie)
    return wrap(heading + side * turn_max_rad * (1.0 - max(0.0, sonar_m) / avoid_m)), True


def within(p: dict[str, Any], name: str, lo: float, hi: float, *, lo_open: bool = False,
           hi_open: bool = False) -> None:
    v = p[name]
    ok = isinstance(v, int | float) and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok:
        brackets = ("(" if lo_open else "[") + f"{lo:g}, {hi:g}" + (")" if hi_open else "]")
        raise ValueError(f"{name}: must lie in {brackets}, got {v!r}")


class Iterated(IterationSchedule, Controller):
    """One robot of a synchronous broadcast-then-move swarm algorithm (the skeleton of the four baselines)."""

    needs_radio = True  # a config must give its robots an XBee
    topic: ClassVar[str] = "baseline"  # the log topic and the name in messages
    defaults: ClassVar[dict[str, Any]] = COMMON_DEFAULTS
    ranges: ClassVar[dict[str, str]] = COMMON_RANGES
    # read only at init: the iteration clock every robot shares and the swarm's size
    static_params = frozenset({"iteration_s", "n_total"})

    # -- what a subclass provides ------------------------------------------------------------------------------
    @staticmethod
    @abstractmethod
    def decode(data: bytes) -> Any | None:
        """This algorithm's frame in ``data`` (with ``robot`` and ``k`` fields), or None when it is not one."""

    @abstractmethod
    def reset_algorithm(self) -> None:
        """The algorithm's state right after ``init``."""

    @abstractmethod
    def tell(self) -> bytes:
        """Phase A, after sensing: this iteration's frame."""

    @abstractmethod
    def decide(self) -> dict[str, Any]:
        """Phase B, with ``self.heard`` (frames of this iteration by sender): update, move; returns log fields."""

    @classmethod
    def check(cls, p: dict[str, Any]) -> None:
        """Refuse combinations of the algorithm's own parameters that mean nothing (ValueError naming the parameter);
        each one's kind and range are checked already (``ranges``)."""

    # -- parameters -----------------------------------------------------------------------------------------
    @classmethod
    def resolve(cls, params: dict[str, Any]) -> dict[str, Any]:
        """Defaults merged with ``params``, checked; ValueError names the parameter and the reason."""
        p = cls.with_defaults(params)  # each value of its kind and in its range
        within(p, "comm_window_s", 0.0, p["iteration_s"], lo_open=True, hi_open=True)
        within(p, "send_jitter_s", 0.0, p["comm_window_s"], hi_open=True)
        cls.check(p)
        return p

    # -- life cycle -----------------------------------------------------------------------------------------
    def init(self, robot: Robot) -> None:
        super().init(robot)
        if robot.xbee is None:
            raise ValueError(f"{self.topic} needs a radio (robots.xbee in the session config)")
        if not 0 <= robot.id <= 255:
            raise ValueError(f"{self.topic}: robot ids travel as one byte, got id {robot.id}")
        self.p = self.resolve(robot.params)
        self.reset()
        if robot.start_pose is not None:
            robot.llc.set_odometry(*robot.start_pose)
        self._begin()

    def reset(self) -> None:
        self.x = self.y = self.theta = 0.0
        self.h = -math.inf  # the objective as sensed this iteration
        self.sonar = math.inf  # the sonar's range this iteration (inf: no echo)
        self.heard: dict[int, Any] = {}
        self.dropped = {"late": 0, "malformed": 0}  # received frames not used, by cause (logged)
        self.outgoing = b""
        self.led: tuple[int, int, int] | None = None
        self.reset_algorithm()

    def destroy(self) -> None:
        self.robot.llc.stop()

    def step(self) -> None:
        """Phase A at k * iteration_s, the send U(0, jitter) later, phase B comm_window_s after A."""
        self._iterate()

    # -- phases ---------------------------------------------------------------------------------------------
    def _phase_a(self) -> None:
        st = self.robot.llc.state
        self.x, self.y, self.theta = float(st.x), float(st.y), float(st.theta)
        self.h = float(st.light_raw)
        self.sonar = float(st.sonar_m) if st.sonar_valid else math.inf
        self.outgoing = self.tell()

    def _send(self) -> None:
        self.robot.xbee.send_nowait(None, self.outgoing, radius=1)  # a local broadcast: the neighbours

    def _phase_b(self) -> None:
        self.heard = self._listen()
        fields = self.decide()
        every = int(self.p["log_every"])
        if every and self.k % every == 0:
            self.robot.log(self.topic, k=self.k, x=self.x, y=self.y, h=self.h, heard=len(self.heard),
                           dropped=dict(self.dropped), **fields)

    def _listen(self) -> dict[int, Any]:
        """Drain the radio: this iteration's frames by sender; late and malformed ones counted and dropped."""
        return {msg.robot: msg for msg, _ in self._frames_of_iteration(self.decode, "malformed")}

    # -- moving ---------------------------------------------------------------------------------------------
    def move_by(self, vx: float, vy: float) -> Vec:
        """Drive the displacement (vx, vy), clamped to dx_max (rotate-then-go); returns what was commanded."""
        vx, vy = clamp(vx, vy, self.p["dx_max_m"])
        return self.move_along(math.atan2(vy, vx), math.hypot(vx, vy))

    def move_along(self, heading: float, dist: float) -> Vec:
        """Turn to ``heading`` (arena frame), then drive ``dist`` (at most dx_max; nothing below min_move_m)."""
        dist = min(dist, self.p["dx_max_m"])
        if dist < self.p["min_move_m"]:
            return 0.0, 0.0
        self.robot.llc.move(wrap(heading - self.theta), dist, self.p["speed_mps"])
        return dist * math.cos(heading), dist * math.sin(heading)

    def show(self, rgb: tuple[int, int, int]) -> None:
        if rgb != self.led:
            self.led = rgb
            self.robot.llc.set_led(*rgb)


def wire(v: float) -> float:
    """A value for a float32 field: -inf (nothing yet) as a very low finite number, clipped to float32's range."""
    return max(-3.0e38, min(3.0e38, v)) if not math.isnan(v) else -3.0e38
