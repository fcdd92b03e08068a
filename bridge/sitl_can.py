"""The ``sitl`` python-can interface: a robot's simulated CAN bus, found by python-can's entry point.

``can.Bus(interface="sitl", channel="can0")`` inside a SITL robot program returns this bus; the swarm
logic cannot tell it from a real adapter. Frames go onto the session's CAN medium (arbitration, bit
time) and arrive at the other nodes of the robot's bus. Timestamps are in simulated seconds, and a
blocking ``recv(timeout)`` waits in simulated time.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any

import can
from can import BusABC, CanInitializationError, CanOperationError, Message

from bridge import sim_context
from bridge.can_medium import frame_fault


class SitlBus(BusABC):
    def __init__(self, channel: Any = "can0", *, receive_own_messages: bool = False, **kwargs: Any) -> None:
        try:
            self._rt = sim_context.current()
        except sim_context.NotInSession as e:
            raise CanInitializationError(str(e)) from None
        if receive_own_messages:
            raise CanInitializationError("the sitl interface does not support receive_own_messages yet")
        self.channel = str(channel)
        self.channel_info = f"swarm-sitl robot {self._rt.robot_id} {self.channel}"
        try:
            self._rx: deque = self._rt.open_bus(self.channel)
        except OSError as e:
            raise CanInitializationError(str(e)) from None
        self._open = True
        super().__init__(channel=channel, **kwargs)

    def _check_thread(self) -> None:
        if threading.current_thread() is not self._rt.thread:
            raise CanOperationError(
                "a sitl bus is used from its robot's own thread only (python-can Notifier threads are not "
                "supported in SITL: they would run outside simulated time)"
            )

    def send(self, msg: Message, timeout: float | None = None) -> None:
        self._check_thread()
        if not self._open:
            raise CanOperationError("bus is shut down")
        if msg.is_fd or msg.is_error_frame or msg.is_remote_frame:
            raise CanOperationError("the simulated bus carries classic CAN data frames only")
        data = bytes(msg.data)
        if (fault := frame_fault(msg.arbitration_id, data, msg.is_extended_id)) is not None:
            raise CanOperationError(fault)
        self._rt.outbox.append([self.channel, msg.arbitration_id, data, msg.is_extended_id])

    def _to_message(self, item: tuple) -> Message:
        arb_id, data, ext, t_ns = item
        return Message(timestamp=t_ns / 1e9, arbitration_id=arb_id, data=data, is_extended_id=ext,
                       channel=self.channel, is_rx=True)

    def recv(self, timeout: float | None = None) -> Message | None:
        """Next frame that passes the filters; waits up to ``timeout`` simulated seconds."""
        self._check_thread()
        rt = self._rt
        deadline = None if timeout is None else rt.t_ns + max(0, round(timeout * 1e9))
        while True:
            while self._rx:
                msg = self._to_message(self._rx.popleft())
                if self._matches_filters(msg):
                    return msg
            if deadline is not None and rt.t_ns >= deadline:
                return None
            rt.block(deadline, self.channel)

    def shutdown(self) -> None:
        if self._open:
            self._open = False
            self._rt.close_bus(self.channel)
        super().shutdown()

    @staticmethod
    def _detect_available_configs() -> list[can.typechecking.AutoDetectedConfig]:
        return []
