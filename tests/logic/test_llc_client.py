"""The swarm-logic LLC driver works over any python-can bus: here python-can's own ``virtual`` bus, wired
to the emulated LLC board, with no part of the session (hub, zenoh, SITL bus) involved."""

from __future__ import annotations

import math
import uuid

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_sim.board.arduino import Board
from firmware_sim.board.can_controller import Frame
from firmware_sim.robots.eswarbot.llc import PIN_BATTERY, PIN_PWM, LlcParams, LowLevelController
from swarm_logic.drivers.llc_client import LlcClient


class VirtualWiredLlc:
    """An LLC board whose CAN controller is attached to a python-can virtual bus channel."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.board = Board()
        self.board.analog_volts[PIN_BATTERY] = 4.1
        self.llc = LowLevelController(self.board, LlcParams())
        self.llc.setup()

    def loop_ms(self, ms: int) -> None:
        for _ in range(ms // 20):
            while (m := self.bus.recv(timeout=0)) is not None:
                self.board.can.on_bus_frame(Frame(m.arbitration_id, bytes(m.data)))
            self.board.time_us += 20_000
            self.llc.loop()
            for f in self.board.can.take_tx():
                self.bus.send(can.Message(arbitration_id=f.arbitration_id, data=f.data, is_extended_id=False))


def pair() -> tuple[LlcClient, VirtualWiredLlc, can.BusABC]:
    ch = f"t-{uuid.uuid4().hex}"
    llc = VirtualWiredLlc(ch)
    bus = can.Bus(interface="virtual", channel=ch)
    return LlcClient(bus), llc, bus


def test_client_commands_and_telemetry_over_virtual_bus() -> None:
    client, llc, bus = pair()
    try:
        client.drive(0.2, 0.0)
        client.set_led(1, 2, 3)
        llc.loop_ms(200)
        assert llc.llc.v_cmd == 0.2
        assert llc.board.led_rgb == (1, 2, 3)
        assert llc.board.pwm[PIN_PWM[0]] > 0
        client.poll()
        st_ = client.state
        assert st_.heartbeat >= 1 and st_.battery_v > 8.0
        assert st_.odom_t is not None and st_.sonar_t is not None
        assert client.rx_unknown == 0 and client.rx_bad_length == 0
    finally:
        bus.shutdown()
        llc.bus.shutdown()


def test_client_counts_and_drops_malformed_frames() -> None:
    client, llc, bus = pair()
    try:
        llc.bus.send(can.Message(arbitration_id=0x7AB, data=b"\x01", is_extended_id=False))
        llc.bus.send(can.Message(arbitration_id=0x181, data=b"\x01\x02", is_extended_id=False))
        llc.bus.send(can.Message(arbitration_id=0x100, data=bytes(5), is_extended_id=False))  # a command, not telemetry
        llc.bus.send(can.Message(arbitration_id=0x181, data=bytes(8)))  # python-can's default: an extended id
        client.poll()
        assert client.rx_unknown == 2 and client.rx_bad_length == 2 and client.rx_frames == 0
    finally:
        bus.shutdown()
        llc.bus.shutdown()


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 0x7FF), st.binary(max_size=8)), max_size=30))
def test_random_frames_never_crash_the_client(frames: list[tuple[int, bytes]]) -> None:
    client, llc, bus = pair()
    try:
        for arb, data in frames:
            llc.bus.send(can.Message(arbitration_id=arb, data=data, is_extended_id=False))
        client.poll()
        assert client.rx_frames + client.rx_unknown + client.rx_bad_length == len(frames)
    finally:
        bus.shutdown()
        llc.bus.shutdown()


def test_client_moves_and_decodes_move_status() -> None:
    client, llc, bus = pair()
    try:
        seq = client.move(math.pi / 2, 0.0, 0.1)
        llc.loop_ms(100)
        client.poll()
        st_ = client.state
        assert (st_.move_seq, st_.move_state, st_.move_rot_pulses) == (seq, "rotating", 0) and st_.move_t is not None
        llc.board.encoder_counts = [-25, 25]  # the wheels turned (no plant here): 25 pulses each
        llc.loop_ms(40)
        client.poll()
        assert (st_.move_seq, st_.move_state, st_.move_rot_pulses, st_.move_fwd_pulses) == (seq, "done", 25, 0)
        seq2 = client.move(-0.5, 0.2, 5.0)  # 5 m/s: the LLC caps it at the wheels' top speed
        assert seq2 == (seq + 1) & 0xFF
        llc.loop_ms(40)
        client.drive(0.0, 0.0)  # a DRIVE_CMD aborts it
        llc.loop_ms(40)
        client.poll()
        assert (st_.move_seq, st_.move_state) == (seq2, "aborted")
        assert llc.llc.move_pps * llc.llc.m_per_pulse == pytest.approx(16.6 * 0.02109)
        assert not st_.pose_ideal and st_.faults and "pose_ideal" not in st_.faults
    finally:
        bus.shutdown()
        llc.bus.shutdown()


def test_client_refuses_moves_the_llc_would_refuse() -> None:
    client, llc, bus = pair()
    try:
        for args in ((0.0, -0.1, 0.1), (0.0, 0.1, 0.0), (math.nan, 0.1, 0.1)):
            with pytest.raises(ValueError):
                client.move(*args)
        client.move(3 * math.pi / 2, 0.1, 0.1)  # 270 deg counter-clockwise is 90 deg clockwise
        llc.loop_ms(20)
        assert llc.llc.move_dir == -1 and llc.llc.move_pulses == (25, 36) and llc.llc.rx_bad == 0
    finally:
        bus.shutdown()
        llc.bus.shutdown()


def test_client_sees_the_ideal_pose_flag() -> None:
    client, llc, bus = pair()
    try:
        llc.board.external_pose = (1.2, 3.4, -0.5)
        llc.loop_ms(200)
        client.poll()
        st_ = client.state
        assert st_.pose_ideal and (st_.x, st_.y, st_.theta) == (1.2, 3.4, -0.5)
    finally:
        bus.shutdown()
        llc.bus.shutdown()


def test_client_speaks_the_can_database_it_is_given() -> None:
    """A robot with another CAN interface hands the client its database; the eSwarBot's is the default."""
    import cantools

    from swarm_logic.robots.eswarbot import ESWARBOT_LLC_DBC, eswarbot_llc_db

    dbc = ESWARBOT_LLC_DBC.read_text().replace("BO_ 256 DRIVE_CMD:", "BO_ 300 DRIVE_CMD:")
    other = cantools.database.load_string(dbc, database_format="dbc")
    ch = f"t-{uuid.uuid4().hex}"
    with can.Bus(interface="virtual", channel=ch) as tx, can.Bus(interface="virtual", channel=ch) as rx:
        assert LlcClient(tx).db is eswarbot_llc_db()
        LlcClient(tx, other).drive(0.1, 0.0)
        m = rx.recv(timeout=0)
        assert m is not None and m.arbitration_id == 300
        assert other.decode_message(300, m.data)["v_mm_s"] == 100
