"""What the three Zebro controllers share: their devices, the flocking parameters (Algorithm 2; A-1, A-2) and
steering by a heading target.

A controller step is one tick of the thesis' model: read the neighbours, the messages and the utility sensor,
decide, broadcast, and leave the legs walking (or halted) with a turn rate that reaches the chosen heading by the
next step.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any, ClassVar

from swarm_logic.controller import Controller
from swarm_logic.families.zebro.flocking import FlockRules, turn_away, turn_towards
from swarm_logic.families.zebro.messages import NAMES
from swarm_logic.geometry import wrap
from swarm_logic.robot import Robot
from swarm_logic.robots.decizebro.interfaces import (
    BODY_LENGTH_M,
    IMU,
    LEGS,
    UTILITY,
    UWB_RADIO,
    Imu,
    Locomotion,
    Neighbour,
    UtilitySensor,
    ZebroRadio,
)

TURN = "[0, 180]"


class ZebroController(Controller):
    """The common part of the silent, immature and mature controllers (abstract: ``step`` is theirs)."""

    period_s = 1.0
    defaults: ClassVar[dict[str, Any]] = {
        "period_s": 1.0,  # one tick: the thesis' event cycle (one control period; the UWB's 1 Hz update)
        "d_min_m": BODY_LENGTH_M,  # SEPARATE below this range (NetLogo minimum-separation: one body length)
        "d_max_m": 1.6,  # COHERE beyond this range (the study: 0.8 x the communication radius)
        "align_turn_deg": 5.0,  # per tick (NetLogo max-align-turn)
        "cohere_turn_deg": 3.0,  # per tick (NetLogo max-cohere-turn)
        "separate_turn_deg": 1.5,  # per tick (NetLogo max-separate-turn)
        "taxis_turn_deg": 10.0,  # per tick: towards a sensed particle / away from an obstacle
        "align_mean": "circular",  # circular | arithmetic (literal)
        "cohere_mode": "bearing",  # bearing | heading (literal)
        "separate_mode": "turn_away",  # turn_away | plus90 (literal)
        # before the first tick, wait until the radio has heard the neighbourhood once (the thesis' swarm is a formed
        # flock at launch; a real one forms its UWB network first)
        "wait_radio": True,
    }
    ranges: ClassVar[dict[str, str]] = {
        "period_s": "(0, 60]", "d_min_m": "[0, inf)", "d_max_m": "[0, inf)", "align_turn_deg": TURN,
        "cohere_turn_deg": TURN, "separate_turn_deg": TURN, "taxis_turn_deg": TURN,
    }
    choices: ClassVar[dict[str, tuple[str, ...]]] = {
        "align_mean": ("circular", "arithmetic"), "cohere_mode": ("bearing", "heading"),
        "separate_mode": ("turn_away", "plus90"),
    }
    static_params = frozenset({"period_s", "wait_radio"})

    radio: ZebroRadio
    sensor: UtilitySensor
    imu: Imu
    legs: Locomotion

    def set_param(self, name: str, value: Any) -> None:
        super().set_param(name, value)
        self.rules = self._rules()

    def init(self, robot: Robot) -> None:
        super().init(robot)
        self.p = self.resolve(robot.params)
        self.period_s = float(self.p["period_s"])
        self.radio = robot.device(UWB_RADIO)
        self.sensor = robot.device(UTILITY)
        self.imu = robot.device(IMU)
        self.legs = robot.device(LEGS)
        if self.p["wait_radio"]:
            self.radio.wait_neighbourhood()
        self.rules = self._rules()
        self.sent: Counter[str] = Counter()  # frames broadcast, by type (logged as zebro_tx when it stops)
        self.refused = 0  # broadcasts the radio's budget refused
        self.reset()

    def _rules(self) -> FlockRules:
        p = self.p
        return FlockRules(float(p["d_min_m"]), float(p["d_max_m"]), math.radians(p["align_turn_deg"]),
                          math.radians(p["cohere_turn_deg"]), math.radians(p["separate_turn_deg"]), p["align_mean"],
                          p["cohere_mode"], p["separate_mode"])

    def send(self, data: bytes) -> bool:
        """Broadcast ``data``, counting it by frame type."""
        ok = self.radio.broadcast(data)
        if ok:
            self.sent[NAMES.get(data[0], "other")] += 1
        else:
            self.refused += 1
        return ok

    def steer(self, h_now: float, h_target: float, fast: bool = False) -> None:
        """Walk so that the heading is ``h_target`` one tick from now."""
        self.legs.walk(wrap(h_target - h_now) / self.period_s, fast)

    def taxis(self, h: float, h0: float, u: int, turn_deg: float | None = None) -> float:
        """Algorithm 3: ``h`` turned towards what the sensor sees (u > 0) or away from it (u < 0); ``h0`` is the
        heading the sensor's bearing is relative to."""
        b = self.sensor.bearing()
        if u == 0 or b is None:
            return h
        turn = math.radians(self.p["taxis_turn_deg"] if turn_deg is None else turn_deg)
        return turn_towards(h, h0 + b, turn) if u > 0 else turn_away(h, h0 + b, turn)

    def follow(self, h: float, h0: float, nbrs: list[Neighbour], leader: int | None, relay: int | None,
               mode: str, turn_deg: float) -> float:
        """REALIGN (Algorithm 6; A-3): towards the leader's bearing when it is a neighbour (``bearing``) or to its
        heading (``heading``, literal); when it is not a neighbour, to the heading of the neighbour it was learnt
        from (``relay``); unchanged when neither is in range."""
        turn = math.radians(turn_deg)
        guide = None
        for n in nbrs:
            if n.id == leader:
                guide = n
                break
            if n.id == relay:
                guide = n
        if guide is None:
            return h
        if (mode == "bearing" and guide.id == leader) or guide.heading_rad is None:
            return turn_towards(h, h0 + guide.bearing_rad, turn)
        return turn_towards(h, guide.heading_rad, turn)

    def destroy(self) -> None:
        """Halt, and log the frames sent by type (``zebro_tx``)."""
        legs = getattr(self, "legs", None)
        if legs is not None:
            legs.halt()
            self.robot.log("zebro_tx", refused=self.refused, **self.sent)
