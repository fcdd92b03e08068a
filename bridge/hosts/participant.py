"""The loop every participant process runs: wait for a tick, run the due entities, answer ``done``.

A participant never advances time by itself: it computes quantum k only when the world's tick for k
arrives, and the world starts k+1 only when every ticked participant has answered. It exits when the
world says stop, and also when its parent (the launcher) disappears; a remote logic (``swarm-sitl join``, no
launcher parent) instead when it is interrupted or loses the world (``watch``).
"""

from __future__ import annotations

import os
import queue
import sys
import traceback
from collections.abc import Callable
from typing import Any, Protocol

import zenoh

from bridge.core import transport


class Host(Protocol):
    def run(self, ent: str, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]: ...

    def stats(self) -> dict[str, dict]: ...

    def stop(self) -> None: ...


def serve(proc: str, endpoint: str, namespace: str, host: Host, parent_pid: int | None = None, *,
          session: zenoh.Session | None = None, watch: Callable[[], int | None] | None = None) -> int:
    """Answer the world's ticks for ``proc`` until it says stop (exit code 0).

    A launcher's child connects to ``endpoint`` itself and stops (code 3) when its parent ``parent_pid`` is gone. A
    joiner on another computer has no such parent: it passes its own ``session`` (connected over TCP; left open for
    it) and ``watch``, polled after every tick and every idle second, whose first non-None answer ends the loop with
    that code (Ctrl-C, the world gone)."""
    own = session is None
    if session is None:
        session = transport.open_session(endpoint, namespace, listen=False)
    q: queue.SimpleQueue = queue.SimpleQueue()
    _sub = transport.queue_subscriber(session, f"tick/{proc}", q, "tick")
    done = transport.publisher(session, f"done/{proc}")
    hello = transport.publisher(session, f"hello/{proc}")
    transport.wait_matched(done, 60, f"done/{proc}")
    transport.wait_matched(hello, 60, f"hello/{proc}")
    hello.put(transport.pack({"proc": proc, "pid": os.getpid()}))
    code = 0
    try:
        while True:
            try:
                _, data = q.get(timeout=1.0)
            except queue.Empty:
                if parent_pid is not None and os.getppid() != parent_pid:
                    code = 3
                    break
                if watch is not None and (verdict := watch()) is not None:
                    code = verdict
                    break
                continue
            try:
                tick = transport.unpack(data)
                k = tick["k"]
            except Exception:
                print(f"{proc}: malformed tick dropped", file=sys.stderr)
                continue
            if tick.get("stop"):
                stats = host.stats() if hasattr(host, "stats") else {}
                host.stop()
                done.put(transport.pack({"k": k, "bye": True, "stats": stats}))
                break
            t = tick["t"]
            ents: dict[str, Any] = {}
            for ent in sorted(tick["run"]):
                try:
                    ents[ent] = host.run(ent, t, tick["run"][ent])
                except Exception:
                    ents[ent] = {"err": traceback.format_exc(), "wake": None}
            done.put(transport.pack({"k": k, "ents": ents}))
            if watch is not None and (verdict := watch()) is not None:
                code = verdict
                break
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        if own:
            session.close()
    return code
