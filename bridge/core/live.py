"""The live scene: Foxglove's WebSocket server (foxglove-sdk) in the world process, serving the recording's scene
channels while the session runs (``swarm-sitl run --live``), on loopback.

It serves what the recording gets (``bridge.core.scene``), decimated in wall time so a fast session does not flood
the viewer: at most ``LIVE_HZ`` updates of ``/scene/robots`` and ``/tf`` a wall second, every ``/log`` line, the arena
again every ``ARENA_EVERY_S`` for viewers that connect late, and the simulated time as the server's clock. What is
served never feeds back into the session: the recording is the same with ``--live`` or without.
"""

from __future__ import annotations

import json
import time
from typing import Any

from bridge.core.endpoints import is_loopback
from bridge.core.recorder import SCHEMAS

LIVE_HZ = 10.0
ARENA_EVERY_S = 2.0
DECIMATED = ("/scene/robots", "/tf")


def parse_listen(listen: str) -> tuple[str, int]:
    """``HOST:PORT`` with HOST a loopback address (the scene is served on this computer only) and PORT 0 for any free
    one; ValueError naming what is wrong."""
    host, sep, port = listen.rpartition(":")
    host = host.strip("[]")
    if not sep or not port.isdigit() or not 0 <= int(port) < 65536:
        raise ValueError(f"{listen!r} is not HOST:PORT (e.g. 127.0.0.1:8765, or 127.0.0.1:0 for any free port)")
    if not is_loopback(host):
        raise ValueError(f"{host!r} is not a loopback address: the live scene is served on this computer only "
                         "(127.0.0.1 or ::1)")
    return host, int(port)


class LiveScene:
    """Foxglove's WebSocket server with one JSON channel per scene topic."""

    def __init__(self, listen: str, name: str) -> None:
        import foxglove

        self._fx = foxglove
        host, port = parse_listen(listen)
        self.ctx = foxglove.Context()
        self.server = foxglove.start_server(name=f"swarm-sitl {name}", host=host, port=port, context=self.ctx)
        self.url = f"ws://{'[' + host + ']' if ':' in host else host}:{self.server.port}"
        self.channels: dict[str, Any] = {}
        self.sent_wall: dict[str, float] = {}
        self.arena: tuple[dict[str, Any], int] | None = None
        self.arena_wall = 0.0
        self.sent = 0

    def _channel(self, topic: str, schema: str) -> Any:
        ch = self.channels.get(topic)
        if ch is None:
            ch = self.channels[topic] = self._fx.Channel(
                topic, schema=self._fx.Schema(name=schema, encoding="jsonschema",
                                              data=json.dumps(SCHEMAS[schema]).encode()),
                message_encoding="json", context=self.ctx)
        return ch

    def log(self, topic: str, schema: str, msg: dict[str, Any], t_ns: int) -> None:
        """One message of the scene at simulated ``t_ns``: served now, unless decimated away."""
        now = time.monotonic()  # wall time decides only what a viewer is shown, never what the session does
        if topic == "/scene/arena":
            self.arena, self.arena_wall = (msg, t_ns), now
        elif topic in DECIMATED:
            if now - self.sent_wall.get(topic, -1e9) < 1.0 / LIVE_HZ:
                return
            self.sent_wall[topic] = now
            if self.arena is not None and now - self.arena_wall >= ARENA_EVERY_S:
                self.arena_wall = now
                self._channel("/scene/arena", schema).log(self.arena[0], log_time=t_ns)
            self.server.broadcast_time(t_ns)
        self._channel(topic, schema).log(msg, log_time=t_ns)
        self.sent += 1

    def close(self) -> None:
        self.server.stop()
