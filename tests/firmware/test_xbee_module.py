"""XBee module emulation: framing, AT commands, radio behaviour, buffers, RSSI PWM, fuzzing.

digi-xbee is the independent oracle: frames the module emits must parse with its packet classes, frames it
builds must be accepted, and its ``XBeeDevice.open()`` must identify the emulated module correctly.
"""

from __future__ import annotations

import threading
import time
from collections import deque

import numpy as np
import pytest
from digi.xbee.comm_interface import XBeeCommunicationInterface
from digi.xbee.devices import XBeeDevice
from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress
from digi.xbee.models.hw import HardwareVersion
from digi.xbee.models.mode import OperatingMode
from digi.xbee.models.protocol import Role, XBeeProtocol
from digi.xbee.models.status import ATCommandStatus, ModemStatus, TransmitStatus
from digi.xbee.packets.base import XBeeAPIPacket
from digi.xbee.packets.common import (
    ATCommPacket,
    ATCommQueuePacket,
    ATCommResponsePacket,
    ModemStatusPacket,
    ReceivePacket,
    TransmitPacket,
    TransmitStatusPacket,
)
from digi.xbee.packets.factory import build_frame
from digi.xbee.packets.raw import RX16Packet, RX64Packet, TX16Packet, TX64Packet, TXStatusPacket
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from firmware_sim.modules.xbee import COUNTER_KEYS, MS, XBeeModule, encode_frame, rssi_pwm_formula

A64, B64, C64 = 0x0013A20040A1B2C3, 0x0013A20040A1B2C4, 0x0013A20040A1B2C5
BCAST64 = XBee64BitAddress.BROADCAST_ADDRESS
MODE = {1: OperatingMode.API_MODE, 2: OperatingMode.ESCAPED_API_MODE}


def make(series=1, serial64=A64, node_id="R001", seed=1, **kw) -> XBeeModule:
    return XBeeModule(series=series, serial64=serial64, node_id=node_id, rng=np.random.default_rng(seed), **kw)


def frames(stream: bytes, api_mode: int = 1) -> list[bytes]:
    """Split a clean output stream into unescaped frames (test helper, independent of the module's parser)."""
    out, i = [], 0
    raw = bytes(stream)
    parts = [raw] if api_mode == 1 else [b"\x7e" + p for p in raw.split(b"\x7e") if p]
    for part in parts:
        data = bytes(XBeeAPIPacket.unescape_data(bytearray(part))) if api_mode == 2 else part
        i = 0
        while i < len(data):
            assert data[i] == 0x7E
            n = int.from_bytes(data[i + 1:i + 3], "big")
            out.append(data[i:i + n + 4])
            i += n + 4
    return out


def packets(stream: bytes, api_mode: int = 1) -> list:
    return [build_frame(bytearray(f), MODE[api_mode]) for f in frames(stream, api_mode)]


class Rig:
    """Drives modules with a manual clock and an ideal medium (every frame on a channel reaches every module)."""

    def __init__(self, *mods: XBeeModule, rssi: int = -60, air_ns: int = 2 * MS, fail: dict | None = None):
        self.mods = list(mods)
        self.t = 0
        self.rssi = rssi
        self.air_ns = air_ns
        self.fail = fail or {}  # handle-independent: module index -> list of statuses to report in turn
        self.events: list[list[dict]] = [[] for _ in mods]
        self.host: list[bytearray] = [bytearray() for _ in mods]
        self.air: list[list[dict]] = [[] for _ in mods]
        self.nodes: list[dict | None] = [None for _ in mods]
        self.pwm: list[list[float]] = [[] for _ in mods]
        self.inp: list[bytearray] = [bytearray() for _ in mods]

    def send(self, i: int, data: bytes) -> None:
        self.inp[i] += data

    def run(self, until_ns: int, dt: int = MS) -> None:
        while self.t < until_ns:
            self.t += dt
            for i, m in enumerate(self.mods):
                evs = sorted((e for e in self.events[i] if e["t_ns"] <= self.t), key=lambda e: e["t_ns"])
                self.events[i] = [e for e in self.events[i] if e["t_ns"] > self.t]
                out = m.step(self.t, bytes(self.inp[i]), evs)
                self.inp[i].clear()
                self.host[i] += out.uart_tx
                if out.node is not None:
                    self.nodes[i] = out.node
                if out.rssi_pwm is not None:
                    self.pwm[i].append(out.rssi_pwm)
                for fr in out.air_tx:
                    self.air[i].append(fr)
                    self._deliver(i, fr)

    def _deliver(self, i: int, fr: dict) -> None:
        t_end = self.t + self.air_ns
        for j in range(len(self.mods)):
            if j != i and self.nodes[j] and self.nodes[j]["channel"] == fr["channel"]:
                self.events[j].append({"ev": "rx", "t_ns": t_end, "frame": fr, "rssi_dbm": self.rssi})
        todo = self.fail.get(i)
        status = todo.pop(0) if todo else "ok"
        self.events[i].append({"ev": "done", "t_ns": t_end, "handle": fr["handle"], "status": status,
                               "attempts": 1})

    def take(self, i: int) -> list:
        pk = packets(bytes(self.host[i]), self.mods[i].api_mode)
        self.host[i].clear()
        return pk


def query(m: XBeeModule, cmd: str, param: bytes | None = None, t0: int = 0) -> ATCommResponsePacket:
    """Send one AT command (after boot) and return digi's parse of the answer."""
    rig = Rig(m)
    rig.t = t0
    rig.run(t0 + 400 * MS, dt=10 * MS)
    rig.take(0)
    rig.send(0, ATCommPacket(7, cmd, bytearray(param) if param is not None else None).output())
    rig.run(rig.t + 100 * MS, dt=10 * MS)
    (resp,) = [p for p in rig.take(0) if isinstance(p, ATCommResponsePacket)]
    return resp


# -- power-up, identity, digi-xbee classification ---------------------------------------------------------------------
def test_series1_power_up_hardware_reset_paced_at_baud():
    m = make()
    out = m.step(5 * MS, b"", [])
    assert out.uart_tx == b""  # nothing has left the wire yet
    assert out.node == {"channel": 0x0C, "pan_id": 0x3332, "addr64": A64, "addr16": 0xFFFE, "tx_power_dbm": 0.0,
                        "sensitivity_dbm": -92.0, "series": 1}
    byte_ns = round(1e10 / 9600)
    assert m.next_wake() == 5 * MS + 6 * byte_ns
    out = m.step(m.next_wake() - 1, b"", [])
    assert len(out.uart_tx) == 5
    out2 = m.step(m.next_wake(), b"", [])
    (pk,) = packets(out.uart_tx + out2.uart_tx)
    assert isinstance(pk, ModemStatusPacket) and pk.modem_status == ModemStatus.HARDWARE_RESET
    assert m.next_wake() is None


def test_series2_joins_after_scan_delay():
    m = make(series=2, channel=0x0C)
    rig = Rig(m)
    rig.run(100 * MS)
    assert rig.take(0) == [] and not m.joined
    assert query(make(series=2), "AI").command_value == bytearray([0x00])
    rig.run(400 * MS)
    (pk,) = rig.take(0)
    assert isinstance(pk, ModemStatusPacket) and pk.modem_status == ModemStatus.JOINED_NETWORK
    # one channel scanned: 2^3 x 15.36 ms + 38 ms + 20 ms, plus < 50 ms association
    assert m.joined and 0 < m.addr16() < 0xFFF8
    late = make(series=2, channel=0x17)  # 12 channels of SC 0x1FFE before it
    rig2 = Rig(late)
    rig2.run(1900 * MS, dt=10 * MS)
    assert not late.joined
    rig2.run(2100 * MS, dt=10 * MS)
    assert late.joined


@pytest.mark.parametrize(("series", "proto", "hw"), [(1, XBeeProtocol.RAW_802_15_4, HardwareVersion.XB24_AXX_XX),
                                                      (2, XBeeProtocol.ZIGBEE, HardwareVersion.XB24_BXIX_XXX)])
def test_versions_classified_by_digi(series, proto, hw):
    hv = query(make(series=series), "HV").command_value
    vr = query(make(series=series), "VR").command_value
    assert len(hv) == 2 and len(vr) == 2
    assert HardwareVersion.get(hv[0]) == hw
    assert XBeeProtocol.determine_protocol(hv[0], vr) == proto


@pytest.mark.parametrize("series", [1, 2])
def test_at_queries_have_real_formats(series):
    kw = {"my16": 0x1234} if series == 1 else {"my16": 0x4321}
    m = lambda: make(series=series, node_id="robot-7", **kw)  # noqa: E731
    assert query(m(), "SH").command_value == bytearray(0x0013A200.to_bytes(4, "big"))
    assert query(m(), "SL").command_value == bytearray(0x40A1B2C3.to_bytes(4, "big"))
    assert query(m(), "NI").command_value == bytearray(b"robot-7")
    assert query(m(), "MY").command_value == bytearray((0x1234 if series == 1 else 0x4321).to_bytes(2, "big"))
    assert query(m(), "CH").command_value == bytearray([0x0C])
    assert query(m(), "AP").command_value == bytearray([1])
    assert int.from_bytes(query(m(), "BD").command_value, "big") == 3
    assert query(m(), "PL").command_value == bytearray([4])
    assert query(m(), "DB").command_value == bytearray([0])
    assert query(m(), "AI").command_value == bytearray([0])
    if series == 1:
        assert query(m(), "ID").command_value == bytearray(b"\x33\x32")
        assert query(m(), "RR").command_value == bytearray([0])
        assert query(m(), "CE").command_value == bytearray([0])
    else:
        assert query(m(), "ID").command_value == bytearray((0x3332).to_bytes(8, "big"))
        assert query(m(), "NP").command_value == bytearray((84).to_bytes(2, "big"))
        assert query(m(), "OP").command_value == bytearray((0x3332).to_bytes(8, "big"))


@pytest.mark.parametrize(("series", "cmd", "param", "status"), [
    (1, "MR", None, ATCommandStatus.INVALID_COMMAND),
    (1, "NP", None, ATCommandStatus.INVALID_COMMAND),
    (2, "RR", None, ATCommandStatus.INVALID_COMMAND),
    (2, "CE", None, ATCommandStatus.INVALID_COMMAND),
    (1, "PL", b"\x05", ATCommandStatus.INVALID_PARAMETER),
    (1, "CH", b"\x0a", ATCommandStatus.INVALID_PARAMETER),
    (1, "SH", b"\x00", ATCommandStatus.INVALID_PARAMETER),
    (1, "NI", b"x" * 21, ATCommandStatus.INVALID_PARAMETER),
    (1, "NI", b"bad\x01", ATCommandStatus.INVALID_PARAMETER),
    (2, "MY", b"\x00\x01", ATCommandStatus.INVALID_PARAMETER),
    (2, "SM", b"\x01", ATCommandStatus.INVALID_PARAMETER),
    (1, "AC", b"\x01", ATCommandStatus.INVALID_PARAMETER),
    (1, "PL", b"\x02", ATCommandStatus.OK),
])
def test_at_errors(series, cmd, param, status):
    assert query(make(series=series), cmd, param).status == status


def test_queued_parameters_apply_on_ac_and_reset_loses_unsaved():
    m = make()
    rig = Rig(m)
    rig.run(20 * MS)
    rig.send(0, ATCommQueuePacket(1, "PL", bytearray([1])).output())
    rig.send(0, ATCommPacket(2, "PL").output())
    rig.run(60 * MS)
    r1, r2 = rig.take(0)[-2:]
    assert r1.status == ATCommandStatus.OK and r2.command_value == bytearray([4])
    assert m.tx_power_dbm() == 0.0
    rig.send(0, ATCommPacket(3, "AC").output())
    rig.run(100 * MS)
    assert m.tx_power_dbm() == -6.0 and rig.nodes[0]["tx_power_dbm"] == -6.0
    rig.take(0)
    rig.send(0, ATCommPacket(4, "FR").output())
    rig.run(300 * MS)
    pk = rig.take(0)
    assert pk[0].status == ATCommandStatus.OK
    assert isinstance(pk[1], ModemStatusPacket) and pk[1].modem_status == ModemStatus.WATCHDOG_TIMER_RESET
    assert m.tx_power_dbm() == 0.0 and m.counters["resets"] == 1  # PL was never written
    rig.send(0, ATCommPacket(5, "PL", bytearray([2])).output() + ATCommPacket(6, "WR").output()
             + ATCommPacket(7, "FR").output())
    rig.run(600 * MS)
    assert m.tx_power_dbm() == -4.0


def test_baud_and_api_mode_changes_take_effect_after_the_answer():
    m = make()
    rig = Rig(m)
    rig.run(20 * MS)
    rig.take(0)
    rig.send(0, ATCommPacket(1, "BD", bytearray([7])).output())
    rig.run(40 * MS)
    assert m.baud == 115200 and rig.take(0)[0].status == ATCommandStatus.OK
    rig.send(0, ATCommPacket(2, "AP", bytearray([2])).output())
    rig.run(60 * MS)
    assert m.api_mode == 2
    (resp,) = packets(bytes(rig.host[0]), 1)  # the answer itself is still API 1
    rig.host[0].clear()
    assert resp.status == ATCommandStatus.OK
    rig.send(0, ATCommPacket(0x11, "NI", op_mode=MODE[2]).output(escaped=True))
    rig.run(63 * MS)  # 115200 baud: the answer takes about 1.3 ms
    out = bytes(rig.host[0])
    assert b"\x7d\x31" in out  # the frame id 0x11 escaped
    (resp,) = packets(out, 2)
    assert resp.frame_id == 0x11 and resp.command_value == bytearray(b"R001")


# -- digi-xbee XBeeDevice.open() against the emulation ----------------------------------------------------------------
class LoopIface(XBeeCommunicationInterface):
    """A digi-xbee communication interface coupled to the module; simulated time moves 10 ms a poll."""

    def __init__(self, module: XBeeModule):
        self.m = module
        self.t = 0
        self.lock = threading.Lock()
        self.pending = bytearray()
        self.buf = bytearray()
        self.frames: deque[bytes] = deque()
        self._open = False

    def open(self):
        self._open = True

    def close(self):
        self._open = False

    @property
    def is_interface_open(self):
        return self._open

    @property
    def timeout(self):
        return 0.01

    @timeout.setter
    def timeout(self, value):
        pass

    def wait_for_frame(self, operating_mode):
        with self.lock:
            if not self.frames:
                self.t += 10 * MS
                self.buf += self.m.step(self.t, bytes(self.pending), []).uart_tx
                self.pending.clear()
                for f in frames(bytes(self.buf), self.m.api_mode):
                    self.frames.append(f)
                self.buf.clear()  # frames are clocked out whole within 10 ms at 115200 baud
            if self.frames:
                return bytearray(self.frames.popleft())
        time.sleep(0.001)
        return None

    def quit_reading(self):
        pass

    def write_frame(self, frame):
        with self.lock:
            self.pending += frame


@pytest.mark.parametrize(("series", "api_mode"), [(1, 1), (1, 2), (2, 1)])
def test_digi_xbee_device_open_identifies_module(series, api_mode):
    # Series 2 (2x7x) has no CE: digi-xbee reads its role from the module's own ZDO (a node descriptor request to
    # itself, answered as 0x91 with AO set to 1 for the while)
    m = make(series=series, node_id="eSwarBot-3", api_mode=api_mode, baud=115200, my16=0x0033)
    iface = LoopIface(m)
    iface.t = 2000 * MS  # opened once the module has joined (its scan takes about 1.5 s)
    m.step(0, b"", [])  # power-up
    m.step(iface.t, b"", [])
    dev = XBeeDevice(comm_iface=iface)
    dev.set_sync_ops_timeout(60)  # each operation returns on its answer: the bound only catches a hang
    dev.open()
    try:
        assert dev.get_protocol() == (XBeeProtocol.RAW_802_15_4 if series == 1 else XBeeProtocol.ZIGBEE)
        assert dev.get_64bit_addr() == XBee64BitAddress.from_hex_string("0013A20040A1B2C3")
        assert dev.get_node_id() == "eSwarBot-3"
        assert dev.get_hardware_version().code == (0x17 if series == 1 else 0x19)
        assert dev.get_firmware_version() == bytearray((0x10EF if series == 1 else 0x23A7).to_bytes(2, "big"))
        if series == 1:
            assert dev.get_16bit_addr() == XBee16BitAddress.from_hex_string("0033")
            assert dev.get_power_level().code == 4
        else:
            assert dev.get_role() == Role.ROUTER
    finally:
        dev.close()


# -- radio: Series 1 --------------------------------------------------------------------------------------------------
def test_series1_unicast_64_end_to_end_with_rssi():
    a, b = make(serial64=A64), make(serial64=B64, seed=2)
    rig = Rig(a, b, rssi=-71)
    rig.run(20 * MS)
    rig.take(0), rig.take(1)
    rig.send(0, TX64Packet(9, XBee64BitAddress(B64.to_bytes(8, "big")), 0, bytearray(b"hello~}")).output())
    rig.run(60 * MS)
    (fr,) = rig.air[0]
    assert fr["dst"] == "64" and fr["dst_addr"] == B64 and fr["ack"] and fr["mac_retries"] == 3
    assert fr["src64"] == A64 and fr["src16"] == 0xFFFE and fr["pan_id"] == 0x3332 and fr["channel"] == 0x0C
    assert fr["psdu_len"] == 2 + 1 + 2 + 8 + 8 + 7 + 2 and 0 <= fr["seq"] <= 255
    (st_pk,) = rig.take(0)
    assert isinstance(st_pk, TXStatusPacket) and st_pk.frame_id == 9 and st_pk.transmit_status == TransmitStatus.SUCCESS
    (rx,) = rig.take(1)
    assert isinstance(rx, RX64Packet) and rx.rf_data == bytearray(b"hello~}") and rx.rssi == 71
    assert rx.x64bit_source_addr == XBee64BitAddress(A64.to_bytes(8, "big")) and rx.receive_options == 0
    assert query(b, "DB", t0=rig.t).command_value == bytearray([71])


def test_series1_16bit_addressing_gives_rx16():
    a, b = make(my16=0x0001), make(serial64=B64, my16=0x0002, seed=2)
    rig = Rig(a, b)
    rig.run(20 * MS)
    rig.take(1)
    rig.send(0, TX16Packet(1, XBee16BitAddress.from_hex_string("0002"), 0, bytearray(b"x")).output())
    rig.send(0, TX16Packet(2, XBee16BitAddress.from_hex_string("FFFF"), 0, bytearray(b"y")).output())
    rig.send(0, TX16Packet(3, XBee16BitAddress.from_hex_string("0003"), 0, bytearray(b"z")).output())
    rig.run(80 * MS)
    rx = rig.take(1)
    assert [type(p) for p in rx] == [RX16Packet, RX16Packet]
    assert [bytes(p.rf_data) for p in rx] == [b"x", b"y"]
    assert rx[0].x16bit_source_addr == XBee16BitAddress.from_hex_string("0001")
    assert rx[1].receive_options == 0x02  # address broadcast
    assert b.counters["rx_filtered"] == 1


def test_series1_filters_pan_and_accepts_pan_broadcast():
    a, b = make(), make(serial64=B64, pan_id=0x1111, seed=2)
    rig = Rig(a, b)
    rig.run(20 * MS)
    rig.take(1)
    rig.send(0, TX64Packet(1, BCAST64, 0, bytearray(b"p")).output())
    rig.send(0, TX64Packet(2, BCAST64, 0x04, bytearray(b"q")).output())
    rig.run(80 * MS)
    (rx,) = rig.take(1)
    assert bytes(rx.rf_data) == b"q" and rx.receive_options == 0x06
    assert rig.air[0][1]["pan_id"] == 0xFFFF and not rig.air[0][0]["ack"]


@pytest.mark.parametrize(("rr", "statuses", "expect", "n_air"), [
    (0, ["no_ack"], TransmitStatus.NO_ACK, 1),
    (0, ["cca_fail"], TransmitStatus.CCA_FAILURE, 1),
    (2, ["no_ack", "no_ack", "no_ack"], TransmitStatus.NO_ACK, 3),
    (2, ["no_ack", "ok"], TransmitStatus.SUCCESS, 2),
])
def test_series1_xbee_retries(rr, statuses, expect, n_air):
    a = make(seed=3)
    rig = Rig(a, fail={0: list(statuses)})
    rig.run(20 * MS)
    rig.send(0, ATCommPacket(1, "RR", bytearray([rr])).output())
    rig.send(0, TX64Packet(5, XBee64BitAddress(B64.to_bytes(8, "big")), 0, bytearray(b"r")).output())
    rig.run(400 * MS)
    st_pk = [p for p in rig.take(0) if isinstance(p, TXStatusPacket)]
    assert [p.transmit_status for p in st_pk] == [expect]
    assert len(rig.air[0]) == n_air and len({f["seq"] for f in rig.air[0]}) == 1
    assert len({f["handle"] for f in rig.air[0]}) == n_air


def test_series1_broadcast_repeats_rr_plus_two_and_receiver_drops_duplicates():
    a, b = make(), make(serial64=B64, seed=2)
    rig = Rig(a, b)
    rig.run(20 * MS)
    rig.take(1)
    rig.send(0, ATCommPacket(0, "RR", bytearray([1])).output())
    rig.send(0, TX64Packet(1, BCAST64, 0, bytearray(b"b")).output())
    rig.run(400 * MS)
    assert len(rig.air[0]) == 3
    assert len(rig.take(1)) == 1 and b.counters["rx_duplicates"] == 2
    (st_pk,) = [p for p in rig.take(0) if isinstance(p, TXStatusPacket)]
    assert st_pk.transmit_status == TransmitStatus.SUCCESS


def test_series1_oversized_payload_is_not_sent():
    a = make()
    rig = Rig(a)
    rig.run(20 * MS)
    rig.take(0)
    rig.send(0, TX64Packet(1, BCAST64, 0, bytearray(101)).output())
    rig.send(0, TX64Packet(2, BCAST64, 0, bytearray(100)).output())
    rig.run(400 * MS)
    assert [len(f["payload"]) for f in rig.air[0]] == [100] and a.counters["tx_too_large"] == 1
    assert [p.frame_id for p in rig.take(0)] == [2]


# -- radio: Series 2 --------------------------------------------------------------------------------------------------
def joined_pair(**kw):
    a, b = make(series=2, my16=0x1A1A, **kw), make(series=2, serial64=B64, my16=0x2B2B, seed=2, **kw)
    rig = Rig(a, b, rssi=-70)
    rig.run(400 * MS, dt=2 * MS)
    assert a.joined and b.joined
    rig.take(0), rig.take(1)
    return a, b, rig


def test_series2_unicast_and_broadcast_end_to_end():
    _, b, rig = joined_pair()  # one hop: the frames on the air
    rig.send(0, TransmitPacket(1, XBee64BitAddress(B64.to_bytes(8, "big")), XBee16BitAddress.from_hex_string("FFFE"),
                               0, 0, rf_data=bytearray(b"uni")).output())
    rig.send(0, TransmitPacket(2, BCAST64, XBee16BitAddress.from_hex_string("FFFE"), 0, 0,
                               rf_data=bytearray(b"all")).output())
    rig.run(rig.t + 100 * MS)
    uni, bc = rig.air[0]
    assert uni["psdu_len"] == 43 + 3 and bc["psdu_len"] == 35 + 3 and uni["ack"] and not bc["ack"]
    assert uni["pan_id"] == bc["pan_id"] == rig.nodes[0]["pan_id"] and uni["src16"] == 0x1A1A
    rx = rig.take(1)
    assert [type(p) for p in rx] == [ReceivePacket, ReceivePacket]
    assert rx[0].rf_data == bytearray(b"uni") and rx[0].receive_options == 0x01
    assert rx[1].receive_options == 0x02 and rx[1].x16bit_source_addr == XBee16BitAddress.from_hex_string("1A1A")
    s1, s2 = rig.take(0)
    assert isinstance(s1, TransmitStatusPacket) and s1.transmit_status == TransmitStatus.SUCCESS
    assert s2.transmit_status == TransmitStatus.SUCCESS
    assert s2.x16bit_dest_addr == XBee16BitAddress.from_hex_string("FFFE")
    assert b.rssi_pwm_duty() == pytest.approx((295 + 17.5 * (-70 + 94)) / 10.24 / 100)
    # b learned a's network address: its answer reports it
    rig.send(1, TransmitPacket(3, XBee64BitAddress(A64.to_bytes(8, "big")), XBee16BitAddress.from_hex_string("FFFE"),
                               0, 0, rf_data=bytearray(b"back")).output())
    rig.run(rig.t + 100 * MS)
    (s3,) = rig.take(1)
    assert s3.x16bit_dest_addr == XBee16BitAddress.from_hex_string("1A1A")


@pytest.mark.parametrize(("dest", "size", "opts", "status"), [
    (B64, 85, 0, TransmitStatus.PAYLOAD_TOO_LARGE),
    (0xFFFF, 93, 0, TransmitStatus.PAYLOAD_TOO_LARGE),
    (0xFFFF, 92, 0, TransmitStatus.SUCCESS),
    (B64, 84, 0, TransmitStatus.SUCCESS),
    (A64, 1, 0, TransmitStatus.SELF_ADDRESSED),
    (B64, 1, 0x20, TransmitStatus.BROADCAST_ERROR_APS_EE0),
])
def test_series2_transmit_statuses(dest, size, opts, status):
    _, _, rig = joined_pair()
    rig.send(0, TransmitPacket(4, XBee64BitAddress(dest.to_bytes(8, "big")), XBee16BitAddress.from_hex_string("FFFE"),
                               0, opts, rf_data=bytearray(size)).output())
    rig.run(rig.t + 100 * MS)
    (pk,) = rig.take(0)
    assert pk.transmit_status == status


def test_series2_not_joined_and_aps_retries():
    m = make(series=2)
    rig = Rig(m, fail={0: ["no_ack"] * 3})
    rig.run(5 * MS)
    rig.send(0, TransmitPacket(1, XBee64BitAddress(B64.to_bytes(8, "big")), XBee16BitAddress.from_hex_string("FFFE"),
                               0, 0, rf_data=bytearray(b"x")).output())
    rig.run(20 * MS)
    (pk,) = rig.take(0)
    assert pk.transmit_status == TransmitStatus.NOT_JOINED_NETWORK
    rig.run(400 * MS, dt=2 * MS)
    rig.take(0)
    t0 = rig.t
    rig.send(0, TransmitPacket(2, XBee64BitAddress(B64.to_bytes(8, "big")), XBee16BitAddress.from_hex_string("FFFE"),
                               0, 0, rf_data=bytearray(b"x")).output())
    rig.run(t0 + 3000 * MS, dt=10 * MS)
    assert rig.take(0) == []  # still retrying after 3 s: 1.6 s per attempt
    rig.run(t0 + 5000 * MS, dt=10 * MS)
    (pk,) = rig.take(0)
    assert pk.transmit_status == TransmitStatus.NETWORK_ACK_FAILURE and pk.transmit_retry_count == 2
    assert pk.x16bit_dest_addr == XBee16BitAddress.from_hex_string("FFFD") and len(rig.air[0]) == 3


def test_series2_network_reset_rejoins():
    m = make(series=2)
    rig = Rig(m)
    rig.run(400 * MS, dt=2 * MS)
    rig.take(0)
    rig.send(0, ATCommPacket(1, "NR", bytearray([0])).output())
    rig.run(rig.t + 20 * MS)
    assert not m.joined
    rig.run(rig.t + 400 * MS, dt=2 * MS)
    pk = rig.take(0)
    assert [p.modem_status for p in pk if isinstance(p, ModemStatusPacket)] == [ModemStatus.DISASSOCIATED,
                                                                                ModemStatus.JOINED_NETWORK]
    assert m.joined
    rig.send(0, ATCommPacket(2, "ID", bytearray((0x99).to_bytes(8, "big"))).output())  # a network nobody formed
    rig.run(rig.t + 1000 * MS, dt=5 * MS)
    assert not m.joined and query(m, "AI", t0=rig.t).command_value == bytearray([0x22])


# -- buffers ----------------------------------------------------------------------------------------------------------
def test_rf_to_serial_buffer_drops_whole_packets_at_low_baud():
    b = make(serial64=B64)
    out = bytearray(b.step(0, b"", []).uart_tx)
    evs = [{"ev": "rx", "t_ns": 10 * MS, "rssi_dbm": -50,
            "frame": {"handle": k, "src64": 0x100 + k, "src16": 0xFFFE, "dst": "bcast", "dst_addr": 0xFFFF,
                      "pan_id": 0x3332, "channel": 0x0C, "ack": False, "mac_retries": 0, "psdu_len": 123,
                      "seq": 1, "payload": bytes(100), "opts": 0}} for k in range(5)]
    out += b.step(10 * MS, b"", evs).uart_tx
    assert b.counters["rx_delivered"] == 1 and b.counters["rx_buffer_drops"] == 4  # 116-byte frames, 202-byte buffer
    last = 10 * MS
    while (w := b.next_wake()) is not None and w < 1000 * MS:  # the RSSI PWM timer runs for 4 s
        chunk = b.step(w, b"", []).uart_tx
        out += chunk
        last = w if chunk else last
    assert len(packets(bytes(out))) == 2  # the reset status and one packet: 115 bytes on the wire
    assert last - 10 * MS == 115 * round(1e10 / 9600)


def test_serial_receive_buffer_overflow_is_silent():
    a = make()
    host = bytearray(a.step(0, b"", []).uart_tx)
    burst = b"".join(TX64Packet(k + 1, XBee64BitAddress(B64.to_bytes(8, "big")), 0, bytearray(60)).output()
                     for k in range(4))  # 75 bytes each, 202-byte buffer: two fit besides nothing in flight
    out = a.step(10 * MS, burst, [])
    host += out.uart_tx
    assert len(out.air_tx) == 1 and a.counters["serial_rx_overflow"] == 2
    h = out.air_tx[0]["handle"]
    out = a.step(20 * MS, b"", [{"ev": "done", "t_ns": 15 * MS, "handle": h, "status": "ok", "attempts": 1}])
    host += out.uart_tx
    h2 = out.air_tx[0]["handle"]
    host += a.step(30 * MS, b"", [{"ev": "done", "t_ns": 25 * MS, "handle": h2, "status": "ok", "attempts": 1}]).uart_tx
    host += a.step(200 * MS, b"", []).uart_tx
    got = packets(bytes(host))
    assert [p.frame_id for p in got if isinstance(p, TXStatusPacket)] == [1, 2]


# -- RSSI PWM ---------------------------------------------------------------------------------------------------------
def test_rssi_pwm_formula_and_hold():
    assert rssi_pwm_formula(-92, -92) == pytest.approx(0.295 / 1.024)
    assert rssi_pwm_formula(-40, -94) == 1.0 and rssi_pwm_formula(-120, -94) == 0.0
    b = make(serial64=B64)
    b.step(0, b"", [])
    ev = {"ev": "rx", "t_ns": 10 * MS, "rssi_dbm": -80,
          "frame": {"handle": 1, "src64": A64, "src16": 0xFFFE, "dst": "64", "dst_addr": B64, "pan_id": 0x3332,
                    "channel": 0x0C, "ack": True, "mac_retries": 3, "psdu_len": 30, "seq": 5, "payload": b"a",
                    "opts": 0}}
    out = b.step(10 * MS, b"", [ev])
    assert out.rssi_pwm == pytest.approx((295 + 17.5 * 12) / 10.24 / 100)
    assert b.next_wake() is not None
    assert b.step(10 * MS + 4000 * MS - 1, b"", []).rssi_pwm is None and b.rssi_pwm_duty() > 0
    out = b.step(10 * MS + 4000 * MS, b"", [])
    assert out.rssi_pwm == 0.0 and b.rssi_pwm_duty() == 0.0


# -- malformed input --------------------------------------------------------------------------------------------------
def test_malformed_input_is_counted_and_silent():
    m = make()
    m.step(0, b"", [])
    m.step(10 * MS, b"", [])
    good = ATCommPacket(1, "VR").output()
    bad_cs = good[:-1] + bytes([good[-1] ^ 1])
    unknown = encode_frame(b"\x42\x01abc", 1)
    stream = b"junk" + bad_cs + unknown + b"\x7e\x00\x00" + b"\x7e\xff\xff" + encode_frame(b"\x08\x01V", 1)
    out = m.step(20 * MS, stream, ["not a dict", {"ev": "rx"}, {"ev": "done", "handle": "x", "status": "ok"}])
    out = m.step(200 * MS, b"", [])
    assert out.uart_tx == b""
    c = m.counters
    assert (c["checksum_errors"], c["unknown_frame_type"], c["zero_length_frames"], c["oversize_frames"],
            c["malformed_frames"]) == (1, 1, 1, 1, 1)
    assert c["bad_air_events"] == 2 and c["rx_malformed"] == 1
    m2 = make(api_mode=2)
    m2.step(0, b"", [])
    esc_end = b"\x7e\x00\x04\x08\x01\x56\x7d"
    m2.step(1 * MS, esc_end, [])
    assert m2.parser_busy()
    m2.step(2 * MS, b"\x7e" + good[1:4], [])  # escape followed by a delimiter, then a cut-off frame
    m2.step(3 * MS, good, [])
    assert m2.counters["escape_errors"] == 1 and m2.counters["truncated_frames"] == 1
    assert m2.counters["frames_ok"] == 1


def test_escaped_mode_accepts_digi_frames_and_escapes_output():
    a, b = make(api_mode=2), make(serial64=B64, api_mode=2, seed=2)
    rig = Rig(a, b)
    rig.run(20 * MS)
    rig.take(1)
    payload = bytearray(b"\x7e\x7d\x11\x13plain")
    rig.send(0, TX64Packet(0x7E, XBee64BitAddress(B64.to_bytes(8, "big")), 0, payload,
                           op_mode=MODE[2]).output(escaped=True))
    rig.run(80 * MS)
    (rx,) = rig.take(1)
    assert rx.rf_data == payload
    (st_pk,) = rig.take(0)[-1:]
    assert st_pk.frame_id == 0x7E


def test_deterministic_per_seed():
    def trace(seed):
        a, b = make(series=2, seed=seed), make(series=2, serial64=B64, seed=seed + 1)
        rig = Rig(a, b, fail={0: ["no_ack", "ok"]})
        rig.run(400 * MS, dt=2 * MS)
        rig.send(0, TransmitPacket(1, BCAST64, XBee16BitAddress.from_hex_string("FFFE"), 0, 0,
                                   rf_data=bytearray(b"d")).output())
        rig.run(2500 * MS, dt=5 * MS)
        return bytes(rig.host[0]), bytes(rig.host[1]), [f["seq"] for f in rig.air[0]], a.addr16(), b.addr16()

    assert trace(5) == trace(5)
    assert trace(5) != trace(6)


# -- fuzzing ----------------------------------------------------------------------------------------------------------
def _check_counters(m: XBeeModule) -> None:
    c = m.counters
    assert set(c) == set(COUNTER_KEYS) and all(v >= 0 for v in c.values())
    ended = sum(c[k] for k in ("frames_ok", "checksum_errors", "oversize_frames", "zero_length_frames",
                               "truncated_frames", "escape_errors"))
    assert c["frames_started"] == ended + (1 if m.parser_busy() else 0)
    assert c["frames_ok"] == sum(c[k] for k in ("frames_handled", "unknown_frame_type", "malformed_frames",
                                                "serial_rx_overflow"))


_valid = st.sampled_from([
    ATCommPacket(1, "NI").output(), ATCommPacket(2, "PL", bytearray([3])).output(), ATCommPacket(0, "FR").output(),
    ATCommQueuePacket(3, "RP", bytearray([1])).output(), ATCommPacket(4, "BD", bytearray([7])).output(),
    TX64Packet(5, BCAST64, 0, bytearray(b"\x7e\x7d")).output(),
    TX16Packet(6, XBee16BitAddress.from_hex_string("0002"), 1, bytearray(3)).output(),
    TransmitPacket(7, BCAST64, XBee16BitAddress.from_hex_string("FFFE"), 0, 0, rf_data=bytearray(8)).output(),
    ATCommPacket(8, "AP", bytearray([2])).output(),
])
_chunk = st.one_of(st.binary(max_size=40), _valid,
                   _valid.flatmap(lambda f: st.integers(0, len(f) - 1).map(lambda i: f[:i] + bytes([f[i] ^ 0x5A])
                                                                             + f[i + 1:])))


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(series=st.sampled_from([1, 2]), api_mode=st.sampled_from([1, 2]),
       chunks=st.lists(st.tuples(st.integers(0, 30 * MS), _chunk), max_size=25))
def test_fuzz_parser_never_raises_and_counters_add_up(series, api_mode, chunks):
    m = make(series=series, api_mode=api_mode)
    t = 0
    m.step(t, b"", [])
    for dt, data in chunks:
        t += dt
        out = m.step(t, data, [])
        assert isinstance(out.uart_tx, bytes)
        for fr in out.air_tx:
            m.step(t, b"", [{"ev": "done", "t_ns": t, "handle": fr["handle"], "status": "ok", "attempts": 1}])
        _check_counters(m)
    while (w := m.next_wake()) is not None and w < t + 10_000 * MS:
        t = w
        m.step(t, b"", [])
    _check_counters(m)


_air_value = st.one_of(st.none(), st.booleans(), st.integers(-5, 1 << 65), st.binary(max_size=120),
                       st.sampled_from(["bcast", "64", "16", "rx", "done", "ok", "no_ack"]))


@settings(max_examples=300, deadline=None)
@given(series=st.sampled_from([1, 2]),
       events=st.lists(st.dictionaries(st.sampled_from(["ev", "t_ns", "frame", "rssi_dbm", "handle", "status"]),
                                       _air_value, max_size=6), max_size=10))
def test_fuzz_air_events_never_raise(series, events):
    m = make(series=series)
    m.step(0, b"", [])
    m.step(500 * MS, b"", events)
    frame = {"handle": 1, "src64": B64, "src16": 0xFFFE, "dst": "bcast", "dst_addr": 0xFFFF, "pan_id": 0x3332,
             "channel": 0x0C, "ack": False, "mac_retries": 0, "psdu_len": 20, "seq": 1, "payload": b"z", "opts": 0}
    m.step(600 * MS, b"", [{"ev": "rx", "t_ns": 550 * MS, "frame": frame | e, "rssi_dbm": -60}
                           for e in events if all(isinstance(k, str) for k in e)])
    _check_counters(m)
