"""The CAN medium: arbitration by ID, bit time on the wire, carry-over, delivery at k+1 or later."""

from __future__ import annotations

from bridge.can_medium import CanMedium, frame_bits

Q = 10_000_000  # 10 ms


def test_frame_bits_worst_case_stuffing() -> None:
    assert frame_bits(0) == 47 + 8  # 47 bits framing incl. interframe + (34-1)//4 = 8 stuff bits
    assert frame_bits(8) == 47 + 64 + (34 + 64 - 1) // 4  # 135
    assert frame_bits(8, extended=True) > frame_bits(8)


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
    assert ends[0] == -(-frame_bits(2) * 1_000_000_000 // 500_000)


def test_same_id_orders_by_sender_then_sequence() -> None:
    bus = CanMedium("t")
    bus.offer("r001/logic", 2, 0x100, b"b")
    bus.offer("r001/logic", 1, 0x100, b"a")
    bus.offer("r000/llc", 9, 0x100, b"c")
    assert [d.data for d in bus.transmit(0, Q)] == [b"c", b"a", b"b"]


def test_overloaded_bus_carries_frames_over() -> None:
    bus = CanMedium("t", bitrate=125_000)  # one 8-byte frame ~ 1.05 ms
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
    bus = CanMedium("t", bitrate=10_000)  # 8-byte frame takes ~13.5 ms > one quantum
    bus.offer("x", 1, 0x1, bytes(8))
    (d,) = bus.transmit(0, Q)
    assert d.wire_end_ns > Q and d.t_ns == 2 * Q


def test_standard_frame_beats_extended_with_same_base_id() -> None:
    bus = CanMedium("t")
    bus.offer("x", 1, (0x100 << 18) | 5, b"e", extended=True)
    bus.offer("y", 1, 0x101, b"s2")
    bus.offer("z", 1, 0x100, b"s1")
    bus.offer("w", 1, 0x005, b"lowest", extended=True)  # base id 0: wins over every standard id above 0
    assert [d.data for d in bus.transmit(0, Q)] == [b"lowest", b"s1", b"e", b"s2"]
