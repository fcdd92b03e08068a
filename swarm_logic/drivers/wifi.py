"""The robot's Wi-Fi link: datagrams to the central services and the other robots, by URL.

``udp://HOST:PORT`` is a real UDP socket bound there (``udp://0.0.0.0:5005`` on a SonPI's Raspberry Pi), able to
broadcast; ``SCHEME://...`` is a link another package offers under that scheme (entry point group ``swarm_sitl.wifi``,
as python-can finds its interfaces), such as ``sitl://wifi``, the robot's node on a session's simulated Wi-Fi network.
The robot code is the same either way:

    link = open_link(url)
    link.send(data)                 # a broadcast to every node (the port's, on a real network)
    link.send(data, "camera")       # to one node: a service's name or a robot's rNNN in a session, HOST:PORT on UDP
    got = link.recv(0.1)            # (data, src) or None after 0.1 s (simulated seconds in a session)
    link.close()
"""

from __future__ import annotations

import socket
import urllib.parse
from typing import Any, Protocol

from swarm_logic.plugins import Registry

LINKS: Registry[Any] = Registry("swarm_sitl.wifi", "Wi-Fi link", callable)
MAX_DATAGRAM = 65507


class Link(Protocol):
    def send(self, data: bytes, dest: str | None = None) -> None: ...

    def recv(self, timeout: float | None) -> tuple[bytes, str] | None: ...

    def close(self) -> None: ...


def open_link(url: str, **options: Any) -> Link:
    """An open link on ``url``: ``udp://HOST:PORT`` or ``SCHEME://...`` of a registered link class (given
    ``options``)."""
    if not isinstance(url, str) or "://" not in url:
        raise ValueError(f"a Wi-Fi link is a URL (udp://HOST:PORT, sitl://wifi), got {url!r}")
    cls = LINKS.get(url.split("://", 1)[0])
    return cls(url, **options)


def split_host_port(text: str, what: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[v6]:PORT`` too) as (host, port); ValueError naming ``what``."""
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) < 65536:
        raise ValueError(f"{what}: HOST:PORT expected, got {text!r}")
    return host.strip("[]"), int(port)


class UdpLink:
    """``udp://HOST:PORT``: a UDP socket bound to HOST:PORT (port 0: any free one), with broadcasts allowed. A
    broadcast goes to ``broadcast`` (an address, default 255.255.255.255) at ``broadcast_port`` (default: the bound
    port, as every SonPI listens on the same one)."""

    def __init__(self, url: str, broadcast: str = "255.255.255.255", broadcast_port: int | None = None) -> None:
        parts = urllib.parse.urlsplit(url)
        if parts.scheme != "udp" or parts.path not in ("", "/") or parts.query:
            raise ValueError(f"expected udp://HOST:PORT, got {url!r}")
        host, port = split_host_port(parts.netloc, url)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.sock.bind((host, port))
        except OSError:
            self.sock.close()
            raise
        self.address = self.sock.getsockname()
        self.broadcast = (broadcast, int(broadcast_port if broadcast_port is not None else self.address[1]))

    def send(self, data: bytes, dest: str | None = None) -> None:
        """``data`` to ``dest`` (``HOST:PORT``) or, with None, to the broadcast address."""
        if not 0 < len(data) <= MAX_DATAGRAM:
            raise ValueError(f"a datagram has 1 to {MAX_DATAGRAM} bytes, got {len(data)}")
        to = self.broadcast if dest is None else split_host_port(dest, "destination")
        self.sock.sendto(bytes(data), to)

    def recv(self, timeout: float | None) -> tuple[bytes, str] | None:
        """The next datagram and its sender (``HOST:PORT``), waiting up to ``timeout`` s (None: forever)."""
        self.sock.settimeout(timeout)
        try:
            data, (host, port) = self.sock.recvfrom(MAX_DATAGRAM)
        except (TimeoutError, BlockingIOError):
            return None
        return data, f"{host}:{port}"

    def close(self) -> None:
        self.sock.close()
