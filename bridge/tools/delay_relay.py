"""A TCP relay that delays each direction by a fixed one-way delay: a LAN's latency on one machine, where the kernel's
``netem`` is not always there.

Every connection accepted on the listening address is relayed to the target; each chunk read from one side is written
to the other ``delay_s`` after it was read (in order; a closed side is closed on the other after the same delay). One
thread, ``select.select`` with microsecond timeouts (not epoll's millisecond ones) and a timer slack of 1 us, so a
chunk leaves within tens of microseconds of its time; ``measure`` reports what the relay itself adds.

``python -m bridge.tools.delay_relay --listen 127.0.0.1:0 --to 127.0.0.1:7447 --delay-ms 0.2`` prints the port it
listens on and relays until killed.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import ctypes
import select
import socket
import statistics
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field

PR_SET_TIMERSLACK = 29
CHUNK = 65536


def precise_timers() -> None:
    """Ask the kernel to wake this thread within 1 us of its timeouts (the default slack is 50 us)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_TIMERSLACK, 1000, 0, 0, 0)


@dataclass
class _Direction:
    """One direction of a relayed connection: chunks read from ``src``, due for ``dst`` at their times."""

    src: socket.socket
    dst: socket.socket
    due: collections.deque = field(default_factory=collections.deque)  # (time, bytes); b"" is the end
    out: bytearray = field(default_factory=bytearray)  # due, not yet written
    eof: bool = False  # src has closed (its end is queued)
    closed: bool = False  # the end was passed on (dst shut down for writing)


class DelayRelay:
    """Relay connections from ``listen`` (host, port; port 0: any free one) to ``target``, ``delay_s`` each way."""

    def __init__(self, listen: tuple[str, int], target: tuple[str, int], delay_s: float) -> None:
        self.target, self.delay_s = target, delay_s
        self.server = socket.create_server(listen)
        self.server.setblocking(False)
        self.address = self.server.getsockname()[:2]
        self.dirs: list[_Direction] = []
        self._stop = False

    def _accept(self) -> None:
        conn, _ = self.server.accept()
        try:
            up = socket.create_connection(self.target)
        except OSError:  # nobody at the target (not yet, or no longer): refuse this one as the target would
            conn.close()
            return
        for s in (conn, up):
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            s.setblocking(False)
        self.dirs += [_Direction(conn, up), _Direction(up, conn)]

    def serve(self) -> None:
        """Relay until ``stop``."""
        precise_timers()
        while not self._stop:
            now = time.perf_counter()
            for d in self.dirs:  # what is due moves to the output
                while d.due and d.due[0][0] <= now:
                    data = d.due.popleft()[1]
                    if data:
                        d.out += data
                    else:
                        d.closed = True
            waits = [d.due[0][0] - now for d in self.dirs if d.due]
            readers = [self.server] + [d.src for d in self.dirs if not d.eof]
            writers = [d.dst for d in self.dirs if d.out or (d.closed and not d.due)]
            timeout = max(0.0, min(waits)) if waits else 0.2
            r, w, _ = select.select(readers, writers, [], timeout)
            stamp = time.perf_counter()
            if self.server in r:
                with contextlib.suppress(BlockingIOError, InterruptedError):
                    self._accept()
            for d in list(self.dirs):
                if d.src in r and not d.eof:
                    try:
                        data = d.src.recv(CHUNK)
                    except (BlockingIOError, InterruptedError):
                        data = None
                    except OSError:
                        data = b""
                    if data is not None:
                        d.eof = not data
                        d.due.append((stamp + self.delay_s, data))
                if d.dst in w:
                    self._write(d)
            self.dirs = [d for d in self.dirs if not (d.closed and not d.out and not d.due and d.eof)]

    def _write(self, d: _Direction) -> None:
        try:
            if d.out:
                n = d.dst.send(d.out)
                del d.out[:n]
            if not d.out and d.closed and not d.due:
                d.dst.shutdown(socket.SHUT_WR)
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            d.out.clear()

    def start(self) -> threading.Thread:
        """Relay in a daemon thread (tests, ``measure``)."""
        t = threading.Thread(target=self.serve, daemon=True)
        t.start()
        return t

    def stop(self) -> None:
        self._stop = True


def _echo_server() -> tuple[socket.socket, threading.Thread]:
    srv = socket.create_server(("127.0.0.1", 0))

    def run() -> None:
        c, _ = srv.accept()
        c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        while data := c.recv(CHUNK):
            c.sendall(data)
        c.close()

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return srv, t


def round_trip_us(address: tuple[str, int], n: int = 2000) -> float:
    """The median round trip (us) of a 64-byte message to an echo behind ``address``."""
    s = socket.create_connection(address)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    msg = b"x" * 64
    rtts = []
    for _ in range(n):
        t0 = time.perf_counter()
        s.sendall(msg)
        got = 0
        while got < len(msg):
            got += len(s.recv(CHUNK))
        rtts.append(time.perf_counter() - t0)
    s.close()
    return statistics.median(rtts) * 1e6


def measure(delays_ms: tuple[float, ...] = (0.0, 0.2, 1.0), n: int = 2000) -> list[tuple[str, float]]:
    """Median round trips over loopback to an echo: direct, then through a relay process at each one-way delay; what
    the relay adds beyond twice its delay is its own cost."""
    srv, _ = _echo_server()
    echo = srv.getsockname()[:2]
    rows = [("direct", round_trip_us(echo, n))]
    srv.close()
    for d in delays_ms:
        srv, _ = _echo_server()
        relay = start_relay(srv.getsockname()[:2], d)
        try:
            rows.append((f"relay {d:g} ms one way", round_trip_us(("127.0.0.1", relay.port), n)))
        finally:
            relay.kill()
            relay.wait()
            srv.close()
    return rows


def start_relay(target: tuple[str, int], delay_ms: float, listen: str = "127.0.0.1:0") -> subprocess.Popen:
    """A relay process to ``target`` (its ``port`` attribute: where it listens), in a process group of its own."""
    p = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "bridge.tools.delay_relay",
            "--listen",
            listen,
            "--to",
            f"{target[0]}:{target[1]}",
            "--delay-ms",
            str(delay_ms),
        ],
        stdout=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
        start_new_session=True,
    )
    line = p.stdout.readline() if p.stdout else ""
    if not line.strip().isdigit():
        p.kill()
        p.wait()
        raise RuntimeError(f"the delay relay did not start (exit {p.poll()})")
    p.port = int(line)  # type: ignore[attr-defined]
    return p


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m bridge.tools.delay_relay", description=__doc__.splitlines()[0])
    ap.add_argument("--listen", default="127.0.0.1:0", help="HOST:PORT to accept on (port 0: any free one)")
    ap.add_argument("--to", help="HOST:PORT to relay to")
    ap.add_argument("--delay-ms", type=float, default=0.0, help="one-way delay, each direction (ms)")
    ap.add_argument("--measure", action="store_true", help="print what the relay adds to a round trip, and exit")
    a = ap.parse_args(argv)
    if a.measure:
        for what, us in measure():
            print(f"{what:>24}: median round trip {us:8.1f} us")
        return
    if not a.to:
        ap.error("--to is required")
    host, _, port = a.listen.rpartition(":")
    thost, _, tport = a.to.rpartition(":")
    relay = DelayRelay((host, int(port)), (thost, int(tport)), a.delay_ms / 1000)
    print(relay.address[1], flush=True)
    relay.serve()


if __name__ == "__main__":
    main()
