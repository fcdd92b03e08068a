"""``sitl://wifi``: a robot's node on the session's Wi-Fi network (``bridge.media.wifi``), as the robot program's
Wi-Fi link (``swarm_logic.drivers.wifi.open_link``; entry point group ``swarm_sitl.wifi``, name ``sitl``).

A datagram sent leaves at the end of the current quantum; ``recv(timeout)`` waits in simulated time for the next
one. Addresses are the session's: a robot's ``rNNN``, a service's name; None sends to every other node.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any

from bridge.hosts import sim_context
from bridge.media.wifi import KIND

URL = "sitl://wifi"


class SitlLink:
    def __init__(self, url: str, **options: Any) -> None:
        if url != URL:
            raise ValueError(f"the session's Wi-Fi link is {URL!r}, got {url!r} (a real one: udp://HOST:PORT)")
        if options:
            raise ValueError(f"{URL} takes no options, got {sorted(options)}")
        try:
            self._rt = sim_context.current()
        except sim_context.NotInSession as e:
            raise OSError(f"{URL}: {e}") from None
        self._rx: deque | None = self._rt.open_bus(KIND)

    def _check(self) -> sim_context.RobotRuntime:
        if self._rx is None:
            raise OSError(f"{URL}: the link is closed")
        if threading.current_thread() is not self._rt.thread:
            raise RuntimeError(f"{URL} is used from its robot's own thread only (simulated time)")
        return self._rt

    def send(self, data: bytes, dest: str | None = None) -> None:
        """``data`` to node ``dest`` (None: every other node), leaving at the end of the quantum."""
        rt = self._check()
        if not data:
            raise ValueError("a datagram has at least one byte")
        rt.outbox.append([KIND, dest, bytes(data)])

    def recv(self, timeout: float | None) -> tuple[bytes, str] | None:
        """The next datagram and its sender, waiting up to ``timeout`` simulated seconds (None: until one comes)."""
        rt = self._check()
        rx = self._rx
        deadline = None if timeout is None else rt.t_ns + max(0, round(timeout * 1e9))
        while not rx and (deadline is None or rt.t_ns < deadline):
            rt.block(deadline, KIND)
        if not rx:
            return None
        src, data = rx.popleft()
        return bytes(data), str(src)

    def close(self) -> None:
        if self._rx is not None:
            self._rt.close_bus(KIND)
            self._rx = None
