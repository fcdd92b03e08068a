"""The swarm-logic LLC driver works over any python-can bus: here python-can's own ``virtual`` bus, wired
to the emulated LLC board, with no part of the session (hub, zenoh, SITL bus) involved."""

from __future__ import annotations

import uuid

import can
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_sim.arduino import Board
from firmware_sim.can_controller import Frame
from firmware_sim.llc import PIN_BATTERY, PIN_PWM, LlcParams, LowLevelController
from swarm_logic.llc_client import LlcClient


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
