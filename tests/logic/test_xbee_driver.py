"""The swarm-logic XBee driver: its byte reader (digi-xbee frames as the oracle, hypothesis for noise), its
request/response logic against a scripted module in simulated time, a real pty in wall time, and the module
emulation ``firmware_sim.modules.xbee.XBeeModule`` end to end when it is there."""

from __future__ import annotations

import os
import tty

import numpy as np
import pytest
import serial
from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress
from digi.xbee.models.status import ModemStatus, TransmitStatus
from digi.xbee.packets.common import (
    ATCommPacket,
    ATCommQueuePacket,
    ATCommResponsePacket,
    ModemStatusPacket,
    ReceivePacket,
    TransmitPacket,
    TransmitStatusPacket,
)
from digi.xbee.packets.raw import RX16Packet, RX64Packet, TX64Packet, TXStatusPacket
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_sim.modules.xbee import XBeeModule
from swarm_logic.clock import WallClock
from swarm_logic.drivers.xbee import (
    COUNTER_NAMES,
    RX_QUEUE_MAX,
    STALL_S,
    FrameReader,
    ModuleInfo,
    Received,
    XBee,
    XBeeError,
    XBeeTimeout,
    series_of,
)
from tests.support.xbee_loop import ScriptedModule, World

SPECIAL = bytes([0x7E, 0x7D, 0x11, 0x13])
A64 = 0x0013A20040A1B2C3


def a64(v: int) -> XBee64BitAddress:
    return XBee64BitAddress(v.to_bytes(8, "big"))


def sample_packets() -> list:
    """One of every frame the driver reads, with escape-worthy bytes in addresses, IDs and payloads."""
    return [
        ATCommResponsePacket(0x11, "NI", 0, bytearray(b"robot~}")),
        ATCommResponsePacket(0x7E, "SH", 0, bytearray(b"\x00\x13\xa2\x00")),
        TXStatusPacket(0x13, TransmitStatus.NO_ACK),
        TransmitStatusPacket(0x7D, XBee16BitAddress(b"\x7e\x11"), 3, TransmitStatus.NETWORK_ACK_FAILURE),
        RX64Packet(a64(0x0013A2007E7D1113), 0x37, 0x02, bytearray(SPECIAL * 5)),
        RX16Packet(XBee16BitAddress(b"\x11\x13"), 0x50, 0x00, bytearray(b"x")),
        ReceivePacket(a64(A64), XBee16BitAddress(b"\x7d\x7e"), 0x01, bytearray(range(84))),
        ModemStatusPacket(ModemStatus.JOINED_NETWORK),
    ]


def wire(pkt, api_mode: int) -> bytes:
    return bytes(pkt.output(escaped=api_mode == 2))


def reader(api_mode: int) -> FrameReader:
    return FrameReader(api_mode, dict.fromkeys(COUNTER_NAMES, 0))


def balanced(r: FrameReader) -> bool:
    c = r.counters
    return c["rx_bytes"] == c["frame_bytes"] + c["dropped_bytes"] + r.pending


# -- the byte reader ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("api_mode", [1, 2])
def test_reader_returns_digi_frames_unescaped_whatever_the_chunking(api_mode: int) -> None:
    pkts = sample_packets()
    stream = b"".join(wire(p, api_mode) for p in pkts)
    for chunk in (1, 2, 7, len(stream)):
        r = reader(api_mode)
        frames = []
        for i in range(0, len(stream), chunk):
            frames += r.feed(stream[i : i + chunk])
        assert [bytes(f) for f in frames] == [bytes(p.output()) for p in pkts]
        assert r.counters["frames"] == len(pkts) and r.counters["dropped_bytes"] == 0 and r.pending == 0
        assert balanced(r)


def test_reader_skips_noise_and_resynchronises_after_a_bad_checksum() -> None:
    good = wire(ATCommResponsePacket(1, "MY", 0, bytearray(b"\x00\x07")), 1)
    bad = bytearray(good)
    bad[-1] ^= 0xFF
    r = reader(1)
    frames = r.feed(b"\x00\x13garbage" + bytes(bad) + good)
    assert [bytes(f) for f in frames] == [good]
    assert r.counters["checksum_errors"] == 1 and r.counters["dropped_bytes"] == 9 + len(bad)
    assert balanced(r)


def test_reader_finds_a_frame_swallowed_by_a_noise_delimiter() -> None:
    """API 1: a stray 0x7E with a plausible length eats the next frame; when its checksum fails the search
    restarts right after the stray delimiter and the real frame is found."""
    good = wire(ATCommResponsePacket(1, "MY", 0, bytearray(b"\x00\x07")), 1)
    r = reader(1)
    assert r.feed(b"\x7e\x00\x0c\x88" + good) == []  # the noise frame is still incomplete
    assert r.pending == 4 + len(good)
    frames = r.feed(b"\x01\x02\x03")  # now the noise frame is complete, its checksum fails, the search resumes
    assert [bytes(f) for f in frames] == [good]
    assert r.counters["checksum_errors"] == 1 and balanced(r)


def test_reader_rejects_insane_lengths_at_once() -> None:
    good = wire(ModemStatusPacket(ModemStatus.HARDWARE_RESET), 1)
    r = reader(1)
    frames = r.feed(b"\x7e\x00\x00" + b"\x7e\xff\xff" + good)
    assert [bytes(f) for f in frames] == [good]
    assert r.counters["bad_length"] == 2 and balanced(r)


def test_reader_api2_drops_a_frame_cut_by_a_raw_delimiter() -> None:
    good = wire(ATCommResponsePacket(1, "MY", 0, bytearray(b"\x00\x07")), 2)
    r = reader(2)
    frames = r.feed(good[:6] + b"\x7d" + good)  # a frame cut short, even in the middle of an escape
    assert [bytes(f) for f in frames] == [bytes(ATCommResponsePacket(1, "MY", 0, bytearray(b"\x00\x07")).output())]
    assert r.counters["truncated"] == 1 and r.counters["dropped_bytes"] == 7 and balanced(r)


@pytest.mark.parametrize("api_mode", [1, 2])
@settings(max_examples=400, deadline=None)
@given(data=st.lists(st.binary(max_size=64) | st.sampled_from([b"\x7e", b"\x7d", b"\x7e\x00", b"\x7e\x00\x05"]),
                     max_size=40))
def test_reader_never_raises_and_accounts_for_every_byte(api_mode: int, data: list[bytes]) -> None:
    r = reader(api_mode)
    for chunk in data:
        for f in r.feed(chunk):
            assert f[0] == 0x7E and int.from_bytes(f[1:3], "big") == len(f) - 4 and sum(f[3:]) & 0xFF == 0xFF
        assert balanced(r)


@settings(max_examples=300, deadline=None)
@given(noise=st.binary(max_size=200), which=st.integers(0, 7))
def test_reader_api2_recovers_the_next_frame_after_any_noise(noise: bytes, which: int) -> None:
    """In API 2 every data 0x7E is escaped, so a raw 0x7E always starts a frame: nothing can swallow it."""
    pkt = sample_packets()[which]
    r = reader(2)
    frames = r.feed(noise + wire(pkt, 2))
    assert frames and bytes(frames[-1]) == bytes(pkt.output())
    assert r.pending == 0 and balanced(r)


@settings(max_examples=300, deadline=None)
@given(noise=st.binary(max_size=200).map(lambda b: b.replace(b"\x7e", b"")), which=st.integers(0, 7))
def test_reader_api1_recovers_frames_after_noise_without_delimiters(noise: bytes, which: int) -> None:
    pkt = sample_packets()[which]
    r = reader(1)
    frames = r.feed(noise + wire(pkt, 1) + wire(pkt, 1))
    assert [bytes(f) for f in frames] == [bytes(pkt.output())] * 2
    assert r.counters["dropped_bytes"] == len(noise) and balanced(r)


def checksummed(body: bytes) -> bytes:
    return b"\x7e" + len(body).to_bytes(2, "big") + body + bytes([0xFF - (sum(body) & 0xFF)])


FRAME_TYPES = [0x88, 0x89, 0x8B, 0x80, 0x81, 0x90, 0x8A, 0x91, 0x97, 0x10, 0x08, 0x00, 0x42]


@settings(max_examples=400, deadline=None)
@given(bodies=st.lists(st.tuples(st.sampled_from(FRAME_TYPES), st.binary(max_size=40)), max_size=12),
       api_mode=st.sampled_from([1, 2]))
def test_driver_dispatch_of_any_checksummed_frame_never_raises(bodies: list[tuple[int, bytes]], api_mode: int) -> None:
    """Frames with good checksums but random content: each ends up queued, kept, unexpected, unhandled or
    malformed, and the driver stays usable."""
    world = World([ScriptedModule(api_mode=api_mode)])
    x = XBee(world.ports[0], world.clock, api_mode=api_mode, series=1)
    for ftype, body in bodies:
        frame = checksummed(bytes([ftype]) + body)
        if api_mode == 2:
            frame = frame[:1] + bytes(ATCommPacket._escape_data(bytearray(frame[1:])))
        world.ports[0].inject(frame)
    x.poll()
    c = x.counters
    assert c["frames"] == len(bodies)
    assert c["rx_packets"] + c["modem_status"] + c["unexpected"] + c["unhandled"] + c["malformed"] == len(bodies)
    while x.recv() is not None:
        pass
    assert x.at("NI") == b"SCRIPTED"


@pytest.mark.parametrize("api_mode", [1, 2])
@settings(max_examples=200, deadline=None)
@given(noise=st.binary(max_size=120))
def test_driver_recovers_from_line_noise_once_the_line_is_quiet(api_mode: int, noise: bytes) -> None:
    world = World([ScriptedModule(api_mode=api_mode)])
    x = XBee(world.ports[0], world.clock, api_mode=api_mode, series=1)
    world.ports[0].inject(noise)
    x.poll()
    world.clock.sleep(STALL_S)
    x.poll()
    assert x.reader.pending == 0
    assert x.at("NI") == b"SCRIPTED"
    assert x.counters["rx_bytes"] == x.counters["frame_bytes"] + x.counters["dropped_bytes"]


def test_a_noise_delimiter_holding_back_an_answer_is_abandoned_after_a_quiet_gap() -> None:
    x, _, world = scripted()
    world.ports[0].inject(b"\x7e\x00\x40")  # claims 64 bytes: swallows the answer, which is shorter
    assert x.at("NI") == b"SCRIPTED"
    assert x.counters["stalled"] == 1 and x.counters["checksum_errors"] == 0
    # request (8 bytes) + 2 ms + answer (17 bytes) at 9600 baud, then STALL_S of silence
    assert world.clock.now() == pytest.approx((8 + 17) * 10 / 9600 + 0.002 + STALL_S, abs=1e-3)


# -- request/response against a scripted module (simulated time) --------------------------------------------------


def scripted(series: int = 1, api_mode: int = 1, **kw) -> tuple[XBee, ScriptedModule, World]:
    mod = ScriptedModule(series=series, api_mode=api_mode, **kw)
    world = World([mod])
    xbee_kw = {"rssi_from_db": True} if series == 2 else {}
    return XBee(world.ports[0], world.clock, api_mode=api_mode, **xbee_kw), mod, world


@pytest.mark.parametrize(("series", "api_mode"), [(1, 1), (1, 2), (2, 1), (2, 2)])
def test_identify_reads_the_module_and_detects_its_series(series: int, api_mode: int) -> None:
    x, mod, world = scripted(series, api_mode, at={"SL": bytes.fromhex("7E7D1113")})
    info = x.identify()
    assert info == ModuleInfo(
        serial64=0x0013A2007E7D1113, addr16=0x0007 if series == 1 else 0x1A2B, node_id="SCRIPTED",
        hw_version=0x1744 if series == 1 else 0x1941, fw_version=0x10EC if series == 1 else 0x21A7, series=series,
    )
    assert x.series == series and [p.command for p in mod.received] == ["SH", "SL", "MY", "NI", "HV", "VR"]
    # six request/response round trips at 9600 baud, each 8 + ~10 bytes on the lines plus 2 ms latency
    assert 0.1 < world.clock.now() < 0.2
    assert x.counters["malformed"] == x.counters["unexpected"] == x.counters["dropped_bytes"] == 0


def test_series_from_versions() -> None:
    assert series_of(0x1744, 0x10EC) == 1 and series_of(0x1842, 0x10ED) == 1  # XBee / XBee-PRO 802.15.4
    assert series_of(0x1941, 0x21A7) == 2 and series_of(0x1A42, 0x23A7) == 2  # XBee / XBee-PRO ZB
    assert series_of(0x2241, 0x2003) == 1 and series_of(0x2241, 0x4060) == 2  # S2C with 802.15.4 / ZigBee firmware
    assert series_of(0x0000, 0x10EC) == 1 and series_of(0x0000, 0x21A7) == 2  # unknown hardware


def test_at_set_forms_queue_and_errors() -> None:
    x, mod, _ = scripted()
    assert x.at("CH", 0x0C) == b""
    assert x.at("ID", 0x3332) == b""
    assert x.at("NI", "bot-7", apply=False) == b""
    assert x.at("KY", b"\x00\x01") == b""
    assert x.at("PL", 0) == b""
    sent = mod.received
    assert [type(p) for p in sent] == [ATCommPacket, ATCommPacket, ATCommQueuePacket, ATCommPacket, ATCommPacket]
    assert [bytes(p.parameter) for p in sent] == [b"\x0c", b"\x33\x32", b"bot-7", b"\x00\x01", b"\x00"]
    with pytest.raises(XBeeError) as e:
        x.at("ZZ")
    assert e.value.status == 2 and e.value.command == "ZZ" and not isinstance(e.value, XBeeTimeout)
    assert x.counters["at_errors"] == 1
    with pytest.raises(ValueError):
        x.at("TOO")


def test_at_timeout_waits_in_simulated_time_and_a_late_answer_is_counted() -> None:
    x, mod, world = scripted(silent=True)
    t0 = world.clock.now()
    with pytest.raises(XBeeTimeout) as e:
        x.at("SH", timeout=0.25)
    assert isinstance(e.value, TimeoutError) and e.value.status is None
    assert world.clock.now() - t0 == pytest.approx(0.25, abs=1e-6)
    mod.emit_packet(ATCommResponsePacket(1, "SH", 0, bytearray(4)))  # the answer to frame 1, too late
    world.clock.sleep(0.05)
    x.poll()
    assert x.counters["unexpected"] == 1 and x.counters["timeouts"] == 1


def test_response_with_another_command_or_frame_id_is_not_taken() -> None:
    x, mod, _ = scripted(latency_ns=20_000_000)
    mod.emit_packet(ATCommResponsePacket(1, "SL", 0, bytearray(4)), t_ns=5_000_000)  # right ID, wrong command
    mod.emit_packet(ATCommResponsePacket(9, "SH", 0, bytearray(4)), t_ns=5_000_000)  # right command, wrong ID
    assert x.at("SH") == bytes.fromhex("0013A200")
    assert x.counters["unexpected"] == 2


@pytest.mark.parametrize(("series", "api_mode"), [(1, 1), (1, 2), (2, 1), (2, 2)])
def test_send_uses_the_series_frames_and_returns_the_tx_status(series: int, api_mode: int) -> None:
    x, mod, _ = scripted(series, api_mode)
    payload = SPECIAL * 10
    st_ = x.send(0x0013A20040000001, payload)
    assert st_.ok and st_.status == 0 and st_.description == "Success"
    st_b = x.send(None, b"hello")
    assert st_b.ok
    tx = [p for p in mod.received if isinstance(p, TX64Packet | TransmitPacket)]
    assert [type(p) for p in tx] == [TX64Packet if series == 1 else TransmitPacket] * 2
    dest = [int.from_bytes(bytes(p.x64bit_dest_addr.address), "big") for p in tx]
    assert dest == [0x0013A20040000001, 0xFFFF] and bytes(tx[0].rf_data) == payload
    if series == 2:
        assert all(p.x16bit_dest_addr == XBee16BitAddress.UNKNOWN_ADDRESS for p in tx)
        assert st_.retries == 1 and st_.discovery == 0
    assert x.tx_result(st_.frame_id) is None  # send took it


@pytest.mark.parametrize(("series", "code", "text"), [(1, 1, "No acknowledgement"), (1, 2, "CCA"),
                                                       (2, 0x21, "Network ACK"), (2, 0x74, "too large")])
def test_send_failures_carry_the_module_status(series: int, code: int, text: str) -> None:
    x, _, _ = scripted(series, tx_status=code)
    st_ = x.send(5, b"x")
    assert not st_.ok and st_.status == code and text in st_.description


def test_send_nowait_and_tx_result() -> None:
    x, _, world = scripted()
    x.identify()
    t0 = world.clock.now()
    ids = [x.send_nowait(7, bytes([i])) for i in range(3)]
    assert world.clock.now() == t0 and len(set(ids)) == 3  # no wait at all
    assert all(x.tx_result(i) is None for i in ids)
    world.clock.sleep(0.2)
    x.poll()
    results = [x.tx_result(i) for i in ids]
    assert all(r is not None and r.ok for r in results)
    assert x.tx_result(ids[0]) is None


def test_send_timeout_when_the_module_is_silent() -> None:
    x, _, _ = scripted(silent=True)
    x2 = XBee(x.port, x.clock, series=1)
    with pytest.raises(XBeeTimeout):
        x2.send(1, b"x", timeout=0.5)


def test_frame_ids_cycle_through_1_to_255_and_skip_pending_ones() -> None:
    x, _, _ = scripted(silent=True)
    x2 = XBee(x.port, x.clock, series=1)
    first = x2.send_nowait(1, b"a")
    ids = [x2.send_nowait(1, b"a") for _ in range(254)]
    assert first == 1 and ids == list(range(2, 256))
    assert x2.tx_result(1) is None
    x2._pending.pop(7)  # as if its status had been read
    assert x2.send_nowait(1, b"a") == 7


def test_recv_series1_with_rssi_and_timeouts() -> None:
    x, mod, world = scripted()
    assert x.recv() is None and world.clock.now() == 0
    t0 = world.clock.now()
    assert x.recv(timeout=0.1) is None
    assert world.clock.now() - t0 == pytest.approx(0.1, abs=1e-6)
    mod.deliver(0x0013A20040000002, b"\x7e\x7dhi", rssi_dbm=-71, broadcast=True)
    r = x.recv(timeout=1.0)
    assert r == Received(0x0013A20040000002, None, b"\x7e\x7dhi", -71, True, r.t)
    # 2 ms latency, then 20 bytes at ~1.04 ms each; the driver sees the frame when its last byte arrives
    assert r.t == pytest.approx(0.1 + 0.002 + 20 * 10 / 9600, abs=2e-3)


def test_recv_blocks_forever_with_none() -> None:
    x, mod, _ = scripted()
    mod.emit_packet(RX16Packet(XBee16BitAddress(b"\x00\x09"), 40, 0, bytearray(b"z")), t_ns=3_000_000_000)
    r = x.recv(timeout=None)
    assert r is not None and r.src16 == 9 and r.src64 is None and r.rssi_dbm == -40 and not r.broadcast
    assert r.t > 3.0


def test_recv_series2_asks_db_for_the_rssi() -> None:
    x, mod, _ = scripted(series=2)
    mod.deliver(0x0013A20040000003, b"payload", rssi_dbm=-83)
    r = x.recv(timeout=1.0)
    assert r is not None and r.rssi_dbm == -83 and r.src16 == 0x1234 and not r.broadcast
    assert [p.command for p in mod.received] == ["DB"]


def test_recv_series2_without_db_leaves_rssi_unknown_and_db_failure_is_counted() -> None:
    mod = ScriptedModule(series=2)
    world = World([mod])
    x = XBee(world.ports[0], world.clock)
    mod.deliver(1, b"a")
    r = x.recv(timeout=1.0)
    assert r is not None and r.rssi_dbm is None and mod.received == []
    x.rssi_from_db = True
    mod.deliver(1, b"b")
    del mod.at_values["DB"]  # the module answers ATDB with "invalid command"
    r = x.recv(timeout=1.0)
    assert r is not None and r.rssi_dbm is None and x.counters["db_failed"] == 1


def test_modem_status_is_kept_and_poll_does_not_block() -> None:
    x, mod, world = scripted()
    mod.power_up()
    x.poll()
    assert x.modem_status == [] and world.clock.now() == 0
    world.clock.sleep(0.05)
    x.poll()
    assert [(m.code, m.name) for m in x.modem_status] == [(0, "HARDWARE_RESET")]
    assert world.clock.now() == pytest.approx(0.05)


def test_receive_queue_is_bounded() -> None:
    x, _, world = scripted()
    for i in range(RX_QUEUE_MAX + 3):
        world.ports[0].inject(wire(RX64Packet(a64(i), 40, 0, bytearray(b"d")), 1))
    x.poll()
    assert x.counters["rx_overflow"] == 3
    assert x.recv().src64 == 3


# -- a real serial port (pty) in wall time ------------------------------------------------------------------------


def test_driver_on_a_real_pty_in_wall_time() -> None:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    port = serial.Serial(os.ttyname(slave), 9600)
    try:
        x = XBee(port, WallClock())
        os.write(master, wire(ModemStatusPacket(ModemStatus.HARDWARE_RESET), 1) + b"\x00noise"
                 + wire(ATCommResponsePacket(1, "NI", 0, bytearray(b"real")), 1))
        assert x.at("NI", timeout=60.0) == b"real"  # the answer is already on the line: the bound catches a hang
        request = os.read(master, 64)
        assert request == wire(ATCommPacket(1, "NI"), 1)
        assert x.modem_status[0].code == 0 and x.counters["dropped_bytes"] == 6
        with pytest.raises(XBeeTimeout):
            x.at("SH", timeout=0.05)
    finally:
        port.close()
        os.close(master)
        os.close(slave)


# -- end to end: the driver against the module emulation ----------------------------------------------------------

SERIALS = (0x0013A20040A10001, 0x0013A20040A10002, 0x0013A20040A10003)


def link_rssi(i: int, j: int) -> int | None:
    """Robot 2 hears nobody and is heard by nobody; the others at -52 / -67 dBm."""
    if 2 in (i, j):
        return None
    return -52 if i == 0 else -67


def module_pair(series: int, api_mode: int, n: int = 2, **kw) -> tuple[list[XBee], list, World]:
    mods = [XBeeModule(series=series, serial64=SERIALS[i], node_id=f"r{i:03d}", api_mode=api_mode,
                               rng=np.random.default_rng(i)) for i in range(n)]
    world = World(mods, link=link_rssi)
    drivers = [XBee(p, world.clock, api_mode=api_mode, rssi_from_db=series == 2, **kw) for p in world.ports]
    return drivers, mods, world


def wait_joined(x: XBee, timeout: float = 5.0) -> None:
    t_end = x.clock.now() + timeout
    while not any(m.code == 2 for m in x.modem_status):
        assert x.clock.now() < t_end, "no 'joined network' modem status"
        x.recv(timeout=0.05)


@pytest.mark.parametrize("api_mode", [1, 2])
def test_e2e_series1_identify_send_receive(api_mode: int) -> None:
    (a, b), mods, _ = module_pair(1, api_mode)
    info = a.identify()
    assert info == ModuleInfo(SERIALS[0], 0xFFFE, "r000", 0x1744, 0x10EF, 1)
    assert b.identify().serial64 == SERIALS[1] and b.series == 1
    assert [m.code for m in a.modem_status] == [0]  # hardware reset at power-up
    payload = bytes(range(100))  # the Series 1 maximum, full of bytes API 2 escapes
    st_ = a.send(SERIALS[1], payload)
    assert st_.ok
    r = b.recv(timeout=1.0)
    assert r is not None and (r.src64, r.src16, r.data, r.rssi_dbm, r.broadcast) == (SERIALS[0], None, payload,
                                                                                   -52, False)
    assert a.send(None, b"all").ok
    r = b.recv(timeout=1.0)
    assert r is not None and r.broadcast and r.data == b"all"
    st_ = b.send(SERIALS[0], b"back")
    r = a.recv(timeout=1.0)
    assert st_.ok and r is not None and r.rssi_dbm == -67
    for x in (a, b):
        assert {k: v for k, v in x.counters.items() if v and k in ("dropped_bytes", "malformed", "unexpected",
                                                                      "unhandled", "checksum_errors")} == {}
    assert all(m.counters["checksum_errors"] == m.counters["discarded_bytes"] == 0 for m in mods)


def test_e2e_series1_failures_and_at_status() -> None:
    (a, _), _, _ = module_pair(1, 1)
    st_ = a.send(0x0013A200DEADBEEF, b"nobody")  # nobody has this address: MAC ACK never comes
    assert not st_.ok and st_.status == 1
    with pytest.raises(XBeeError) as e:
        a.at("ZZ")
    assert e.value.status == 2
    with pytest.raises(XBeeError) as e:
        a.at("CH", 0x30)
    assert e.value.status == 3
    a.at("NI", "renamed", apply=False)
    a.at("AC")  # applies the queued setting
    assert a.at("NI") == b"renamed"
    a.at("RR", 3)
    st_ = a.send(0x0013A200DEADBEEF, b"nobody")  # now with three XBee-level retries on top of the MAC's
    assert not st_.ok and st_.status == 1
    # a payload the module refuses (Series 1: silently) ends in a timeout, not a hang
    with pytest.raises(XBeeTimeout):
        a.send(SERIALS[1], bytes(101), timeout=0.5)


@pytest.mark.parametrize("api_mode", [1, 2])
def test_e2e_series2_join_send_receive_with_db_rssi(api_mode: int) -> None:
    (a, b, c), mods, _ = module_pair(2, api_mode, n=3)
    info = a.identify()
    assert info.series == 2 and info.hw_version == 0x1941 and info.fw_version == 0x23A7 and info.node_id == "r000"
    st_ = a.send(SERIALS[1], b"early")
    assert not st_.ok and st_.status == 0x22  # not joined yet
    for x in (a, b, c):
        wait_joined(x)
    assert a.at("AI") == b"\x00"
    st_ = a.send(SERIALS[1], b"hello \x7e\x7d\x11\x13")
    assert st_.ok and st_.retries == 0
    r = b.recv(timeout=1.0)
    assert r is not None and r.src64 == SERIALS[0] and r.data == b"hello \x7e\x7d\x11\x13"
    assert r.rssi_dbm == -52 and not r.broadcast and r.src16 == mods[0].addr16()
    assert a.send(None, b"x" * 92).ok  # broadcasts carry 8 bytes more than unicasts
    r = b.recv(timeout=1.0)
    assert r is not None and r.broadcast and len(r.data) == 92
    assert c.recv(timeout=0.5) is None  # robot 2 is out of range
    st_ = a.send(SERIALS[1], bytes(85))
    assert st_.status == 0x74 and "too large" in st_.description
    st_ = a.send(SERIALS[2], b"far", timeout=10.0)  # three APS attempts, each with its network ACK timeout
    assert st_.status == 0x21 and st_.retries == 2
    assert a.counters["timeouts"] == 0 and b.counters["db_failed"] == 0


def test_e2e_many_packets_queue_for_recv_and_nowait_statuses() -> None:
    (a, b), _, world = module_pair(1, 2)
    ids = [a.send_nowait(SERIALS[1], f"msg{i}".encode()) for i in range(5)]
    world.clock.sleep(1.0)
    a.poll()
    assert [a.tx_result(i).ok for i in ids] == [True] * 5
    got = [b.recv().data for _ in range(5)]
    assert got == [f"msg{i}".encode() for i in range(5)] and b.recv() is None


def test_e2e_line_noise_from_the_host_side_does_not_break_the_pair() -> None:
    (a, b), mods, world = module_pair(1, 1)
    a.identify()
    world.ports[0].inject(b"\x7e\x00\x30\x90garbage")  # noise on the module -> host line
    world.ports[0].write(b"\x7e\x00\x02\x08\x01\x00junk")  # and on the host -> module line
    world.clock.sleep(0.3)
    assert a.at("NI") == b"r000"
    assert a.send(SERIALS[1], b"ok").ok and b.recv(timeout=1.0).data == b"ok"
    assert a.counters["stalled"] >= 1 and mods[0].counters["checksum_errors"] + \
        mods[0].counters["discarded_bytes"] > 0
