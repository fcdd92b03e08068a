"""Each robot's I2C bus: its main computer is the master, its modules (a Zebro's leg modules) the slaves.

A transaction is what Linux's ``I2C_RDWR`` ioctl sends: one or more messages, each after a START or repeated START,
then a STOP. It takes its time on the wire at the master's SCL rate (100 or 400 kHz): one bit for each START,
repeated START and STOP, nine for every address and data byte (eight bits and the ACK). It starts when the master
issues it (the quantum its program ran in), or when the bus is free.

- A slave answers its address once it has powered up and announced itself (``["i2c_attach", addr, general_call]``).
  An address nobody answers (absent, not booted, a multicast address other than the general call, any read of a
  multicast address) is NACKed: the master stops there and gets ``EREMOTEIO`` (121), as the Raspberry Pi's
  ``i2c-bcm2835`` driver returns it. Messages before the NACKed one did cross the wire and reach their slaves.
- A slave may refuse a read, as an AVR's TWI slave does by clearing TWEA before the read's address (after a write set
  a register pointer it has no data for), if it said so when it attached (``["i2c_attach", addr, general_call,
  True]``): it answers that read with ``None``. The read's address is then NACKed, the STOP follows and the master
  gets ``EREMOTEIO`` at the same time a read would have returned; nothing after that read is on the wire. So that no
  message after a refusable read reaches anyone before its answer is known, a transaction in which one is followed by
  a message to another address goes on the wire in stages: up to that read, then (if it was accepted) the rest, from
  where the wire had got to, reaching its slaves a quantum later. Messages after it to the same slave stay in its
  stage: the slave ignores what follows a read it refuses, as the master has stopped there.
- The general call 0x00 (a write) reaches every slave that listens to it.
- Writes reach their slaves at the first quantum boundary at or after the transaction's end (never in the quantum it
  was issued in). The master's call returns then.
- A read round-trips through the slave's firmware, as clock stretching does on a real bus: the slave holds SCL low
  after its address until its firmware has loaded the data. The transaction's messages reach the slaves at the first
  boundary after the read's address byte (``t1``); the slave answers in that quantum; the read bytes and the STOP then
  follow at the bus rate from ``t1`` (or from where the wire had got to, if later), and the master's call returns at
  the boundary after that, one quantum after ``t1`` at the earliest. A read therefore costs at least two quanta in a
  session. The stretch is the session's: a real leg module answers from its TWI interrupt within microseconds (and
  the Pi's BCM2835 controller is known not to tolerate long stretches), so a read takes up to a quantum longer here
  than on the robot. A slave that does not answer within its quantum times the transaction out (``ETIMEDOUT``).

Items: the master sends ``["i2c", seq, [[addr, read, data_or_length], ...], scl_hz]`` and gets
``["i2c", [seq, errno, [read bytes, ...], end_ns]]`` (errno 0: done); a slave gets ``["i2c", txn, [[addr, read,
data_or_length], ...]]`` (its own messages and the general calls, in order, then the STOP; a transaction staged
after a refusable read reaches its slaves as one item per stage, with the same ``txn``) and answers reads with
``["i2c", txn, [bytes | None, ...]]``. Every transaction is recorded on ``/rNNN/i2c`` at its end, and counted in the
summary (``per_robot[].i2c``). Any master can use a robot's bus through :meth:`I2cBuses.submit`: the robot program
does through its items, and so does a USB-to-I2C adapter on the bus (a firmware entity of role ``i2c_adapter``, e.g.
``bridge.hil.usb_iss``: a program outside the session drives the bus through it), which gets the same answers.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from bridge.core.medium import Medium
from bridge.core.recorder import register_schema

if TYPE_CHECKING:
    from bridge.core.hub import Hub

# Linux errno values the master sees (asm-generic/errno.h): the session runs on Linux, as the robot's computer does
EREMOTEIO = 121  # no ACK (i2c-bcm2835)
ETIMEDOUT = 110  # the slave stretched the clock too long
EINVAL = 22  # a transaction the adapter refuses
ERRNO_STATUS = {0: "ok", EREMOTEIO: "nack", ETIMEDOUT: "timeout", EINVAL: "invalid"}

GENERAL_CALL = 0x00
MULTICAST_END = 0x0F
MIN_HZ, MAX_HZ = 1_000, 3_400_000
MAX_MSG_BYTES = 8192  # Linux's I2C_RDWR message limit
MAX_MSGS = 42  # I2C_RDWR_IOCTL_MAX_MSGS
SIM_URL = "sitl://i2c"  # what a HAL table names as its bus to be on the simulated one
ADAPTER = "i2c_adapter"  # the role of a firmware entity that is a master of its robot's bus (a USB-to-I2C adapter)

SCHEMA = "swarm_sitl.I2c"
register_schema(
    SCHEMA,
    {
        "type": "object",
        "description": "One I2C transaction on a robot's bus (master: its main computer), recorded at its end",
        "properties": {
            "seq": {"type": "integer", "description": "the master's transaction number"},
            "status": {"type": "string", "enum": ["ok", "nack", "timeout", "invalid"]},
            "start_ns": {"type": "integer"},
            "end_ns": {"type": "integer"},
            "scl_hz": {"type": "integer"},
            "bits": {"type": "integer"},
            "msgs": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "addr": {"type": "integer"},
                        "read": {"type": "boolean"},
                        "data": {"type": "string"},
                        "ack": {"type": "boolean"},
                    },
                },
            },
        },
    },
)

Done = Callable[[int, list], None]  # (delivery time, [seq, errno, reads, end_ns])


def uses_i2c(hal: dict[str, Any]) -> bool:
    """Whether a robot's HAL tables put a device on the simulated I2C bus."""
    return any(isinstance(v, dict) and v.get("bus") == SIM_URL for v in hal.values())


@dataclass
class _Txn:
    id: int
    r: int
    seq: int
    msgs: list[tuple[int, bool, bytes | int]]
    hz: int
    issued: int
    done: Done
    start: int = 0
    bits: int = 0
    pre_bits: int = 0  # up to the ACK of the stage's first read's address: where the slave stretches the clock
    acks: list[bool] = field(default_factory=list)
    addr_bits: list[int] = field(default_factory=list)  # each message's bits up to its address's ACK
    pos: int = 0  # the next message to put on the wire
    first: int = 0  # the first message of the stage on the wire
    base_t: int = 0  # the wire's time at ``base_bits`` bits (its start, then where a clock stretch ended)
    base_bits: int = 0
    reads: list[bytes] = field(default_factory=list)  # what the reads so far got
    t1: int = 0  # the boundary at which the slaves get the messages (reads: when they answer)
    waiting: set[str] = field(default_factory=set)  # slaves whose answers are due
    answers: dict[str, list[bytes]] = field(default_factory=dict)
    errno: int = 0


class I2cBus:
    """One robot's bus: the slaves that answer, what waits for the bus, what is on it, and its counters."""

    def __init__(self) -> None:
        self.slaves: dict[int, str] = {}  # address -> entity
        self.general_call: set[str] = set()  # slaves that listen to 0x00
        self.refusers: set[str] = set()  # slaves that may refuse a read (NACK its address)
        self.queue: deque[_Txn] = deque()
        self.active: _Txn | None = None  # a read waiting for its slaves' answers
        self.busy_until = 0
        self.counts = {
            "transactions": 0,
            "nacks": 0,
            "timeouts": 0,
            "invalid": 0,
            "bytes": 0,
            "bits": 0,
            "general_calls": 0,
            "address_conflicts": 0,
            "busy_ns": 0,
        }


class I2cBuses(Medium):
    """Every robot's I2C bus in a session (``I2cBus`` each): transactions from its master, timed at the master's SCL
    rate, to the slaves that announced themselves, with reads answered by the slaves' firmware."""

    name = "i2c"
    order = 25
    routes = {  # noqa: RUF012
        ("i2c", "logic"): "master",
        ("i2c", ADAPTER): "master",
        ("i2c", "*"): "slave",
        ("i2c_attach", "*"): "attach",
    }

    @classmethod
    def wanted(cls, hub: Hub) -> bool:
        """Some robot's program is given the simulated bus (its robot model's HAL tables name ``sitl://i2c``), or an
        adapter on it is."""
        return any(uses_i2c(_hal(hub, r, rp)) or ADAPTER in rp.modules() for r, rp in enumerate(hub.plan.robots))

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        self.buses = [I2cBus() for _ in hub.plan.robots]
        self.topics = [f"/r{r:03d}/i2c" for r in range(hub.n)]
        self.next_id = 0
        self.in_flight: dict[int, _Txn] = {}
        self.touched: set[int] = set()

    # -- routes -------------------------------------------------------------------------------------------------
    def attach(self, e: str, r: int, t: int, item: list) -> None:
        """``["i2c_attach", addr, general_call(, refuses_reads)]``: a slave powered up and answers ``addr`` from now
        on; one that may refuse a read says so (its answer to that read is then ``None``)."""
        _, addr, gc, *rest = item
        refuses = rest[0] if rest else False
        if (
            type(addr) is not int
            or not 0x08 <= addr <= 0x77
            or not isinstance(gc, bool)
            or len(rest) > 1
            or not isinstance(refuses, bool)
        ):
            raise ValueError
        bus = self.buses[r]
        if bus.slaves.get(addr, e) != e:  # two slaves on one address: the first keeps it
            bus.counts["address_conflicts"] += 1
            return
        bus.slaves[addr] = e
        if gc:
            bus.general_call.add(e)
        if refuses:
            bus.refusers.add(e)

    def master(self, e: str, r: int, t: int, item: list) -> None:
        """``["i2c", seq, msgs, scl_hz]`` from a robot's program or an adapter on its bus: a transaction; its result
        goes back to that master."""
        seq = item[1] if len(item) > 1 else None
        if type(seq) is not int:
            raise ValueError
        done = self._to_master(e)
        try:
            _, _, msgs, hz = item
            checked = check_transaction(msgs, hz)
        except (ValueError, TypeError):
            self.hub.counts["i2c_invalid"] += 1
            self.buses[r].counts["invalid"] += 1
            self.hub.deliver_at(t + self.hub.q_ns, lambda t_, s=seq: done(t_, [s, EINVAL, [], t_]))
            return
        self.submit(r, t, seq, checked, hz, done)

    def slave(self, e: str, r: int, t: int, item: list) -> None:
        """``["i2c", txn, [bytes | None, ...]]``: a slave's answer to the reads addressed to it (``None``: it refuses
        that read, if it said it may)."""
        _, txn_id, replies = item
        txn = self.in_flight.get(txn_id)
        if txn is None or e not in txn.waiting or not isinstance(replies, list):
            raise ValueError
        refuses = e in self.buses[r].refusers
        if not all(isinstance(b, bytes) or (b is None and refuses) for b in replies):
            raise TypeError
        txn.waiting.discard(e)
        txn.answers[e] = replies

    # -- any master -------------------------------------------------------------------------------------------
    def submit(self, r: int, t: int, seq: int, msgs: list[tuple[int, bool, bytes | int]], hz: int, done: Done) -> None:
        """A transaction on robot ``r``'s bus, issued at ``t``; ``done(t_deliver, [seq, errno, reads, end_ns])`` is
        scheduled for when it ends (at a quantum boundary after ``t``)."""
        self.next_id += 1
        self.buses[r].queue.append(_Txn(self.next_id, r, seq, msgs, hz, t, done))
        self.touched.add(r)

    # -- the quantum --------------------------------------------------------------------------------------------
    def advance(self, t: int) -> None:
        """At the end of every quantum (``end_outputs`` runs only in quanta where some entity ran): finish the reads
        whose slaves answered in this quantum, then put what waits on the bus."""
        for r in sorted(self.touched):
            bus = self.buses[r]
            if bus.active is not None and bus.active.t1 <= t:
                self._finish_read(bus, bus.active, t)
            while bus.queue and bus.active is None:
                self._start(bus, bus.queue.popleft(), t)
        self.touched = {r for r, b in enumerate(self.buses) if b.queue or b.active is not None}

    def _start(self, bus: I2cBus, txn: _Txn, t: int) -> None:
        txn.start = txn.base_t = max(txn.issued, bus.busy_until)
        txn.bits = 1  # START
        self._stage(bus, txn, t)

    def _stage(self, bus: I2cBus, txn: _Txn, t: int) -> None:
        """Put the transaction's next messages on the wire, from ``txn.pos``: to its end, to an address nobody ACKs,
        or to a read of a slave that may refuse reads when another address follows it (the rest waits for its
        answer: a refused read ends the transaction, and what follows it must not reach anyone)."""
        hub = self.hub
        q = hub.q_ns
        msgs = txn.msgs
        txn.first = i = txn.pos
        bits = txn.bits
        deliver: dict[str, list] = {}
        reads = False
        while i < len(msgs):
            addr, read, data = msgs[i]
            bits += (1 if i else 0) + 9  # repeated START, address + ACK
            targets = self._targets(bus, addr, read)
            txn.acks.append(bool(targets))
            txn.addr_bits.append(bits)
            if not targets:
                txn.errno = EREMOTEIO
                break
            if read and not reads:
                reads = True
                txn.pre_bits = bits
            for ent in targets:
                deliver.setdefault(ent, []).append([addr, read, data])
                if read:
                    txn.waiting.add(ent)
            bits += 9 * (data if read else len(data))  # type: ignore[arg-type]
            if addr == GENERAL_CALL:
                bus.counts["general_calls"] += 1
            i += 1
            if read and targets[0] in bus.refusers and i < len(msgs) and msgs[i][0] != addr:
                break
        txn.pos = i
        final = bool(txn.errno) or i == len(msgs)
        txn.bits = bits + final  # STOP
        if txn.errno:  # NACKed: the writes before it reached their slaves, a read before it is not answered
            txn.waiting.clear()
            deliver = {e: kept for e, segs in deliver.items() if (kept := [s for s in segs if not s[1]])}
        if reads and not txn.errno:
            txn.t1 = max(t + q, _ceil(self._wire(txn, txn.pre_bits), q))
            self.in_flight[txn.id] = txn
            bus.active = txn
        else:
            end = self._wire(txn, txn.bits)
            txn.t1 = max(t + q, _ceil(end, q))
            bus.busy_until = end
        for ent, segs in deliver.items():  # the slaves see the whole stage at once (the last: STOP included)
            hub.deliver_at(txn.t1, hub.to_inbox, ent, ["i2c", txn.id, segs])
        if bus.active is not txn:
            self._done(bus, txn, txn.t1, end, txn.reads)

    def _finish_read(self, bus: I2cBus, txn: _Txn, t: int) -> None:
        """The slaves had their quantum: the read bytes follow on the wire, up to a read a slave refused (or the
        transaction timed out); then the rest of the transaction, if it waited for a refusable read."""
        bus.active = None
        del self.in_flight[txn.id]
        q = self.hub.q_ns
        if txn.waiting:  # a slave that never answered (its robot failed, it lost the request)
            txn.errno = ETIMEDOUT
            bus.busy_until = t + q
            self._done(bus, txn, t + q, t + q, txn.reads)
            return
        # SCL held low until the firmware answered: the wire goes on from there
        txn.base_t, txn.base_bits = max(self._wire(txn, txn.pre_bits), txn.t1), txn.pre_bits
        pos: dict[str, int] = {}
        for i in range(txn.first, txn.pos):
            addr, read, n = txn.msgs[i]
            if read:
                ent = bus.slaves[addr]
                k = pos.get(ent, 0)
                got = txn.answers[ent][k] if k < len(txn.answers[ent]) else b""
                pos[ent] = k + 1
                if got is None:  # the slave refused it: its address NACKed, then the STOP
                    txn.errno = EREMOTEIO
                    txn.acks[i] = False
                    del txn.acks[i + 1 :]
                    txn.bits = txn.addr_bits[i] + 1
                    break
                txn.reads.append(bytes(got[:n]).ljust(n, b"\xff"))  # type: ignore[misc]  # pull-ups: a short answer
        if not txn.errno and txn.pos < len(txn.msgs):
            self._stage(bus, txn, t)
            return
        end = self._wire(txn, txn.bits)
        bus.busy_until = end
        self._done(bus, txn, max(t + q, _ceil(end, q)), end, txn.reads)

    @staticmethod
    def _wire(txn: _Txn, bits: int) -> int:
        """When the wire has carried ``bits`` of the transaction (from its last clock stretch)."""
        return txn.base_t + round((bits - txn.base_bits) * (1_000_000_000 / txn.hz))

    def _done(self, bus: I2cBus, txn: _Txn, at: int, end: int, reads: list[bytes]) -> None:
        """Count and record the transaction, and give its result to its master at ``at``."""
        c = bus.counts
        c["transactions"] += 1
        c["bits"] += txn.bits
        c["busy_ns"] += max(0, end - txn.start)
        if txn.errno == EREMOTEIO:
            c["nacks"] += 1
        elif txn.errno == ETIMEDOUT:
            c["timeouts"] += 1
        rd = iter(reads)
        msgs = []
        for (addr, read, data), ack in zip(txn.msgs, txn.acks, strict=False):  # what went on the wire
            if ack:
                c["bytes"] += data if read else len(data)  # type: ignore[operator, arg-type]
            shown = next(rd, b"") if read else data
            msgs.append({"addr": addr, "read": read, "ack": ack, "data": bytes(shown).hex()})  # type: ignore[arg-type]
        hub = self.hub
        hub.deliver_at(
            at,
            hub.record,
            self.topics[txn.r],
            SCHEMA,
            {
                "seq": txn.seq,
                "status": ERRNO_STATUS[txn.errno],
                "start_ns": txn.start,
                "end_ns": end,
                "scl_hz": txn.hz,
                "bits": txn.bits,
                "msgs": msgs,
            },
        )
        hub.deliver_at(at, txn.done, [txn.seq, txn.errno, [] if txn.errno else reads, end])

    def _targets(self, bus: I2cBus, addr: int, read: bool) -> list[str]:
        """Who ACKs ``addr``: the general call's listeners (writes only), the slave at a device address."""
        if addr == GENERAL_CALL:
            return [] if read else sorted(e for e in bus.general_call if not self._dead(e))
        if addr <= MULTICAST_END:
            return []
        ent = bus.slaves.get(addr)
        return [] if ent is None or self._dead(ent) else [ent]

    def _dead(self, ent: str) -> bool:
        return int(ent[1 : ent.index("/")]) in self.hub.dead

    def _to_master(self, master: str) -> Done:
        def done(t: int, result: list) -> None:
            self.hub.to_inbox(t, master, ["i2c", result])

        return done

    # -- the summary --------------------------------------------------------------------------------------------
    def report(self, result: dict[str, Any]) -> None:
        """Per robot with a bus in use: its slaves, transactions, NACKs, time-outs, bytes, bus load."""
        sim_ns = max(self.hub.sim_end_ns, 1)
        for r, bus in enumerate(self.buses):
            c = bus.counts
            if bus.slaves or c["transactions"] or c["invalid"]:
                result["robots"][r]["i2c"] = {
                    "slaves": {f"0x{a:02X}": e[e.index("/") + 1 :] for a, e in sorted(bus.slaves.items())},
                    **{k: v for k, v in c.items() if k != "busy_ns"},
                    "bus_load": round(c["busy_ns"] / sim_ns, 5),
                }
        counts = result.setdefault("message_counts", {})
        for key in ("transactions", "nacks", "timeouts", "bytes"):
            total = sum(b.counts[key] for b in self.buses)
            if total:
                counts[f"i2c_{key}"] = total


def _ceil(t: int, q: int) -> int:
    return -(-t // q) * q


def _hal(hub: Hub, r: int, rp: Any) -> dict[str, Any]:
    spec = hub.robot_spec(r)
    if spec.hal is None or rp.gateway is not None:
        return {}
    return dict(spec.hal(rp, hub.cfg))


def check_transaction(msgs: Any, hz: Any) -> list[tuple[int, bool, bytes | int]]:
    """A transaction as the adapter takes it: 1-42 messages of an address, a direction and 1-8192 bytes (a write
    may be empty: a quick command), at a sane SCL rate. Anything else is refused (``EINVAL``)."""
    if type(hz) is not int or not MIN_HZ <= hz <= MAX_HZ:
        raise ValueError
    if not isinstance(msgs, list | tuple) or not 1 <= len(msgs) <= MAX_MSGS:
        raise ValueError
    out: list[tuple[int, bool, bytes | int]] = []
    for m in msgs:
        addr, read, data = m
        if type(addr) is not int or not 0 <= addr <= 0x7F or not isinstance(read, bool):
            raise ValueError
        if read:
            if type(data) is not int or not 1 <= data <= MAX_MSG_BYTES:
                raise ValueError
        elif not isinstance(data, bytes) or len(data) > MAX_MSG_BYTES:
            raise ValueError
        out.append((addr, read, data))
    return out
