"""Hosts on one machine: network namespaces linked like computers on a LAN, to test what spans several computers
(trials on a cluster, a session whose hosts join over the network) without a second computer or root.

A ``Lab`` is a user and network namespace of its own (``unshare --user --map-root-user --net``: no root needed where
the kernel allows unprivileged user namespaces, as Debian's does), its *hub*, with a bridge to which each *host*, a
network namespace of its own, is linked by a veth pair. Every address is in the loopback range (127.77.0.0/24,
``route_localnet`` on), so nothing a test sends can leave the machine, and a host reaches the others only over its
link: its own loopback is its own. Processes started in the lab (``popen``) and the namespaces end with it.

There is no delay on the links (the kernel's ``netem`` is not always there); a link with a latency is a relay
process on the path, which the test that needs one starts.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from dataclasses import dataclass
from typing import Any

SUBNET = "127.77.0"
_TOOLS = ("unshare", "nsenter", "ip")
_SETUP_S = 30.0  # a guard only: a namespace is made in milliseconds


def _comm(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/comm") as f:
            return f.read().strip()
    except OSError:
        return ""


@dataclass(frozen=True)
class Host:
    """One namespace of a lab: its name, its IPv4 address and a process (``pid``) holding the namespace open."""

    name: str
    address: str
    pid: int


class LabError(RuntimeError):
    """The lab cannot be built: the message says which step failed and what it printed."""


def _loopback_only(dev: str) -> str:
    """Shell lines that make ``dev`` carry loopback-range addresses: the loopback keeps only 127.0.0.1, and
    ``route_localnet`` lets 127.x be routed over ``dev``."""
    return (
        "ip link set lo up\n"
        "ip route del table local local 127.0.0.0/8 dev lo\n"
        "ip route replace table local local 127.0.0.1 dev lo\n"
        "sysctl -qw net.ipv4.conf.all.route_localnet=1\n"
        f"sysctl -qw net.ipv4.conf.{dev}.route_localnet=1\n"
    )


class Lab:
    """A hub namespace and the hosts linked to it; a context manager that tears everything down on exit."""

    def __init__(self) -> None:
        self._procs: list[subprocess.Popen] = []
        self._holders: list[subprocess.Popen] = []
        self.hosts: list[Host] = []
        holder = self._hold(["unshare", "--user", "--map-root-user", "--net"])
        self.hub = Host("hub", f"{SUBNET}.1", holder.pid)
        try:
            self._sh(
                self.hub,
                "ip link add br0 type bridge\n"
                + _loopback_only("br0")
                + f"ip addr add {self.hub.address}/24 dev br0\nip link set br0 up\n",
                "the hub's bridge",
            )
        except BaseException:
            self.close()
            raise

    @staticmethod
    def unavailable() -> str | None:
        """Why a lab cannot be built on this machine (a missing tool, user namespaces disabled), or None."""
        missing = [t for t in _TOOLS if shutil.which(t) is None]
        if missing:
            return f"network namespaces need {', '.join(missing)} (util-linux, iproute2)"
        r = subprocess.run(
            [
                "unshare",
                "--user",
                "--map-root-user",
                "--net",
                "ip",
                "link",
                "add",
                "t0",
                "type",
                "veth",
                "peer",
                "name",
                "t1",
            ],
            capture_output=True,
            text=True,
        )
        if r.returncode != 0:
            return f"unprivileged network namespaces are not allowed here ({r.stderr.strip() or r.returncode})"
        return None

    def _hold(self, prefix: list[str]) -> subprocess.Popen:
        """A process that holds a new namespace open (``sleep`` exec'd in place, so its pid is the namespace's)."""
        p = subprocess.Popen([*prefix, "sleep", "infinity"], stdin=subprocess.DEVNULL, start_new_session=True)
        self._holders.append(p)
        deadline = time.monotonic() + _SETUP_S
        while _comm(p.pid) != "sleep":  # unshare has made the namespace once it has exec'd sleep
            if p.poll() is not None or time.monotonic() > deadline:
                raise LabError(f"network lab: {' '.join(prefix)} did not start (exit {p.poll()})")
            time.sleep(0.005)
        return p

    def _enter(self, host: Host) -> list[str]:
        return self.enter_argv(host)

    def enter_argv(self, host: Host, inside: bool = False) -> list[str]:
        """The argv prefix that runs a command in ``host``'s network namespace: from outside the lab (the default,
        entering its user namespace too), or from a process already inside it (``inside``: one started in the hub or
        another host, which is in the lab's user namespace already and may not enter it again)."""
        net = f"--net=/proc/{host.pid}/ns/net"
        return ["nsenter", net] if inside else ["nsenter", "--target", str(self.hub.pid), "--user", net]

    def _sh(self, host: Host, script: str, what: str) -> None:
        r = subprocess.run([*self._enter(host), "sh", "-ec", script], capture_output=True, text=True)
        if r.returncode != 0:
            raise LabError(f"network lab: {what} failed: {r.stderr.strip() or r.returncode}")

    def add_host(self, name: str) -> Host:
        """A new namespace linked to the hub's bridge, with the next address of the subnet."""
        n = len(self.hosts) + 2
        if n > 254:
            raise LabError("network lab: at most 253 hosts")
        holder = self._hold([*self._enter(self.hub), "unshare", "--net"])
        host = Host(name, f"{SUBNET}.{n}", holder.pid)
        hub_end = f"v{n}"
        self._sh(
            self.hub,
            f"ip link add {hub_end} type veth peer name eth0 netns {host.pid}\n"
            f"ip link set {hub_end} master br0\nip link set {hub_end} up\n",
            f"linking host {name!r}",
        )
        self._sh(
            host,
            _loopback_only("eth0") + f"ip addr add {host.address}/24 dev eth0\nip link set eth0 up\n",
            f"host {name!r}'s address",
        )
        self.hosts.append(host)
        return host

    def popen(self, host: Host, argv: list[str], **kwargs: Any) -> subprocess.Popen:
        """Start ``argv`` in ``host``'s namespace (as the namespace's root, which is this user outside it), in a
        session of its own so that closing the lab ends it and its children."""
        kwargs.setdefault("start_new_session", True)
        p = subprocess.Popen([*self._enter(host), *argv], **kwargs)
        self._procs.append(p)
        return p

    def close(self) -> None:
        """End every process started in the lab, then the namespaces' holders (the namespaces go with them)."""
        for p in [*self._procs, *reversed(self._holders)]:
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    p.kill()
            p.wait()
        self._procs.clear()
        self._holders.clear()

    def __enter__(self) -> Lab:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
