"""The ``Clock`` a controller lives by: the wall clock on a real robot, the session clock in SITL."""

from __future__ import annotations

import time
from typing import Protocol, runtime_checkable


@runtime_checkable
class Clock(Protocol):
    def now(self) -> float:
        """Seconds since an arbitrary epoch (monotonic)."""
        ...

    def sleep(self, dt: float) -> None: ...

    def sleep_until(self, t: float) -> None: ...


class WallClock:
    """Monotonic wall time, for real robots."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, dt: float) -> None:
        if dt > 0:
            time.sleep(dt)

    def sleep_until(self, t: float) -> None:
        self.sleep(t - time.monotonic())


class RealtimeClock(WallClock):
    """Wall time since the Unix epoch, for controllers that must agree on time across robots (RDPSO numbers its
    iterations from the clock): keep the robots' clocks synchronised (NTP, chrony, PTP)."""

    def now(self) -> float:
        return time.time()

    def sleep_until(self, t: float) -> None:
        self.sleep(t - time.time())


class SteppedClock:
    """Time its owner sets (``t``, seconds) for code that must never block on it: a runner that drives controllers
    by their period, a relay polled once per quantum. ``sleep`` raises with ``why``."""

    def __init__(self, why: str = "nothing may sleep on this clock") -> None:
        self.t = 0.0
        self.why = why

    def now(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        raise RuntimeError(self.why)

    def sleep_until(self, t: float) -> None:
        self.sleep(t - self.t)
