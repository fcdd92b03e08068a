"""What every harness shares: the ``Target`` record, a reader that turns a fuzz input into small fields, and stand-ins
for a serial port and a clock, so a driver that blocks on a port runs against scripted device bytes in simulated time.

Kept free of atheris: the regression test replays the corpus through the same functions without it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Target:
    """One fuzz target: ``run(data)`` feeds one input to the parser; ``seeds()`` are valid inputs built with the
    project's own encoders (the corpus starts from them); ``about`` says which parser and how the bytes arrive."""

    name: str
    about: str
    run: Callable[[bytes], None]
    seeds: Callable[[], list[bytes]] = field(default=lambda: [])


class Cursor:
    """A fuzz input read as a sequence of small fields, front to back; past its end every field reads as zero or
    empty, so any input is a complete script."""

    def __init__(self, data: bytes) -> None:
        self.data = bytes(data)
        self.i = 0

    def more(self) -> bool:
        return self.i < len(self.data)

    def u8(self) -> int:
        if self.i >= len(self.data):
            return 0
        self.i += 1
        return self.data[self.i - 1]

    def u16(self) -> int:
        return self.u8() | self.u8() << 8

    def take(self, n: int) -> bytes:
        out = self.data[self.i:self.i + max(0, n)]
        self.i += len(out)
        return out

    def chunk(self) -> bytes:
        """A length-prefixed field: one length byte, then that many bytes (fewer at the end of the input)."""
        return self.take(self.u8())

    def rest(self) -> bytes:
        return self.take(len(self.data) - self.i)


def lp(body: bytes) -> bytes:
    """Seed helper: ``body`` as ``Cursor.chunk`` reads it back (a length byte, then the bytes)."""
    if len(body) > 255:
        raise ValueError("a chunk holds at most 255 bytes")
    return bytes((len(body),)) + body


def chunks(*parts: tuple[int, bytes]) -> bytes:
    """Seed helper: ``(header byte, chunk)`` pairs as ``Cursor`` reads them back with ``u8`` then ``chunk``."""
    return b"".join(bytes((head,)) + lp(body) for head, body in parts)


class FakeClock:
    """Simulated time (s) that moves only when someone waits: a read that times out, ``sleep``."""

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        if dt > 0:
            self.t += dt

    def sleep_until(self, t: float) -> None:
        self.sleep(t - self.t)


class ScriptedPort:
    """A pyserial-like port on a device that answers each write with the next scripted answer, and whose unsolicited
    bytes the harness ``feed``s. A read takes what has arrived; with nothing there it waits ``timeout`` seconds of
    the clock (one second for a blocking read: the script never blocks for good; 0.1 ms for a non-blocking one, the
    time a real poll takes) and returns nothing."""

    def __init__(self, clock: FakeClock, answers: list[bytes] | None = None) -> None:
        self.clock = clock
        self.answers = list(answers or [])
        self.buf = bytearray()
        self.written = bytearray()
        self.timeout: float | None = 0.0
        self.is_open = True

    @property
    def in_waiting(self) -> int:
        return len(self.buf)

    def feed(self, data: bytes) -> None:
        self.buf += data

    def read(self, size: int = 1) -> bytes:
        if not self.buf:
            self.clock.sleep(1.0 if self.timeout is None else max(self.timeout, 1e-4))
            return b""
        out = bytes(self.buf[:size])
        del self.buf[:size]
        return out

    def write(self, data: bytes) -> int:
        self.written += data
        if self.answers:
            self.buf += self.answers.pop(0)
        return len(data)

    def reset_input_buffer(self) -> None:
        self.buf.clear()

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self.is_open = False
