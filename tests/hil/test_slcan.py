"""slcan adapter firmware: the LAWICEL line protocol, a fuzz of its parser, and python-can over a pseudo-terminal.

python-can's own slcan interface is the independent oracle: its bit-rate table and BTR registers must mean the
same to the adapter, and a real ``can.Bus(interface="slcan")`` must open, send and receive through a pty.
"""

from __future__ import annotations

import contextlib
import os
import re
import select
import threading
import time
import tty
from collections.abc import Callable, Iterator

import can
import pytest
from can.interfaces.slcan import slcanBus
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from firmware_sim.modules.slcan import MAX_LINE, SlcanAdapter

REJECT_KEYS = ("malformed_lines", "unknown_commands", "refused", "tx_refused", "tx_queue_full", "remote_refused")
RX_KEYS = ("rx_frames", "rx_invalid", "rx_dropped_closed", "rx_dropped_bus_off", "rx_bitrate_mismatch",
           "rx_filtered", "rx_overrun")


def cmd(a: SlcanAdapter, *lines: str) -> bytes:
    """Send each line with a CR and return everything the adapter answered."""
    for line in lines:
        a.feed(line.encode("latin-1") + b"\r")
    return a.take_output()


def opened(**kw) -> SlcanAdapter:
    a = SlcanAdapter(**kw)
    assert cmd(a, "S6", "O") == b"\r\r"
    return a


def nonzero(a: SlcanAdapter) -> dict[str, int]:
    return {k: v for k, v in a.counters.items() if v}


# -- open / close / bit rate ----------------------------------------------------------------------------------------


def test_python_can_startup_sequence_succeeds() -> None:
    a = SlcanAdapter()
    # what slcanBus(bitrate=500000) writes: C, S6, the empty data-bitrate line, O from set_bitrate, O from __init__
    a.feed(b"C\rS6\r\rO\rO\r")
    assert a.take_output() == b"\r\r\r\r"
    assert a.is_open and not a.listen_only and a.bitrate == 500_000 and a.bitrate_matches
    assert nonzero(a) == {"lines": 4, "commands_ok": 4, "empty_lines": 1}


@pytest.mark.parametrize(("bitrate", "code"), slcanBus._BITRATES.items())
def test_bitrate_table_is_python_cans(bitrate: int, code: str) -> None:
    a = SlcanAdapter()
    assert cmd(a, code) == b"\r"
    assert a.bitrate == bitrate


@pytest.mark.parametrize("bitrate", [20_000, 33_333, 83_333, 125_000, 250_000, 500_000, 800_000, 1_000_000])
@pytest.mark.parametrize("sample_point", [75.0, 87.5])
def test_btr_registers_mean_what_python_can_means(bitrate: int, sample_point: float) -> None:
    timing = can.BitTiming.from_sample_point(f_clock=8_000_000, bitrate=bitrate, sample_point=sample_point)
    a = SlcanAdapter(bus_bitrate=bitrate)
    assert cmd(a, f"s{timing.btr0:02X}{timing.btr1:02x}") == b"\r"
    assert a.bitrate == timing.bitrate and a.bitrate_matches


def test_open_close_and_configuration_rules() -> None:
    a = SlcanAdapter()
    assert cmd(a, "O", "L") == b"\a\a"  # no bit rate yet
    assert cmd(a, "C", "C") == b"\r\r"  # closing a closed channel is fine
    assert cmd(a, "Z1", "M00000000", "mFFFFFFFF", "S6", "O") == b"\r" * 5
    assert a.is_open and a.timestamps
    assert cmd(a, "O") == b"\r"  # reopening in the same mode is fine (python-can sends O twice)
    assert cmd(a, "L", "S5", "s001C", "Z0", "M00000000", "m00000000") == b"\a" * 6
    assert a.bitrate == 500_000 and a.timestamps and a.acceptance_mask == 0xFFFFFFFF
    assert cmd(a, "C", "L", "L", "O") == b"\r\r\r\a"
    assert a.is_open and a.listen_only
    assert cmd(a, "C", "S4") == b"\r\r"
    assert not a.is_open and a.bitrate == 125_000
    assert a.counters["refused"] == 9 and a.counters["commands_ok"] == 13


def test_version_serial_number_and_flags_need_open() -> None:
    a = SlcanAdapter(serial_number="R7x2")
    assert cmd(a, "V", "N", "F") == b"V1013\rNR7x2\r\a"
    assert a.counters["refused"] == 1
    with pytest.raises(ValueError, match="serial number"):
        SlcanAdapter(serial_number="A01")


def test_line_endings_and_empty_lines() -> None:
    a = SlcanAdapter()
    a.feed(b"V\nV\r\nV\r\r\n\n")
    assert a.take_output() == b"V1013\r" * 3
    assert a.counters["lines"] == 3 and a.counters["empty_lines"] == 4


# -- transmit -------------------------------------------------------------------------------------------------------


def test_transmit_standard_and_extended_frames() -> None:
    a = opened()
    out = cmd(a, "t1232AABB", "T1ABCDEF081122334455667788", "t7FF0", "T000000000", "t0ff1c3", "T1fffffff0")
    assert out == b"z\rZ\rz\rZ\rz\rZ\r"
    assert a.take_tx() == [
        (0x123, b"\xaa\xbb", False), (0x1ABCDEF0, bytes.fromhex("1122334455667788"), True), (0x7FF, b"", False),
        (0, b"", True), (0x0FF, b"\xc3", False), (0x1FFFFFFF, b"", True)]
    assert a.take_tx() == []
    assert a.counters["tx_frames"] == 6 and a.counters["commands_ok"] == 8


@pytest.mark.parametrize("line", [
    "t12", "t123", "t1232AAB", "t1232AABBCC", "t12G1AA", "t8000", "t1239" + "00" * 9, "t123-1", "t 1230",
    "t1231\x00A", "t0x11AA", "t1_231AA",
    "T1234567", "T200000000", "T1234567891122334455667788", "T123456781", "TFFFFFFFF0",
    "r8000", "r123", "r1239", "R200000000", "r1230AA",
    "S", "S10", "Sx", "s12", "s12G4", "s001C0", "Z", "Z2", "Z01", "M1234", "mFFFFFFFFF", "M0000000G",
    "O1", "L0", "C0", "V1", "N0", "F1",
])
def test_malformed_lines_answer_bel_and_are_counted(line: str) -> None:
    a = opened()
    assert cmd(a, line) == b"\a"
    assert a.counters["malformed_lines"] == 1 and a.take_tx() == []
    assert a.is_open and a.bitrate == 500_000


@pytest.mark.parametrize("line", ["X", "Q1", "v", "P", "A", "U1", "W2", "Y2", "d1231AA", "?", "\x00", "\xe9", " t1230"])
def test_unknown_commands_answer_bel(line: str) -> None:
    a = opened()
    assert cmd(a, line) == b"\a"
    assert a.counters["unknown_commands"] == 1


def test_overlong_line_is_discarded_with_one_bel() -> None:
    a = opened()
    a.feed(b"t123" + b"1" * (MAX_LINE - 4))  # exactly MAX_LINE characters: still a line
    assert a.take_output() == b""
    a.feed(b"1")
    assert a.take_output() == b"\a"  # answered as soon as it overflows
    a.feed(b"22" * 100 + b"\rt1230\r")
    assert a.take_output() == b"z\r"
    a.feed(b"t123" + b"1" * (MAX_LINE - 4) + b"\r")
    assert a.take_output() == b"\a"
    assert nonzero(a) == {"lines": 4, "commands_ok": 3, "tx_frames": 1, "overlong_lines": 1, "malformed_lines": 1}


def test_remote_frames_are_refused() -> None:
    a = opened()
    assert cmd(a, "r1230", "R1234567F8", "r7FF1") == b"\a\a\a"
    assert a.counters["remote_refused"] == 3 and a.take_tx() == []


def test_transmit_needs_an_open_channel_that_may_talk() -> None:
    a = SlcanAdapter()
    assert cmd(a, "t1230", "S6", "t1230", "L", "t1230", "T000000010") == b"\a\r\a\r\a\a"
    assert a.counters["tx_refused"] == 4 and a.take_tx() == []
    a.on_bus_frame(0, 0x42, b"\x01")  # listen-only still hears the bus
    assert a.take_output() == b"t042101\r"


def test_transmit_queue_full_is_refused_and_flagged() -> None:
    a = opened(tx_queue=2)
    assert cmd(a, "t1000", "t1010", "t1020") == b"z\rz\r\a"
    assert a.counters["tx_queue_full"] == 1
    assert cmd(a, "F") == b"F02\r"
    assert len(a.take_tx()) == 2
    assert cmd(a, "F", "t1030") == b"F00\rz\r"


# -- receive --------------------------------------------------------------------------------------------------------


def test_received_frames_reach_the_host_only_while_open() -> None:
    a = SlcanAdapter()
    a.on_bus_frame(0, 0x100, b"\x01")
    assert cmd(a, "S6", "O") == b"\r\r"
    a.on_bus_frame(1_000, 0x100, b"\x01\x02")
    a.on_bus_frame(2_000, 0x1ABCDEF0, bytes(range(8)), extended=True)
    a.on_bus_frame(3_000, 0x7FF, b"")
    assert a.take_output() == b"t1002 0102\rT1ABCDEF080001020304050607\rt7FF0\r".replace(b" ", b"")
    assert cmd(a, "C") == b"\r"
    a.on_bus_frame(4_000, 0x100, b"")
    assert a.take_output() == b""
    assert a.counters["rx_frames"] == 3 and a.counters["rx_dropped_closed"] == 2


def test_invalid_bus_frames_are_counted_not_raised() -> None:
    a = opened()
    a.on_bus_frame(0, 0x800, b"")
    a.on_bus_frame(0, 0x20000000, b"", extended=True)
    a.on_bus_frame(0, -1, b"")
    a.on_bus_frame(0, 0x1, bytes(9))
    assert a.take_output() == b"" and a.counters["rx_invalid"] == 4


def test_timestamps_are_milliseconds_modulo_60000() -> None:
    a = SlcanAdapter()
    assert cmd(a, "S6", "Z1", "O") == b"\r\r\r"
    a.on_bus_frame(61_234_567_890, 0x123, b"\xab")  # 61234 ms -> 1234 = 0x04D2
    a.on_bus_frame(59_999_999_999, 0x1234567, b"", extended=True)  # 59999 ms = 0xEA5F
    a.on_bus_frame(120_000_000_000, 0x7, b"")
    assert a.take_output() == b"t1231AB04D2\rT012345670EA5F\rt00700000\r"
    assert cmd(a, "C", "Z0", "O") == b"\r\r\r"
    a.on_bus_frame(61_234_567_890, 0x123, b"\xab")
    assert a.take_output() == b"t1231AB\r"


def test_acceptance_filter_is_the_sja1000_single_filter() -> None:
    a = SlcanAdapter()
    # standard id 0x123 exactly (ACR0..1 bits 31..21), everything else don't care
    assert cmd(a, "S6", f"M{0x123 << 21:08X}", f"m{0x001FFFFF:08X}", "O") == b"\r" * 4
    for ident in (0x123, 0x122, 0x523):
        a.on_bus_frame(0, ident, b"\x00")
    # an extended frame compares ID.28-18 at the same bits
    a.on_bus_frame(0, 0x123 << 18 | 0x2ABCD, b"", extended=True)
    a.on_bus_frame(0, 0x124 << 18, b"", extended=True)
    assert a.take_output() == b"t123100\rT048EABCD0\r"
    assert a.counters["rx_filtered"] == 3

    # first data byte 0x55 on any standard id; frames without data are not compared there
    assert cmd(a, "C", f"M{0x55 << 8:08X}", f"m{0xFFFF00FF:08X}", "O") == b"\r" * 4
    a.on_bus_frame(0, 0x001, b"\x55\x01")
    a.on_bus_frame(0, 0x002, b"\x56\x01")
    a.on_bus_frame(0, 0x003, b"")
    assert a.take_output() == b"t001255 01\rt0030\r".replace(b" ", b"")

    # the RTR bit must be 1: no data frame passes
    assert cmd(a, "C", f"M{1 << 20:08X}", f"m{0xFFEFFFFF:08X}", "O") == b"\r" * 4
    a.on_bus_frame(0, 0x001, b"")
    assert a.take_output() == b""

    # extended: full 29-bit id at bits 31..3
    assert cmd(a, "C", f"M{0x1ABCDEF0 << 3:08X}", "m00000003", "O") == b"\r" * 4
    a.on_bus_frame(0, 0x1ABCDEF0, b"\x01", extended=True)
    a.on_bus_frame(0, 0x1ABCDEF1, b"\x01", extended=True)
    a.on_bus_frame(0, 0x1ABCDEF0 >> 18, b"\x01")
    assert a.take_output() == b"T1ABCDEF0101\r"


def test_receive_buffer_overrun_drops_and_flags() -> None:
    a = opened(rx_buffer=2)
    for i in range(3):
        a.on_bus_frame(0, i, b"")
    assert a.counters["rx_overrun"] == 1
    assert cmd(a, "F") == b"t0000\rt0010\rF09\r"
    assert cmd(a, "F") == b"F00\r"


# -- bit rate, bus state, flags -------------------------------------------------------------------------------------


def test_a_node_at_the_wrong_bitrate_only_sees_errors() -> None:
    a = SlcanAdapter(bus_bitrate=500_000)
    assert cmd(a, "S5", "O") == b"\r\r"
    assert not a.bitrate_matches
    assert cmd(a, "F") == b"F00\r"
    a.on_bus_frame(0, 0x100, b"\x01")
    assert cmd(a, "t1230", "T000000010") == b"z\rZ\r"  # the controller takes them; they never make it
    assert a.take_tx() == []
    assert cmd(a, "F", "F") == b"F80\rF00\r"
    assert a.counters["rx_bitrate_mismatch"] == 1 and a.counters["tx_bitrate_mismatch"] == 2
    assert a.counters["tx_frames"] == 0


def test_bus_off_neither_sends_nor_receives() -> None:
    a = opened()
    a.set_bus_state("bus_off", tec=256)
    assert cmd(a, "t1230") == b"\a"
    a.on_bus_frame(0, 0x100, b"")
    assert a.take_output() == b"" and a.take_tx() == []
    assert cmd(a, "F") == b"F24\r"
    a.set_bus_state("active")
    assert cmd(a, "F", "F", "t1230") == b"F24\rF00\rz\r"  # the change back is latched once
    assert a.counters["tx_refused"] == 1 and a.counters["rx_dropped_bus_off"] == 1


def test_error_warning_and_passive_flags() -> None:
    a = opened()
    a.set_bus_state("active", tec=95)
    assert cmd(a, "F") == b"F00\r"
    a.set_bus_state("active", rec=96)
    assert cmd(a, "F", "F") == b"F04\rF04\r"  # a condition that holds reads 1 every time
    a.set_bus_state("passive", tec=130)
    assert cmd(a, "F", "t1230") == b"F24\rz\r"  # error passive still sends
    a.set_bus_state("active", tec=10)
    assert cmd(a, "F", "F") == b"F24\rF00\r"
    with pytest.raises(ValueError, match="bus state"):
        a.set_bus_state("warning")


# -- fuzz -----------------------------------------------------------------------------------------------------------

VALID_LINES = ("t1232AABB", "t7FF0", "t0001C3", "t12380011223344556677", "T1FFFFFFF81122334455667788", "T000000000",
               "T0ABCDEF02BEEF", "F", "V", "N", "r1230", "R123456780", "C", "O", "L", "S6", "S5", "S9", "s001C",
               "s031C", "Z1", "Z0", "M00000000", "mFFFFFFFF", "m001FFFFF")
TERMINATORS = (b"\r", b"\r", b"\n", b"\r\n", b"")
REPLY = re.compile(rb"(?:|z|Z|V\d{4}|N\w{4}|F[0-9A-F]{2}"
                   rb"|(?:t[0-9A-F]{3}|T[0-9A-F]{8})(?P<dlc>[0-8])(?P<rest>[0-9A-F]*))\r")


@st.composite
def mutated_line(draw: st.DrawFn) -> bytes:
    line = bytearray(draw(st.sampled_from(VALID_LINES)).encode())
    for _ in range(draw(st.sampled_from((0, 0, 1, 2, 3)))):
        pos = draw(st.integers(0, len(line)))
        op = draw(st.sampled_from(("insert", "delete", "replace")))
        if op == "insert":
            line.insert(pos, draw(st.integers(0, 255)))
        elif pos < len(line):
            if op == "delete":
                del line[pos]
            else:
                line[pos] = draw(st.integers(0, 255))
    return bytes(line) + draw(st.sampled_from(TERMINATORS))


PRELUDES = (b"S6\rO\r", b"", b"S5\rO\r", b"S6\rZ1\rO\r", b"s001C\rL\r", b"S6\rM24600000\rm001FFFFF\rO\r")
line_bytes = st.lists(mutated_line(), min_size=1, max_size=8).map(b"".join)
host_bytes = st.one_of(line_bytes, line_bytes, line_bytes, st.binary(max_size=80),
                       st.builds(lambda n: b"7" * n, st.integers(60, 140)))
bus_frame = st.tuples(st.integers(0, 10**12), st.one_of(st.integers(0, 0x7FF), st.integers(-2, 0x20000001)),
                      st.binary(max_size=9), st.booleans())
feed_event = st.tuples(st.just("feed"), host_bytes, st.lists(st.integers(0, 200), max_size=4))
events = st.lists(st.one_of(
    feed_event, feed_event,
    st.tuples(st.just("frame"), bus_frame),
    st.tuples(st.just("state"), st.sampled_from(("active", "active", "passive", "bus_off")), st.integers(0, 300)),
    st.tuples(st.just("take")),
), max_size=60)


@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(PRELUDES), events)
def test_fuzz_never_raises_and_counters_add_up(prelude: bytes, script: list[tuple]) -> None:
    a = SlcanAdapter(tx_queue=3, rx_buffer=4)
    a.feed(prelude)
    stream, out, tx, n_frames = bytearray(prelude), bytearray(), [], 0
    for event in script:
        if event[0] == "feed":
            data, cuts = event[1], sorted({c % (len(event[1]) + 1) for c in event[2]})
            for lo, hi in zip([0, *cuts], [*cuts, len(data)], strict=True):
                a.feed(data[lo:hi])
            stream += data
        elif event[0] == "frame":
            a.on_bus_frame(*event[1])
            n_frames += 1
        elif event[0] == "state":
            a.set_bus_state(event[1], tec=event[2])
        else:
            out += a.take_output()
            tx += a.take_tx()
    out += a.take_output()
    tx += a.take_tx()
    c = a.counters

    segments = re.split(rb"[\r\n]", bytes(stream))
    assert c["lines"] == sum(0 < len(s) <= MAX_LINE for s in segments[:-1])
    assert c["empty_lines"] == sum(len(s) == 0 for s in segments[:-1])
    assert c["overlong_lines"] == sum(len(s) > MAX_LINE for s in segments)
    assert c["lines"] == c["commands_ok"] + sum(c[k] for k in REJECT_KEYS)
    assert sum(c[k] for k in RX_KEYS) == n_frames
    assert out.count(b"\a") == sum(c[k] for k in REJECT_KEYS) + c["overlong_lines"]
    assert out.count(b"\r") == c["commands_ok"] + c["rx_frames"]
    for reply in re.split(rb"(?<=[\r\a])", bytes(out))[:-1]:
        m = REPLY.fullmatch(reply)
        assert reply == b"\a" or m, reply
        if m and m["dlc"]:  # data, then the timestamp if one was on
            assert len(m["rest"]) - 2 * int(m["dlc"]) in (0, 4), reply
    assert len(tx) == c["tx_frames"] <= c["commands_ok"]
    assert all(len(f.data) <= 8 and 0 <= f.arbitration_id <= (0x1FFFFFFF if f.extended else 0x7FF) for f in tx)


# -- end to end: python-can's slcan interface over a pseudo-terminal ------------------------------------------------


class PtyPump:
    """The adapter behind a pty: a thread moves bytes between the master fd and the adapter."""

    def __init__(self, adapter: SlcanAdapter, link: str) -> None:
        self.adapter = adapter
        self.lock = threading.Lock()
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        os.symlink(os.ttyname(self.slave), link)
        self.errors: list[BaseException] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, name="slcan-pty", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        pending = b""
        try:
            while not self.stop.is_set():
                readable, _, _ = select.select([self.master], [], [], 0.005)
                data = os.read(self.master, 4096) if readable else b""
                with self.lock:
                    if data:
                        self.adapter.feed(data)
                    pending += self.adapter.take_output()
                if pending:
                    with contextlib.suppress(BlockingIOError):
                        pending = pending[os.write(self.master, pending):]
        except Exception as e:  # reported by close()
            self.errors.append(e)

    def wait_for(self, condition: Callable[[], bool], timeout: float = 60.0) -> None:  # the bound catches a hang
        deadline = time.monotonic() + timeout
        while True:
            with self.lock:
                if condition():
                    return
            assert time.monotonic() < deadline, "timed out"
            time.sleep(0.002)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=60.0)
        os.close(self.master)
        os.close(self.slave)
        assert not self.thread.is_alive() and self.errors == []


ANSWER_S = 30.0  # the adapter's thread answers at once; a generous bound, for a loaded machine


@pytest.fixture
def pty_adapter(tmp_path) -> Iterator[tuple[PtyPump, str]]:
    link = str(tmp_path / "ttySLCAN0")
    pump = PtyPump(SlcanAdapter(serial_number="S1T1"), link)
    try:
        yield pump, link
    finally:
        pump.close()


@pytest.mark.timeout(180)
@pytest.mark.parametrize("how", [
    {"bitrate": 500_000},
    {"timing": can.BitTiming.from_sample_point(f_clock=8_000_000, bitrate=500_000, sample_point=87.5)},
], ids=["bitrate", "btr"])
def test_python_can_slcan_over_a_pty(pty_adapter: tuple[PtyPump, str], how: dict) -> None:
    pump, link = pty_adapter
    adapter = pump.adapter
    bus = can.Bus(interface="slcan", channel=link, sleep_after_open=0, **how)
    try:
        pump.wait_for(lambda: adapter.is_open)
        assert adapter.bitrate == 500_000 and not adapter.listen_only
        assert bus.get_version(ANSWER_S) == (10, 13)  # each returns on the adapter's answer
        assert bus.get_serial_number(ANSWER_S) == "S1T1"

        sent = [can.Message(arbitration_id=0x123, data=b"\x01\x02\x03", is_extended_id=False),
                can.Message(arbitration_id=0x1ABCDEF0, data=bytes(range(8)), is_extended_id=True),
                can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False),
                can.Message(arbitration_id=0x5, data=b"\xff", is_extended_id=True)]
        for msg in sent:
            bus.send(msg)
        got: list = []
        pump.wait_for(lambda: bool(got.extend(adapter.take_tx())) or len(got) >= len(sent))
        assert got == [(m.arbitration_id, bytes(m.data), m.is_extended_id) for m in sent]

        injected = [(0x321, b"\xde\xad", False), (0x1FFFFFFF, bytes(8), True), (0x0, b"", False)]
        with pump.lock:
            for i, (ident, data, ext) in enumerate(injected):
                adapter.on_bus_frame(i * 1_000_000, ident, data, ext)
        for ident, data, ext in injected:
            msg = bus.recv(timeout=ANSWER_S)
            assert msg is not None
            assert (msg.arbitration_id, bytes(msg.data), msg.is_extended_id, msg.dlc) == (ident, data, ext, len(data))
            assert not msg.is_remote_frame
    finally:
        bus.shutdown()
    pump.wait_for(lambda: not adapter.is_open)
    assert {k: v for k, v in adapter.counters.items() if k in REJECT_KEYS and v} == {}
    assert adapter.counters["tx_frames"] == 4 and adapter.counters["rx_frames"] == 3


@pytest.mark.timeout(180)
def test_python_can_listen_only_over_a_pty(pty_adapter: tuple[PtyPump, str]) -> None:
    pump, link = pty_adapter
    adapter = pump.adapter
    bus = can.Bus(interface="slcan", channel=link, bitrate=500_000, listen_only=True, sleep_after_open=0)
    try:
        pump.wait_for(lambda: adapter.is_open)
        assert adapter.listen_only
        bus.send(can.Message(arbitration_id=0x10, data=b"\x01", is_extended_id=False))
        pump.wait_for(lambda: adapter.counters["tx_refused"] == 1)
        with pump.lock:
            adapter.on_bus_frame(0, 0x10, b"\x02")
        msg = bus.recv(timeout=ANSWER_S)
        assert msg is not None and (msg.arbitration_id, bytes(msg.data)) == (0x10, b"\x02")
    finally:
        bus.shutdown()
    pump.wait_for(lambda: not adapter.is_open)
    assert adapter.take_tx() == []
