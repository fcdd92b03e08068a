"""The I2C medium and the simulated smbus2 bus, on a lock-step bench with DeciZebro leg modules (no processes): bit
timing at 100 and 400 kHz, the read round trip through the slave's firmware, NACKs as the Linux driver reports them,
the general call, time-outs, refused transactions, and the smbus2 calls."""

from __future__ import annotations

import errno
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from smbus2 import i2c_msg

from bridge.core.registry import MEDIA
from bridge.media.i2c import EINVAL, EREMOTEIO, ETIMEDOUT, I2cBuses, uses_i2c
from bridge.robots.decizebro import firmware
from bridge.sitl.smbus import SMBus
from firmware_sim.robots.decizebro import zebrobus as zb
from firmware_sim.robots.sonpi.hcsr04 import RangerParams, Rangers
from firmware_sim.robots.sonpi.sonar_board import SonarBoard
from swarm_logic.drivers.i2c import open_smbus
from swarm_logic.robots.sonpi import board_protocol as P
from swarm_logic.robots.sonpi.interfaces import SONAR_ANGLES_RAD
from tests.support.i2c_bench import I2cBench, Q
from tests.support.sonpi_bench import MOTORS

US = 1_000


def bench_run(program: Any, until_ns: int = 200 * Q, **kw: Any) -> I2cBench:
    b = I2cBench(program, **kw)
    try:
        b.run_until(until_ns)
    finally:
        b.close()
    return b


def test_linux_errno_values() -> None:
    assert (EREMOTEIO, ETIMEDOUT, EINVAL) == (errno.EREMOTEIO, errno.ETIMEDOUT, errno.EINVAL)


@pytest.mark.parametrize("hz", [100_000, 400_000])
def test_a_write_takes_its_bits_at_the_bus_rate_and_returns_at_the_next_boundary(hz: int) -> None:
    got: dict[str, Any] = {}

    def program(rt, clock) -> None:
        bus = SMBus("sitl://i2c", scl_hz=hz)
        t0 = rt.t_ns
        bus.write_i2c_block_data(0x10, zb.TEST_FIELD, [1, 2, 3])
        got["took"] = rt.t_ns - t0

    b = bench_run(program)
    assert got["took"] == Q  # the call blocks until the transaction ends, at the next quantum boundary
    (txn,) = b.transactions()
    bits = 1 + 9 + 9 * 4 + 1  # START, address, register + 3 data bytes, STOP
    assert txn["bits"] == bits and txn["status"] == "ok"
    assert txn["end_ns"] - txn["start_ns"] == round(bits * 1e9 / hz)  # 470 us at 100 kHz, 117.5 us at 400 kHz
    assert b.modules["r000/leg0"].vregs[zb.TEST_FIELD] == 1


def test_a_long_transaction_ends_when_its_bits_do() -> None:
    got: dict[str, Any] = {}

    def program(rt, clock) -> None:
        bus = SMBus("sitl://i2c")
        t0 = rt.t_ns
        bus.i2c_rdwr(i2c_msg.write(0x00, [zb.TEST_FIELD] + [0] * 1199))  # 10,811 bits at 100 kHz: 108 ms
        got["took"] = rt.t_ns - t0

    b = bench_run(program)
    (txn,) = b.transactions()
    assert txn["end_ns"] - txn["start_ns"] == 108_110 * US
    assert got["took"] == 11 * Q


def test_a_read_round_trips_through_the_slaves_firmware() -> None:
    got: dict[str, Any] = {}

    def program(rt, clock) -> None:
        bus = SMBus("sitl://i2c", scl_hz=100_000)
        t0 = rt.t_ns
        got["ids"] = bus.read_i2c_block_data(0x12, zb.ZEBROBUS_VERSION, 7)
        got["took"] = rt.t_ns - t0
        got["byte"] = bus.read_byte_data(0x12, zb.ZEBROBUS_ADDRESS)

    b = bench_run(program)
    assert got["ids"] == [1, zb.LEG_CLASS, 1, 1, 1, 1, 0x12] and got["byte"] == 0x12
    assert got["took"] == 2 * Q  # the slave answers in the quantum it gets the request; the master one later
    txn = b.transactions()[0]
    # the slave stretched SCL from the read's address until its firmware ran at the next boundary; then 7 bytes
    # and the STOP at 10 us a bit
    assert txn["end_ns"] == Q + (9 * 7 + 1) * 10 * US and txn["bits"] == 1 + 9 + 9 + 1 + 9 + 63 + 1
    assert txn["msgs"][1] == {"addr": 0x12, "read": True, "ack": True, "data": "01010101010112"}


def test_an_absent_address_is_nacked_as_the_linux_driver_reports_it() -> None:
    got: dict[str, Any] = {}

    def program(rt, clock) -> None:
        bus = SMBus("sitl://i2c")
        for name, call in (
            ("absent", lambda: bus.write_byte_data(0x30, 0, 1)),
            ("multicast", lambda: bus.write_byte_data(0x05, 0, 1)),
            ("general call read", lambda: bus.read_byte(0x00)),
        ):
            t0 = rt.t_ns
            try:
                call()
            except OSError as e:
                got[name] = (e.errno, rt.t_ns - t0)
        got["still"] = bus.read_byte_data(0x10, zb.CLASS_ID)  # the program goes on

    b = bench_run(program)
    assert got["absent"] == got["multicast"] == got["general call read"] == (errno.EREMOTEIO, Q)
    assert got["still"] == zb.LEG_CLASS
    txns = b.transactions()
    assert [t["status"] for t in txns] == ["nack", "nack", "nack", "ok"]
    assert txns[0]["bits"] == 1 + 9 + 1 and txns[0]["msgs"] == [
        {"addr": 0x30, "read": False, "ack": False, "data": "0001"}
    ]
    out: dict[str, Any] = {"robots": [{}]}
    b.sim_end_ns = b.t
    b.medium.report(out)
    i2c = out["robots"][0]["i2c"]
    assert i2c["nacks"] == 3 and i2c["transactions"] == 4 and i2c["slaves"]["0x10"] == "leg0"
    assert i2c["bytes"] == 2  # the register byte and the byte read; NACKed messages carry none
    assert out["message_counts"]["i2c_nacks"] == 3


def sonpi_bench(program: Any) -> I2cBench:
    """The bench with one leg module at 0x10 and a SonPI's Arduino sketch at 0x20, a slave that may refuse reads."""
    rangers = Rangers(RangerParams(SONAR_ANGLES_RAD, 0.09, 0.0, 0.0, 0.0))
    arduino = SonarBoard(rangers, MOTORS, np.random.default_rng(1))
    return bench_run(program, legs=1, slaves={"r000/arduino": arduino})


def test_a_slave_may_refuse_a_read_and_its_address_is_nacked() -> None:
    got: dict[str, Any] = {}

    def program(rt, clock) -> None:
        bus = SMBus("sitl://i2c", scl_hz=100_000)
        t0 = rt.t_ns
        try:
            bus.read_byte_data(P.ADDRESS, 0x07)  # a missing register: the sketch refuses the read
        except OSError as e:
            got["refused"] = (e.errno, rt.t_ns - t0)
        got["who"] = bus.read_byte_data(P.ADDRESS, P.WHO_AM_I)
        got["errors"] = bus.read_i2c_block_data(P.ADDRESS, P.ERROR_COUNT, 2)

    b = sonpi_bench(program)
    assert got["refused"] == (errno.EREMOTEIO, 2 * Q)  # as long as a read: the sketch decided in its quantum
    assert got["who"] == P.WHO_AM_I_VALUE and got["errors"] == [1, P.ERR_BAD_REGISTER]
    txn = b.transactions()[0]
    assert txn["status"] == "nack" and txn["bits"] == 1 + 9 + 9 + 1 + 9 + 1  # the read's address NACKed, STOP
    assert txn["msgs"] == [
        {"addr": 0x20, "read": False, "ack": True, "data": "07"},
        {"addr": 0x20, "read": True, "ack": False, "data": ""},
    ]
    # SCL held from the read's address until the sketch ran at the next boundary, then the NACK and the STOP
    assert txn["start_ns"] == 0 and txn["end_ns"] == Q + 10 * US
    assert b.modules["r000/arduino"].counters["refused_reads"] == 1
    out: dict[str, Any] = {"robots": [{}]}
    b.sim_end_ns = b.t
    b.medium.report(out)
    assert out["robots"][0]["i2c"]["nacks"] == 1 and out["robots"][0]["i2c"]["slaves"]["0x20"] == "arduino"


def test_a_refused_read_ends_the_transaction_and_what_follows_it_never_runs() -> None:
    got: dict[str, Any] = {}

    def program(rt, clock) -> None:
        bus = SMBus("sitl://i2c")
        leg_write = i2c_msg.write(0x10, [zb.TEST_FIELD, 0x5A])
        try:
            bus.i2c_rdwr(i2c_msg.write(P.ADDRESS, [0x30]), i2c_msg.read(P.ADDRESS, 2), leg_write)
        except OSError as e:
            got["refused"] = e.errno
        got["leg"] = bus.read_byte_data(0x10, zb.TEST_FIELD)
        # accepted, the rest goes on once the sketch has answered: one quantum more than the reads take together
        who, back, firing = i2c_msg.read(P.ADDRESS, 2), i2c_msg.read(0x10, 1), i2c_msg.read(P.ADDRESS, 1)
        msgs = [i2c_msg.write(P.ADDRESS, [P.WHO_AM_I]), who, leg_write, i2c_msg.write(0x10, [zb.CLASS_ID]), back]
        t0 = rt.t_ns
        bus.i2c_rdwr(*msgs, i2c_msg.write(P.ADDRESS, [P.FIRING]), firing)
        got["took"] = rt.t_ns - t0
        got["reads"] = [list(who), list(back), list(firing)]

    b = sonpi_bench(program)
    assert got["refused"] == errno.EREMOTEIO and got["leg"] == 0  # the leg never saw its write
    assert got["reads"] == [[P.WHO_AM_I_VALUE, P.VERSION_VALUE], [zb.LEG_CLASS], [P.FIRING_SEQUENTIAL]]
    assert got["took"] == 3 * Q
    assert b.modules["r000/leg0"].vregs[zb.TEST_FIELD] == 0x5A
    refused, _, accepted = b.transactions()
    assert [m["addr"] for m in refused["msgs"]] == [0x20, 0x20] and refused["msgs"][1]["ack"] is False
    assert accepted["status"] == "ok" and all(m["ack"] for m in accepted["msgs"]) and len(accepted["msgs"]) == 7
    assert accepted["bits"] == 1 + (9 + 9) + (1 + 9 + 18) + (1 + 9 + 18) + 4 * (1 + 9 + 9) + 1
    assert b.modules["r000/arduino"].counters["transactions"] == 2  # the second came in two parts


def test_only_a_slave_that_said_it_may_refuse_reads_can() -> None:
    b = I2cBench(legs=1)
    b.run_until(Q)
    b.medium.submit(0, b.t, 1, [(0x10, False, bytes([zb.CLASS_ID])), (0x10, True, 1)], 100_000, lambda t, r: None)
    b.medium.advance(b.t)
    (txn,) = b.medium.in_flight
    with pytest.raises(TypeError):  # the hub counts it as a malformed item
        b.medium.slave("r000/leg0", 0, b.t, ["i2c", txn, [None]])
    for bad in (["i2c_attach", 0x40, False, 1], ["i2c_attach", 0x40, False, True, True]):
        with pytest.raises(ValueError):
            b.medium.attach("r000/x", 0, b.t, bad)


def test_a_slave_answers_only_once_it_has_powered_up() -> None:
    got: list[Any] = []

    def program(rt, clock) -> None:
        bus = SMBus("sitl://i2c")
        for _ in range(2):
            try:
                got.append(bus.read_byte_data(0x10, zb.CLASS_ID))
            except OSError as e:
                got.append(e.errno)
            clock.sleep(0.2)

    bench_run(program, boot_ns=20 * Q)
    assert got == [errno.EREMOTEIO, zb.LEG_CLASS]


def test_the_general_call_reaches_every_leg_at_once() -> None:
    def program(rt, clock) -> None:
        SMBus("sitl://i2c").write_byte_data(0x00, zb.TEST_FIELD, 0x5A)

    b = bench_run(program)
    assert all(m.vregs[zb.TEST_FIELD] == 0x5A for m in b.modules.values())
    assert b.medium.buses[0].counts["general_calls"] == 1


def test_i2c_rdwr_fills_the_read_buffers_and_smbus_words_are_little_endian() -> None:
    got: dict[str, Any] = {}

    def program(rt, clock) -> None:
        with SMBus("sitl://i2c") as bus:
            w, r = i2c_msg.write(0x11, [zb.ZEBROBUS_ADDRESS]), i2c_msg.read(0x11, 2)
            bus.i2c_rdwr(w, r)
            got["rdwr"] = list(r)
            got["word"] = bus.read_word_data(0x11, zb.ZEBROBUS_VERSION)
            bus.write_quick(0x11)
            bus.write_byte(0x11, zb.TEST_FIELD)  # sets the pointer only
            got["byte"] = bus.read_byte(0x11)  # reads at the pointer
            with pytest.raises(ValueError):
                bus.write_i2c_block_data(0x11, 0, [0] * 33)
            with pytest.raises(OSError) as e:
                bus.read_block_data(0x11, 0)
            got["block"] = e.value.errno
            with pytest.raises(OSError):
                bus.enable_pec()
        with pytest.raises(OSError) as e:
            bus.read_byte(0x11)  # closed
        got["closed"] = e.value.errno

    bench_run(program)
    assert got["rdwr"] == [0x11, 0] and got["word"] == 0x0101 and got["byte"] == 0
    assert got["block"] == errno.EOPNOTSUPP and got["closed"] == errno.EBADF


def test_a_slave_that_does_not_answer_times_the_read_out() -> None:
    got: dict[str, Any] = {}

    class Mute:
        def run(self, t_ns: int, inputs: dict) -> dict:
            out = [["i2c_attach", 0x40, False]] if t_ns == 0 else []
            return {"out": out, "wake": None, "wom": ["i2c"]}

    def program(rt, clock) -> None:
        bus = SMBus("sitl://i2c")
        t0 = rt.t_ns
        try:
            bus.read_byte_data(0x40, 0)
        except OSError as e:
            got["err"] = (e.errno, rt.t_ns - t0)

    b = I2cBench(program, legs=0)
    b.modules["r000/mute0"] = Mute()
    b.next_wake["r000/mute0"] = 0
    try:
        b.run_until(50 * Q)
    finally:
        b.close()
    assert got["err"] == (errno.ETIMEDOUT, 2 * Q)
    assert b.transactions()[0]["status"] == "timeout"


def test_a_malformed_transaction_is_refused_not_fatal() -> None:
    b = I2cBench()
    b.medium.master("r000/logic", 0, 0, ["i2c", 7, [[0x10, False, "not bytes"]], 100_000])
    b.medium.master("r000/logic", 0, 0, ["i2c", 8, [[0x10, True, 0]], 100_000])
    b.medium.master("r000/logic", 0, 0, ["i2c", 9, [[0x10, False, b"\x00"]], 5])
    with pytest.raises(ValueError):
        b.medium.master("r000/logic", 0, 0, ["i2c", "no seq"])  # the hub counts it as a malformed item
    b.run_until(2 * Q)
    assert [item[1][:2] for item in b.inbox["r000/logic"]] == [[7, EINVAL], [8, EINVAL], [9, EINVAL]]
    assert b.counts["i2c_invalid"] == 3


def test_transactions_from_two_masters_share_the_bus_in_turn() -> None:
    b = I2cBench()
    b.run_until(Q)  # the legs have announced themselves
    done: list[list] = []
    for seq in (1, 2):
        b.medium.submit(
            0, b.t, seq, [(0x10, False, bytes([zb.TEST_FIELD, seq]))], 100_000, lambda t, res: done.append([t, *res])
        )
    b.run_until(3 * Q)
    (t1, s1, e1, _, end1), (t2, s2, e2, _, end2) = done
    assert (s1, s2, e1, e2) == (1, 2, 0, 0) and t1 == t2 == 2 * Q
    assert end2 - end1 == 290 * US  # the second starts when the first has ended: 29 bits at 10 us


def test_the_medium_is_built_for_robots_whose_hal_names_the_bus_and_found_by_url() -> None:
    assert uses_i2c({"legs": {"bus": "sitl://i2c"}}) and not uses_i2c({"legs": {"bus": 1}, "uwb": {}})
    specs = {"plain": SimpleNamespace(hal=None), "legged": SimpleNamespace(hal=firmware.hal)}

    def hub(*kinds: str, options: dict | None = None) -> Any:
        roles = ("i2c_adapter",) if options else ()
        robots = [SimpleNamespace(profile=k, gateway=None, options=options or {}, modules=lambda: roles) for k in kinds]
        return SimpleNamespace(
            plan=SimpleNamespace(robots=robots), cfg=None, robot_spec=lambda r: specs[robots[r].profile]
        )

    assert I2cBuses.wanted(hub("plain", "legged")) and not I2cBuses.wanted(hub("plain"))
    exposed = hub("legged", options={"i2c_pty": "r{id}-i2c"})  # the program outside has the bus, not the HAL
    assert not uses_i2c(firmware.hal(exposed.plan.robots[0], None)) and I2cBuses.wanted(exposed)
    assert MEDIA.get("i2c") is I2cBuses
    others = [key for name, cls in MEDIA.items() if name != "i2c" for key in cls.routes]
    assert not set(I2cBuses.routes) & set(others)  # no other medium carries its items
    with pytest.raises(FileNotFoundError, match="no SITL robot"):
        open_smbus("sitl://i2c")  # found by its scheme; outside a session there is no bus to open
    with pytest.raises(ValueError):
        open_smbus(True)  # type: ignore[arg-type]
