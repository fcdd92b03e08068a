"""The CAN medium: arbitration by ID, exact bit time on the wire, carry-over, delivery at k+1 or later, and
ISO 11898-1 fault confinement (error frames, error counters, error-passive, bus-off and recovery)."""

from __future__ import annotations

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from bridge.media.can import (
    RECOVERY_BITS,
    CanEvent,
    CanMedium,
    Delivery,
    crc15,
    frame_bits,
    stuff_count,
    wire_bits,
)

Q = 10_000_000  # 10 ms
LLC, LOGIC, SLCAN = "r003/llc", "r003/logic", "r003/slcan"


def ns(bits: int, bitrate: int = 500_000) -> int:
    return -(-bits * 1_000_000_000 // bitrate)


def error_bits(arbitration_id: int, data: bytes) -> int:
    """Bus time of a destroyed standard frame: its bits to the CRC delimiter, error flag, delimiter, intermission."""
    return wire_bits(arbitration_id, data) - 12 + 6 + 8 + 3


def run(bus: CanMedium, t0: int, t1: int, busy: list[int] | None = None) -> list[Delivery]:
    """The world's loop: transmit in every quantum the medium says it is busy (those quanta go to ``busy``)."""
    out = []
    for t in range(t0, t1, Q):
        if bus.busy(t, Q):
            out += bus.transmit(t, Q)
            if busy is not None:
                busy.append(t)
    return out


def poly_crc(bits: str) -> int:
    """CRC-15/CAN by polynomial long division: the remainder of M(x) * x^15 by x^15+x^14+x^10+x^8+x^7+x^4+x^3+1."""
    m = int(bits or "0", 2) << 15
    g = 0x4599 | 1 << 15
    for i in range(m.bit_length() - 1, 14, -1):
        if m >> i & 1:
            m ^= g << (i - 15)
    return m


def naive_stuff(bits: str) -> int:
    """Insert stuff bits one by one as a transmitter does and count them."""
    out: list[str] = []
    n = 0
    for b in bits:
        out.append(b)
        if len(out) >= 5 and len(set(out[-5:])) == 1:
            out.append("1" if b == "0" else "0")
            n += 1
    return n


def test_frame_bits_worst_case_stuffing() -> None:
    assert frame_bits(0) == 47 + 8  # 47 bits framing incl. interframe + (34-1)//4 = 8 stuff bits
    assert frame_bits(8) == 47 + 64 + (34 + 64 - 1) // 4  # 135
    assert frame_bits(8, extended=True) > frame_bits(8)


def test_crc15_published_check_value_and_long_division() -> None:
    # CRC-15/CAN in the CRC catalogue (width 15, poly 0x4599, init 0, no reflection): check("123456789") = 0x059E
    assert crc15(int.from_bytes(b"123456789", "big"), 72) == 0x059E
    assert crc15(0, 19) == 0


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet="01", max_size=160))
@example("")
@example("11111")
@example("0000011110000111100001")  # worst case: every stuff bit is the first of the next run
@example("1" * 23)
def test_crc15_and_stuffing_match_bitwise_definitions(bits: str) -> None:
    assert crc15(int(bits or "0", 2), len(bits)) == poly_crc(bits)
    assert stuff_count(int(bits or "0", 2), len(bits)) == naive_stuff(bits)


def test_wire_bits_worked_by_hand() -> None:
    # ID 0x000, DLC 0: SOF..DLC are 19 dominant bits and the CRC of all zeros is 0, so 34 zeros to stuff:
    # a stuff bit after zeros 5, 10, ..., 30 (each stuff bit is recessive, so the zeros start a new run) = 6.
    assert wire_bits(0x000, b"") == 34 + 6 + 13
    # ID 0x7FF, DLC 0: 0 11111111111 000 0000 + CRC 010011100101111 (0x272F, by long division, see poly_crc).
    # Stuff bits: after the 5th and 10th ID one; after the 5th zero of RTR,IDE,r0,DLC + the CRC's leading 0.
    assert poly_crc("0" + "1" * 11 + "0" * 7) == 0x272F
    assert wire_bits(0x7FF, b"") == 34 + 3 + 13
    # Extended ID 0, DLC 0: 0 00000000000 11 0*18 000 0000 + CRC 100011000010000 (0x4610): 12 zeros give 2
    # stuff bits, "11" none, the next 25 zeros 5 (the last stuff bit, a 1, runs into the CRC's 1: no 6th).
    assert poly_crc("0" * 12 + "11" + "0" * 25) == 0x4610
    assert wire_bits(0, b"", extended=True) == 54 + 7 + 13


@settings(max_examples=300, deadline=None)
@given(st.booleans(), st.integers(0, 0x1FFFFFFF), st.binary(max_size=8))
def test_wire_bits_between_unstuffed_and_worst_case(extended: bool, ident: int, data: bytes) -> None:
    ident = ident if extended else ident & 0x7FF
    unstuffed = (67 if extended else 47) + 8 * len(data)
    assert unstuffed <= wire_bits(ident, data, extended) <= frame_bits(len(data), extended)


def test_zero_data_stuffs_more_than_alternating() -> None:
    for ident, ext in ((0x123, False), (0x18FF50E5, True)):
        unstuffed = (67 if ext else 47) + 64
        zeros, alternating = wire_bits(ident, bytes(8), ext), wire_bits(ident, b"\x55" * 8, ext)
        assert zeros - unstuffed >= 64 // 5  # the zero data alone needs a stuff bit after every 5 bits
        assert alternating - unstuffed < zeros - unstuffed


def test_lowest_id_wins_and_delivery_is_next_quantum() -> None:
    bus = CanMedium("t", bitrate=500_000)
    bus.offer("b", 1, 0x300, b"\x01")
    bus.offer("a", 1, 0x100, b"\x02\x03")
    bus.offer("a", 2, 0x200, b"")
    out = bus.transmit(0, Q)
    assert [d.arbitration_id for d in out] == [0x100, 0x200, 0x300]
    assert all(d.t_ns == Q for d in out)
    ends = [d.wire_end_ns for d in out]
    assert ends == sorted(ends)
    assert ends[0] == ns(wire_bits(0x100, b"\x02\x03"))
    assert ends[1] == ends[0] + ns(wire_bits(0x200, b""))
    assert bus.bits == sum(wire_bits(d.arbitration_id, d.data) for d in out)


def test_same_id_orders_by_sender_then_sequence() -> None:
    bus = CanMedium("t")
    bus.offer("r001/logic", 2, 0x100, b"b")
    bus.offer("r001/logic", 1, 0x100, b"a")
    bus.offer("r000/llc", 9, 0x100, b"c")
    assert [d.data for d in bus.transmit(0, Q)] == [b"c", b"a", b"b"]


def test_overloaded_bus_carries_frames_over() -> None:
    bus = CanMedium("t", bitrate=125_000)  # one 8-byte frame ~ 1 ms
    for i in range(20):
        bus.offer("x", i, 0x100 + i, bytes(8))
    first = bus.transmit(0, Q)
    assert 5 <= len(first) < 20
    assert bus.pending
    later = bus.transmit(Q, Q)
    assert later and all(d.t_ns >= 2 * Q for d in later)
    assert len(first) + len(later) + len(bus.pending) == 20
    assert later[0].wire_end_ns > first[-1].wire_end_ns


def test_frame_crossing_quantum_edge_is_delivered_after_it() -> None:
    bus = CanMedium("t", bitrate=10_000)  # 8-byte frame takes ~12.5 ms > one quantum
    bus.offer("x", 1, 0x1, bytes(8))
    (d,) = bus.transmit(0, Q)
    assert d.wire_end_ns == ns(wire_bits(0x1, bytes(8)), 10_000) > Q and d.t_ns == 2 * Q
    assert bus.busy_until_ns == d.wire_end_ns


def test_standard_frame_beats_extended_with_same_base_id() -> None:
    bus = CanMedium("t")
    bus.offer("x", 1, (0x100 << 18) | 5, b"e", extended=True)
    bus.offer("y", 1, 0x101, b"s2")
    bus.offer("z", 1, 0x100, b"s1")
    bus.offer("w", 1, 0x005, b"lowest", extended=True)  # base id 0: wins over every standard id above 0
    assert [d.data for d in bus.transmit(0, Q)] == [b"lowest", b"s1", b"e", b"s2"]


def test_registered_nodes_receive_and_arbitration_is_by_id() -> None:
    bus = CanMedium("t")
    for n in (LLC, LOGIC, SLCAN):
        bus.add_node(n)
    bus.offer(LOGIC, 1, 0x300, b"\x01")
    bus.offer(LLC, 1, 0x101, b"\x02")
    bus.offer(SLCAN, 1, 0x100, b"\x03")
    out = bus.transmit(0, Q)
    assert [(d.src, d.receivers) for d in out] == [(SLCAN, (LLC, LOGIC)), (LLC, (LOGIC, SLCAN)),
                                                   (LOGIC, (LLC, SLCAN))]
    assert bus.drain_events() == []
    assert all(bus.node_state(n) == ("active", 0, 0) for n in (LLC, LOGIC, SLCAN))
    assert not bus.busy(Q, Q)


def test_tx_error_drives_node_to_bus_off_after_32_attempts() -> None:
    bus = CanMedium("t")
    bus.add_node(LLC)
    bus.add_node(LOGIC)
    bus.inject(LLC, "tx_error", 0)
    for i in range(5):
        bus.offer(LLC, i, 0x100 + i, b"\x01\x02")
    assert bus.transmit(0, Q) == []
    events = bus.drain_events()
    errors = [e for e in events if e.kind == "error_frame"]
    assert len(errors) == 32 == bus.error_frames
    assert {(e.node, e.arbitration_id) for e in errors} == {(LLC, 0x100)}
    assert [e.tec for e in errors] == [8 * i for i in range(1, 33)]
    states = [(e.node, e.state, e.tec, e.wire_ns) for e in events if e.kind == "state"]
    back = errors[31].wire_ns + ns(RECOVERY_BITS)  # restart_ns=0: recovers in this quantum, its frames gone
    assert states == [(LLC, "passive", 128, errors[15].wire_ns), (LLC, "bus_off", 256, errors[31].wire_ns),
                      (LLC, "active", 0, back)]
    # each attempt: stuffed bits to the CRC delimiter, then the error frame; error-passive adds 8 suspend bits
    b = wire_bits(0x100, b"\x01\x02")
    t = 0
    for i, e in enumerate(errors, start=1):
        assert e.wire_ns == t + ns(b - 12)
        t += ns(error_bits(0x100, b"\x01\x02")) + (ns(8) if i >= 16 else 0)
    assert bus.bits == 32 * error_bits(0x100, b"\x01\x02")
    # the bus-off node's other frames are dropped with the one it was sending
    assert bus.pending == []
    st_ = bus.stats()["nodes"]
    assert st_[LLC] == {"state": "active", "tec": 0, "rec": 0, "tx_errors": 32, "rx_errors": 0,
                        "bus_off_count": 1, "dropped_bus_off": 5}
    assert bus.node_state(LOGIC) == ("active", 0, 32) and st_[LOGIC]["rx_errors"] == 32


def test_other_nodes_keep_communicating_and_bus_off_node_does_not_receive() -> None:
    bus = CanMedium("t")
    for n in (LLC, LOGIC, SLCAN):
        bus.add_node(n, restart_ns=None)
    bus.inject(LLC, "tx_error", 0)
    bus.offer(LLC, 1, 0x100, b"\x01")
    for i in range(3):
        bus.offer(LOGIC, i, 0x200, bytes([i]))
    out = bus.transmit(0, Q)
    errors = [e for e in bus.drain_events() if e.kind == "error_frame"]
    # the faulty node wins arbitration with its lower ID until, error-passive, it must suspend for 8 bits
    assert [d.data for d in out] == [b"\x00", b"\x01", b"\x02"]
    assert all(errors[15].wire_ns < d.wire_end_ns < errors[19].wire_ns for d in out)
    assert all(d.receivers == (LLC, SLCAN) for d in out)
    bus.offer(LOGIC, 4, 0x201, b"\x04")
    (d,) = bus.transmit(Q, Q)
    assert d.receivers == (SLCAN,)
    assert bus.node_state(LLC) == ("bus_off", 256, 0)
    assert bus.node_state(SLCAN) == ("active", 0, 32 - 4)  # 32 errors seen, then 4 good frames received


@pytest.mark.parametrize("restart_ns", [0, 50_000_000])
def test_recovery_after_1408_bits_plus_restart_delay(restart_ns: int) -> None:
    bus = CanMedium("t")
    bus.add_node(LLC, restart_ns=restart_ns)
    bus.add_node(LOGIC)
    bus.inject(LLC, "tx_error", 0, 200_000_000)
    bus.offer(LLC, 1, 0x100, b"\x01")
    busy: list[int] = []
    run(bus, 0, 100_000_000, busy)
    events = bus.drain_events()
    (off,) = [e for e in events if e.kind == "state" and e.state == "bus_off"]
    back = off.wire_ns + ns(RECOVERY_BITS) + restart_ns
    assert events[-1] == CanEvent(-(-back // Q) * Q, back, "state", LLC, "active", 0, 0, None)
    assert busy == sorted({0, back // Q * Q})  # idle but for the recovery
    assert bus.node_state(LLC) == ("active", 0, 0)
    assert not bus.busy(100_000_000, Q)
    # the fault lasts: back on the bus, it goes bus-off again after another 32 attempts
    assert bus.offer(LLC, 2, 0x100, b"\x02")
    run(bus, 100_000_000, 110_000_000)
    assert [e.state for e in bus.drain_events() if e.kind == "state"][:2] == ["passive", "bus_off"]
    assert bus.stats()["nodes"][LLC]["bus_off_count"] == 2


def test_restart_none_stays_bus_off_until_recover() -> None:
    bus = CanMedium("t")
    bus.add_node(LLC)
    bus.add_node(LOGIC, restart_ns=None)
    bus.inject(LOGIC, "tx_error", 0, Q)
    bus.offer(LOGIC, 1, 0x100, b"\x01")
    run(bus, 0, Q)
    assert bus.node_state(LOGIC) == ("bus_off", 256, 0)
    assert not any(bus.busy(t, Q) for t in range(Q, 1_000_000_000, Q))
    assert bus.offer(LOGIC, 2, 0x100, b"\x02") is False
    assert bus.offer(LOGIC, 3, 0x101, b"\x03") is False
    assert bus.stats()["nodes"][LOGIC]["dropped_bus_off"] == 1 + 2
    assert bus.pending == [] and bus.recover(LLC, 0) is None  # LLC is not bus-off
    t_restart = 500_000_000 - ns(RECOVERY_BITS)
    back = bus.recover(LOGIC, t_restart)
    assert back == 500_000_000  # on a quantum boundary: recovered as transmit(500 ms) starts, reported at its end
    bus.drain_events()
    busy: list[int] = []
    run(bus, Q, 600_000_000, busy)
    assert busy == [500_000_000]
    assert bus.drain_events() == [CanEvent(510_000_000, back, "state", LOGIC, "active", 0, 0, None)]
    assert bus.offer(LOGIC, 4, 0x100, b"\x04")  # the fault window is over
    (d,) = bus.transmit(600_000_000, Q)
    assert d.receivers == (LLC,) and bus.node_state(LOGIC) == ("active", 0, 0)


def test_receive_error_counter_rules() -> None:
    bus = CanMedium("t")
    bus.add_node(LLC)
    bus.add_node(LOGIC)
    data = b"\x10\x20"
    bus.inject(LLC, "tx_error", 0, 3 * ns(error_bits(0x100, data)))  # the 4th attempt starts after it
    bus.offer(LLC, 1, 0x100, data)
    (d,) = bus.transmit(0, Q)
    events = bus.drain_events()
    assert [(e.kind, e.tec) for e in events] == [("error_frame", 8), ("error_frame", 16), ("error_frame", 24)]
    assert d.receivers == (LOGIC,)
    assert bus.node_state(LLC) == ("active", 24 - 1, 0)
    assert bus.node_state(LOGIC) == ("active", 0, 3 - 1)


def test_rec_above_127_drops_to_119_on_a_good_reception() -> None:
    bus = CanMedium("t")
    senders = [f"r00{i}/llc" for i in range(5)]
    for n in senders:
        bus.add_node(n, restart_ns=None)
    bus.add_node(LOGIC)
    bus.inject("*", "noise", 0, 100_000_000)
    for i, n in enumerate(senders):
        bus.offer(n, 1, 0x100 + i, b"\x01")
    run(bus, 0, 100_000_000)
    assert bus.error_frames == 5 * 32 and all(bus.node_state(n)[0] == "bus_off" for n in senders)
    assert bus.node_state(LOGIC) == ("passive", 0, 160)
    bus.offer(SLCAN, 1, 0x200, b"\x02")  # a new node, registered by its offer
    (d,) = bus.transmit(100_000_000, Q)
    assert d.receivers == (LOGIC,)
    assert bus.node_state(LOGIC) == ("active", 0, 119)
    logic = [(e.state, e.rec) for e in bus.drain_events() if e.kind == "state" and e.node == LOGIC]
    assert logic == [("passive", 128), ("active", 119)]


def noisy_session(seed: int, p: float = 0.05) -> tuple[list[Delivery], list[CanEvent], CanMedium]:
    bus = CanMedium("t", seed=seed)
    bus.add_node(LLC)
    bus.add_node(LOGIC)
    bus.inject("*", "noise", 0, probability=p)
    out: list[Delivery] = []
    events: list[CanEvent] = []
    for k in range(400):
        t = k * Q
        for i in range(10):
            bus.offer(LLC if i % 2 else LOGIC, k * 10 + i, 0x100 + i, bytes([k % 256, i]))
        out += bus.transmit(t, Q)
        events += bus.drain_events()
    return out, events, bus


def test_noise_destroys_about_p_of_frames_and_is_seeded() -> None:
    out, events, bus = noisy_session(seed=7)
    assert len(out) == bus.frames == 4000 and not bus.pending
    ratio = bus.error_frames / (bus.frames + bus.error_frames)
    assert 0.04 < ratio < 0.06
    assert sum(e.kind == "error_frame" for e in events) == bus.error_frames
    nodes = bus.stats()["nodes"]
    assert nodes[LLC]["tx_errors"] + nodes[LOGIC]["tx_errors"] == bus.error_frames
    assert nodes[LLC]["rx_errors"] == nodes[LOGIC]["tx_errors"]
    assert noisy_session(seed=7)[:2] == (out, events)
    assert noisy_session(seed=8)[1] != events
    # events come in time order, each reported at the quantum boundary at or after it
    assert [e.wire_ns for e in events] == sorted(e.wire_ns for e in events)
    assert all(e.t_ns % Q == 0 and 0 <= e.t_ns - e.wire_ns < Q for e in events)


def test_heavy_noise_takes_nodes_through_passive_and_bus_off_in_order() -> None:
    out, events, bus = noisy_session(seed=1, p=0.3)
    states = [e for e in events if e.kind == "state"]
    assert {e.state for e in states} == {"passive", "bus_off", "active"}
    allowed = {("active", "passive"), ("passive", "active"), ("passive", "bus_off"), ("bus_off", "active")}
    for n in (LLC, LOGIC):
        seq = [e.state for e in states if e.node == n]
        assert set(zip(["active", *seq], seq, strict=False)) <= allowed
    assert [e.wire_ns for e in events] == sorted(e.wire_ns for e in events)
    assert bus.stats()["nodes"][LLC]["dropped_bus_off"] > 0
    assert all(d.src not in d.receivers for d in out)


def test_inject_rejects_nonsense() -> None:
    bus = CanMedium("t")
    with pytest.raises(ValueError):
        bus.inject("*", "tx_error", 0)
    with pytest.raises(ValueError):
        bus.inject(LLC, "smoke", 0)  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        bus.inject(LLC, "noise", 10, 10)
    with pytest.raises(ValueError):
        bus.inject(LLC, "noise", 0, probability=1.5)
    with pytest.raises(ValueError):
        bus.add_node(LLC, restart_ns=-1)
