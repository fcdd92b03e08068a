"""The XBee module's firmware as a host reaches it over its UART (API 1, API 2 escaped, AT command frames), and the
robot's XBee driver as a real module's bytes reach it.

Inputs are scripts of chunks (``Cursor``): a header byte (bit 0: the chunk is frame data, which the harness frames with
its length and checksum, escaped in API 2, so the fuzzer's mutations reach past the checksum; the other bits: time
to let pass before it) and the chunk itself, fed as the host (or the module) writes it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress
from digi.xbee.models.status import ATCommandStatus, DiscoveryStatus, ModemStatus, TransmitStatus
from digi.xbee.packets.common import (
    ATCommPacket,
    ATCommResponsePacket,
    ExplicitAddressingPacket,
    ModemStatusPacket,
    ReceivePacket,
    RemoteATCommandPacket,
    TransmitPacket,
    TransmitStatusPacket,
)
from digi.xbee.packets.raw import RX16Packet, RX64Packet, TX16Packet, TX64Packet, TXStatusPacket

from bridge.hil.xbee_gateway import TWIN_API_MODE, XBeeGateway
from firmware_sim.modules.xbee import MS, XBeeModule, encode_frame
from fuzz.harness import Cursor, FakeClock, ScriptedPort, Target, chunks, lp
from swarm_logic.drivers.xbee import XBee, XBeeError

A64 = 0x0013A20040A1B2C3
DONE = ("ok", "no_ack", "cca_fail")
AT_COMMANDS = ("AP", "HV", "VR", "SH", "SL", "NI", "MY", "CE", "ID", "CH", "AI", "DB", "PL", "RP", "BD", "SM", "DH",
               "DL", "AC", "WR", "FR", "RR", "EA", "EC", "OP", "OI", "SC", "NH", "AO", "NP", "NR", "ND", "DN", "NT",
               "NO", "BH", "DD", "EE", "%V", "NC", "N?", "TP")


def _module(series: int, api_mode: int, mesh: bool = False) -> XBeeModule:
    return XBeeModule(series=series, serial64=A64, node_id="FUZZ", rng=np.random.default_rng(1), api_mode=api_mode,
                      routing="mesh" if mesh else "one_hop")


def _drive(m: XBeeModule, c: Cursor, frame_of: Callable[[XBeeModule, bytes], bytes]) -> None:
    """Feed the script's chunks; every air frame the module sends is answered (ok, no ACK, CCA failure by the next
    byte), so its transmit path and status frames run; then its timers (resets, retries, joins) run out."""
    t = 0
    m.step(t, b"", [])
    while c.more():
        head = c.u8()
        t += (head >> 1) * MS
        body = c.chunk()
        data = frame_of(m, body) if head & 1 else body
        out = m.step(t, data, [])
        done = [{"ev": "done", "t_ns": t, "handle": fr["handle"], "status": DONE[c.u8() % 3], "attempts": 1}
                for fr in out.air_tx]
        if done:
            m.step(t, b"", done)
    for _ in range(64):
        w = m.next_wake()
        if w is None or w > t + 3000 * MS:
            break
        t = max(t, w)
        m.step(t, b"", [])


def _framed(m: XBeeModule, body: bytes) -> bytes:
    return encode_frame(body, m.api_mode) if len(body) > 0 else b""


def _api(api_mode: int) -> Callable[[bytes], None]:
    def run(data: bytes) -> None:
        c = Cursor(data)
        first = c.u8()  # bit 0: Series 2; bit 1: its mesh routing
        _drive(_module(1 + (first & 1), api_mode, bool(first & 2)), c, _framed)

    return run


def _at(data: bytes) -> None:
    """AT command frames: each chunk is ``flags, command (2 bytes), parameter``; flags bit 0 queues it (0x09), bit 1
    asks for no response (frame ID 0). The module's API mode may change under it (AP): each frame is framed in the
    mode the module is in then."""
    c = Cursor(data)
    first = c.u8()

    def frame_of(m: XBeeModule, body: bytes) -> bytes:
        flags = body[0] if body else 0
        fid = 0 if flags & 2 else 0x52
        return encode_frame(bytes((0x09 if flags & 1 else 0x08, fid)) + body[1:], m.api_mode)

    _drive(_module(1 + (first & 1), 1 + (first >> 1 & 1), bool(first & 4)), c, frame_of)


def _api_seeds(api_mode: int) -> list[bytes]:
    bcast = XBee64BitAddress.BROADCAST_ADDRESS
    s1 = [TX64Packet(1, XBee64BitAddress.from_hex_string("0013A20040A1B2C4"), 0, bytearray(b"hello")),
          TX64Packet(2, bcast, 0, bytearray(b"\x7e\x7d\x11\x13")),
          TX16Packet(3, XBee16BitAddress.from_hex_string("0002"), 1, bytearray(3)),
          ATCommPacket(4, "NI", bytearray(b"R007")), ATCommPacket(5, "RR", bytearray([3]))]
    s2 = [TransmitPacket(6, bcast, XBee16BitAddress.from_hex_string("FFFE"), 0, 0, rf_data=bytearray(8)),
          TransmitPacket(7, XBee64BitAddress.from_hex_string("0013A20040A1B2C4"),
                         XBee16BitAddress.from_hex_string("FFFE"), 0, 0, rf_data=bytearray(b"unicast")),
          ATCommPacket(8, "SC", bytearray([0x1F, 0xFE])), ATCommPacket(9, "NR", None),
          ExplicitAddressingPacket(10, XBee64BitAddress.from_hex_string("0013A20040A1B2C3"),
                                   XBee16BitAddress.from_hex_string("FFFE"), 0, 0, 0x0002, 0, 0, 0,
                                   bytearray(b"\x0a\xfe\xff")),
          RemoteATCommandPacket(11, XBee64BitAddress.from_hex_string("0013A20040A1B2C4"),
                                XBee16BitAddress.from_hex_string("FFFE"), 0x02, "NI", bytearray(b"R9")),
          ATCommPacket(12, "ND", None)]
    out = []
    for first, pkts in ((0, s1), (1, s2), (3, s2)):  # Series 1; Series 2 one hop; Series 2 mesh
        join = [(0xFE, b""), (0xFE, b"")] if first else []  # a Series 2 module sends once it has joined
        raw = [(0x14, bytes(p.output(escaped=api_mode == 2))) for p in pkts]
        framed = [(0x15, bytes(p.output()[3:-1])) for p in pkts]
        out.append(bytes((first,)) + chunks(*join, *raw, (0x40, b"\x7e\x00\x00\x7e\x00\x05")))
        out.append(bytes((first,)) + chunks(*join, *framed, (0xFE, b"")))
    return out


def _at_seeds() -> list[bytes]:
    out = []
    for series, mesh in ((1, 0), (2, 0), (2, 1)):
        for api_mode in (1, 2):
            first = (series - 1) | (api_mode - 1) << 1 | mesh << 2
            queries = [(0x03, b"\x00" + cmd.encode()) for cmd in AT_COMMANDS]
            sets = [(0x03, b"\x01CH\x0e"), (0x03, b"\x00AC"), (0x03, b"\x00RP\xff"), (0x03, b"\x00NIROBOT 7"),
                    (0x03, b"\x00PL\x09"), (0x03, b"\x00AP\x02"), (0x03, b"\x02ID\x12\x34"), (0x03, b"\x00WR"),
                    (0x03, b"\x00BD\x07"), (0x03, b"\x00FR"), (0x03, b"\x00NR\x01"), (0x03, b"\x00zz")]
            out.append(bytes((first,)) + chunks(*queries))
            out.append(bytes((first,)) + chunks(*sets))
    return out


# -- the robot's driver ------------------------------------------------------------------------------------------------
def _driver(data: bytes) -> None:
    """The driver over a port whose module answers with the script: header bits 0-1 the operation (an AT query, or
    with bit 5 the six of ``identify``; a send waiting for its status; a receive; a poll), bit 2 frame the chunks;
    a chunk is the module's answer to one of the operation's writes, or what it sends unasked."""
    c = Cursor(data)
    first = c.u8()
    api_mode, series = 1 + (first & 1), 1 + (first >> 1 & 1)
    clock = FakeClock()
    port = ScriptedPort(clock)
    xb = XBee(port, clock, api_mode=api_mode, series=None if first & 8 else series, rssi_from_db=bool(first & 4))
    while c.more():
        head = c.u8()
        op = head & 3
        identify = op == 0 and head & 0x20
        for _ in range(6 if identify else 1):
            body = c.chunk()
            data_ = encode_frame(body, api_mode) if head & 4 and body else body
            if op in (0, 1):
                port.answers.append(data_)
            else:
                port.feed(data_)
        try:
            if identify:
                xb.identify(timeout=0.2)
            elif op == 0:
                xb.at(("NI", "DB", "SH", "MY")[head >> 3 & 3], timeout=0.2)
            elif op == 1:
                xb.send(None if head & 8 else A64, b"payload", timeout=0.2)
            elif op == 2:
                xb.recv(timeout=0.05)
            else:
                clock.sleep((head >> 3) * 0.01)
                xb.poll()
        except XBeeError:  # the module's non-zero status, or no answer: the driver's documented errors
            pass
    while xb.recv(0) is not None:
        pass


def _driver_seeds() -> list[bytes]:
    a64 = XBee64BitAddress.from_hex_string("0013A20040A1B2C4")
    out = []
    for api_mode in (1, 2):
        esc = api_mode == 2
        at = ATCommResponsePacket(1, "NI", ATCommandStatus.OK, bytearray(b"R001")).output(escaped=esc)
        tx1 = TXStatusPacket(2, TransmitStatus.SUCCESS).output(escaped=esc)
        tx2 = TransmitStatusPacket(3, XBee16BitAddress.from_hex_string("0001"), 0, TransmitStatus.SUCCESS,
                                   DiscoveryStatus.NO_DISCOVERY_OVERHEAD).output(escaped=esc)
        rx64 = RX64Packet(a64, 40, 2, bytearray(b"hi")).output(escaped=esc)
        rx16 = RX16Packet(XBee16BitAddress.from_hex_string("0002"), 50, 0, bytearray(b"yo")).output(escaped=esc)
        rx = ReceivePacket(a64, XBee16BitAddress.from_hex_string("1234"), 2, bytearray(b"zb")).output(escaped=esc)
        ms = ModemStatusPacket(ModemStatus.JOINED_NETWORK).output(escaped=esc)
        first = api_mode - 1
        ident = [ATCommResponsePacket(fid, cmd, ATCommandStatus.OK, bytearray(v)).output(escaped=esc)
                 for fid, (cmd, v) in enumerate((("SH", b"\x00\x13\xa2\x00"), ("SL", b"\x40\xa1\xb2\xc4"),
                                                 ("MY", b"\xff\xfe"), ("NI", b"R002"), ("HV", b"\x19\x41"),
                                                 ("VR", b"\x23\xa7")), start=1)]
        out.append(bytes((first | 8,)) + b"\x20" + b"".join(lp(bytes(p)) for p in ident) + chunks((0x02, bytes(rx))))
        out.append(bytes((first,)) + chunks((0x00, bytes(at)), (0x01, bytes(tx1)), (0x02, bytes(rx64) + bytes(rx16)),
                                            (0x03, bytes(ms)), (0x02, b"\x7e\x00\x03noise" + bytes(rx64))))
        db = ATCommResponsePacket(3, "DB", ATCommandStatus.OK, bytearray([60])).output(escaped=esc)
        out.append(bytes((first | 2 | 4,)) + chunks((0x01, bytes(tx2)), (0x02, bytes(rx)), (0x08, bytes(db)),
                                                    (0x06, b"\x8a\x02")))
    return out


# -- the HIL gateway --------------------------------------------------------------------------------------------------
def _gateway(data: bytes) -> None:
    """The XBee gateway's relay (``bridge.hil.xbee_gateway``) between a real module's bytes (the script's chunks,
    header bit 0 clear) and the simulated module's (bit 0 set: a frame the harness builds from the chunk); bit 1
    frames a real module's chunk too; the rest of the header is time passing in 10 ms. The first byte picks the
    series and the real module's API mode."""
    c = Cursor(data)
    first = c.u8()
    series, api_mode = 1 + (first & 1), 1 + (first >> 1 & 1)
    gw = XBeeGateway({"device": "loop://", "baud": 9600, "series": series, "api_mode": api_mode,
                      "peer": "0013A20040A1B2C4" if first & 4 else None})
    gw.real_line.port.close()
    gw.real_line.port = ScriptedPort(FakeClock())  # type: ignore[assignment]
    t = 0
    while c.more():
        head = c.u8()
        t += (head >> 2) * 10 * MS
        gw.set_time(t)
        body = c.chunk()
        if head & 1:
            gw.write(encode_frame(body, TWIN_API_MODE) if body else b"")
        else:
            gw.real_line.port.feed(encode_frame(body, api_mode) if head & 2 and body else body)
        gw.read()
    gw.stats()
    gw.close()


def _gateway_seeds() -> list[bytes]:
    a64 = XBee64BitAddress.from_hex_string("0013A20040A1B2C4")
    out = []
    for series in (1, 2):
        for api_mode in (1, 2):
            if series == 1:
                real_rx = RX64Packet(a64, 40, 0, bytearray(b"from the desk")).output(escaped=api_mode == 2)
                status = TXStatusPacket(1, TransmitStatus.SUCCESS).output(escaped=api_mode == 2)
                twin_rx = RX64Packet(a64, 50, 2, bytearray(b"from the swarm")).output()[3:-1]
                twin_status = TXStatusPacket(1, TransmitStatus.SUCCESS).output()[3:-1]
            else:
                real_rx = ReceivePacket(a64, XBee16BitAddress.from_hex_string("1234"), 2,
                                        bytearray(b"from the desk")).output(escaped=api_mode == 2)
                status = TransmitStatusPacket(1, XBee16BitAddress.from_hex_string("FFFE"), 0, TransmitStatus.SUCCESS,
                                              DiscoveryStatus.NO_DISCOVERY_OVERHEAD).output(escaped=api_mode == 2)
                twin_rx = ReceivePacket(a64, XBee16BitAddress.from_hex_string("0001"), 2,
                                        bytearray(b"from the swarm")).output()[3:-1]
                twin_status = bytes((0x8B, 1, 0xFF, 0xFE, 0, 0, 0))
            first = (series - 1) | (api_mode - 1) << 1
            out.append(bytes((first,)) + chunks((0x04, bytes(real_rx)), (0x05, bytes(twin_rx)),
                                                (0x04, bytes(status)), (0x05, twin_status),
                                                (0x06, bytes(real_rx)[3:-1]), (0x04, b"\x7e\x00\x02garbage")))
    return out


TARGETS = [
    Target("xbee_api1", "XBee module firmware (Series 1 and 2): a host's serial bytes in API mode 1", _api(1),
           lambda: _api_seeds(1)),
    Target("xbee_api2", "XBee module firmware (Series 1 and 2): a host's serial bytes in API mode 2 (escaped)",
           _api(2), lambda: _api_seeds(2)),
    Target("xbee_at", "XBee module firmware: AT command frames (0x08/0x09), every command and parameter", _at,
           _at_seeds),
    Target("xbee_driver", "the robot's XBee driver (FrameReader, dispatch): a real module's bytes, API 1 and 2",
           _driver, _driver_seeds),
    Target("xbee_gateway", "the HIL XBee gateway's relay: a real module's bytes and the simulated module's frames",
           _gateway, _gateway_seeds),
]
