"""The immature algorithm (thesis Algorithms 4-6, Table 3.2): flocking plus one-hop gossip of the best utility
heard; each robot follows its own my-leader while the swarm keeps walking ("decides while moving").

Every tick a robot broadcasts m1 (its id: the neighbour list mat1); while it senses a particle, m2 (id, utility),
and STOP (m0) when it starts sensing; while it has a my-leader, m3 (id, max-utility, my-leader: 3 bytes). A robot
adopts a neighbour's my-leader when that neighbour's max-utility beats its own (line 16), its own id when what it
senses is the best it knows (the missing line 11: max over its own reading and mat2). It then REALIGNs (Algorithm 6)
towards its my-leader, or walks to its particle when it is its own my-leader.

Readings of the ambiguities (``docs/zebro-algorithms.md``):

- A-3 ``follow_mode``: ``bearing`` turns towards my-leader's bearing when it is a neighbour, else copies the heading
  of the neighbour my-leader was learnt from (the relay); ``heading`` (literal) copies my-leader's heading (or the
  relay's);
- A-8 ``stop_mode``: STOP is a one-tick pause (``pause``), ignored (``ignore``), or the literal latched stop that
  nothing resumes (``latched``);
- A-9 ``reset_mode``: ``timeout`` drops my-leader ``reset_ticks`` ticks after the robot it was learnt from last
  confirmed it (the leader's m2/m3, or the relay's m3), and then refuses that rumour for ``reset_ticks`` + 1 ticks
  (so a rumour cannot keep itself alive around a cycle); ``never`` (literal) keeps it for good;
- A-10 ``m1_utility``: m1 carries only the id (Table 3.2) or also the utility (the prose).
"""

from __future__ import annotations

from typing import Any, ClassVar

from swarm_logic.families.zebro import messages as msg
from swarm_logic.families.zebro.base import TURN, ZebroController
from swarm_logic.families.zebro.flocking import flock


class ZebroImmature(ZebroController):
    """Algorithm 4: FLOCKING, CHOOSING A LEADER (Algorithm 5), REALIGN (Algorithm 6), every tick."""

    defaults: ClassVar[dict[str, Any]] = {
        **ZebroController.defaults,
        "realign_turn_deg": 10.0,  # per tick, towards my-leader
        "follow_mode": "bearing",  # bearing | heading (literal)
        "stop_mode": "pause",  # pause | ignore | latched (literal)
        "reset_mode": "timeout",  # timeout | never (literal)
        "reset_ticks": 3,  # k
        "m1_utility": False,  # the table (id only); True: the prose (id + utility)
    }
    ranges: ClassVar[dict[str, str]] = {**ZebroController.ranges, "realign_turn_deg": TURN, "reset_ticks": "[1, 1000]"}
    choices: ClassVar[dict[str, tuple[str, ...]]] = {
        **ZebroController.choices, "follow_mode": ("bearing", "heading"), "stop_mode": ("pause", "ignore", "latched"),
        "reset_mode": ("timeout", "never"),
    }

    def reset(self) -> None:
        self.k = 0  # ticks (steps) so far
        self.mat1: set[int] = set()
        self.mat2: dict[int, tuple[int, int]] = {}  # id -> (utility, tick heard)
        self.mat3: dict[int, tuple[int, int, int]] = {}  # id -> (max-utility, my-leader, tick heard)
        self.max_utility = 0
        self.my_leader: int | None = None
        self.relay: int | None = None  # the neighbour my-leader was learnt from (None: self, or the leader's m2)
        self.deadline = 0
        self.refused: dict[tuple[int, int], int] = {}  # (leader, value) -> refused until this tick
        self.sensing = 0
        self.pause = False
        self.latched = False

    def step(self) -> None:
        self.k += 1
        me, k, p = self.robot.id, self.k, self.p
        h0 = self.imu.heading()
        nbrs = self.radio.neighbours()
        heard: list[tuple[int, int, int]] = []  # (value, leader, sender) offers this tick
        for m in self.radio.receive():
            f = msg.decode(m.data)
            if f is None:
                continue
            if f.kind == msg.M0_STOP:
                if p["stop_mode"] == "pause":
                    self.pause = True
                elif p["stop_mode"] == "latched":
                    self.latched = True
            elif f.kind == msg.M1:
                self.mat1.add(f.src)
            elif f.kind == msg.M2:
                self.mat2[f.src] = (f.value, k)
                heard.append((f.value, f.src, f.src))
            elif f.kind == msg.M3 and f.origin is not None:
                self.mat3[f.src] = (f.value, f.origin, k)
                heard.append((f.value, f.origin, f.src))
        u = self.sensor.read()
        if u > 0 and self.sensing <= 0:
            self.send(msg.m0(me))  # "stagnate the crowd"
        self.sensing = u
        self._choose(u, heard)
        self.send(msg.m1(me, u if p["m1_utility"] else None))
        if u > 0:
            self.send(msg.m2(me, min(u, 127)))
        if self.my_leader is not None:
            self.send(msg.m3(me, min(self.max_utility, 127), self.my_leader))
        eaten = self.sensor.consumed()
        if eaten:
            self.robot.log("zebro_consumed", utility=eaten, leader=self.my_leader)
        if self.latched or self.pause:
            self.pause = False
            self.legs.halt()
            return
        self.steer(h0, self._heading(h0, nbrs, u))

    def _choose(self, u: int, heard: list[tuple[int, int, int]]) -> None:
        """Lines 10-17 of Algorithm 5: my-leader and max-utility from my reading and the m2/m3 heard this tick."""
        me, k, timeout = self.robot.id, self.k, self.p["reset_mode"] == "timeout"
        before = (self.my_leader, self.max_utility)
        if self.my_leader == me and u <= 0:
            self._drop()  # what I led with is gone (eaten, or out of my cone)
        if timeout and self.my_leader is not None and k > self.deadline:
            self.refused[(self.my_leader, self.max_utility)] = k + int(self.p["reset_ticks"]) + 1
            self._drop()
        if u > 0 and (self.my_leader is None or u > self.max_utility or self.my_leader == me):
            self.my_leader, self.max_utility, self.relay = me, u, None
        for value, leader, src in heard:
            if leader == me or value <= 0:
                continue  # nobody tells me what I lead with
            if timeout and src != leader and self.refused.get((leader, value), 0) > k:
                self.refused[(leader, value)] = k + int(self.p["reset_ticks"]) + 1
                continue  # a rumour that died here stays dead while anyone around still repeats it
            if self.my_leader is None or value > self.max_utility:
                self.my_leader, self.max_utility = leader, value
                self.relay = None if src == leader else src
                self.deadline = k + int(self.p["reset_ticks"])
            elif (leader, value) == (self.my_leader, self.max_utility) and src in (leader, self.relay):
                self.deadline = k + int(self.p["reset_ticks"])  # confirmed by where I learnt it
        if self.my_leader == me:
            self.deadline = k + int(self.p["reset_ticks"])
        if (self.my_leader, self.max_utility) != before:
            self.robot.log("zebro_leader", leader=-1 if self.my_leader is None else self.my_leader,
                           max_utility=self.max_utility)

    def _drop(self) -> None:
        self.my_leader, self.max_utility, self.relay = None, 0, None

    def _heading(self, h0: float, nbrs: list, u: int) -> float:
        """FLOCKING, then REALIGN towards my-leader (Algorithm 6), or walk to my particle when I lead myself."""
        h = flock(h0, nbrs, self.rules)
        if u < 0:
            return self.taxis(h, h0, u)
        if self.my_leader is None:
            return h
        if self.my_leader == self.robot.id:
            return self.taxis(h, h0, u)
        return self.follow(h, h0, nbrs, self.my_leader, self.relay, self.p["follow_mode"],
                           self.p["realign_turn_deg"])

    def telemetry(self) -> dict[str, float | int]:
        return {"leader": -1 if self.my_leader is None else self.my_leader, "max_u": self.max_utility}
