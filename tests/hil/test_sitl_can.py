"""The ``sitl`` python-can interface: found by entry point, sim-time timestamps and timeouts, filters."""

from __future__ import annotations

import can
import pytest

from bridge.hosts.sim_context import RobotRuntime, SessionClock

MS = 1_000_000


def test_registered_as_python_can_interface() -> None:
    assert "sitl" in can.interfaces.VALID_INTERFACES


def test_clear_error_outside_a_session() -> None:
    with pytest.raises(can.CanInitializationError, match="no SITL robot in this thread"):
        can.Bus(interface="sitl", channel="can0")


def run_program(program) -> RobotRuntime:
    rt = RobotRuntime(0)
    rt.start(program)
    return rt


def test_recv_blocks_in_sim_time_and_honours_filters() -> None:
    log: list = []

    def program() -> None:
        bus = can.Bus(interface="sitl", channel="can0", can_filters=[{"can_id": 0x180, "can_mask": 0x7FF}])
        log.append(("first", bus.recv(timeout=0.5)))
        log.append(("second", bus.recv(timeout=0.5)))
        bus.shutdown()

    rt = run_program(program)
    rt.resume(0)
    assert rt.wake_ns == 500 * MS and rt.wom  # blocked until t=0.5 s or a message
    rt.deliver("can0", (0x181, b"\x00", False, 100 * MS))  # filtered out
    rt.resume(100 * MS)
    assert not log and rt.wake_ns == 500 * MS  # still waiting, same deadline
    rt.deliver("can0", (0x180, b"\x01\x02", False, 200 * MS))
    rt.resume(200 * MS)
    assert log[0][1].arbitration_id == 0x180 and log[0][1].timestamp == pytest.approx(0.2)
    assert rt.wake_ns == 700 * MS
    rt.resume(700 * MS)
    assert log[1] == ("second", None)
    assert rt.finished and rt.error is None


def test_send_goes_to_outbox_and_rejects_invalid_frames() -> None:
    errors: list = []

    def program() -> None:
        bus = can.Bus(interface="sitl", channel="can0")
        bus.send(can.Message(arbitration_id=0x100, data=b"\x01\x02", is_extended_id=False))
        for bad in (can.Message(arbitration_id=0x800, data=b"", is_extended_id=False),
                    can.Message(arbitration_id=0x1, data=bytes(12), is_fd=True)):
            try:
                bus.send(bad)
            except can.CanOperationError as e:
                errors.append(str(e))
        SessionClock(rt).sleep(0.1)

    rt = run_program(program)
    rt.resume(0)
    assert rt.outbox == [["can0", 0x100, b"\x01\x02", False]]
    assert len(errors) == 2
    assert rt.wake_ns == 100 * MS and not rt.wom


def test_exception_in_robot_code_is_reported_not_raised() -> None:
    def program() -> None:
        raise ValueError("boom")

    rt = run_program(program)
    rt.resume(0)
    assert rt.finished and "ValueError: boom" in rt.error


def test_stop_unwinds_a_blocked_robot() -> None:
    cleaned: list = []

    def program() -> None:
        try:
            SessionClock(rt).sleep(10)
        finally:
            cleaned.append(True)

    rt = run_program(program)
    rt.resume(0)
    rt.stop()
    assert cleaned == [True] and rt.finished and rt.error is None


def test_receive_own_messages_and_error_frames() -> None:
    got: list = []

    def program() -> None:
        bus = can.Bus(interface="sitl", channel="can0", receive_own_messages=True)
        bus.send(can.Message(arbitration_id=0x100, data=b"\x07", is_extended_id=False))
        got.append(bus.recv(timeout=1.0))
        got.append(bus.recv(timeout=1.0))
        quiet = can.Bus(interface="sitl", channel="can1", ignore_rx_error_frames=True)
        got.append(quiet.recv(timeout=1.0))

    rt = run_program(program)
    rt.resume(0)
    assert rt.outbox == [["can0", 0x100, b"\x07", False, True]]  # asks the world for the echo
    rt.deliver("can0", (0x100, b"\x07", False, 3 * MS, 1))  # the echo, as the world sends it after the wire
    rt.deliver("can0", (0x88, bytes([0, 0x20, 0, 0, 0, 0, 130, 0]), False, 4 * MS, 2))  # an error frame
    rt.deliver("can1", (0x88, bytes(8), False, 4 * MS, 2))
    rt.resume(10 * MS)
    rt.resume(10 * MS)
    rt.resume(1010 * MS)
    own, err, nothing = got
    assert own.arbitration_id == 0x100 and not own.is_rx and own.timestamp == pytest.approx(0.003)
    assert err.is_error_frame and err.data[6] == 130
    assert nothing is None  # the error frame on can1 was ignored as asked


def test_bus_off_state_refuses_sends() -> None:
    seen: list = []

    def program() -> None:
        bus = can.Bus(interface="sitl", channel="can0")
        seen.append(bus.state)
        SessionClock(rt).sleep(0.1)
        seen.append(bus.state)
        try:
            bus.send(can.Message(arbitration_id=0x100, data=b"", is_extended_id=False))
        except can.CanOperationError as e:
            seen.append(str(e))

    rt = run_program(program)
    rt.resume(0)
    rt.bus_state["can0"] = ("bus_off", 256, 0)
    rt.resume(100 * MS)
    assert seen[0] == can.BusState.ACTIVE and seen[1] == can.BusState.ERROR
    assert "bus-off" in seen[2] and rt.outbox == []


def test_send_periodic_runs_in_sim_time_while_the_thread_sleeps() -> None:
    tasks: list = []

    def program() -> None:
        bus = can.Bus(interface="sitl", channel="can0")
        msg = can.Message(arbitration_id=0x101, data=b"\x00", is_extended_id=False)

        def count(m: can.Message) -> None:
            m.data[0] = (m.data[0] + 1) & 0xFF

        tasks.append(bus.send_periodic(msg, 0.025, duration=0.1, modifier_callback=count))
        SessionClock(rt).sleep(1.0)
        bus.shutdown()

    rt = run_program(program)
    rt.resume(0)
    assert [i[2] for i in rt.outbox] == [b"\x01"] and rt.next_wake() == 25 * MS  # the first at once
    sent = list(rt.outbox)
    for t in range(10, 200, 10):  # the world wakes the entity for the timer; the thread sleeps on
        rt.outbox = []
        rt.run_timers(t * MS)
        assert not rt.due(t * MS, set())
        sent += rt.outbox
    assert [i[2][0] for i in sent] == [1, 2, 3, 4]  # at 0, 25, 50, 75 ms; the duration ends it before 100 ms
    assert rt.timers == [] and rt.next_wake() == 1000 * MS
    rt.resume(1000 * MS)
    assert rt.finished and rt.error is None


def test_send_periodic_stops_with_the_bus() -> None:
    def program() -> None:
        bus = can.Bus(interface="sitl", channel="can0")
        bus.send_periodic(can.Message(arbitration_id=0x101, data=b"", is_extended_id=False), 0.01)
        SessionClock(rt).sleep(0.05)
        bus.shutdown()
        SessionClock(rt).sleep(1.0)

    rt = run_program(program)
    rt.resume(0)
    for t in range(10, 60, 10):
        rt.run_timers(t * MS)
    rt.resume(50 * MS)
    assert len(rt.outbox) == 6 and rt.timers == [] and rt.next_wake() == 1050 * MS
