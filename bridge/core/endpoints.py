"""UDP endpoints as pymavlink writes them (``udpin:HOST:PORT``, ``udpout:HOST:PORT``), whether a host is this
machine, and a session's UDP port to a program outside it (polled once per quantum, answering whoever spoke last):
what the config checks and the MAVLink endpoint and a robot's Wi-Fi node (``wifi_udp``) open."""

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


class UdpPort:
    """A non-blocking UDP socket bound to ``host:port`` (port 0: any free one) that talks to ``peer`` until someone
    sends to it, then to whoever sent to it last (as pymavlink's ``udpin``). OSError if it cannot be bound."""

    MAX = 65535

    def __init__(self, host: str, port: int, peer: tuple | None = None) -> None:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self.sock.setblocking(False)
            self.sock.bind((host, port))
        except OSError:
            self.sock.close()
            raise
        self.peer = peer
        self.bound: tuple[str, int] = self.sock.getsockname()[:2]

    def send(self, data: bytes) -> bool:
        """``data`` to the peer now; False when there is none yet or the system dropped it (as UDP may)."""
        if self.peer is None:
            return False
        try:
            self.sock.sendto(data, self.peer)
        except OSError:  # nobody listens (ICMP port unreachable) or the buffer is full: UDP drops it
            return False
        return True

    def recv_all(self) -> list[bytes]:
        """Every datagram waiting, in arrival order (the last one's sender becomes the peer)."""
        out = []
        while True:
            try:
                data, addr = self.sock.recvfrom(self.MAX)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # e.g. ICMP port unreachable reported on a later call
                continue
            self.peer = addr
            out.append(data)
        return out

    def close(self) -> None:
        self.sock.close()
