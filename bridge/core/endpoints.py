"""UDP endpoints as pymavlink writes them (``udpin:HOST:PORT``, ``udpout:HOST:PORT``), and whether a host is this
machine: what the config checks and the MAVLink endpoint opens."""

from __future__ import annotations

import socket
from dataclasses import dataclass


@dataclass(frozen=True)
class Endpoint:
    mode: str  # "udpin" or "udpout"
    host: str
    port: int

    def __str__(self) -> str:
        return f"{self.mode}:{self.host}:{self.port}"


def parse_endpoint(url: str) -> Endpoint:
    """``udpin:HOST:PORT`` or ``udpout:HOST:PORT``; ValueError naming what is wrong."""
    mode, _, rest = url.partition(":")
    host, _, port = rest.rpartition(":")
    if mode not in ("udpin", "udpout"):
        raise ValueError(f"{url!r}: expected udpin:HOST:PORT or udpout:HOST:PORT")
    try:
        p = int(port)
    except ValueError:
        raise ValueError(f"{url!r}: the port must be a number") from None
    if not host or not 0 <= p <= 65535 or (mode == "udpout" and p == 0):
        raise ValueError(f"{url!r}: needs a host and a port (0..65535; udpout needs a real port)")
    return Endpoint(mode, host, p)


def is_loopback(host: str) -> bool:
    try:
        return all(info[4][0].startswith("127.") or info[4][0] == "::1"
                   for info in socket.getaddrinfo(host, None, type=socket.SOCK_DGRAM))
    except OSError:
        return False
