"""Series 2 beyond data, frame by frame: the AT commands a 2x7x router answers and refuses, node discovery (ND,
DN, NO, NT), remote AT commands and their failures, the ZDO server (answers, NOT_SUPPORTED, AO 0/1/3)."""

from __future__ import annotations

import pytest
from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress
from digi.xbee.models.status import ATCommandStatus
from digi.xbee.packets.common import (
    ATCommPacket,
    ATCommResponsePacket,
    ExplicitAddressingPacket,
    ExplicitRXIndicatorPacket,
    RemoteATCommandPacket,
    RemoteATCommandResponsePacket,
)

from firmware_sim.modules import zigbee as zb
from firmware_sim.modules.xbee import MS
from tests.firmware.test_xbee_module import A64, B64, C64, Rig, joined_pair, make, query

FFFE = XBee16BitAddress.from_hex_string("FFFE")


def addr(a: int) -> XBee64BitAddress:
    return XBee64BitAddress(a.to_bytes(8, "big"))


def trio(**kw) -> Rig:
    mods = [make(series=2, serial64=a, node_id=n, seed=s, my16=m, baud=115200, **kw)
            for a, n, s, m in ((A64, "alpha", 1, 0x1A1A), (B64, "bravo", 2, 0x2B2B), (C64, "charlie", 3, 0x3C3C))]
    rig = Rig(*mods, rssi=-70)
    rig.run(400 * MS, dt=2 * MS)
    for i in range(3):
        rig.take(i)
    return rig


def at(rig: Rig, i: int, cmd: str, param: bytes | None = None, fid: int = 9) -> None:
    rig.send(i, ATCommPacket(fid, cmd, bytearray(param) if param is not None else None).output())


@pytest.mark.parametrize(("cmd", "param", "status"), [
    ("AO", b"\x02", ATCommandStatus.INVALID_PARAMETER),  # 0, 1 and 3 only
    ("AO", b"\x03", ATCommandStatus.OK),
    ("EE", b"\x01", ATCommandStatus.INVALID_PARAMETER),  # encryption is not modelled: refused as the module refuses
    ("NT", b"\x1f", ATCommandStatus.INVALID_PARAMETER),  # 0x20..0xFF
    ("NO", b"\x04", ATCommandStatus.INVALID_PARAMETER),  # no RSSI bit on 2x7x
    ("CE", None, ATCommandStatus.INVALID_COMMAND),  # the role is the firmware's
    ("TP", None, ATCommandStatus.INVALID_COMMAND),  # the PRO (S2B) only
    ("N?", None, ATCommandStatus.INVALID_COMMAND),
    ("MP", None, ATCommandStatus.INVALID_COMMAND),  # end devices only
])
def test_a_2x7x_router_answers_and_refuses_as_the_manual_says(cmd, param, status) -> None:
    assert query(make(series=2), cmd, param).status == status


def test_supply_voltage_dd_and_discovery_defaults() -> None:
    def ask(cmd: str) -> bytes:
        return bytes(query(make(series=2), cmd).command_value)

    assert int.from_bytes(ask("%V"), "big") * 1200 / 1024 == pytest.approx(3300, abs=2)
    assert ask("DD") == bytes((0, 3, 0, 0)) and ask("NT") == b"\x3c" and ask("NO") == ask("BH") == b"\x00"


@pytest.mark.parametrize("routing", ["one_hop", "mesh"])
def test_nd_collects_every_answer_within_nt_and_the_local_record_first_with_no_2(routing: str) -> None:
    rig = trio(routing=routing)
    at(rig, 0, "NT", b"\x20")
    at(rig, 0, "NO", b"\x03")  # local record first, DD appended (to the local record: NO is each module's own)
    rig.run(rig.t + 50 * MS)
    rig.take(0)
    t0 = rig.t
    at(rig, 0, "ND")
    rig.run(t0 + 3300 * MS, dt=5 * MS)
    nd = [p for p in rig.take(0) if isinstance(p, ATCommResponsePacket)]
    names = [bytes(p.command_value[10:]).split(b"\x00")[0] for p in nd]
    assert names[0] == b"alpha" and sorted(names[1:]) == [b"bravo", b"charlie"]
    assert all(p.command == "ND" and p.status == ATCommandStatus.OK for p in nd)
    local = bytes(nd[0].command_value)
    assert local[:2] == b"\x1a\x1a" and local[2:10] == A64.to_bytes(8, "big") and local[-4:] == b"\x00\x03\x00\x00"
    rec = bytes(nd[1].command_value)  # MY SH SL NI 00 parent type status profile manufacturer
    assert rec[-8:] == bytes.fromhex("FFFE0100C105101E")
    # every answer came within NT (3.2 s): nothing more after the window
    rig.run(rig.t + 3000 * MS, dt=10 * MS)
    assert rig.take(0) == []


@pytest.mark.parametrize("routing", ["one_hop", "mesh"])
def test_nd_of_one_name_and_dn(routing: str) -> None:
    rig = trio(routing=routing)
    at(rig, 0, "NT", b"\x20")
    rig.run(rig.t + 50 * MS)
    rig.take(0)
    at(rig, 0, "ND", b"charlie")
    rig.run(rig.t + 3300 * MS, dt=5 * MS)
    (p,) = rig.take(0)
    assert bytes(p.command_value[2:10]) == C64.to_bytes(8, "big")
    at(rig, 0, "ND", b"nobody")  # no match: ERROR once NT is over
    rig.run(rig.t + 3300 * MS, dt=5 * MS)
    (p,) = rig.take(0)
    assert p.command == "ND" and p.status == ATCommandStatus.ERROR
    at(rig, 0, "DN", b"bravo")  # the 16- and 64-bit addresses of bravo
    rig.run(rig.t + 3300 * MS, dt=5 * MS)
    (p,) = rig.take(0)
    assert p.command == "DN" and p.status == ATCommandStatus.OK
    assert bytes(p.command_value) == b"\x2b\x2b" + B64.to_bytes(8, "big")
    at(rig, 0, "DN", b"nobody")
    rig.run(rig.t + 3300 * MS, dt=5 * MS)
    (p,) = rig.take(0)
    assert p.status == ATCommandStatus.ERROR
    at(rig, 0, "DN")  # no name: ERROR at once
    rig.run(rig.t + 20 * MS)
    (p,) = rig.take(0)
    assert p.status == ATCommandStatus.ERROR


@pytest.mark.parametrize("routing", ["one_hop", "mesh"])
def test_remote_at_applies_or_queues_and_fails_with_status_4(routing: str) -> None:
    a, b, rig = joined_pair(baud=115200, routing=routing)
    rig.send(0, RemoteATCommandPacket(5, addr(B64), FFFE, 0x00, "NI", bytearray(b"queued")).output())
    rig.run(rig.t + 50 * MS)
    (p,) = rig.take(0)
    assert isinstance(p, RemoteATCommandResponsePacket) and p.status == ATCommandStatus.OK
    assert p.x64bit_source_addr == addr(B64) and p.x16bit_source_addr == XBee16BitAddress.from_hex_string("2B2B")
    assert b.node()["addr16"] == 0x2B2B and bytes(b._set["NI"]) == b"R001"  # queued: not applied (no option 2)
    rig.send(0, RemoteATCommandPacket(6, addr(B64), FFFE, 0x02, "AC").output())
    rig.run(rig.t + 50 * MS)
    rig.take(0)
    assert bytes(b._set["NI"]) == b"queued"
    # a node nobody has: one hop, nobody acknowledges its three attempts (1.6 s each); mesh, its address is not
    # found (5 s of address discovery); then status 4
    t0 = rig.t
    if routing == "one_hop":
        rig.fail[0] = ["no_ack"] * 3
    rig.send(0, RemoteATCommandPacket(7, addr(0x0013A200DEADBEEF), FFFE, 0x02, "NI").output())
    rig.run(t0 + (3000 if routing == "one_hop" else 4700) * MS, dt=10 * MS)
    assert rig.take(0) == []
    rig.run(t0 + 5100 * MS, dt=10 * MS)
    (p,) = rig.take(0)
    assert p.status == ATCommandStatus.TX_FAILURE and p.x16bit_source_addr == FFFE
    # to itself: status 4 at once
    rig.send(0, RemoteATCommandPacket(8, addr(A64), FFFE, 0x02, "NI").output())
    rig.run(rig.t + 20 * MS)
    (p,) = rig.take(0)
    assert p.status == ATCommandStatus.TX_FAILURE
    assert a.counters["remote_at_timeouts"] == 0 and b.counters["remote_at_served"] == 2


@pytest.mark.parametrize("routing", ["one_hop", "mesh"])
def test_a_broadcast_remote_at_is_answered_by_every_node(routing: str) -> None:
    rig = trio(routing=routing)
    rig.send(0, RemoteATCommandPacket(3, addr(0xFFFF), FFFE, 0x00, "NI").output())
    rig.run(rig.t + 100 * MS)
    names = sorted(bytes(p.command_value) for p in rig.take(0) if isinstance(p, RemoteATCommandResponsePacket))
    assert names == [b"bravo", b"charlie"]


def zdo(rig: Rig, i: int, dest: int, dest16: int, cluster: int, payload: bytes, fid: int = 0x21) -> None:
    rig.send(i, ExplicitAddressingPacket(fid, addr(dest), XBee16BitAddress(dest16.to_bytes(2, "big")), 0, 0,
                                         cluster, 0, 0, 0, bytearray(payload)).output())


@pytest.mark.parametrize("routing", ["one_hop", "mesh"])
def test_the_zdo_server_answers_and_ao_decides_what_the_host_sees(routing: str) -> None:
    a, b, rig = joined_pair(baud=115200, routing=routing)
    at(rig, 0, "AO", b"\x01")
    rig.run(rig.t + 50 * MS)
    rig.take(0)
    zdo(rig, 0, B64, 0x2B2B, zb.NODE_DESC_REQ, b"\x21\x2b\x2b")
    zdo(rig, 0, B64, 0x2B2B, 0x0038, b"\x22\x00")  # Mgmt_NWK_Update: not served
    zdo(rig, 0, B64, 0x2B2B, zb.MGMT_LQI_REQ, b"\x23\x00")
    rig.run(rig.t + 100 * MS)
    rsp = {p.cluster_id: bytes(p.rf_data) for p in rig.take(0) if isinstance(p, ExplicitRXIndicatorPacket)}
    assert rsp[0x8002] == bytes.fromhex("2100") + b"\x2b\x2b" + bytes.fromhex("01408E1E1052FF000000FF0000")
    assert rsp[0x8038] == bytes((0x22, zb.ZDP_NOT_SUPPORTED))
    lqi = rsp[0x8031]
    assert lqi[:5] == bytes((0x23, 0, 1, 0, 1)) and lqi[13:21] == A64.to_bytes(8, "little")  # b has heard a
    # AO 0: the answers are not shown
    at(rig, 0, "AO", b"\x00")
    rig.run(rig.t + 50 * MS)
    rig.take(0)
    zdo(rig, 0, B64, 0x2B2B, zb.NODE_DESC_REQ, b"\x24\x2b\x2b")
    rig.run(rig.t + 100 * MS)
    assert not [p for p in rig.take(0) if isinstance(p, ExplicitRXIndicatorPacket)]
    # AO 3 on b: Active_EP goes to b's host, which must answer it; b's stack does not
    at(rig, 1, "AO", b"\x03")
    rig.run(rig.t + 50 * MS)
    rig.take(1)
    served = b.counters["zdo_answered"]
    zdo(rig, 0, B64, 0x2B2B, zb.ACTIVE_EP_REQ, b"\x25\x2b\x2b")
    rig.run(rig.t + 100 * MS)
    (p,) = [p for p in rig.take(1) if isinstance(p, ExplicitRXIndicatorPacket)]
    assert p.cluster_id == zb.ACTIVE_EP_REQ and b.counters["zdo_answered"] == served
    assert a.counters["ddo_malformed"] == b.counters["ddo_malformed"] == 0


def test_a_zdo_request_to_itself_is_self_addressed_and_answered_locally() -> None:
    _, _, rig = joined_pair(baud=115200)
    at(rig, 0, "AO", b"\x01")
    rig.run(rig.t + 50 * MS)
    rig.take(0)
    zdo(rig, 0, A64, 0x1A1A, zb.NODE_DESC_REQ, b"\x30\x1a\x1a", fid=0x30)
    rig.run(rig.t + 50 * MS)
    status, answer = rig.take(0)
    assert status.frame_id == 0x30 and status.transmit_status.code == 0x23
    assert answer.x64bit_source_addr == addr(A64) and bytes(answer.rf_data)[:4] == b"\x30\x00\x1a\x1a"
    assert not rig.air[0]  # nothing went on the air
