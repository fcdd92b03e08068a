"""UWB ranging: module TLV framing and TDMA budget, medium statistics, host driver, range filter.

``python tests/media/test_uwb.py`` prints the filtered-vs-raw RMS figures quoted in docs/uwb.md.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import struct
from collections import Counter
from typing import Any

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bridge.core.rng import stream
from bridge.media.uwb import UwbCfg, UwbMedium
from firmware_sim.modules.uwb import UwbModule, qf_from_gap, tdma_budget, tlv
from swarm_logic.drivers.ranging import RangeTracker
from swarm_logic.drivers.uwb import Uwb, UwbError, UwbProtocolError, UwbTimeout, decode_loc, parse_tlvs

Q_NS = 10_000_000  # the session quantum
BYTE_NS = 10 * 1_000_000_000 // 115200


class Geo:
    """Geometry stand-in: fixed or time-varying positions, walls from a function, all alive unless told."""

    def __init__(self, pos: Any, walls: Any = None, alive: Any = None) -> None:
        self.pos = np.asarray(pos, dtype=float)
        self.wall_fn = walls or (lambda s, d: 0)
        self.alive_mask = np.ones(len(self.pos), bool) if alive is None else np.asarray(alive, bool)

    def positions(self) -> np.ndarray:
        return self.pos

    def walls(self, src: int, dsts: np.ndarray) -> np.ndarray:
        return np.array([self.wall_fn(src, int(d)) for d in dsts], dtype=int)

    def alive(self) -> np.ndarray:
        return self.alive_mask


def ring(n: int, radius: float = 5.0) -> np.ndarray:
    a = np.arange(n) * 2 * math.pi / max(n, 1)
    return np.c_[radius * np.cos(a) + 10, radius * np.sin(a) + 10]


class Swarm:
    """What the world and firmware hosts do for UWB: step modules each quantum, route requests to the medium."""

    def __init__(self, n: int, cfg: UwbCfg | None = None, seed: int = 7, geo: Geo | None = None) -> None:
        self.cfg = cfg or UwbCfg()
        self.n = n
        self.geo = geo or Geo(ring(n))
        self.modules = [UwbModule(addr16=0x1000 + i, robot=i, peers=[(j, 0x1000 + j) for j in range(n)], slot=i,
                                  n_slots=n, rng=stream(seed, "uwb-fw", i), cfg=self.cfg) for i in range(n)]
        self.medium = UwbMedium(self.cfg, n, seed, self.geo)
        self.inbox: list[list[tuple[int, dict]]] = [[] for _ in range(n)]
        self.uart_in = [bytearray() for _ in range(n)]
        self.uart_out = [bytearray() for _ in range(n)]
        self.requests: list[tuple[int, int, int]] = []
        self.events: list[tuple[int, int, dict]] = []
        self.now_ns = -Q_NS
        self.step()

    def step(self) -> None:
        self.now_ns += Q_NS
        t = self.now_ns
        reqs = []
        for i, m in enumerate(self.modules):
            due = [ev for te, ev in self.inbox[i] if te <= t]
            self.inbox[i] = [(te, ev) for te, ev in self.inbox[i] if te > t]
            out = m.step(t, bytes(self.uart_in[i]), due)
            self.uart_in[i].clear()
            self.uart_out[i] += out.uart_tx
            for r in out.requests:
                assert r["op"] == "range" and r["t_ns"] <= t
                reqs.append((r["t_ns"], i, r["peer"]))
        for tr, i, j in sorted(reqs):
            self.requests.append((tr, i, j))
            for td, rob, ev in self.medium.exchange(tr, i, j):
                self.inbox[rob].append((td, ev))
                self.events.append((td, rob, ev))

    def run_until(self, t_ns: int) -> None:
        while self.now_ns + Q_NS <= t_ns:
            self.step()


class SwarmClock:
    def __init__(self, swarm: Swarm) -> None:
        self.swarm = swarm

    def now(self) -> float:
        return self.swarm.now_ns / 1e9

    def sleep(self, dt: float) -> None:
        self.sleep_until(self.now() + dt)

    def sleep_until(self, t: float) -> None:
        while self.now() + Q_NS / 1e9 <= t + 1e-12:
            self.swarm.step()


class SwarmPort:
    """A pyserial-like port on robot ``r``'s module UART; blocking reads advance simulated time."""

    def __init__(self, swarm: Swarm, r: int) -> None:
        self.swarm, self.r, self.timeout = swarm, r, None
        self.clock = SwarmClock(swarm)

    def write(self, data: bytes) -> int:
        self.swarm.uart_in[self.r] += data
        return len(data)

    @property
    def in_waiting(self) -> int:
        return len(self.swarm.uart_out[self.r])

    def reset_input_buffer(self) -> None:
        self.swarm.uart_out[self.r].clear()

    def read(self, n: int = 1) -> bytes:
        deadline = self.clock.now() + (self.timeout if self.timeout is not None else 3600.0)
        buf = self.swarm.uart_out[self.r]
        while len(buf) < n and self.clock.now() + Q_NS / 1e9 <= deadline + 1e-12:
            self.swarm.step()
        out = bytes(buf[:n])
        del buf[:n]
        return out


def lone_module(**kw: Any) -> UwbModule:
    args = {"addr16": 0x0101, "robot": 0, "peers": [(1, 0x0202), (2, 0x0303)], "slot": 0, "n_slots": 3,
            "rng": np.random.default_rng(0), "cfg": UwbCfg()}
    args.update(kw)
    return UwbModule(**args)


def talk(m: UwbModule, t0: int, req: bytes, events: list[dict] | None = None) -> tuple[bytes, int]:
    """Send ``req`` at ``t0``, then step every 1 ms for 60 ms (a long answer takes ~30 ms at 115200 baud)."""
    out = bytearray(m.step(t0, req, events or []).uart_tx)
    t = t0
    for _ in range(60):
        t += 1_000_000
        out += m.step(t, b"", []).uart_tx
    return bytes(out), t


def range_event(peer: int, range_m: float, t_ns: int, rx: float = -70.0, fp: float = -72.0,
                responder: bool = False) -> dict:
    return {"ev": "range", "peer": peer, "ok": True, "range_m": range_m, "rx_dbm": rx, "fp_dbm": fp, "t_ns": t_ns,
            "responder": responder}


# -- module: TLV framing ----------------------------------------------------------------------------


def test_loc_get_layout_matches_the_dwm1001_api() -> None:
    m = lone_module()
    m.step(0, b"", [range_event(1, 3.2104, 1_000_000), range_event(2, 7.5, 2_000_000, rx=-80, fp=-95)])
    ans, _ = talk(m, 50_000_000, bytes((0x0C, 0x00)))
    tl = parse_tlvs(ans)
    assert tl[0] == (0x40, b"\x00")
    assert tl[1] == (0x41, struct.pack("<iiiB", 0, 0, 0, 0))
    typ, val = tl[2]
    assert typ == 0x48 and val[0] == 2 and len(val) == 1 + 2 * 13
    assert struct.unpack_from("<QIB", val, 1) == (0x0202, 3210, 100)  # oldest first, LOS gap 2 dB -> qf 100
    addr, mm, qf = struct.unpack_from("<QIB", val, 14)
    assert (addr, mm) == (0x0303, 7500) and qf == qf_from_gap(15, 6, 10) == 0
    typ, val = tl[3]
    assert typ == 0xC0 and val[0] == 2 and len(val) == 1 + 2 * 9
    assert struct.unpack_from("<HhhBH", val, 1) == (0x0202, -7000, -7200, 0, 49)
    assert struct.unpack_from("<HhhBH", val, 10) == (0x0303, -8000, -9500, 1, 48)  # NLOS flag
    # ranges are handed out once: the next call lists none
    ans2, _ = talk(m, 300_000_000, bytes((0x0C, 0x00)))
    assert parse_tlvs(ans2)[2] == (0x48, b"\x00")
    assert m.counters["loc_get"] == 2 and m.counters["ranges_reported"] == 2


def test_loc_get_lists_at_most_15_and_keeps_the_rest() -> None:
    peers = [(r, 0x2000 + r) for r in range(1, 21)]
    m = lone_module(peers=peers, n_slots=21)
    m.step(0, b"", [range_event(r, 1.0 + r, r * 1000) for r in range(1, 21)])
    first = decode_loc(parse_tlvs(talk(m, 20_000_000, b"\x0c\x00")[0])[1:], 0.0)
    second = decode_loc(parse_tlvs(talk(m, 400_000_000, b"\x0c\x00")[0])[1:], 0.0)
    assert [r.addr16 for r in first] == [0x2000 + r for r in range(1, 16)]
    assert [r.addr16 for r in second] == [0x2000 + r for r in range(16, 21)]


@pytest.mark.parametrize(("req", "status"), [
    (b"\x0c", 1),  # truncated header
    (b"\x0c\x02\x00", 1),  # length says 2, 1 byte arrived
    (b"\x0c\x01\x00", 1),  # loc_get takes no value
    (b"\x77\x00", 1),  # unknown command
    (b"\x03\x04" + struct.pack("<HH", 0, 10), 3),  # update rate 0
    (b"\x03\x04" + struct.pack("<HH", 20, 10), 3),  # static period below the normal one
    (b"\x0c\x00\x0c\x00", 1),  # two requests without waiting: one broken frame to the module
    (bytes(300), 1),  # longer than any TLV
])
def test_malformed_requests_get_the_real_error_codes(req: bytes, status: int) -> None:
    m = lone_module()
    ans, _ = talk(m, 0, req)
    assert ans == bytes((0x40, 0x01, status))


def test_update_rate_version_status_swarm_info_and_reset() -> None:
    m = lone_module()
    assert talk(m, 0, b"\x03\x04" + struct.pack("<HH", 5, 50))[0] == b"\x40\x01\x00"
    assert m.period_ns == 500_000_000
    assert talk(m, 100_000_000, b"\x04\x00")[0] == b"\x40\x01\x00\x45\x04" + struct.pack("<HH", 5, 50)
    ver = parse_tlvs(talk(m, 200_000_000, b"\x15\x00")[0])
    assert [t for t, _ in ver] == [0x40, 0x50, 0x51, 0x52] and ver[3][1] == struct.pack("<I", 0xDECA002A)
    assert talk(m, 300_000_000, b"\x32\x00")[0] == b"\x40\x01\x00\x5a\x02\x02\x00"
    assert talk(m, 400_000_000, b"\xa0\x00")[0] == b"\x40\x01\x00\xc1\x08" + struct.pack("<HHHH", 0x0101, 0, 3, 2)
    assert talk(m, 500_000_000, b"\x14\x00")[0] == b"\x40\x01\x00"
    assert m.period_ns == 1_000_000_000 and m.counters["resets"] == 1


def test_uart_gap_and_pacing() -> None:
    """A request is answered once the line was quiet for 25/32768 s; bytes leave at 115200 baud."""
    m = lone_module()
    m.step(0, b"\x04", [])
    assert m.next_wake() == 762_940
    m.step(500_000, b"\x00", [])  # second byte inside the gap: same request
    assert m.next_wake() == 500_000 + 762_940
    out = m.step(500_000 + 762_940 + 3 * BYTE_NS, b"", []).uart_tx
    assert out == b"\x40\x01\x00"  # 3 bytes clocked out by now, the rest still on the line
    assert m.next_wake() == 500_000 + 762_940 + 4 * BYTE_NS
    rest = m.step(10_000_000, b"", []).uart_tx
    assert rest == b"\x45\x04\x0a\x00\x0a\x00"


# -- module: TDMA --------------------------------------------------------------------------------------


def test_tdma_budget_formula() -> None:
    b16, b32, b4 = (tdma_budget(512, 4, n, 1.0) for n in (16, 32, 4))
    assert b16["slot_s"] == pytest.approx(4 / 512) and b16["swarm_exchanges_per_s"] == 128
    assert b16["turns_per_s"] == 8 and b32["turns_per_s"] == 4  # Zebro: 32 resp. 16 frames per robot per s
    assert b4["pair_rate_hz"] == 1.0 and not b4["budget_limited"]
    assert b16["pair_rate_hz"] == 1.0 and not b16["budget_limited"]  # 128 / 120 pairs > 1 Hz
    assert b32["pair_rate_hz"] == pytest.approx(128 / 496) and b32["budget_limited"]
    assert UwbCfg().budget(32) == b32


@pytest.mark.parametrize("n", [4, 16, 24, 32])
def test_tdma_turns_and_pair_rate_follow_the_budget(n: int) -> None:
    sw = Swarm(n)
    sw.run_until(30_000_000_000)
    cfg = sw.cfg
    slot_ns = cfg.frames_per_exchange * 1_000_000_000 // cfg.frames_per_s
    # every exchange starts on its initiator's own slot and no two exchanges share a slot
    starts = [t for t, _, _ in sw.requests]
    assert len(set(starts)) == len(starts)
    for t, i, _ in sw.requests:
        m = t * cfg.frames_per_s // (cfg.frames_per_exchange * 1_000_000_000)
        assert (m * cfg.frames_per_exchange * 1_000_000_000) // cfg.frames_per_s == t and m % n == i
    ss = sorted(starts)
    assert min(b - a for a, b in itertools.pairwise(ss)) >= slot_ns
    # measured rates after a 5 s warm-up versus the budget
    t0, t1 = 5e9, 30e9
    span = (t1 - t0) / 1e9
    frames = len([t for t in starts if t0 <= t < t1]) * cfg.frames_per_exchange
    assert frames / span <= cfg.frames_per_s
    pair = Counter(tuple(sorted((rob, ev["peer"]))) for td, rob, ev in sw.events
                   if ev["ok"] and not ev["responder"] and t0 <= td < t1)
    # every exchange (either end initiating) is one range of the pair; dropouts cost a few per cent
    attempts = Counter(tuple(sorted((i, j))) for t, i, j in sw.requests if t0 <= t < t1)
    expect = tdma_budget(cfg.frames_per_s, cfg.frames_per_exchange, n, cfg.update_rate_hz)["pair_rate_hz"]
    rates = np.array([attempts[(a, b)] / span for a in range(n) for b in range(a + 1, n)])
    ok_rates = np.array([pair[(a, b)] / span for a in range(n) for b in range(a + 1, n)])
    print(f"n={n}: pair rate mean {rates.mean():.3f} Hz (min {rates.min():.3f}, max {rates.max():.3f}), "
          f"budget {expect:.3f} Hz, ranged ok {ok_rates.mean():.3f} Hz")
    assert rates.mean() == pytest.approx(expect, rel=0.12)
    assert rates.min() >= 0.6 * expect and rates.max() <= 2.0 * expect
    assert ok_rates.mean() >= 0.9 * rates.mean()
    if n == 32:  # budget-limited: the swarm uses (nearly) all 128 exchanges/s
        assert frames / span >= 0.9 * cfg.frames_per_s


def test_module_sleeps_between_updates_in_a_small_swarm() -> None:
    sw = Swarm(3)
    sw.run_until(2_000_000_000)
    m = sw.modules[0]
    w = m.next_wake()
    assert w is not None and w > sw.now_ns + Q_NS  # nothing due before the next update period


def test_events_are_msgpack_safe_and_deterministic() -> None:
    runs = []
    for _ in range(2):
        geo = Geo(ring(6), walls=lambda s, d: int((s + d) % 3 == 0))
        sw = Swarm(6, seed=11, geo=geo)
        sw.run_until(5_000_000_000)
        runs.append(msgpack.packb([[td, r, ev] for td, r, ev in sw.events]))
    assert runs[0] == runs[1]
    assert msgpack.unpackb(runs[0])


# -- medium statistics --------------------------------------------------------------------------------


def _many_links(cfg: UwbCfg, walls: int, dist: float = 8.0, n_links: int = 60, per_link: int = 80,
                seed: int = 3) -> tuple[UwbMedium, list[dict]]:
    n = 2 * n_links
    pos = np.zeros((n, 2))
    pos[1::2, 0] = dist
    pos[:, 1] = np.repeat(np.arange(n_links) * 100.0, 2)
    med = UwbMedium(cfg, n, seed, Geo(pos, walls=lambda s, d: walls))
    evs = []
    for k in range(per_link):
        for link in range(n_links):
            for _td, rob, ev in med.exchange(k * 1_000_000_000, 2 * link, 2 * link + 1):
                if rob == 2 * link:
                    evs.append(ev)
    return med, evs


def test_medium_los_statistics_match_the_configuration() -> None:
    cfg = UwbCfg()
    med, evs = _many_links(cfg, walls=0)
    s = med.stats()["all"]
    e = s["err_los"]
    assert s["err_nlos"]["n"] == 0 and e["n"] == s["ok"]
    assert abs(e["mean_m"]) < 0.03
    assert e["std_m"] == pytest.approx(math.hypot(cfg.sigma_los_m, cfg.bias_sigma_m), rel=0.12)
    assert s["dropout"] / s["exchanges"] == pytest.approx(cfg.dropout_los, abs=0.01)
    ok = [ev for ev in evs if ev["ok"]]
    gaps = np.array([ev["rx_dbm"] - ev["fp_dbm"] for ev in ok])
    assert np.mean(gaps < cfg.los_fp_gap_db) > 0.9
    rx = np.mean([ev["rx_dbm"] for ev in ok])
    assert rx == pytest.approx(cfg.rx_1m_dbm - 20 * math.log10(8.0), abs=0.5)
    assert all(ev["t_ns"] % 1_000_000_000 == 4 * 1_953_125 for ev in evs)


def test_medium_nlos_statistics_match_the_configuration() -> None:
    cfg = UwbCfg()
    med, evs = _many_links(cfg, walls=1)
    s = med.stats()["all"]
    e = s["err_nlos"]
    assert s["err_los"]["n"] == 0
    assert e["mean_m"] == pytest.approx(cfg.nlos_bias_m + cfg.nlos_exp_scale_m, abs=0.04)
    expect_std = math.sqrt(cfg.nlos_sigma_m**2 + cfg.nlos_exp_scale_m**2 + cfg.bias_sigma_m**2)
    assert e["std_m"] == pytest.approx(expect_std, rel=0.12)
    p_drop = 1 - (1 - cfg.dropout_los) * (1 - cfg.dropout_per_wall)
    assert s["dropout"] / s["exchanges"] == pytest.approx(p_drop, abs=0.03)
    gaps = np.array([ev["rx_dbm"] - ev["fp_dbm"] for ev in evs if ev["ok"]])
    assert np.mean(gaps > cfg.nlos_fp_gap_db) > 0.8  # the APS006 rule catches most NLOS ranges
    assert all(ev["nlos"] for ev in evs)


def test_medium_range_limits_and_dead_peers() -> None:
    cfg = UwbCfg()
    pos = np.array([[0, 0], [61, 0], [55, 0], [5, 0]], float)
    med = UwbMedium(cfg, 4, 1, Geo(pos, alive=[True, True, True, False]))
    far = [med.exchange(k * 10**9, 0, 1) for k in range(50)]
    assert all(len(x) == 1 and x[0][2]["cause"] == "out_of_range" for x in far)
    edge = [med.exchange(k * 10**9, 0, 2) for k in range(400)]
    drop = np.mean([x[-1][2]["cause"] == "dropout" for x in edge])
    assert drop == pytest.approx(1 - 0.99 * (1 - (55 / 60) ** 6), abs=0.06)  # about 60 % near the edge
    dead = med.exchange(0, 0, 3)
    assert dead[0][2]["cause"] == "no_response" and dead[0][1] == 0
    assert med.exchange(0, 3, 0) == []  # a dead robot's module does not range
    st_ = med.stats()["robots"][0]
    assert st_["out_of_range"] == 50 and st_["no_response"] == 1


def test_link_bias_drifts_slowly_and_is_reciprocal() -> None:
    cfg = UwbCfg(sigma_los_m=0.0, bias_sigma_m=0.1, bias_tau_s=60.0, dropout_los=0.0)
    med = UwbMedium(cfg, 2, 5, Geo([[0, 0], [5, 0]]))
    errs = []
    for k in range(600):
        i, j = (0, 1) if k % 2 == 0 else (1, 0)
        ev = med.exchange(k * 100_000_000, i, j)[-1][2]
        errs.append(ev["range_m"] - ev["true_m"])
    d = np.diff(errs)
    assert np.std(d) < 0.02 and np.std(errs) > 0.02  # correlated over 0.1 s, both directions share it


# -- host driver ---------------------------------------------------------------------------------------


def test_driver_reads_ranges_through_the_module() -> None:
    sw = Swarm(4, geo=Geo(ring(4, 3.0)))
    port = SwarmPort(sw, 0)
    uwb = Uwb(port, port.clock)
    info = uwb.identify()
    assert info.swarm == {"addr16": 0x1000, "slot": 0, "n_slots": 4, "n_peers": 3} and uwb.vendor
    assert info.hw_version == 0xDECA002A and info.fw_version[0] == 1
    port.clock.sleep(3.0)
    readings = uwb.loc_get()
    true = {0x1000 + j: float(np.hypot(*(sw.geo.pos[0] - sw.geo.pos[j]))) for j in (1, 2, 3)}
    assert {r.addr16 for r in readings} == set(true)
    for r in readings:
        assert abs(r.range_m - true[r.addr16]) < 0.6
        assert r.rx_dbm is not None and r.age_s is not None and r.t <= port.clock.now()
        assert r.qf > 50 and not r.nlos
    assert uwb.update_rate() == (1.0, 1.0)
    uwb.set_update_rate(0.5, 2.0)
    assert uwb.update_rate() == (0.5, 2.0)
    assert uwb.status()["uwbmac_joined"]
    with pytest.raises(UwbError) as ei:
        uwb.request(0x77)
    assert ei.value.status == 1 and uwb.counters["errors"] == 1


def test_driver_times_out_in_clock_time() -> None:
    sw = Swarm(2)
    port = SwarmPort(sw, 0)
    sw.modules[0].step = lambda t, rx, ev: type("O", (), {"uart_tx": b"", "requests": []})()  # a dead module
    uwb = Uwb(port, port.clock, timeout=0.25, vendor=True)
    t0 = port.clock.now()
    with pytest.raises(UwbTimeout):
        uwb.loc_get()
    assert 0.25 <= port.clock.now() - t0 <= 0.27 and uwb.counters["timeouts"] == 1


class CannedPort:
    """Answers every write with ``reply``; reads return at most ``chunk`` bytes; empty reads jump the clock."""

    def __init__(self, reply: bytes, chunk: int = 7) -> None:
        self.reply, self.chunk, self.buf, self.timeout, self.t = reply, chunk, bytearray(), None, 0.0

    def now(self) -> float:
        return self.t

    def write(self, data: bytes) -> int:
        self.buf += self.reply
        return len(data)

    in_waiting = 0

    def reset_input_buffer(self) -> None:
        self.buf.clear()

    def read(self, n: int = 1) -> bytes:
        if not self.buf:
            self.t += self.timeout or 0.0
            return b""
        out = bytes(self.buf[:min(n, self.chunk)])
        del self.buf[:len(out)]
        self.t += 0.001
        return out


def test_driver_with_a_stock_dwm1001_reply() -> None:
    """No vendor TLV: readings carry distance and quality only (0x49 tag layout with positions too)."""
    ent = struct.pack("<HIB", 0xBEEF, 4321, 77) + struct.pack("<iiiB", 1, 2, 3, 100)
    reply = b"\x40\x01\x00" + tlv(0x41, struct.pack("<iiiB", 0, 0, 0, 0)) + tlv(0x49, bytes((1,)) + ent)
    port = CannedPort(reply)
    uwb = Uwb(port, port, vendor=False)
    (r,) = uwb.loc_get()
    assert (r.addr16, r.range_m, r.qf, r.rx_dbm, r.age_s) == (0xBEEF, 4.321, 77, None, None)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(reply=st.binary(max_size=120), chunk=st.integers(1, 40), vendor=st.booleans(),
       cmd=st.sampled_from(["loc", "ur", "status", "identify", "raw"]))
def test_fuzz_driver_reader(reply: bytes, chunk: int, vendor: bool, cmd: str) -> None:
    port = CannedPort(reply, chunk)
    uwb = Uwb(port, port, timeout=0.2, vendor=vendor)
    try:
        if cmd == "loc":
            for r in uwb.loc_get():
                assert 0 <= r.addr16 <= 0xFFFF and r.range_m >= 0
        elif cmd == "ur":
            uwb.update_rate()
        elif cmd == "status":
            uwb.status()
        elif cmd == "identify":
            uwb.identify()
        else:
            uwb.request(0x0C, follow=3)
    except UwbError:
        pass
    assert port.t < 10.0


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_fuzz_tlv_decoders(data: bytes) -> None:
    try:
        tl = parse_tlvs(data)
    except UwbProtocolError:
        return
    assert sum(2 + len(v) for _, v in tl) == len(data)
    with contextlib.suppress(UwbProtocolError):
        decode_loc(tl, 0.0)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.integers(1, 3_000_000), st.binary(max_size=80)), max_size=12))
def test_fuzz_module_request_parser(chunks: list[tuple[int, bytes]]) -> None:
    """Random byte streams at random times never raise; every request frame gets exactly one status TLV."""
    m = lone_module()
    t, out = 0, bytearray()
    for dt, data in chunks:
        t += dt
        out += m.step(t, data, []).uart_tx
    t += 1_000_000_000
    out += m.step(t, b"", []).uart_tx
    out += m.step(t + 1_000_000_000, b"", []).uart_tx
    c = m.counters
    assert c["uart_rx_bytes"] == sum(len(d) for _, d in chunks)
    assert len(out) == c["uart_tx_bytes"]
    tl = parse_tlvs(bytes(out))
    status = [v for typ, v in tl if typ == 0x40]
    assert len(status) == c["uart_frames"]
    assert sum(v != b"\x00" for v in status) == c["uart_broken_frames"] + c["uart_unknown_cmd"] + c["uart_bad_param"]


# -- range filter -------------------------------------------------------------------------------------


def slow(t: float) -> float:
    """Range between two robots (m): slow approach and retreat, 3..13.5 m, up to 0.18 m/s, 0.01 m/s^2."""
    return 8.0 + 5.0 * math.sin(2 * math.pi * t / 240.0) + 0.5 * math.sin(2 * math.pi * t / 60.0)


def agile(t: float) -> float:
    """Faster relative motion: 1.5..14.5 m, up to 0.76 m/s, 0.14 m/s^2."""
    return 8.0 + 5.0 * math.sin(2 * math.pi * t / 90.0) + 1.5 * math.sin(2 * math.pi * t / 23.0)


SCENARIOS = {
    "los": lambda t: False,
    "nlos_intermittent": lambda t: (t % 60.0) >= 30.0,  # behind an obstacle half of the time
    "nlos_all": lambda t: True,
}


def _trajectory(seed: int, duration_s: float, traj: Any, nlos_of_t: Any, tracker: dict) -> dict[str, Any]:
    """Robot 1 moves relative to robot 0 along ``traj``; 1 Hz exchanges through the medium, as the module
    would flag them (APS006 thresholds), into a RangeTracker; errors at each measurement time."""
    cfg = UwbCfg()
    geo = Geo(np.zeros((2, 2)))
    clock = {"t": 0.0}
    geo.wall_fn = lambda s, d: int(nlos_of_t(clock["t"]))
    med = UwbMedium(cfg, 2, seed, geo)
    tr = RangeTracker(**tracker)
    raw, filt, flagged = [], [], []
    for k in range(int(duration_s)):
        t = k + 0.37
        clock["t"] = t
        geo.pos = np.array([[0.0, 0.0], [traj(t), 0.0]])
        ev = med.exchange(round(t * 1e9), 0, 1)[-1][2]
        if not ev["ok"]:
            continue
        gap = ev["rx_dbm"] - ev["fp_dbm"]
        tm = ev["t_ns"] / 1e9
        tr.update(1, ev["range_m"], tm, nlos=gap > cfg.nlos_fp_gap_db,
                  nlos_possible=cfg.los_fp_gap_db < gap <= cfg.nlos_fp_gap_db)
        if k < 10:
            continue
        raw.append(ev["range_m"] - ev["true_m"])
        filt.append(tr.estimate(1, tm).range_m - ev["true_m"])
        flagged.append(ev["nlos"])
    raw_a, filt_a, nl = np.array(raw), np.array(filt), np.array(flagged, bool)

    def rms(a: np.ndarray) -> float:
        return float(np.sqrt(np.mean(a**2))) if len(a) else 0.0

    return {"raw_rms": rms(raw_a), "filt_rms": rms(filt_a), "raw_rms_nlos": rms(raw_a[nl]),
            "filt_rms_nlos": rms(filt_a[nl]), "nlos_share": float(nl.mean())}


def rms_figures(traj: Any = slow, tracker: dict | None = None, seeds: range = range(1, 6),
                duration_s: float = 900.0) -> dict[str, dict[str, float]]:
    """Filtered vs raw RMS range error (m), averaged over seeds, for LOS, intermittent NLOS and full NLOS."""
    out = {}
    for name, fn in SCENARIOS.items():
        runs = [_trajectory(s, duration_s, traj, fn, tracker or {}) for s in seeds]
        out[name] = {k: float(np.mean([r[k] for r in runs])) for k in
                     ("raw_rms", "filt_rms", "raw_rms_nlos", "filt_rms_nlos", "nlos_share")}
    return out


FIGURE_CASES = {
    "slow, accel_sigma 0.05": (slow, {"accel_sigma": 0.05}),
    "slow, accel_sigma 0.05, nlos_bias 0.5 m": (slow, {"accel_sigma": 0.05, "nlos_bias_m": 0.5}),
    "agile, defaults": (agile, {}),
}


def print_figures(figs: dict[str, dict[str, dict[str, float]]]) -> None:
    for case, fig in figs.items():
        for name, f in fig.items():
            print(f"{case:40s} {name:18s} raw RMS {f['raw_rms']:.3f} m  filtered {f['filt_rms']:.3f} m  "
                  f"(NLOS ranges: raw {f['raw_rms_nlos']:.3f}, filtered {f['filt_rms_nlos']:.3f}; "
                  f"NLOS share {f['nlos_share']:.2f})")


def test_filter_beats_raw_ranges_in_los_and_nlos() -> None:
    figs = {case: rms_figures(traj, kw, range(1, 4), 600.0) for case, (traj, kw) in FIGURE_CASES.items()}
    print()
    print_figures(figs)
    plain = figs["slow, accel_sigma 0.05"]
    assert plain["los"]["filt_rms"] < 0.9 * plain["los"]["raw_rms"]
    assert plain["nlos_intermittent"]["filt_rms"] < 0.9 * plain["nlos_intermittent"]["raw_rms"]
    assert plain["nlos_intermittent"]["filt_rms_nlos"] < 0.9 * plain["nlos_intermittent"]["raw_rms_nlos"]
    assert plain["nlos_all"]["filt_rms"] < 0.95 * plain["nlos_all"]["raw_rms"]
    corrected = figs["slow, accel_sigma 0.05, nlos_bias 0.5 m"]
    assert corrected["nlos_intermittent"]["filt_rms"] < 0.5 * corrected["nlos_intermittent"]["raw_rms"]
    assert corrected["nlos_all"]["filt_rms"] < 0.5 * corrected["nlos_all"]["raw_rms"]
    fast = figs["agile, defaults"]
    for name in SCENARIOS:
        assert fast[name]["filt_rms"] < fast[name]["raw_rms"]


def test_tracker_gates_outliers_follows_jumps_and_drops_stale_tracks() -> None:
    tr = RangeTracker()
    for k in range(20):
        assert tr.update(5, 4.0 + 0.1 * k, float(k))
    assert not tr.update(5, 9.0, 20.0)  # a 3 m outlier is gated
    assert tr.counters["gated"] == 1
    e = tr.estimate(5, 20.0)
    assert e.range_m == pytest.approx(6.0, abs=0.15) and e.rate_mps == pytest.approx(0.1, abs=0.05)
    for k in range(21, 26):  # the peer really jumped (e.g. the track was wrong): re-initialised
        tr.update(5, 12.0, float(k))
    assert tr.counters["reinit"] == 1 and tr.estimate(5).range_m == pytest.approx(12.0, abs=0.1)
    assert not tr.update(5, 12.0, 10.0) and tr.counters["late"] == 1
    assert tr.estimates(26.0).keys() == {5}
    assert tr.estimates(40.0) == {} and tr.counters["dropped"] == 1


def test_swarm_logic_ranging_imports_filterpy_lazily() -> None:
    import subprocess
    import sys

    code = ("import sys\nimport swarm_logic.drivers.ranging, swarm_logic.drivers.uwb\n"
            "assert 'filterpy' not in sys.modules\nprint('ok')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.stdout.strip() == "ok", r.stderr


if __name__ == "__main__":
    print_figures({case: rms_figures(traj, kw) for case, (traj, kw) in FIGURE_CASES.items()})
