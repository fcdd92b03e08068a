"""The DeciZebro's UWB radio with data, without a session: the module's UART protocol (good and malformed frames),
the medium's ranges, bearings, headings and deliveries, faithful against realistic, the TDMA budget at 16 and 32
robots (Z-H1), determinism; the BNO055 IMU's UART; the Pi's drivers against the module."""

from __future__ import annotations

import math
import struct
from collections import defaultdict
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bridge.core.config import ConfigError, load_config
from bridge.core.entities import entity
from bridge.media.uwb import UwbCfg
from bridge.media.uwb_radio import UwbRadioAir
from firmware_sim.robots.decizebro.imu import Bno055
from firmware_sim.robots.decizebro.uwb_radio import UwbRadio
from swarm_logic.robots.decizebro import uwb_protocol as P
from swarm_logic.robots.decizebro.imu import Bno055Imu
from swarm_logic.robots.decizebro.uwb_radio import ZebroUwbRadio

Q = 10_000_000
ROLE = "uwb_radio"


def frames(data: bytes) -> list[Any]:
    """Every frame in ``data`` (the module's bytes to its host), parsed."""
    return P.Parser().feed(0, data)


@pytest.mark.parametrize(("extra", "match"), [
    ('count = 2\nuwb_radio_pty = "x"\n', r"robots\[0\]: uwb_radio_pty: a group of several robots needs '\{id\}'"),
    ('count = 1\nuwb_radio_pty = "x"\n', r"session.speed = 'max': a session with ports to the outside world "
                                         r"\(robots\[0\].uwb_radio_pty\)"),
    ('count = 1\nsensing = "perfect"\n', r"robots\[0\].sensing: Input should be 'realistic' or 'faithful'"),
])
def test_radio_options_are_checked(tmp_path: Path, extra: str, match: str) -> None:
    p = tmp_path / "zebros.toml"
    p.write_text('[session]\nspeed = "max"\n[[robots]]\nprofile = "decizebro"\n' + extra)
    with pytest.raises(ConfigError, match=match):
        load_config(p)


# -- the UART protocol --------------------------------------------------------------------------------------------
def test_frame_layout_and_crc() -> None:
    f = P.frame(P.SET_HEADING, struct.pack("<H", 9000))
    assert f[:3] == bytes((0xA5, 3, 0x02)) and f[3:5] == struct.pack("<H", 9000)
    assert struct.unpack("<H", f[5:])[0] == P.crc16(f[1:5])
    assert P.crc16(b"123456789") == 0x29B1  # the CRC-16/CCITT-FALSE check value
    assert P.Parser().feed(0, f) == [(P.SET_HEADING, struct.pack("<H", 9000))]


def test_module_answers_good_frames() -> None:
    m = UwbRadio(robot=7, slot=2, n_slots=5)
    m.step(0, P.frame(P.INFO_GET) + P.frame(P.SET_HEADING, struct.pack("<H", 4500)) + P.frame(P.STATUS_GET), [])
    got = frames(m.step(50 * Q, b"", []).uart_tx)
    info = dict(zip(("id", "slot", "n_slots", "fps", "max_payload", "queue", "period_ms", "ideal"),
                    P.INFO_BODY.unpack(got[0][1]), strict=True))
    assert got[0][0] == P.INFO and info == {"id": 7, "slot": 2, "n_slots": 5, "fps": 512, "max_payload": 112,
                                            "queue": 16, "period_ms": 1000, "ideal": 0}
    assert got[1] == (P.ACK, bytes((P.SET_HEADING, P.OK))) and m.heading_cdeg == 4500
    assert got[2][0] == P.STATUS and len(got[2][1]) == 4 * len(P.STATUS_FIELDS)


@pytest.mark.parametrize(("data", "status", "counter"), [
    (P.frame(P.INFO_GET)[:-1] + b"\x00", P.BAD_CRC, "uart_bad_crc"),
    (P.frame(0x33, b"x"), P.UNKNOWN_TYPE, "uart_unknown_type"),
    (P.frame(P.SET_HEADING, b"\x01\x02\x03"), P.BAD_LENGTH, "uart_bad_length"),
    (P.frame(P.SEND, b"\x01" + bytes(P.MAX_PAYLOAD + 1)), P.BAD_LENGTH, "uart_bad_length"),
    (P.frame(P.SEND, b"\x01"), P.BAD_LENGTH, "uart_bad_length"),
    (P.frame(P.SET_HEADING, struct.pack("<H", 36000)), P.BAD_PARAM, "uart_bad_param"),
    (bytes((0xA5, 0)), P.BAD_LENGTH, "uart_bad_length"),
])
def test_malformed_frames_are_counted_answered_and_dropped(data: bytes, status: int, counter: str) -> None:
    m = UwbRadio(robot=0, slot=0, n_slots=2)
    m.step(0, b"junk" + data + P.frame(P.INFO_GET), [])  # a good frame after the bad one is still found
    got = frames(m.step(50 * Q, b"", []).uart_tx)
    nacks = [body for typ, body in got if typ == P.ACK and body[1] != P.OK]
    assert nacks and nacks[0][1] == status and m.counters[counter] == 1
    assert any(typ == P.INFO for typ, _ in got) and m.counters["uart_junk_bytes"] >= 4


def test_a_truncated_frame_is_dropped_after_its_timeout() -> None:
    m = UwbRadio(robot=0, slot=0, n_slots=2)
    m.step(0, P.frame(P.INFO_GET)[:3], [])
    assert m.next_wake() is not None and m.next_wake() <= P.FRAME_TIMEOUT_NS
    got = frames(m.step(P.FRAME_TIMEOUT_NS + Q, b"", []).uart_tx + m.step(60 * Q, b"", []).uart_tx)
    assert (P.ACK, bytes((0, P.TRUNCATED))) in got and m.counters["uart_truncated"] == 1


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.binary(max_size=300), max_size=8))
def test_fuzz_the_module_never_raises(chunks: list[bytes]) -> None:
    m = UwbRadio(robot=1, slot=1, n_slots=3)
    for k, c in enumerate(chunks):
        m.step(k * 7 * Q, c, [])
    m.step(100 * Q, b"", [])
    assert m.counters["uart_rx_bytes"] == sum(map(len, chunks))


def test_send_queues_until_full_and_reports_the_queue() -> None:
    m = UwbRadio(robot=0, slot=0, n_slots=4, queue_frames=3)
    m.step(0, b"".join(P.frame(P.SEND, bytes((s,)) + b"hi") for s in range(1, 6)), [])
    assert len(m.queue) == 3 and m.counters["queue_full"] == 2
    got = frames(m.step(2 * Q, b"", []).uart_tx)
    assert (P.TX_STATUS, bytes((5, 3))) in got or any(t == P.TX_STATUS and b[0] == 5 for t, b in got)


# -- the air, through the medium ------------------------------------------------------------------------------------
class Swarm:
    """Modules and the medium in lock-step, each module run every quantum (as often as it could be)."""

    def __init__(self, pos: list[tuple[float, float]], yaw: list[float] | None = None, *, seed: int = 1,
                 ideal: bool = False, walls: int = 0) -> None:
        n = len(pos)
        self.world = SimpleNamespace(pos=np.array(pos, dtype=float), yaw=np.array(yaw or [0.0] * n),
                                     walls=lambda src, dsts: np.full(len(dsts), walls))
        self.records: list[tuple[int, str, dict]] = []
        self.deliveries: dict[int, list] = defaultdict(list)
        self.inbox: dict[str, list] = defaultdict(list)
        hub = SimpleNamespace(
            cfg=SimpleNamespace(uwb=UwbCfg(), session=SimpleNamespace(seed=seed), faults=[]), n=n, q_ns=Q,
            dead=set(),
            roles={r: (ROLE,) for r in range(n)},
            plan=SimpleNamespace(robots=[SimpleNamespace(options={"sensing": "faithful"} if ideal else {})] * n),
            world=self.world, geometry=None, deliver_at=lambda t, h, *a: self.deliveries[t].append((h, a)),
            to_inbox=lambda t, e, msg: self.inbox[e].append(msg),
            rec=SimpleNamespace(write=lambda t, topic, schema, msg: self.records.append((t, topic, msg))))
        self.hub = hub
        self.air = UwbRadioAir(hub)  # type: ignore[arg-type]
        self.modules = [UwbRadio(robot=r, slot=r, n_slots=n, ideal=ideal) for r in range(n)]
        self.host: list[bytearray] = [bytearray() for _ in range(n)]
        self.t = 0

    def run(self, until_ns: int, feed: Any = None) -> None:
        while self.t < until_ns:
            t = self.t
            for h, args in self.deliveries.pop(t, []):
                h(t, *args)
            for r, m in enumerate(self.modules):
                events = [it[1] for it in self.inbox.pop(entity(r, ROLE), [])]
                out = m.step(t, feed(r, m, t) if feed else b"", events)
                self.host[r] += out.uart_tx
                for a in out.air:
                    self.air.transmit(entity(r, ROLE), r, t, [ROLE, a])
            self.t += Q
        self.hub.sim_end_ns = self.t

    def report(self) -> dict[str, Any]:
        out: dict[str, Any] = {"per_robot": {}}
        self.air.radio_report(out)
        return out

    def host_frames(self, r: int, typ: int) -> list[bytes]:
        return [body for t, body in frames(bytes(self.host[r])) if t == typ]


def saturate(r: int, m: UwbRadio, t: int) -> bytes:
    """Keep the module's queue full."""
    return b"".join(P.frame(P.SEND, bytes((k,)) + bytes(20)) for k in range(m.queue_frames - len(m.queue)))


@pytest.mark.parametrize(("n", "share"), [(16, 32), (32, 16)])
def test_z_h1_the_budget_holds_at_16_and_32_robots(n: int, share: int) -> None:
    side = math.ceil(math.sqrt(n))
    s = Swarm([(2.0 * (i % side), 2.0 * (i // side)) for i in range(n)])
    s.run(4_000_000_000 + Q, saturate)
    rep = s.report()["uwb_radio"]
    assert rep["budget_per_robot_per_s"] == share and rep["off_slot"] == 0
    # never more than the share in any second; saturated, exactly the share (a beacon and share - 1 data frames)
    assert rep["max_frames_per_robot_in_a_second"] == share
    assert all([sec[k] for k in range(4)] == [share] * 4 for sec in s.air.per_second.values())
    rates = rep["frames_per_robot_per_s"]
    assert share - 0.2 < rates["min"] <= rates["max"] < share + 0.5  # the window ends mid-second
    assert abs(rep["swarm_frames_per_s"] - 512) < 6 and 4 * n < rep["beacons"] <= 5 * n  # one a second


def test_frames_off_the_slot_plan_are_dropped() -> None:
    s = Swarm([(0.0, 0.0), (3.0, 0.0)])
    s.air.transmit(entity(0, ROLE), 0, 0, [ROLE, {"op": "tx", "t_ns": 1_953_125, "kind": "beacon",
                                                  "heading_cdeg": 0}])  # robot 1's slot
    s.air.transmit(entity(0, ROLE), 0, 0, [ROLE, {"op": "tx", "t_ns": 0, "kind": "beacon", "heading_cdeg": 0}])
    s.air.transmit(entity(0, ROLE), 0, 0, [ROLE, {"op": "tx", "t_ns": 0, "kind": "beacon", "heading_cdeg": 0}])
    assert s.air.count[0]["off_slot"] == 2 and s.air.count[0]["beacons"] == 1
    with pytest.raises(ValueError):
        s.air.transmit(entity(0, ROLE), 0, 0, [ROLE, {"op": "tx", "t_ns": 0, "kind": "shout"}])


def test_data_reaches_the_modules_in_range_and_not_beyond() -> None:
    s = Swarm([(0.0, 0.0), (30.0, 0.0), (70.0, 0.0)], ideal=True)
    s.modules[0].step(0, P.frame(P.SEND, b"\x01hello"), [])
    s.run(500_000_000)
    assert [struct.unpack_from("<HB", b)[0] for b in s.host_frames(1, P.RX_DATA)] == [0]
    assert s.host_frames(1, P.RX_DATA)[0][3:] == b"hello"
    assert s.host_frames(2, P.RX_DATA) == []
    tx = [m for _, topic, m in s.records if topic == "/r000/uwb_radio/tx" and m["kind"] == "data"]
    assert tx[0]["heard"] == [1] and tx[0]["lost"] == [] and tx[0]["data"] == b"hello".hex()


def neighbours(s: Swarm, r: int) -> dict[int, tuple]:
    """The last complete neighbour report robot ``r``'s module sent its host."""
    reps = s.host_frames(r, P.NEIGHBOURS)
    body = reps[-1]
    return {row[0]: row for row in (P.NEIGHBOUR.unpack_from(body, 3 + k * P.NEIGHBOUR.size) for k in range(body[2]))}


def test_faithful_ranges_bearings_and_headings_are_exact() -> None:
    # robot 0 faces north; 1 is 5 m east of it (to its right), 2 is 4 m behind it (south)
    s = Swarm([(0.0, 0.0), (5.0, 0.0), (0.0, -4.0)], [math.pi / 2, 0.0, 0.0], ideal=True)
    for r, h in enumerate((9000, 1000, 35000)):
        s.modules[r].step(0, P.frame(P.SET_HEADING, struct.pack("<H", h)), [])
    s.run(2_100_000_000)
    nb = neighbours(s, 0)
    assert nb[1][1:5] == (5000, -9000, 1000, P.F_BEARING | P.F_HEADING)
    # behind: all round in the faithful mode
    assert nb[2][1:5] in ((4000, 18000, 35000, 3), (4000, -18000, 35000, P.F_BEARING | P.F_HEADING))


def test_realistic_bearings_follow_the_pdoa_model() -> None:
    """Ahead within the field of view: a few degrees of noise; behind: folded to the front; near broadside: flagged
    outside the field of view."""
    targets = {1: 20.0, 2: 160.0, 3: 88.0}  # true bearings seen from robot 0 (facing east), degrees
    pos = [(0.0, 0.0)] + [(8 * math.cos(math.radians(b)), 8 * math.sin(math.radians(b))) for b in targets.values()]
    errs: dict[int, list[float]] = defaultdict(list)
    flags: dict[int, set[int]] = defaultdict(set)
    for seed in range(12):
        s = Swarm(pos, seed=seed)
        s.run(10_100_000_000)
        for body in s.host_frames(0, P.NEIGHBOURS):
            for k in range(body[2]):
                nid, _mm, b, _h, f, _age = P.NEIGHBOUR.unpack_from(body, 3 + k * P.NEIGHBOUR.size)
                errs[nid].append(b / 100.0)
                flags[nid].add(f & P.F_BEARING)
    ahead = np.array(errs[1]) - 20.0
    assert len(ahead) > 50 and abs(ahead.mean()) < 1.5 and 3.0 < ahead.std() < 8.0 and flags[1] == {P.F_BEARING}
    behind = np.array(errs[2])
    assert abs(np.median(behind) - 20.0) < 2.0  # 160 degrees reads as its mirror image, 20
    assert P.F_BEARING not in flags[3] or len(flags[3]) == 2  # near broadside: mostly outside the field of view
    assert np.mean(np.abs(np.array(errs[3]))) > 60.0


def test_realistic_ranges_carry_the_dw1000_errors_and_losses() -> None:
    s = Swarm([(0.0, 0.0), (59.0, 0.0)])
    s.modules[0].step(0, P.frame(P.SEND, b"\x01x"), [])
    s.run(30_100_000_000, lambda r, m, t: P.frame(P.SEND, b"\x02y") if r == 0 and not m.queue else b"")
    tot = s.report()["uwb_radio"]
    assert tot["beacons_lost"] > 0 and tot["data_lost"] > 0  # near the range limit, dropouts grow
    ranges = [m["range_m"] for _, topic, m in s.records if topic == "/r000/uwb_radio/tx" and m["kind"] == "beacon"]
    meas = np.array([x for r in ranges for x in r])
    assert len(meas) and abs(np.mean(meas) - 59.0) < 0.5 and np.std(meas) > 0.02


def test_the_same_seed_gives_the_same_air() -> None:
    def once(seed: int) -> list:
        s = Swarm([(0.0, 0.0), (3.0, 1.0), (1.0, 4.0)], seed=seed)
        s.run(3_000_000_000, saturate)
        return s.records

    assert once(4) == once(4) and once(4) != once(5)


# -- the Pi's drivers, against the module and the chip ---------------------------------------------------------------
class Line:
    """One robot's serial port to a module, in lock-step with it: writes reach the module at the next step, its bytes
    come back as they are clocked out. ``read`` with a timeout advances the shared clock."""

    def __init__(self, clock: Any, step: Any) -> None:
        self.clock, self.step = clock, step
        self.rx = bytearray()
        self.to_module = bytearray()
        self.timeout: float | None = 0

    def tick(self) -> None:
        self.clock.t += 0.01
        self.rx += self.step(round(self.clock.t * 1e9), bytes(self.to_module))
        self.to_module.clear()

    @property
    def in_waiting(self) -> int:
        return len(self.rx)

    def read(self, n: int = 1) -> bytes:
        deadline = self.clock.t + (self.timeout or 0)
        while len(self.rx) < n and self.clock.t < deadline:
            self.tick()
        out = bytes(self.rx[:n])
        del self.rx[:n]
        return out

    def write(self, data: bytes) -> int:
        self.to_module += data
        return len(data)

    def reset_input_buffer(self) -> None:
        self.rx.clear()

    def close(self) -> None:
        pass


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t


def test_the_imu_driver_reads_the_heading_counter_clockwise_from_east() -> None:
    chip, clock = Bno055(), Clock()
    line = Line(clock, lambda t, data: chip.step(t, data, math.radians(30.0)))
    imu = Bno055Imu(line, clock)
    assert chip.regs[0x3D] == 0x0C  # NDOF
    assert imu.heading() == pytest.approx(math.radians(30.0), abs=math.radians(1 / 16))
    line.write(b"\xaa\x01\x7f\x04")  # beyond the register map
    line.timeout = 0.1
    assert line.read(2) == b"\xee\x04" and chip.counters["errors"] == 1


def test_the_imu_reads_its_accelerometer_the_linear_part_and_gravity() -> None:
    """ACC_DATA (gravity's reaction included), LIA_DATA (less gravity) and GRV_DATA in m/s^2, 100 LSB each; in CONFIG
    mode the fusion's registers read zero; a malformed vector from the world is ignored."""
    chip, clock = Bno055(), Clock()
    state: dict = {"acc": [0.52, -0.13, 9.93], "grv": [0.0, 0.3, 9.8]}
    line = Line(clock, lambda t, data: chip.step(t, data, 0.0, state["acc"], state["grv"]))
    imu = Bno055Imu(line, clock)
    assert imu.acceleration() == pytest.approx((0.52, -0.13, 9.93), abs=0.006)
    assert imu.gravity() == pytest.approx((0.0, 0.3, 9.8), abs=0.006)
    assert imu.linear_acceleration() == pytest.approx((0.52, -0.43, 0.13), abs=0.011)
    state["acc"] = [float("nan"), 0.0, 0.0]  # not finite: the chip keeps what it had
    assert imu.acceleration() == pytest.approx((0.52, -0.13, 9.93), abs=0.006)
    state["acc"] = "junk"
    assert imu.acceleration() == pytest.approx((0.52, -0.13, 9.93), abs=0.006)
    imu._write(0x3D, b"\x00")  # CONFIG: no fusion, no sensor data
    assert imu.acceleration() == imu.gravity() == (0.0, 0.0, 0.0)
    state["acc"] = [400.0, 0.0, 0.0]  # beyond the int16 range: clipped
    imu._write(0x3D, b"\x0c")
    assert imu.acceleration()[0] == pytest.approx(327.67)


def test_the_radio_driver_sends_the_imu_heading_broadcasts_and_reads() -> None:
    clock = Clock()
    s = Swarm([(0.0, 0.0), (4.0, 0.0)], ideal=True)
    pending: dict[int, bytearray] = {0: bytearray(), 1: bytearray()}

    def take(r: int, m: UwbRadio, t: int) -> bytes:
        out = bytes(pending[r])
        pending[r].clear()
        return out

    def step(t_ns: int, data: bytes) -> bytes:  # robot 0's port drives the swarm one quantum per tick
        pending[0] += data
        s.run(t_ns + 1, take)
        out, s.host[0] = bytes(s.host[0]), bytearray()
        return out

    line = Line(clock, step)
    robot = SimpleNamespace(clock=clock, devices={"imu": SimpleNamespace(heading=lambda: math.radians(-90.0))})
    radio = ZebroUwbRadio(line, clock, robot)
    assert radio.info["queue"] == 16
    pending[1] += P.frame(P.SET_HEADING, struct.pack("<H", 4500)) + P.frame(P.SEND, b"\x01from-one")
    sent = [radio.broadcast(b"m%d" % k) for k in range(20)]
    assert sent == [True] * 16 + [False] * 4  # the queue's 16 places, counted by the driver
    for _ in range(250):
        line.tick()
    nbs, msgs = radio.neighbours(), radio.receive()
    assert [m.data for m in msgs] == [b"from-one"] and msgs[0].src == 1
    assert len(nbs) == 1 and nbs[0].id == 1 and nbs[0].range_m == 4.0 and nbs[0].bearing_rad == 0.0
    assert nbs[0].heading_rad == pytest.approx(math.radians(45.0))
    assert s.modules[0].heading_cdeg == 27000  # -90 degrees from the IMU, as 0..360
    assert radio.broadcast(b"again")  # the queue drained: room again
    with pytest.raises(ValueError):
        radio.broadcast(bytes(P.MAX_PAYLOAD + 1))


def test_a_model_s_own_serial_ports() -> None:
    """``RobotSpec.ports``: sitl:// knows the installed models' ports; ports belong to a model's own entities."""
    import serial

    from bridge import sitl as urlhandler
    from bridge.core.registry import RobotSpec, robot_spec
    from swarm_logic.plugins import PluginError

    urlhandler.register()
    for dev in ("uwb_radio", "imu"):  # a known port: only the missing session stops it
        with pytest.raises(serial.SerialException, match="no SITL robot in this thread"):
            serial.serial_for_url(f"sitl://{dev}", baudrate=115200)
    with pytest.raises(PluginError, match="serial ports belong to its own firmware entities"):
        RobotSpec("portbot", robot_spec("decizebro").profile, ports={"gps": 9600})
