"""ZigBee mesh routing inside Series 2 modules: a unicast beyond one hop finds its destination's address and a
route, goes hop by hop and is acknowledged end to end; the transmit status says what that cost; a broken link
re-routes through another router, or fails as the real module fails; broadcasts are relayed with the broadcast
transmission table's limits. Modules on an ideal medium (``tests.support.xbee_loop.World``) where only the given
pairs hear each other."""

from __future__ import annotations

import numpy as np
from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress
from digi.xbee.models.status import TransmitStatus
from digi.xbee.packets.common import ReceivePacket, TransmitPacket, TransmitStatusPacket
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_sim.modules.xbee import XBeeModule
from tests.firmware.test_xbee_module import packets
from tests.support.xbee_loop import NS, World

BASE = 0x0013A20040A1B200
MS = 1_000_000
FFFE = XBee16BitAddress.from_hex_string("FFFE")


def mesh(n: int, links: set[frozenset[int]], seed: int = 1) -> tuple[World, list[XBeeModule]]:
    """``n`` routers; ``links``: the pairs that hear each other (at -75 dBm), a mutable set."""
    mods = [XBeeModule(series=2, serial64=BASE + i, node_id=f"n{i}", rng=np.random.default_rng(seed * 100 + i),
                       baud=115200, my16=0x0100 + i, routing="mesh") for i in range(n)]
    world = World(mods, baud=115200, link=lambda i, j: -75 if frozenset((i, j)) in links else None, limit_s=1e6)
    world.run_until(2 * NS)
    for p in world.ports:
        p.rx.clear()
    return world, mods


def line(n: int) -> set[frozenset[int]]:
    return {frozenset((i, i + 1)) for i in range(n - 1)}  # 8 m apart: each hears only the next


def send(world: World, i: int, dest: int, data: bytes, fid: int = 1, bcast: bool = False) -> None:
    dest64 = XBee64BitAddress.BROADCAST_ADDRESS if bcast else XBee64BitAddress((BASE + dest).to_bytes(8, "big"))
    world.ports[i].write(TransmitPacket(fid, dest64, FFFE, 0, 0, rf_data=bytearray(data)).output())


def whole_frames(rx: bytearray) -> bytes:
    """Take the complete API frames that arrived (a frame still being clocked out stays)."""
    n = 0
    while len(rx) >= n + 3 and len(rx) >= n + int.from_bytes(rx[n + 1:n + 3], "big") + 4:
        n += int.from_bytes(rx[n + 1:n + 3], "big") + 4
    out = bytes(rx[:n])
    del rx[:n]
    return out


def status_of(world: World, i: int, fid: int, within_s: float = 30) -> TransmitStatusPacket:
    """Run until module ``i`` answers ``fid`` with its transmit status (simulated time, bounded)."""
    end = world.t_ns + round(within_s * NS)
    backlog = world.__dict__.setdefault("statuses", {})  # what came in before it was asked for, per frame id
    while world.t_ns < end:
        if (i, fid) in backlog:
            return backlog.pop((i, fid))
        world.run_until(world.t_ns + 10 * MS)
        for p in packets(whole_frames(world.ports[i].rx)):
            if isinstance(p, TransmitStatusPacket):
                backlog[(i, p.frame_id)] = p
    raise AssertionError(f"no transmit status for frame {fid} within {within_s} s")


def received(world: World, j: int) -> list[ReceivePacket]:
    return [p for p in packets(whole_frames(world.ports[j].rx)) if isinstance(p, ReceivePacket)]


def test_a_unicast_crosses_a_line_of_six_and_the_status_says_what_it_cost() -> None:
    world, mods = mesh(6, line(6))
    send(world, 0, 5, b"end to end", fid=1)
    st = status_of(world, 0, 1)
    assert st.transmit_status == TransmitStatus.SUCCESS
    # its address was found (NWK_addr_req); the answer's own route discovery made the route both ways (0x01), or a
    # route discovery of its own followed (0x03)
    assert st.discovery_status.code in (0x01, 0x03)
    assert st.x16bit_dest_addr == XBee16BitAddress.from_hex_string("0105") and st.transmit_retry_count == 0
    (rx,) = received(world, 5)
    assert bytes(rx.rf_data) == b"end to end" and rx.x64bit_source_addr.address == bytearray((BASE).to_bytes(8, "big"))
    assert rx.x16bit_source_addr == XBee16BitAddress.from_hex_string("0100")
    assert [m.nwk.stats["relayed"] > 0 for m in mods[1:5]] == [True] * 4  # each middle router relayed
    # the destination counts the hops its host's data took (five), and nothing for the acknowledgements or the ZDO
    assert (mods[5].nwk.stats["data_delivered"], mods[5].nwk.stats["data_hops"]) == (1, 5)
    assert mods[0].nwk.stats["data_delivered"] == 0 and mods[0].counters["nwk_data_hops"] == 0
    # known now: no discovery the second time
    send(world, 0, 5, b"again", fid=2)
    st = status_of(world, 0, 2)
    assert st.transmit_status == TransmitStatus.SUCCESS and st.discovery_status.code == 0x00
    assert [bytes(p.rf_data) for p in received(world, 5)] == [b"again"]
    # and back: node 5 learned its way to node 0 from the route discovery
    send(world, 5, 0, b"reply", fid=3)
    assert status_of(world, 5, 3).discovery_status.code == 0x00


def test_a_broken_link_reroutes_through_another_router() -> None:
    links = line(6) | {frozenset((2, 6)), frozenset((6, 3))}  # node 6 bridges 2 and 3 too
    world, mods = mesh(7, links)
    send(world, 0, 5, b"first", fid=1)
    assert status_of(world, 0, 1).transmit_status == TransmitStatus.SUCCESS
    received(world, 5)
    assert mods[5].nwk.stats["data_hops"] == 5
    links.discard(frozenset((2, 3)))  # the direct link between 2 and 3 breaks
    send(world, 0, 5, b"around", fid=2)
    st = status_of(world, 0, 2)
    assert st.transmit_status == TransmitStatus.SUCCESS
    assert st.transmit_retry_count >= 1 and st.discovery_status.code & 0x02  # a retry, after a new route discovery
    assert [bytes(p.rf_data) for p in received(world, 5)] == [b"around"]
    assert mods[5].nwk.stats["data_delivered"] == 2 and mods[5].nwk.stats["data_hops"] == 5 + 6  # round by 6


def test_a_broken_line_fails_with_a_network_ack_failure_or_no_route() -> None:
    links = line(6)
    world, _ = mesh(6, links)
    send(world, 0, 5, b"first", fid=1)
    assert status_of(world, 0, 1).transmit_status == TransmitStatus.SUCCESS
    received(world, 5)
    links.discard(frozenset((2, 3)))
    send(world, 0, 5, b"lost", fid=2)
    st = status_of(world, 0, 2)
    assert st.transmit_status in (TransmitStatus.NETWORK_ACK_FAILURE, TransmitStatus.ROUTE_NOT_FOUND)
    assert st.x16bit_dest_addr == XBee16BitAddress.from_hex_string("FFFD")
    assert received(world, 5) == []


def test_a_broadcast_reaches_the_whole_line_once_each() -> None:
    world, mods = mesh(6, line(6))
    send(world, 0, 0, b"to all", fid=4, bcast=True)
    assert status_of(world, 0, 4).transmit_status == TransmitStatus.SUCCESS
    world.run_until(world.t_ns + 3 * NS)
    for j in range(1, 6):
        assert [bytes(p.rf_data) for p in received(world, j)] == [b"to all"], j
    sent = [f for _, i, f in world.air_log if f.get("nwk", [None])[0] == 0 and f["dst"] == "bcast"]
    # every router relays (at most three times: fewer when it heard all its neighbours relay)
    assert 6 <= len(sent) <= 18 and sum(m.nwk.stats["bcast_relayed"] for m in mods) == 5


def test_a_full_broadcast_table_refuses_the_host_s_broadcast() -> None:
    world, _ = mesh(2, line(2))
    for k in range(8):
        send(world, 0, 0, bytes((k,)), fid=10 + k, bcast=True)
    for k in range(8):
        assert status_of(world, 0, 10 + k).transmit_status == TransmitStatus.SUCCESS
    send(world, 0, 0, b"ninth", fid=20, bcast=True)  # within 8 s of the first: the table is full
    assert status_of(world, 0, 20).transmit_status.code == 0x32
    world.run_until(world.t_ns + 9 * NS)
    send(world, 0, 0, b"later", fid=21, bcast=True)
    assert status_of(world, 0, 21).transmit_status == TransmitStatus.SUCCESS


def test_the_same_seed_gives_the_same_air() -> None:
    logs = []
    for _ in range(2):
        world, _ = mesh(6, line(6), seed=3)
        send(world, 0, 5, b"x", fid=1)
        status_of(world, 0, 1)
        logs.append([(t, i, f["psdu_len"], f["dst"], f["dst_addr"]) for t, i, f in world.air_log])
    assert logs[0] == logs[1] and len(logs[0]) > 10


_nwk = st.tuples(st.sampled_from([0, 1, 2, 3]), st.sampled_from([0x0100, 0x0101, 0x0105, 0xFFFC, 0xFFFF, 7]),
                 st.sampled_from([0x0100, 0x0101, 0x0102, 0xFFFF, 0xFFFD, 9]), st.integers(0, 255),
                 st.integers(0, 255), st.sampled_from([BASE, BASE + 1, BASE + 5, 0]), st.integers(0, 255),
                 st.integers(0, 3)).map(list)


@settings(max_examples=200, deadline=None)
@given(frames=st.lists(st.tuples(_nwk, st.binary(max_size=40), st.sampled_from(["bcast", "16"]),
                                 st.sampled_from([(0, 0, 0, 0), (0, 0x8000, 0, 0), (0xC105, 0x11, 0xE8, 0xE8),
                                                  (0xC105, 0x95, 0xE6, 0xE6), (0xC105, 0x21, 0xE6, 0xE6)]),
                                 st.integers(-100, -30), st.sampled_from(["ok", "no_ack", "cca_fail"])),
                       max_size=25))
def test_whatever_the_air_brings_the_network_layer_never_raises(frames) -> None:
    """Routing frames, relays, acknowledgements and statuses in any order and any shape the header check lets through:
    counted and handled, never an exception; its own frames' outcomes (any status) too."""
    m = XBeeModule(series=2, serial64=BASE, node_id="n0", rng=np.random.default_rng(1), my16=0x0100, routing="mesh")
    m.step(0, b"", [])
    t = 2 * NS
    m.step(t, b"", [])
    for k, (nwk, payload, dst, aps, rssi, status) in enumerate(frames):
        t += 7 * MS
        fr = {"handle": k + 1, "src64": BASE + 1 + k % 3, "src16": 0x0101 + k % 3, "dst": dst,
              "dst_addr": 0xFFFF if dst == "bcast" else 0x0100, "pan_id": m.node()["pan_id"], "channel": 0x0C,
              "ack": dst != "bcast", "mac_retries": 3, "psdu_len": 40, "seq": k, "payload": payload, "opts": 0,
              "aps": list(aps), "nwk": nwk}
        out = m.step(t, b"", [{"ev": "rx", "t_ns": t, "frame": fr, "rssi_dbm": rssi}])
        done = [{"ev": "done", "t_ns": t + MS, "handle": f["handle"], "status": status, "attempts": 1}
                for f in out.air_tx]
        m.step(t + MS, b"", done)
    for _ in range(200):  # its timers (route discoveries, held frames, broadcasts) run out
        w = m.next_wake()
        if w is None:
            break
        t = max(t, w)
        out = m.step(t, b"", [])
        m.step(t, b"", [{"ev": "done", "t_ns": t, "handle": f["handle"], "status": "no_ack", "attempts": 4}
                        for f in out.air_tx])
    assert m.counters["bad_air_events"] == 0 and m.counters["rx_malformed"] == 0


def test_a_radius_1_broadcast_from_the_driver_reaches_the_neighbours_and_nobody_relays_it() -> None:
    """The driver's ``send_nowait(None, data, radius=1)``: a hello for the neighbours only, as a swarm's local
    broadcast should be under mesh routing (radius 0 is the module's BH: the whole network)."""
    from swarm_logic.drivers.xbee import XBee

    world, mods = mesh(3, line(3))
    drv = XBee(world.ports[0], world.clock, api_mode=1)
    drv.send_nowait(None, b"local", radius=1)
    drv.send_nowait(None, b"far", radius=0)
    world.run_until(world.t_ns + 3 * NS)
    assert [bytes(p.rf_data) for p in received(world, 1)] == [b"local", b"far"]
    assert [bytes(p.rf_data) for p in received(world, 2)] == [b"far"]  # relayed by 1: radius 0 is the maximum
    assert mods[1].counters["nwk_bcast_relayed"] == 1
