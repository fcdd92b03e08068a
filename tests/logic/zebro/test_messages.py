"""The Zebro frames (digest 2.6): every type round-trips, m3 is 3 bytes of logical payload, utilities are int8."""

from __future__ import annotations

import pytest

from swarm_logic.families.zebro import messages as msg


@pytest.mark.parametrize(("data", "expect"), [
    (msg.m0(3), (msg.M0_STOP, 3, 0, None, None, 0)),
    (msg.m1(3), (msg.M1, 3, 0, None, None, 0)),
    (msg.m1(3, -5), (msg.M1, 3, -5, None, None, 0)),
    (msg.m2(4, 95), (msg.M2, 4, 95, None, None, 0)),
    (msg.m3(4, 95, 7), (msg.M3, 4, 95, 7, None, 0)),
    (msg.stop(1, 300), (msg.STOP, 1, 0, None, None, 300 & 0xFF)),
    (msg.n1(9), (msg.N1, 9, 0, None, None, 0)),
    (msg.n2(2, 15), (msg.N2, 2, 15, None, None, 0)),
    (msg.n2(2, 15, 4, 6), (msg.N2, 2, 15, 4, 6, 0)),
    (msg.n2(2, 15, 2, None), (msg.N2, 2, 15, 2, None, 0)),
    (msg.n3(2, -15, 4, 6), (msg.N3, 2, -15, 4, 6, 0)),
    (msg.n4(2, 5, 95), (msg.N4, 2, 95, None, 5, 0)),
    (msg.n4(2, 5, 95, 8), (msg.N4, 2, 95, 8, 5, 0)),
    (msg.eoe(1, 3, 8, 95), (msg.EOE, 1, 95, 8, None, 3)),
    (msg.erase(1, 3), (msg.ERASE, 1, 0, None, None, 3)),
])
def test_frames_round_trip(data: bytes, expect: tuple) -> None:
    f = msg.decode(data)
    assert f is not None
    assert (f.kind, f.src, f.value, f.origin, f.parent, f.seq) == expect


def test_link_lists_round_trip() -> None:
    entries = [(0, 1, False), (1, 0, False), (2, 3, True)]
    f = msg.decode(msg.links(5, entries))
    assert f is not None and f.kind == msg.LINKS and f.src == 5 and list(f.links) == entries
    assert len(msg.links(5, entries)) == 3 + 3 * 3
    with pytest.raises(ValueError):
        msg.links(0, [(0, 1, False)] * 256)


def test_m3_is_three_bytes_of_logical_payload() -> None:
    """Z-U8: own id, max-utility, my-leader, after the type byte; utilities are one signed byte."""
    data = msg.m3(12, 95, 40)
    assert len(data) - 1 == 3
    assert data[1:] == bytes((12, 95, 40))
    assert msg.decode(msg.m3(12, -100, 40)).value == -100


@pytest.mark.parametrize("bad", [128, -129, 200, 1.5])
def test_utilities_are_int8(bad: float) -> None:
    with pytest.raises(ValueError):
        msg.m2(1, bad)  # type: ignore[arg-type]


def test_ids_are_bytes_and_255_means_none() -> None:
    with pytest.raises(ValueError):
        msg.n1(255)
    assert msg.decode(msg.n2(1, 5, 1, None)).parent is None


@pytest.mark.parametrize("data", [b"", b"\x02", b"\x02\x01", b"\x03\x01\x02", b"\x17\x01\x02\x00", b"\x99\x01",
                                  msg.m3(1, 2, 3) + b"\x00"])
def test_foreign_or_truncated_frames_are_none(data: bytes) -> None:
    assert msg.decode(data) is None
