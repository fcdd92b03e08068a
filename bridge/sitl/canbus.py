"""The ``sitl`` python-can interface: a robot's simulated CAN bus, found by python-can's entry point.

``can.Bus(interface="sitl", channel="can0")`` inside a SITL robot program returns this bus; the swarm
logic cannot tell it from a real adapter. Frames go onto the session's CAN medium (arbitration, bit
time, error confinement) and arrive at the other nodes of the robot's bus. What python-can users rely on
works as on socketcan, in simulated time:

- timestamps are simulated seconds (when the frame's last bit left the wire); a blocking ``recv(timeout)``
  waits in simulated time; ``can_filters`` / ``set_filters`` apply;
- ``receive_own_messages=True`` returns the node's own frames once they have been on the wire
  (``is_rx`` False);
- error frames are received as ``Message(is_error_frame=True)`` laid out as socketcan's (class bits in the ID,
  TEC and REC in bytes 6 and 7), unless ``ignore_rx_error_frames=True``;
- ``state`` is the node's fault-confinement state (ACTIVE, PASSIVE, or ERROR when bus-off); a send while
  bus-off fails with ``CanOperationError`` as socketcan's does (no buffer space);
- ``send_periodic`` runs in simulated time: the frames leave on schedule while the robot thread waits, as a
  driver's cyclic transmit would.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import can
from can import BusABC, BusState, CanInitializationError, CanOperationError, Message
from can.broadcastmanager import (
    LimitedDurationCyclicSendTaskABC,
    ModifiableCyclicTaskABC,
    RestartableCyclicTaskABC,
)

from bridge.hosts import sim_context
from bridge.media.can import ERROR_FRAME, OWN, frame_fault

STATES = {"active": BusState.ACTIVE, "passive": BusState.PASSIVE, "bus_off": BusState.ERROR}


class SitlBus(BusABC):
    def __init__(self, channel: Any = "can0", *, receive_own_messages: bool = False,
                 ignore_rx_error_frames: bool = False, **kwargs: Any) -> None:
        try:
            self._rt = sim_context.current()
        except sim_context.NotInSession as e:
            raise CanInitializationError(str(e)) from None
        self.channel = str(channel)
        self.channel_info = f"swarm-sitl robot {self._rt.robot_id} {self.channel}"
        self.receive_own_messages = receive_own_messages
        self.ignore_rx_error_frames = ignore_rx_error_frames
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

    @property
    def state(self) -> BusState:
        """The node's error state on the bus: ACTIVE, PASSIVE, or ERROR (bus-off)."""
        return STATES[self._rt.bus_state.get(self.channel, ("active", 0, 0))[0]]

    @state.setter
    def state(self, new_state: BusState) -> None:
        raise NotImplementedError("the sitl interface has no listen-only mode")

    def send(self, msg: Message, timeout: float | None = None) -> None:
        self._check_thread()
        self._put(msg)

    def _put(self, msg: Message) -> None:
        if not self._open:
            raise CanOperationError("bus is shut down")
        if msg.is_fd or msg.is_error_frame or msg.is_remote_frame:
            raise CanOperationError("the simulated bus carries classic CAN data frames only")
        if self.state is BusState.ERROR:
            raise CanOperationError("Failed to transmit: No buffer space available (the CAN controller is bus-off)")
        data = bytes(msg.data)
        if (fault := frame_fault(msg.arbitration_id, data, msg.is_extended_id)) is not None:
            raise CanOperationError(fault)
        item = [self.channel, msg.arbitration_id, data, msg.is_extended_id]
        if self.receive_own_messages:
            item.append(True)  # the world echoes it back once it has been on the wire
        self._rt.outbox.append(item)

    def _to_message(self, item: tuple) -> Message:
        arb_id, data, ext, t_ns = item[:4]
        kind = item[4] if len(item) > 4 else 0
        return Message(timestamp=t_ns / 1e9, arbitration_id=arb_id, data=data, is_extended_id=ext,
                       channel=self.channel, is_rx=kind != OWN, is_error_frame=kind == ERROR_FRAME)

    def recv(self, timeout: float | None = None) -> Message | None:
        """Next frame that passes the filters; waits up to ``timeout`` simulated seconds."""
        self._check_thread()
        rt = self._rt
        deadline = None if timeout is None else rt.t_ns + max(0, round(timeout * 1e9))
        while True:
            while self._rx:
                msg = self._to_message(self._rx.popleft())
                if msg.is_error_frame and self.ignore_rx_error_frames:
                    continue
                if self._matches_filters(msg):
                    return msg
            if deadline is not None and rt.t_ns >= deadline:
                return None
            rt.block(deadline, self.channel)

    def _send_periodic_internal(self, msgs: Sequence[Message] | Message, period: float, duration: float | None = None,
                                autostart: bool = True,
                                modifier_callback: Callable[[Message], None] | None = None) -> SitlCyclicTask:
        self._check_thread()
        return SitlCyclicTask(self, msgs, period, duration, autostart, modifier_callback)

    def shutdown(self) -> None:
        if self._open:
            super().shutdown()  # stops the periodic tasks first
            self._open = False
            self._rt.close_bus(self.channel)

    @staticmethod
    def _detect_available_configs() -> list[can.typechecking.AutoDetectedConfig]:
        return []


class SitlCyclicTask(LimitedDurationCyclicSendTaskABC, ModifiableCyclicTaskABC, RestartableCyclicTaskABC):
    """``send_periodic`` in simulated time: a timer of the robot's runtime sends the frames on schedule, whether
    or not the robot thread runs (the first at once). A send that fails (bus-off) is skipped, as a driver's
    cyclic transmit skips a full queue; the task goes on."""

    def __init__(self, bus: SitlBus, messages: Sequence[Message] | Message, period: float, duration: float | None,
                 autostart: bool, modifier_callback: Callable[[Message], None] | None) -> None:
        if not period > 0:
            raise ValueError(f"period must be > 0 s, got {period!r}")
        super().__init__(messages, period, duration)
        self.bus = bus
        self.modifier_callback = modifier_callback
        self.next_ns: int | None = None
        self.end_ns: int | None = None
        self.index = 0
        self.failed = 0
        if autostart:
            self.start()

    def start(self) -> None:
        rt = self.bus._rt
        self.next_ns = rt.t_ns
        self.end_ns = None if self.duration is None else rt.t_ns + round(self.duration * 1e9)
        if self not in rt.timers:
            rt.timers.append(self)
        self.fire(rt.t_ns)

    def stop(self) -> None:
        rt = self.bus._rt
        self.next_ns = None
        if self in rt.timers:
            rt.timers.remove(self)

    def fire(self, t_ns: int) -> None:
        while self.next_ns is not None and self.next_ns <= t_ns:
            if self.end_ns is not None and self.next_ns >= self.end_ns:
                self.stop()
                return
            msg = self.messages[self.index]
            if self.modifier_callback is not None:
                self.modifier_callback(msg)
            try:
                self.bus._put(msg)
            except CanOperationError:
                self.failed += 1
            self.index = (self.index + 1) % len(self.messages)
            self.next_ns += self.period_ns
