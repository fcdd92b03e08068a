"""The mature algorithm (thesis Algorithms 7-11, Tables 3.3-3.8): a swarm-wide election before anyone moves.

A robot that senses a particle floods STOP (which halts everyone and opens election ``seq``) and announces its
utility (n2). The election is an echo (PIF) with extinction (digest 2.5.4, 2.5.7): every robot relays only the best
tag it knows, the sender of that tag is its parent, and it acknowledges (n4) to its parent once every other
neighbour is an acknowledged child or a sibling; a wave for a lower value can never collect all its acks. The
contender whose own wave completes is the-leader: it floods EOE, walks to its particle at three times the flocking
speed without flocking, and floods ERASE when it has eaten; everyone else follows at 1x (flocking and realigning
towards the-leader, or the neighbour EOE came from) and clears the election on ERASE. Link lists are gossiped
meanwhile into an adjacency matrix (Algorithm 11, ``graph.LinkGossip``), never used to decide.

Readings of the ambiguities (``docs/zebro-algorithms.md``):

- A-4 ``ack_symbols``: ``swapped`` (a robot with a parent acks, one without and sensing X leads) or ``as_defined``
  (the listed definitions: ack when acks were received, lead when none were);
- A-5 ``election_tags``: ``origin`` (n2 carries origin and parent; tag (X, origin), highest id among cousins) or
  ``utility`` (literal: X alone; any later sender of X is a sibling; a cousin with a lower id withdraws);
- A-6 ``leader_rule``: ``echo`` (every neighbour is the parent, an acked child or a sibling) or ``count`` (the
  literal x = a + b + c on counts);
- A-7: STOP, EOE and ERASE are re-broadcast once per election sequence number;
- A-11 ``leader_pace``: ``fast`` (3x) or ``duty`` (the leader at 1x, followers walking one tick in three);
- A-12 ``new_contenders``: ``serialise`` (contenders are who sensed when the election reached them; nothing new
  until ERASE) or ``join`` (a robot in the election that starts sensing may still contend).

Beyond the thesis, which assumes error-free delivery: ``resend_ticks`` (0, the thesis: never) repeats a robot's part
of the election every that many ticks while it lasts (STOP, its best tag as n3, its n4 once sent; the-leader its EOE
while it leads), so one lost frame no longer stalls the election on a lossy radio. Every handler is idempotent, so a
repeat changes nothing where nothing was lost.
"""

from __future__ import annotations

from typing import Any, ClassVar

from swarm_logic.families.zebro import messages as msg
from swarm_logic.families.zebro.base import TURN, ZebroController
from swarm_logic.families.zebro.flocking import flock
from swarm_logic.families.zebro.graph import LinkGossip

FLOCK, ELECTION, LEAD, FOLLOW = "flock", "election", "lead", "follow"
STATES = (FLOCK, ELECTION, LEAD, FOLLOW)
Tag = tuple[int, int]  # (X, origin id); origin -1 in the literal election


class ZebroMature(ZebroController):
    """Algorithm 7: ELECTION while a particle is sensed, then MOVEMENT and ERASE; DEVELOPING A GRAPH and FLOCKING."""

    defaults: ClassVar[dict[str, Any]] = {
        **ZebroController.defaults,
        "realign_turn_deg": 10.0,  # per tick: followers towards the-leader
        "lead_turn_deg": 30.0,  # per tick: the-leader towards its particle
        "follow_mode": "bearing",  # bearing | heading (literal)
        "ack_symbols": "swapped",  # swapped | as_defined (literal)
        "election_tags": "origin",  # origin | utility (literal)
        "leader_rule": "echo",  # echo | count (literal)
        "leader_pace": "fast",  # fast | duty
        "new_contenders": "serialise",  # serialise | join
        "beacon": True,  # n1 every tick (the neighbour list N1)
        "graph": True,  # Algorithm 11's link-list gossip
        "resend_ticks": 0,  # repeat the election's frames every that many ticks (0: never, as the thesis)
    }
    ranges: ClassVar[dict[str, str]] = {**ZebroController.ranges, "realign_turn_deg": TURN, "lead_turn_deg": TURN,
                                        "resend_ticks": "[0, 1000]"}
    choices: ClassVar[dict[str, tuple[str, ...]]] = {
        **ZebroController.choices, "follow_mode": ("bearing", "heading"), "ack_symbols": ("swapped", "as_defined"),
        "election_tags": ("origin", "utility"), "leader_rule": ("echo", "count"), "leader_pace": ("fast", "duty"),
        "new_contenders": ("serialise", "join"),
    }

    def reset(self) -> None:
        self.k = 0
        self.state = FLOCK
        self.seq = 0  # the newest election this robot took part in
        self.erased = 0  # the newest election it erased
        self.flooded: set[tuple[int, int]] = set()  # (frame type, election number) already re-broadcast
        self.graph = LinkGossip(self.robot.id)
        self.the_leader: int | None = None
        self.guide: int | None = None  # the neighbour EOE came from
        self._clear()

    def _clear(self) -> None:
        self.sensed = -1  # own utility as a contender; -1: none or withdrawn
        self.best: Tag | None = None
        self.parent: int | None = None
        self.children: set[int] = set()
        self.siblings: set[int] = set()
        self.acks: set[int] = set()
        self.acked = False  # n4 sent (or EOE, for the-leader)
        self.told: set[int] = set()  # the neighbours in range when this robot last announced its best tag
        self._since_resend = 0  # ticks since this robot last sent (or repeated) its election frames
        self._n4: bytes | None = None  # the n4 it sent its parent

    @property
    def literal_tags(self) -> bool:
        return self.p["election_tags"] == "utility"

    def _gt(self, a: Tag, b: Tag) -> bool:
        return a[0] > b[0] if self.literal_tags else a > b

    def _set_state(self, state: str) -> None:
        if state != self.state:
            self.state = state
            self.robot.log("zebro_state", state=state, seq=self.seq)

    # -- the tick ---------------------------------------------------------------------------------------------

    def step(self) -> None:
        self.k += 1
        h0 = self.imu.heading()
        nbrs = self.radio.neighbours()
        ids = {n.id for n in nbrs}
        self.ids = ids
        if self.p["graph"]:
            self.graph.update_own(ids)
        for m in self.radio.receive():
            f = msg.decode(m.data)
            if f is not None:
                self._on(f)
        if self.state == FLOCK:
            u = self.sensor.read()
            if u > 0:  # utility found: the swarm STOPs, election seq opens
                seq = max(self.seq, self.erased) + 1
                self.flooded.add((msg.STOP, seq))
                self.send(msg.stop(self.robot.id, seq))
                self._enter(seq)
        elif self.state == ELECTION and self.sensed <= 0 and self.p["new_contenders"] == "join":
            self._contend(self.sensor.read())
        if self.state == ELECTION and self.best is not None and not ids <= self.told:
            # a neighbour came into range after my n2: STOP (it may have missed the flood) and n3, "I know X"
            self.send(msg.stop(self.robot.id, self.seq))
            self._announce(msg.N3)
        if self.state == ELECTION:
            self._check_done(ids)
        every = int(self.p["resend_ticks"])
        if every and self.state in (ELECTION, LEAD):
            self._since_resend += 1
            if self._since_resend >= every:
                self._resend()
        if self.p["beacon"]:
            self.send(msg.n1(self.robot.id))
        if self.p["graph"]:
            out = self.graph.outgoing()
            if out is not None:
                per = max(1, min(255, (self.radio.max_payload - 3) // 3))  # links per frame the radio carries
                for i in range(0, max(1, len(out)), per):
                    self.send(msg.links(self.robot.id, out[i:i + per]))
        eaten = self.sensor.consumed()
        if eaten:
            self.robot.log("zebro_consumed", utility=eaten, state=self.state, seq=self.seq)
            if self.state in (LEAD, FOLLOW):  # the swarm ate: the decision is executed
                self._erase(self.seq)
                self.flooded.add((msg.ERASE, self.seq))
                self.send(msg.erase(self.robot.id, self.seq))
        self._move(h0, nbrs)

    def _move(self, h0: float, nbrs: list) -> None:
        p = self.p
        if self.state == ELECTION:
            self.legs.halt()
            return
        if self.state == LEAD:  # MOVEMENT: to the particle, no flocking
            h = self.taxis(h0, h0, self.sensor.read(), p["lead_turn_deg"])
            self.steer(h0, h, fast=p["leader_pace"] == "fast")
            return
        h = flock(h0, nbrs, self.rules)
        if self.state == FOLLOW:
            if p["leader_pace"] == "duty" and self.k % 3:
                self.legs.halt()
                return
            h = self.follow(h, h0, nbrs, self.the_leader, self.guide, p["follow_mode"], p["realign_turn_deg"])
        else:
            u = self.sensor.read()
            if u < 0:
                h = self.taxis(h, h0, u)
        self.steer(h0, h)

    # -- messages ---------------------------------------------------------------------------------------------

    def _flood(self, kind: int, seq: int, data: bytes) -> None:
        """Re-broadcast STOP / EOE / ERASE once per election (A-7); ``seq`` the election's full number (frames
        carry its low byte)."""
        key = (kind, seq)
        if key not in self.flooded:
            self.flooded = {k for k in self.flooded if k[1] >= seq - 1}  # forget elections long over
            self.flooded.add(key)
            self.send(data)

    def _resend(self) -> None:
        """``resend_ticks``: repeat this robot's part of the election, for neighbours that lost a frame of it."""
        self._since_resend = 0
        me = self.robot.id
        if self.state == LEAD:
            if self.best is not None:
                self.send(msg.eoe(me, self.seq, me, self.best[0]))
            return
        self.send(msg.stop(me, self.seq))
        if self.best is not None:
            x, origin = self.best
            self.send(msg.n2(me, x, kind=msg.N3) if self.literal_tags else
                      msg.n2(me, x, origin, self.parent, kind=msg.N3))
        if self._n4 is not None:
            self.send(self._n4)

    def _newer(self, seq: int, than: int) -> bool:
        """Sequence numbers are one byte: ``seq`` is newer within half the circle."""
        return 0 < (seq - than) % 256 < 128

    def _on(self, f: msg.Frame) -> None:
        me = self.robot.id
        if f.kind == msg.LINKS:
            if self.p["graph"]:
                self.graph.receive(f.src, f.links)
        elif f.kind == msg.STOP:
            if self._newer(f.seq, self.seq & 0xFF) and self._newer(f.seq, self.erased & 0xFF):
                seq = self.seq + (f.seq - self.seq) % 256  # the full number the byte stands for
                self._flood(msg.STOP, seq, msg.stop(me, seq))  # STOP first: my n2 must not overtake it
                self._enter(seq)
        elif self.state == ELECTION and f.kind in (msg.N2, msg.N3):
            self._on_wave(f)
        elif self.state == ELECTION and f.kind == msg.N4:
            if f.parent == me and self.best is not None and f.value == self.best[0] and (
                    self.literal_tags or f.origin == self.best[1]):
                self.acks.add(f.src)
        elif f.kind == msg.EOE:
            if self.state == ELECTION and f.seq == self.seq & 0xFF:
                self.the_leader, self.guide = f.origin, f.src
                self._flood(msg.EOE, self.seq, msg.eoe(me, self.seq, f.origin, f.value))
                self._set_state(FOLLOW)
        elif f.kind == msg.ERASE and f.seq == self.seq & 0xFF and self.erased & 0xFF != f.seq:
            self._flood(msg.ERASE, self.seq, msg.erase(me, self.seq))
            self._erase(self.seq)

    def _enter(self, seq: int) -> None:
        """Join election ``seq``: halt, forget any earlier one, contend if the sensor reads a particle."""
        self.seq = seq
        self._clear()
        self.the_leader = self.guide = None
        self._set_state(ELECTION)
        self.legs.halt()
        self._contend(self.sensor.read())

    def _contend(self, u: int) -> None:
        """Propagation, lines 1-4: a contender announces what it sensed (unless it already knows better)."""
        me = self.robot.id
        if u <= 0:
            return
        tag = (min(u, 127), -1 if self.literal_tags else me)
        if self.best is not None and not self._gt(tag, self.best):
            return
        self.sensed = tag[0]
        self.best, self.parent = tag, None
        self.children, self.siblings, self.acks, self.acked = set(), set(), set(), False
        self._n4 = None
        self.robot.log("zebro_contender", utility=self.sensed, seq=self.seq)
        self._announce(msg.N2)

    def _announce(self, kind: int) -> None:
        """Broadcast the best tag (n2 when it is new to me, n3 "I know X" to neighbours that came since)."""
        assert self.best is not None
        me, (x, origin) = self.robot.id, self.best
        self.told = set(getattr(self, "ids", ()))
        self.send(msg.n2(me, x, kind=kind) if self.literal_tags else msg.n2(me, x, origin, self.parent, kind=kind))

    def _on_wave(self, f: msg.Frame) -> None:
        """Propagation, lines 6-26: adopt a better tag from its sender (the parent) and pass it on; withdraw as a
        contender beaten by it; classify the senders of the tag already held as children or siblings."""
        me = self.robot.id
        literal = self.literal_tags
        tag: Tag = (f.value, -1 if literal else (f.origin if f.origin is not None else -1))
        if literal and self.sensed > 0 and f.value == self.sensed and me < f.src:
            self.sensed = -1  # line 19: a cousin with a higher id contests
            self.robot.log("zebro_withdraw", seq=self.seq)
        if self.best is None or self._gt(tag, self.best):
            if self.sensed > 0 and self._gt(tag, (self.sensed, -1 if literal else me)):
                self.sensed = -1  # WITHDRAW FROM ELECTION
                self.robot.log("zebro_withdraw", seq=self.seq)
            self.best, self.parent = tag, f.src
            self.children, self.siblings, self.acks, self.acked = set(), set(), set(), False
            self._n4 = None
            self._announce(msg.N2)
        elif tag == self.best:
            if not literal and f.parent == me:
                self.children.add(f.src)
            elif f.src != self.parent:
                self.siblings.add(f.src)

    def _check_done(self, ids: set[int]) -> None:
        """Back propagation (Algorithm 10): ack the parent, or, as the contender of the best tag, end the election."""
        if self.best is None or self.acked:
            return
        parent, acks, sibs = self.parent, self.acks, self.siblings
        if self.p["leader_rule"] == "echo":
            done = all(j == parent or j in acks or j in sibs for j in ids)
        else:
            done = len(ids) == (parent is not None) + len(acks & ids) + len(sibs & ids)
        if not done:
            return
        x, origin = self.best
        mine = self.sensed == x and (self.literal_tags or origin == self.robot.id)
        if self.p["ack_symbols"] == "swapped":
            send_ack, lead = parent is not None, parent is None and mine
        else:
            send_ack, lead = bool(acks) and parent is not None, not acks and mine
        me = self.robot.id
        if send_ack:
            self.acked = True
            self._n4 = msg.n4(me, parent, x) if self.literal_tags else msg.n4(me, parent, x, origin)
            self.send(self._n4)
        elif lead:
            self.acked = True
            self.the_leader = me
            self.flooded.add((msg.EOE, self.seq))
            self.send(msg.eoe(me, self.seq, me, x))
            self.robot.log("zebro_elected", utility=x, seq=self.seq)
            self._set_state(LEAD)

    def _erase(self, seq: int) -> None:
        """ERASE: clear the election, give up any title, flock again."""
        self.erased = seq
        self._clear()
        self.the_leader = self.guide = None
        self._set_state(FLOCK)

    def telemetry(self) -> dict[str, float | int]:
        return {"state": STATES.index(self.state), "seq": self.seq,
                "leader": -1 if self.the_leader is None else self.the_leader}
