"""A CAN bus as a shared medium: arbitration by ID, exact bit time on the wire, and fault confinement.

One robot's bus segment in simulated time, advanced one quantum at a time by the world. Frames offered
during quantum k start contending at the end of k (they are delivered at k+1 at the earliest, like every
message in a session). The lowest ID wins arbitration; a frame occupies the bus for its exact length,
bit stuffing included, at the bus bit rate, and is delivered at the first quantum boundary at or after its
last bit. The order of delivery is the order on the wire, so it does not depend on which process sent first.

Faults follow ISO 11898-1 fault confinement so that fault-injection runs see what real nodes see: a
destroyed frame costs the bus its bits up to the error plus an error frame, delivers nothing and is
retransmitted automatically; each node keeps a transmit and a receive error counter, turns error-passive
(and then waits 8 "suspend transmission" bits after each frame it sends) and then bus-off, and recovers
after 128 x 11 recessive bits plus its host's restart delay. Simplifications: every error is a CRC error
detected at the CRC delimiter; every receiver counts REC += 1 per error (ISO gives +8 to the receiver that
detects it first: here no receiver is singled out) and REC saturates at 255 like an 8-bit register; the
128 x 11 recessive bits are taken as 1408 bit times, ending at the first moment the bus is idle; a frame is
always acknowledged (an unregistered listener, like the recorder, acks it), so a lone node sees no ACK errors.
"""

from __future__ import annotations

import heapq
import random
from dataclasses import dataclass, field
from functools import lru_cache
from typing import TYPE_CHECKING, Any, Literal

from bridge.core.entities import entity
from bridge.core.medium import Medium
from bridge.core.rng import stream_seed

if TYPE_CHECKING:
    from bridge.core.hub import Hub

State = Literal["active", "passive", "bus_off"]
FaultKind = Literal["tx_error", "noise"]

CRC15_POLY = 0x4599
TAIL_BITS = 13  # never stuffed: CRC delimiter, ACK slot, ACK delimiter, 7 EOF, 3 intermission
ERROR_BITS = 6 + 8 + 3  # error flag, error delimiter, intermission after the CRC delimiter
SUSPEND_BITS = 8  # an error-passive transmitter waits this long after its frame before it may start again
RECOVERY_BITS = 128 * 11  # bus-off recovery: 128 sequences of 11 recessive bits, taken as bit times
PASSIVE_ABOVE = 127  # TEC or REC above this: error-passive
BUS_OFF_ABOVE = 255  # TEC above this: bus-off
REC_AFTER_PASSIVE = 119  # ISO allows 119..127 after a good reception with REC > 127
REC_MAX = 255  # REC is an 8-bit register (MCP2515, SJA1000); only "> 127" matters to the state


# What a CAN item the world delivers to a node is (its optional sixth field), besides a frame from another node: the
# node's own frame echoed back (python-can's receive_own_messages), or an error frame.
OWN, ERROR_FRAME = 1, 2
# socketcan's error frame classes (linux/can/error.h), the arbitration id of an error frame; bytes 6 and 7 carry
# the node's TEC and REC (CAN_ERR_CNT), byte 1 the controller status for CAN_ERR_CRTL
CAN_ERR_CRTL, CAN_ERR_PROT, CAN_ERR_BUSOFF, CAN_ERR_RESTARTED, CAN_ERR_CNT = 0x04, 0x08, 0x40, 0x100, 0x200


def error_frame(klass: int, ctrl: int, tec: int, rec: int, t_ns: int) -> list:
    """A socketcan error frame as the world delivers it to a node: class bits (with the counters) in the id, the
    controller status in byte 1, TEC and REC in bytes 6 and 7."""
    return ["can0", klass | CAN_ERR_CNT, bytes([0, ctrl, 0, 0, 0, 0, min(tec, 255), min(rec, 255)]), False, t_ns,
            ERROR_FRAME]


def frame_bits(dlc: int, extended: bool = False) -> int:
    """Worst-case bits on the wire for a classic data frame: 47 (standard) or 67 (extended) bits of
    framing including the 3-bit interframe space, 8 per data byte, and the worst-case stuff bits over
    the 34 + 8n (54 + 8n) bits from start of frame to the end of the CRC."""
    if extended:
        return 67 + 8 * dlc + (54 + 8 * dlc - 1) // 4
    return 47 + 8 * dlc + (34 + 8 * dlc - 1) // 4


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 7
        for _ in range(8):
            crc = (crc << 1) ^ CRC15_POLY if crc & 0x4000 else crc << 1
        table.append(crc & 0x7FFF)
    return tuple(table)


def _stuff_step(state: int, bit: int) -> tuple[int, int]:
    """One bit through the stuffing rule. ``state`` = 5 * last bit + length of its run (0: nothing sent yet);
    returns (stuff bits inserted, new state). The stuff bit is the first bit of the next run."""
    last, run = divmod(state, 5)
    run = run + 1 if bit == last else 1
    if run == 5:
        return 1, 5 * (1 - bit) + 1
    return 0, 5 * bit + run


def _stuff_tables() -> tuple[tuple[tuple[int, int], ...], ...]:
    tables = []
    for state in range(10):
        row = []
        for byte in range(256):
            n, s = 0, state
            for i in range(7, -1, -1):
                k, s = _stuff_step(s, byte >> i & 1)
                n += k
            row.append((n, s))
        tables.append(tuple(row))
    return tuple(tables)


_CRC_TABLE = _crc_table()
_STUFF_TABLE = _stuff_tables()  # [state][byte] -> (stuff bits, new state)


def crc15(bits: int, n: int) -> int:
    """CRC-15/CAN (polynomial 0x4599, initial value 0) of the ``n``-bit stream ``bits``, first bit = MSB.

    With a zero initial value leading zero bits do not change the CRC, so the stream is padded at the
    front to whole bytes and run through a byte table."""
    crc = 0
    for byte in bits.to_bytes((n + 7) // 8, "big"):
        crc = ((crc << 8) ^ _CRC_TABLE[((crc >> 7) ^ byte) & 0xFF]) & 0x7FFF
    return crc


def stuff_count(bits: int, n: int) -> int:
    """Stuff bits a transmitter inserts into the ``n``-bit stream ``bits`` (first bit = MSB): one after
    every 5 equal bits in a row, and the stuff bit (the complement) counts as the first bit of the next run.

    The stream is padded at the front to whole bytes with alternating bits that end opposite to its first
    bit: they never stuff, and leave the rule in the state it starts in for that first bit."""
    pad = -n % 8
    if pad:
        bits |= ((0xAA if bits >> (n - 1) & 1 else 0x55) & ((1 << pad) - 1)) << n
        n += pad
    stuffed, state = 0, 0
    for byte in bits.to_bytes(n // 8, "big"):
        k, state = _STUFF_TABLE[state][byte]
        stuffed += k
    return stuffed


def _crc_covered_bits(arbitration_id: int, data: bytes, extended: bool) -> tuple[int, int]:
    """SOF to the end of the data field (the bits the CRC covers) as (value, length), dominant = 0."""
    if extended:  # SOF, base ID, SRR, IDE (both recessive), ID extension, RTR, r1, r0, DLC
        bits = ((arbitration_id >> 18) << 20 | 0b11 << 18 | arbitration_id & 0x3FFFF) << 7 | len(data)
        n = 39
    else:  # SOF, ID, RTR, IDE, r0, DLC
        bits, n = arbitration_id << 7 | len(data), 19
    return bits << 8 * len(data) | int.from_bytes(data, "big"), n + 8 * len(data)


@lru_cache(maxsize=1 << 16)
def wire_bits(arbitration_id: int, data: bytes, extended: bool = False) -> int:
    """Exact bit times a classic CAN 2.0 data frame occupies, including stuff bits (SOF to the end of
    the CRC sequence) and the 3-bit intermission."""
    bits, n = _crc_covered_bits(arbitration_id, data, extended)
    return n + 15 + stuff_count(bits << 15 | crc15(bits, n), n + 15) + TAIL_BITS


def frame_fault(arbitration_id: int, data: bytes, extended: bool) -> str | None:
    """Why a classic CAN data frame cannot exist on the wire, or None if it can."""
    if len(data) > 8:
        return f"classic CAN frame holds at most 8 bytes, got {len(data)}"
    if not 0 <= arbitration_id <= (0x1FFFFFFF if extended else 0x7FF):
        kind = "an extended" if extended else "a standard"
        return f"arbitration id 0x{arbitration_id:X} out of range for {kind} frame"
    return None


def arbitration_key(arbitration_id: int, extended: bool) -> tuple[int, int, int]:
    """Who wins arbitration: the 11-bit base ID first; at equal base IDs a standard frame beats an
    extended one (its RTR/IDE bits are dominant where the extended frame sends recessive SRR/IDE)."""
    if extended:
        return (arbitration_id >> 18, 1, arbitration_id & 0x3FFFF)
    return (arbitration_id, 0, 0)


def _state_of(tec: int, rec: int) -> State:
    if tec > BUS_OFF_ABOVE:
        return "bus_off"
    if tec > PASSIVE_ABOVE or rec > PASSIVE_ABOVE:
        return "passive"
    return "active"


@dataclass(order=True, slots=True)
class _Pending:
    key: tuple[int, int, int]
    src: str
    seq: int
    arbitration_id: int = field(compare=False)
    data: bytes = field(compare=False)
    extended: bool = field(compare=False)
    bits: int = field(compare=False)


@dataclass(frozen=True, slots=True)
class Delivery:
    t_ns: int  # quantum boundary at which it is delivered
    wire_end_ns: int  # when its last bit left the wire
    arbitration_id: int
    data: bytes
    src: str
    extended: bool
    receivers: tuple[str, ...] = ()  # registered nodes other than the sender, none of them bus-off during it


@dataclass(frozen=True, slots=True)
class CanEvent:
    """An error frame (``node`` is the transmitter) or a node's change of state, with its counters after it."""

    t_ns: int  # quantum boundary at or after wire_ns (and after the transmit() call's start): when to report it
    wire_ns: int  # error detected (end of the CRC delimiter) or state changed
    kind: Literal["error_frame", "state"]
    node: str
    state: State
    tec: int
    rec: int
    arbitration_id: int | None  # the frame that caused it; None for a recovery


@dataclass(slots=True)
class _Node:
    name: str
    restart_ns: int | None  # host's delay before restarting after bus-off; None: only recover() does
    tec: int = 0
    rec: int = 0
    state: State = "active"
    recover_at: int | None = None  # bus-off until then (None: until recover())
    tx_errors: int = 0
    rx_errors: int = 0
    bus_off_count: int = 0
    dropped_bus_off: int = 0  # frames dropped because the node was bus-off: pending ones and new offers


@dataclass(frozen=True, slots=True)
class _Fault:
    node: str  # the transmitter whose frames it destroys, or "*"
    start_ns: int
    end_ns: int | None
    probability: float


class CanMedium:
    """One CAN bus segment (one robot's bus).

    Each quantum [t, t+q) the world offers the frames its nodes sent, calls ``transmit(t, q)`` if
    ``busy(t, q)`` and schedules the deliveries and ``drain_events()`` at their ``t_ns``."""

    def __init__(self, name: str, bitrate: int = 500_000, seed: int = 0) -> None:
        self.name = name
        self.bitrate = bitrate
        self.pending: list[_Pending] = []
        self.busy_until_ns = 0
        self.frames = 0
        self.bits = 0  # bus occupancy: frames delivered and destroyed ones with their error frames
        self.error_frames = 0
        self._nodes: dict[str, _Node] = {}
        self._rng = random.Random(seed)
        self._faults: list[_Fault] = []
        self._events: list[CanEvent] = []
        self._off: dict[str, _Node] = {}  # bus-off nodes
        self._suspend: dict[str, int] = {}  # error-passive sender -> when it may start a frame again
        self._receivers: dict[str, tuple[str, ...]] = {}  # sender -> receivers, cleared on any change
        self._counting = False  # some TEC or REC is non-zero: good frames must count them down
        self._q_ns = 1  # the quantum of the running transmit() call, for the events it reports
        self._report_from = 0  # its end: no event is reported earlier (a recovery due at its start included)

    def _ns(self, bits: int) -> int:
        return (bits * 1_000_000_000 + self.bitrate - 1) // self.bitrate

    def add_node(self, name: str, restart_ns: int | None = 0) -> None:
        """Register a node on the bus; registering again changes its restart delay (from its next bus-off).

        ``restart_ns`` is how long its host waits after bus-off before restarting the controller (like
        socketcan's restart-ms; 0 for an MCP2515's automatic recovery; None: stays bus-off until
        :meth:`recover`)."""
        if restart_ns is not None and restart_ns < 0:
            raise ValueError(f"restart_ns must be >= 0 or None, got {restart_ns}")
        node = self._nodes.get(name)
        if node is None:
            self._nodes[name] = _Node(name, restart_ns)
            self._receivers.clear()
        else:
            node.restart_ns = restart_ns

    def offer(self, src: str, seq: int, arbitration_id: int, data: bytes, extended: bool = False) -> bool:
        """Queue a frame from ``src`` (registered with restart_ns=0 if new); False if dropped as ``src`` is bus-off."""
        if (fault := frame_fault(arbitration_id, data, extended)) is not None:
            raise ValueError(fault)
        if src in self._off:
            self._off[src].dropped_bus_off += 1
            return False
        if src not in self._nodes:
            self.add_node(src)
        data = bytes(data)
        heapq.heappush(self.pending, _Pending(arbitration_key(arbitration_id, extended), src, seq, arbitration_id,
                                              data, extended, wire_bits(arbitration_id, data, extended)))
        return True

    def inject(self, node: str, kind: FaultKind, start_ns: int, end_ns: int | None = None,
               probability: float = 1.0) -> None:
        """Destroy frames whose transmission starts in [start_ns, end_ns), each with ``probability``.

        ``"tx_error"``: frames ``node`` transmits (a failing transceiver, a CAN_H/CAN_L fault at its
        connector). ``"noise"``: frames of every node (``node="*"``) or of one, as EMI would do."""
        if kind not in ("tx_error", "noise"):
            raise ValueError(f"unknown CAN fault kind {kind!r}")
        if node == "*" and kind != "noise":
            raise ValueError("only noise applies to every node ('*')")
        if end_ns is not None and end_ns <= start_ns:
            raise ValueError(f"fault window [{start_ns}, {end_ns}) is empty")
        if not 0.0 <= probability <= 1.0:
            raise ValueError(f"probability must be in [0, 1], got {probability}")
        self._faults.append(_Fault(node, start_ns, end_ns, probability))

    def recover(self, name: str, t_ns: int) -> int | None:
        """The host restarts a bus-off node at ``t_ns``; it is error-active again after 128 x 11 recessive
        bits. Returns that time, or None if the node is not bus-off."""
        node = self._nodes[name]
        if node.state != "bus_off":
            return None
        at = t_ns + self._ns(RECOVERY_BITS)
        node.recover_at = at if node.recover_at is None else min(node.recover_at, at)
        return node.recover_at

    def node_state(self, name: str) -> tuple[State, int, int]:
        """(state, TEC, REC) of a node as of the last :meth:`transmit`."""
        node = self._nodes[name]
        return node.state, node.tec, node.rec

    def busy(self, t_ns: int, q_ns: int) -> bool:
        """Whether ``transmit(t_ns, q_ns)`` has anything to do: frames pending or a node recovering by the end
        of that quantum. (A fault window opening or closing changes nothing until a frame starts.)"""
        if self.pending:
            return True
        if not self._off:
            return False
        wake = self._next_recovery()
        return wake is not None and wake < t_ns + q_ns

    def drain_events(self) -> list[CanEvent]:
        """Error frames and state changes since the last call, in time order."""
        events, self._events = self._events, []
        return events

    def stats(self) -> dict[str, Any]:
        """Counters for the session summary."""
        return {"frames": self.frames, "bits": self.bits, "error_frames": self.error_frames,
                "nodes": {n.name: {"state": n.state, "tec": n.tec, "rec": n.rec, "tx_errors": n.tx_errors,
                                   "rx_errors": n.rx_errors, "bus_off_count": n.bus_off_count,
                                   "dropped_bus_off": n.dropped_bus_off} for n in self._nodes.values()}}

    def transmit(self, t_start_ns: int, q_ns: int) -> list[Delivery]:
        """Put pending frames on the wire from ``t_start_ns`` for one quantum; return what completes.

        Frames still contending at the end of the quantum stay pending for the next call, and a frame
        crossing its end keeps the bus busy into the next one; recoveries due in the quantum happen in time
        order with the frames, at the first moment the bus is idle. Error frames and changes of state go to
        :meth:`drain_events`.
        """
        out: list[Delivery] = []
        t = max(self.busy_until_ns, t_start_ns)
        horizon = self._report_from = t_start_ns + q_ns
        self._q_ns = q_ns
        while t < horizon:
            if self._off and self._recover_due(t):
                continue
            f = self._next_frame(t) if self.pending else None
            if f is None:
                wake = self._next_wake(t)
                if wake is None or wake >= horizon:
                    break
                t = wake
                continue
            if self._faults and self._destroyed(f, t):
                t = self._error_frame(f, t)
                continue
            end = t + self._ns(f.bits)
            recv = self._receivers.get(f.src)
            if recv is None:
                recv = self._receivers_of(f.src)
            out.append(Delivery(-(-end // q_ns) * q_ns, end, f.arbitration_id, f.data, f.src, f.extended, recv))
            self.frames += 1
            self.bits += f.bits
            if self._counting:
                self._good_frame(f, end, recv)
            t = end
        self.busy_until_ns = max(self.busy_until_ns, t)
        return out

    def _receivers_of(self, src: str) -> tuple[str, ...]:
        recv = tuple(n for n in self._nodes if n != src and n not in self._off)
        self._receivers[src] = recv
        return recv

    def _next_recovery(self) -> int | None:
        return min((n.recover_at for n in self._off.values() if n.recover_at is not None), default=None)

    def _next_wake(self, t: int) -> int | None:
        """When something may happen on an idle bus: a recovery, or a suspended sender's frame may start."""
        wake = self._next_recovery()
        if self.pending:
            for until in self._suspend.values():
                if until > t and (wake is None or until < wake):
                    wake = until
        return wake

    def _next_frame(self, t: int) -> _Pending | None:
        """Pop the arbitration winner among pending frames whose sender is not suspended at ``t``."""
        if self._suspend:
            for src in [s for s, until in self._suspend.items() if until <= t]:
                del self._suspend[src]
        if not self._suspend:
            return heapq.heappop(self.pending)
        held = []
        winner = None
        while self.pending:
            f = heapq.heappop(self.pending)
            if f.src not in self._suspend:
                winner = f
                break
            held.append(f)
        for f in held:
            heapq.heappush(self.pending, f)
        return winner

    def _destroyed(self, f: _Pending, t: int) -> bool:
        if any(x.end_ns is not None and x.end_ns <= t for x in self._faults):
            self._faults = [x for x in self._faults if x.end_ns is None or x.end_ns > t]
        return any(x.start_ns <= t and x.node in ("*", f.src)
                   and (x.probability >= 1.0 or self._rng.random() < x.probability) for x in self._faults)

    def _error_frame(self, f: _Pending, t: int) -> int:
        """``f`` is destroyed: count the errors, keep it pending (unless its sender went bus-off), return when
        the bus is free again."""
        detect = t + self._ns(f.bits - TAIL_BITS + 1)  # its stuffed bits up to and including the CRC delimiter
        end = t + self._ns(f.bits - TAIL_BITS + 1 + ERROR_BITS)
        self.bits += f.bits - TAIL_BITS + 1 + ERROR_BITS
        self.error_frames += 1
        node = self._nodes[f.src]
        node.tec += 8
        node.tx_errors += 1
        recv = self._receivers.get(f.src)
        if recv is None:
            recv = self._receivers_of(f.src)
        for name in recv:
            r = self._nodes[name]
            r.rec = min(r.rec + 1, REC_MAX)
            r.rx_errors += 1
        self._counting = True
        self._event(detect, "error_frame", node, _state_of(node.tec, node.rec), f.arbitration_id)
        self._update(node, detect, f.arbitration_id)
        for name in recv:
            self._update(self._nodes[name], detect, f.arbitration_id)
        if node.state == "bus_off":
            node.dropped_bus_off += 1
        else:
            heapq.heappush(self.pending, f)
            if node.state == "passive":
                self._suspend[f.src] = end + self._ns(SUSPEND_BITS)
        return end

    def _good_frame(self, f: _Pending, end: int, recv: tuple[str, ...]) -> None:
        node = self._nodes[f.src]
        if node.tec:
            node.tec -= 1
        for name in recv:
            r = self._nodes[name]
            if r.rec > PASSIVE_ABOVE:
                r.rec = REC_AFTER_PASSIVE
            elif r.rec:
                r.rec -= 1
        self._update(node, end, f.arbitration_id)
        for name in recv:
            self._update(self._nodes[name], end, f.arbitration_id)
        if node.state == "passive":
            self._suspend[f.src] = end + self._ns(SUSPEND_BITS)
        self._counting = any(n.tec or n.rec for n in self._nodes.values())

    def _update(self, node: _Node, wire_ns: int, arbitration_id: int) -> None:
        """Move ``node`` to the state its counters call for, reporting the change; bus-off drops its frames."""
        state = _state_of(node.tec, node.rec)
        if state == node.state:
            return
        node.state = state
        self._event(wire_ns, "state", node, state, arbitration_id)
        if state != "bus_off":
            return
        node.bus_off_count += 1
        self._off[node.name] = node
        self._receivers.clear()
        self._suspend.pop(node.name, None)
        if node.restart_ns is not None:
            node.recover_at = wire_ns + self._ns(RECOVERY_BITS) + node.restart_ns
        kept = [p for p in self.pending if p.src != node.name]
        node.dropped_bus_off += len(self.pending) - len(kept)
        self.pending[:] = kept
        heapq.heapify(self.pending)

    def _recover_due(self, t: int) -> bool:
        """Bring back every bus-off node whose recovery is due by ``t`` (the bus is idle at ``t``)."""
        due = sorted((n.recover_at, n.name) for n in self._off.values()
                     if n.recover_at is not None and n.recover_at <= t)
        for _, name in due:
            node = self._off.pop(name)
            node.tec = node.rec = 0
            node.recover_at = None
            node.state = "active"
            self._event(t, "state", node, "active", None)
        if due:
            self._receivers.clear()
            self._counting = any(n.tec or n.rec for n in self._nodes.values())
        return bool(due)

    def _event(self, wire_ns: int, kind: Literal["error_frame", "state"], node: _Node, state: State,
               arbitration_id: int | None) -> None:
        q = self._q_ns
        t_ns = max(-(-wire_ns // q) * q, self._report_from)
        self._events.append(CanEvent(t_ns, wire_ns, kind, node.name, state, node.tec, node.rec, arbitration_id))


class CanBuses(Medium):
    """Every robot's CAN bus in a session, one ``CanMedium`` each: the frames its nodes offer, their delivery (and a
    python-can node's echo), error frames and fault-confinement states to the nodes, the recording and the summary.
    """

    name = "can"
    order = 10
    routes = {("can0", "*"): "frame"}  # noqa: RUF012 (a class-level table)

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        robots = hub.plan.robots
        self.buses = [self._bus(r, rp) for r, rp in enumerate(robots)]
        self.echo: set[str] = set()  # nodes whose own frames come back to them (receive_own_messages)
        self.events: list[dict[str, Any]] = []  # bus-off and recovery of every node, for the summary
        self.noticed: dict[str, tuple[int | None, int]] = {}  # node -> (last notice, events not told since)
        self.seq: dict[str, int] = dict.fromkeys(hub.ents, 0)
        self.touched: set[int] = set()  # robots whose bus was offered a frame this quantum
        self.names = [hub.robot_spec(r).frame_names() for r in range(len(robots))]  # id -> DBC name, per robot
        self.topics = [f"/r{r:03d}/can0" for r in range(len(robots))]

    def _bus(self, r: int, rp: Any) -> CanMedium:
        """Robot ``r``'s CAN bus: its nodes (the LLC's controller recovers from bus-off by itself; the companion
        computer's adapter restarts after ``can.host_restart_ms``), and the faults injected into it."""
        cfg = self.hub.cfg
        bus = CanMedium(f"r{r:03d}/can0", cfg.can.bitrate, seed=stream_seed(cfg.session.seed, "can", r))
        host_ms = cfg.can.host_restart_ms
        host_restart = None if host_ms is None else round(host_ms * 1e6)
        for role in rp.can_nodes():
            bus.add_node(entity(r, role), host_restart if role == "logic" else 0)
        for f in cfg.faults:
            if f.robot == r:
                self._fault(bus, r, rp, f)
        return bus

    @staticmethod
    def _fault(bus: CanMedium, r: int, rp: Any, f: Any) -> bool:
        """Fault ``f`` into robot ``r``'s bus, if it is a CAN fault."""
        if f.kind not in ("can_bus_off", "can_noise"):
            return False
        start = round(f.at_s * 1e9)
        end = None if f.duration_s is None else start + round(f.duration_s * 1e9)
        if f.kind == "can_bus_off":
            bus.inject(entity(r, rp.host_node if f.node == "host" else f.node), "tx_error", start, end)
        else:
            bus.inject("*", "noise", start, end, f.probability)
        return True

    def inject_fault(self, f: Any, t: int) -> bool:
        """A CAN fault injected while the session runs (from ``f.at_s`` on), as one from the config."""
        return (f.robot is not None and f.robot < len(self.buses)
                and self._fault(self.buses[f.robot], f.robot, self.hub.plan.robots[f.robot], f))

    def frame(self, e: str, r: int, t: int, item: list) -> None:
        """``[bus, id, data, extended]`` (a fifth element ``True`` asks for the echo) offered by node ``e``."""
        if not _valid_can(item):
            self.hub.counts["malformed_frames"] += 1
            return
        self.seq[e] += 1
        if len(item) == 5:  # validated: it asks for its echo
            self.echo.add(e)
        if self.buses[r].offer(e, self.seq[e], item[1], item[2], item[3]):
            self.touched.add(r)
        else:  # the node is bus-off: its controller cannot send
            self.hub.counts["can_dropped_bus_off"] += 1

    def end_outputs(self, t: int) -> None:
        """Arbitrate what was offered (and what waits on a busy bus): deliveries and events at their times."""
        q = self.hub.q_ns
        for r, bus in enumerate(self.buses):
            if r in self.touched or bus.busy(t, q):
                for d in bus.transmit(t, q):
                    self.hub.deliver_at(d.t_ns, self._deliver, r, d)
                for ev in bus.drain_events():
                    self.hub.deliver_at(ev.t_ns, self._event, r, ev)
        self.touched.clear()

    def _deliver(self, t: int, r: int, d: Delivery) -> None:
        hub = self.hub
        hub.rec.write_json(t, self.topics[r], "swarm_sitl.CanFrame", (
            f'{{"id":{d.arbitration_id},"data":"{d.data.hex()}","src":"{d.src}",'
            f'"name":"{self.names[r].get(d.arbitration_id, "")}","wire_end_ns":{d.wire_end_ns}}}').encode())
        hub.counts["can_frames"] += 1
        if r in hub.dead:
            return
        inbox = hub.inbox
        for node in d.receivers:
            inbox[node].append(["can0", d.arbitration_id, d.data, d.extended, d.wire_end_ns])
        if d.src in self.echo:
            inbox[d.src].append(["can0", d.arbitration_id, d.data, d.extended, d.wire_end_ns, OWN])

    def _event(self, t: int, r: int, ev: CanEvent) -> None:
        """An error frame or a node's change of fault-confinement state on robot ``r``'s bus: to the recording, to
        the node (its controller's error register; socketcan-style error frames for a logic's python-can bus), and
        a bus-off or recovery to the launcher and the summary."""
        hub = self.hub
        node = ev.node
        if ev.kind == "error_frame":
            name = self.names[r].get(ev.arbitration_id, "")
            hub.rec.write_json(t, self.topics[r], "swarm_sitl.CanFrame", (
                f'{{"id":{ev.arbitration_id},"data":"","src":"{node}","name":"{name}",'
                f'"wire_end_ns":{ev.wire_ns},"error":true}}').encode())
            hub.counts["can_error_frames"] += 1
            logic = entity(r, "logic")  # the only node that shows error frames to its program (python-can)
            if r not in hub.dead and "logic" in hub.roles[r]:
                state, tec, rec = self.buses[r].node_state(logic)
                if state != "bus_off":
                    hub.inbox[logic].append(error_frame(CAN_ERR_PROT, 0, tec, rec, ev.wire_ns))
            return
        hub.rec.write(t, f"/r{r:03d}/can0/state", "swarm_sitl.CanState",
                      {"node": node, "state": ev.state, "tec": ev.tec, "rec": ev.rec, "wire_ns": ev.wire_ns})
        if r in hub.dead:
            return
        hub.inbox[node].append(["can0_state", ev.state, ev.tec, ev.rec])
        if node.endswith("/logic"):  # socketcan reports its own controller's state changes as error frames
            klass, ctrl = {"bus_off": (CAN_ERR_BUSOFF, 0), "passive": (CAN_ERR_CRTL, 0x30),
                           "active": (CAN_ERR_RESTARTED if ev.arbitration_id is None else CAN_ERR_CRTL, 0x40)}[ev.state]
            hub.inbox[node].append(error_frame(klass, ctrl, ev.tec, ev.rec, ev.wire_ns))
        if ev.state == "bus_off" or (ev.state == "active" and ev.arbitration_id is None):
            what = "bus-off" if ev.state == "bus_off" else "recovered from bus-off"
            rec = {"robot": r, "t_s": round(ev.wire_ns / 1e9, 6), "node": node[node.index("/") + 1:],
                   "event": "bus_off" if ev.state == "bus_off" else "recovered", "tec": ev.tec}
            self.events.append(rec)
            if ev.state == "bus_off":
                hub.event(t, {"kind": "can_bus_off", "robot": r, "detail": f"CAN node {node} is bus-off"})
            # a node that keeps failing goes bus-off every restart: tell the user at once, then every 10 s at most
            last, quiet = self.noticed.get(node, (None, 0))
            if last is None or ev.wire_ns - last >= 10_000_000_000:
                more = f"; {quiet} more bus-off/recovery events since the last notice" if quiet else ""
                hub.status(op="notice", text=f"robot {r}: CAN node {rec['node']} {what} at sim t={rec['t_s']:.3f} s "
                                             f"(TEC {ev.tec}){more}")
                self.noticed[node] = (ev.wire_ns, 0)
            else:
                self.noticed[node] = (last, quiet + 1)

    def radio_report(self, out: dict[str, Any]) -> None:
        """The USB-CAN adapter's own counters, and a real board's bridge's (they report them at the end)."""
        hub = self.hub
        for r in range(hub.n):
            for role in ("slcan", "can_bridge"):
                if role in hub.roles[r]:
                    out["per_robot"].setdefault(r, {})[role] = hub.module_stats.get(entity(r, role))

    def report(self, result: dict[str, Any]) -> None:
        result["can_events"] = self.events
        sim_s = max(self.hub.sim_end_ns / 1e9, 1e-9)
        for r, bus in enumerate(self.buses):
            st = bus.stats()
            result["robots"][r].update({
                "can_frames": bus.frames, "can_bus_load": round(bus.bits / bus.bitrate / sim_s, 4),
                # a robot's bus in the summary: error frames, and each node's final state and counters (by role)
                "can": {"error_frames": st["error_frames"],
                        "nodes": {name[name.index("/") + 1:]: v for name, v in st["nodes"].items()}}})


def _valid_can(item: Any) -> bool:
    """[bus, arbitration id, data, extended] as the participants send it, optionally with a fifth element True to
    have the frame echoed back (python-can's receive_own_messages); anything else is dropped."""
    if not (isinstance(item, list | tuple) and len(item) in (4, 5) and item[0] == "can0"
            and (len(item) == 4 or item[4] is True)):
        return False
    arb, data, ext = item[1:4]
    return (isinstance(arb, int) and isinstance(data, bytes) and isinstance(ext, bool)
            and frame_fault(arb, data, ext) is None)
