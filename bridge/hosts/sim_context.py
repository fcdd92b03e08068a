"""Simulated time for robot programs that block: each robot's logic runs in its own thread, and exactly
one thread runs at a time (a strict hand-off with the host), so the order of everything is fixed.

A robot thread runs until it blocks in the session clock (``sleep``) or on a device (``bus.recv`` with
a timeout); it then tells the host when it next needs to run (a time, or the next message) and waits.
Robot code needs no change for this: it calls ``clock.sleep`` and ``bus.recv`` as on a real robot.
"""

from __future__ import annotations

import threading
import traceback
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

_local = threading.local()
RX_QUEUE_FRAMES = 4096  # frames a device queue holds before it drops (a socket receive buffer)


class SessionEnded(BaseException):
    """Raised inside a robot thread when the session ends, to unwind it (not an ``Exception``)."""


class NotInSession(RuntimeError):
    pass


def current() -> RobotRuntime:
    rt = getattr(_local, "rt", None)
    if rt is None:
        raise NotInSession(
            "no SITL robot in this thread: sitl devices and the session clock work only inside a robot "
            "program started by the swarm-sitl launcher"
        )
    return rt


class RobotRuntime:
    """The simulated environment of one robot's logic: time, device queues and the hand-off."""

    def __init__(self, robot_id: int) -> None:
        self.robot_id = robot_id
        self.t_ns = 0
        self.wake_ns: int | None = 0
        self.wom: bool | list[str] = False
        self.rx: dict[str, deque] = {}
        self.gone: set[str] = set()  # devices pulled out (an unplugged fault): they cannot be opened again
        self.unrouted = 0
        self.rx_dropped = 0
        self.outbox: list[list[Any]] = []
        self.bus_state: dict[str, tuple[str, int, int]] = {}  # bus -> (state, TEC, REC) of this robot's node on it
        self.timers: list[Timer] = []  # what the robot's devices do by themselves (a CAN adapter's cyclic sends)
        self.error: str | None = None
        self.finished = False
        self.stopping = False
        self._go = threading.Semaphore(0)
        self._back = threading.Semaphore(0)
        self.thread: threading.Thread | None = None

    # -- host side --------------------------------------------------------------------------------
    def start(self, target: Callable[[], None]) -> None:
        self.thread = threading.Thread(target=self._main, args=(target,), name=f"robot-{self.robot_id}", daemon=True)
        self.thread.start()

    def _main(self, target: Callable[[], None]) -> None:
        self._go.acquire()
        _local.rt = self
        try:
            if not self.stopping:
                target()
        except SessionEnded:
            pass
        except BaseException:
            self.error = traceback.format_exc()
        finally:
            self.finished = True
            self.wake_ns = None
            self._back.release()

    def deliver(self, bus: str, item: Any) -> None:
        if item is None:  # the device is gone (an unplugged module): its port raises from now on
            self.gone.add(bus)
        q = self.rx.get(bus)
        if q is None:
            if item is not None:
                self.unrouted += 1  # nobody has this bus open: a real socket would not exist either
        elif len(q) >= RX_QUEUE_FRAMES and item is not None:  # None: the device is gone, which is never lost
            self.rx_dropped += 1  # the socket's receive buffer is full, as on a real host
        else:
            q.append(item)

    def due(self, t_ns: int, arrived: set[str]) -> bool:
        """Whether the robot thread wants to run at ``t_ns``: its wake time has come, or a delivery (``arrived``: the
        buses something was delivered to) is one it waits on."""
        if self.finished:
            return False
        if self.wake_ns is not None and self.wake_ns <= t_ns:
            return True
        return bool(arrived) and (self.wom is True or (isinstance(self.wom, list) and not arrived.isdisjoint(self.wom)))

    def run_timers(self, t_ns: int) -> None:
        """Let the devices' own timers fire up to ``t_ns`` (outside the robot thread, as hardware would)."""
        for timer in list(self.timers):
            timer.fire(t_ns)

    def next_wake(self) -> int | None:
        """When the robot next needs the host: its thread's wake time or a device timer's, whichever is first."""
        if self.finished:
            return None
        times = [w for w in (self.wake_ns, *(tm.next_ns for tm in self.timers)) if w is not None]
        return min(times) if times else None

    def resume(self, t_ns: int) -> None:
        """Run the robot thread at ``t_ns`` until it blocks again (or ends)."""
        if self.finished:
            return
        self.t_ns = t_ns
        self._go.release()
        self._back.acquire()

    def stop(self, timeout_s: float = 2.0) -> None:
        if self.thread is None or self.finished:
            return
        self.stopping = True
        self._go.release()
        self._back.acquire(timeout=timeout_s)

    # -- robot side ---------------------------------------------------------------------------------
    def block(self, wake_ns: int | None, on_message: bool | str) -> None:
        """Give the CPU back until ``wake_ns`` (sim time) or the next delivery: on any device if ``on_message`` is
        True, on that device if it names one (``"can0"``, ``"uart:xbee"``), on none if False."""
        self.wake_ns = wake_ns
        self.wom = [on_message] if isinstance(on_message, str) else on_message
        self._back.release()
        self._go.acquire()
        if self.stopping:
            raise SessionEnded

    def open_bus(self, name: str) -> deque:
        if name in self.gone:
            raise OSError(f"could not open port {name.removeprefix('uart:')}: [Errno 2] No such file or directory "
                          "(the device was unplugged)")
        if name in self.rx:
            raise OSError(f"bus {name!r} of robot {self.robot_id} is already open in this session")
        q: deque = deque()
        self.rx[name] = q
        return q

    def close_bus(self, name: str) -> None:
        self.rx.pop(name, None)


class Timer(Protocol):
    """A device's own periodic activity (``RobotRuntime.timers``)."""

    next_ns: int | None

    def fire(self, t_ns: int) -> None: ...


class SessionClock:
    """The session's simulated clock, as a ``swarm_logic.clock.Clock``."""

    def __init__(self, rt: RobotRuntime) -> None:
        self.rt = rt

    def now(self) -> float:
        return self.rt.t_ns / 1e9

    def sleep(self, dt: float) -> None:
        self.rt.block(self.rt.t_ns + max(0, round(dt * 1e9)), False)

    def sleep_until(self, t: float) -> None:
        self.rt.block(max(self.rt.t_ns, round(t * 1e9)), False)
