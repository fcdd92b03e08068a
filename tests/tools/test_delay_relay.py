"""The delay relay: bytes pass in order both ways, each direction no sooner than its delay, and a close passes on; and
the hosts benchmark runs."""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time

import pytest

from bridge.tools.delay_relay import DelayRelay
from tests.conftest import ROOT


def _echo() -> socket.socket:
    srv = socket.create_server(("127.0.0.1", 0))

    def run() -> None:
        c, _ = srv.accept()
        while data := c.recv(65536):
            c.sendall(data)
        c.close()  # the client's close came through: pass it back

    threading.Thread(target=run, daemon=True).start()
    return srv


def test_the_relay_delays_each_direction_keeps_order_and_passes_the_close() -> None:
    srv = _echo()
    relay = DelayRelay(("127.0.0.1", 0), srv.getsockname()[:2], 0.005)
    relay.start()
    try:
        c = socket.create_connection(relay.address)
        payload = bytes(range(256)) * 400  # 100 kB: many chunks
        t0 = time.perf_counter()
        c.sendall(b"ping")
        assert c.recv(4) == b"ping"
        assert time.perf_counter() - t0 >= 0.010  # 5 ms each way, never sooner
        got = bytearray()
        sender = threading.Thread(target=c.sendall, args=(payload,))
        sender.start()
        while len(got) < len(payload):
            got += c.recv(65536)
        sender.join()
        assert bytes(got) == payload
        c.shutdown(socket.SHUT_WR)
        assert c.recv(1) == b""  # the echo saw the close and closed too, through the relay
        c.close()
    finally:
        relay.stop()
        srv.close()


@pytest.mark.session
def test_the_hosts_benchmark_runs(tmp_path) -> None:
    # the two robots packed in one firmware and one logic process: still two processes of the remote host, each
    # reaching the world over the (relayed) link, and two robots whose radios hear each other in every case
    r = subprocess.run(
        [sys.executable, "-m", "bridge.tools.cli", "bench", "--hosts", "1", "--link-delay-ms", "0.5", "--robots", "2",
         "--robots-per-process", "2", "--duration", "0.5", "--out", str(tmp_path)],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert any(line.split()[:2] == ["1", "0.5"] for line in lines), r.stdout  # the relayed case's row
    assert "digest: the same in every case" in r.stdout
