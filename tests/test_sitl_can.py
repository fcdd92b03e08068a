"""The ``sitl`` python-can interface: found by entry point, sim-time timestamps and timeouts, filters."""

from __future__ import annotations

import can
import pytest

from bridge.sim_context import RobotRuntime, SessionClock

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
