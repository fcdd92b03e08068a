"""The network lab: hosts reach each other over their links, not over a shared loopback, and nothing outlives it."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from bridge.tools.netns import Lab

pytestmark = pytest.mark.skipif(Lab.unavailable() is not None, reason=str(Lab.unavailable()))

SERVER = """
import socket, sys
l = socket.socket(); l.bind((sys.argv[1], 0)); l.listen()
print(l.getsockname()[1], flush=True)
c, a = l.accept(); c.sendall(a[0].encode()); c.close()
"""

CLIENT = """
import socket, sys
s = socket.create_connection((sys.argv[1], int(sys.argv[2])), timeout=30)
print(s.recv(64).decode())
"""


def _serve(lab: Lab, host, address: str) -> tuple[subprocess.Popen, int]:
    p = lab.popen(host, [sys.executable, "-c", SERVER, address], stdout=subprocess.PIPE, text=True)
    return p, int(p.stdout.readline())


def _connect(lab: Lab, host, address: str, port: int) -> subprocess.CompletedProcess:
    p = lab.popen(
        host,
        [sys.executable, "-c", CLIENT, address, str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    out, err = p.communicate(timeout=60)
    return subprocess.CompletedProcess(p.args, p.returncode, out, err)


def test_hosts_reach_each_other_and_the_hub_over_their_links():
    with Lab() as lab:
        a, b = lab.add_host("a"), lab.add_host("b")
        assert (lab.hub.address, a.address, b.address) == ("127.77.0.1", "127.77.0.2", "127.77.0.3")
        _server, port = _serve(lab, a, a.address)
        got = _connect(lab, b, a.address, port)
        assert got.returncode == 0, got.stderr
        assert got.stdout.strip() == b.address  # the server saw b's address: the packet crossed the bridge
        _server, port = _serve(lab, lab.hub, lab.hub.address)
        got = _connect(lab, a, lab.hub.address, port)
        assert got.stdout.strip() == a.address


def test_a_hosts_loopback_is_its_own():
    with Lab() as lab:
        a, b = lab.add_host("a"), lab.add_host("b")
        server, port = _serve(lab, a, "127.0.0.1")
        got = _connect(lab, b, "127.0.0.1", port)
        assert got.returncode != 0 and "ConnectionRefused" in got.stderr
        server.kill()


def test_closing_the_lab_ends_its_processes():
    with Lab() as lab:
        a = lab.add_host("a")
        p = lab.popen(a, ["sleep", "1000"])
        holders = [lab.hub.pid, a.pid]
    assert p.poll() is not None
    for pid in holders:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_a_process_inside_the_lab_enters_a_host_with_the_inside_prefix():
    with Lab() as lab:
        a = lab.add_host("a")
        argv = [*lab.enter_argv(a, inside=True), "ip", "-4", "-o", "addr", "show", "eth0"]
        p = lab.popen(lab.hub, argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        out, err = p.communicate(timeout=60)
        assert p.returncode == 0 and f"inet {a.address}/24" in out, err
