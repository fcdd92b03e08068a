"""zenoh, configured explicitly: peer mode, no multicast or gossip scouting, a unix socket endpoint in
the session's private directory, and a namespace per session, so two sessions on one machine never see
each other and nothing leaves the machine.

Key space (relative to the session namespace ``swarm-sitl/<session id>``):

==================  ===================  =====================================================
key                 direction            payload (msgpack)
==================  ===================  =====================================================
``hello/<proc>``    participant -> world  ``{"proc", "pid"}`` once subscribed and matched
``tick/<proc>``     world -> participant  one quantum's work for the process's due entities
``done/<proc>``     participant -> world  the entities' outputs and next wake times
``control``         launcher -> world     ``{"op": "stop"}`` or ``{"op": "dead", "proc", ...}``
``status``          world -> launcher     progress once per simulated second, events, the end
==================  ===================  =====================================================

Every publisher that carries something that must arrive uses ``CongestionControl.BLOCK`` (``DROP``
lost messages under load in our measurements). zenoh-python may hang at interpreter exit, so processes
close their session explicitly and leave with ``os._exit``.
"""

from __future__ import annotations

import json
import queue
import time
from typing import Any

import msgpack
import zenoh


def endpoint_for(session_dir: str) -> str:
    return f"unixsock-stream/{session_dir}/zenoh.sock"


def make_config(endpoint: str, namespace: str, listen: bool) -> zenoh.Config:
    c = zenoh.Config()
    c.insert_json5("mode", '"peer"')
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("scouting/gossip/enabled", "false")
    c.insert_json5("namespace", json.dumps(namespace))
    c.insert_json5("listen/endpoints", json.dumps([endpoint] if listen else []))
    c.insert_json5("connect/endpoints", json.dumps([] if listen else [endpoint]))
    c.insert_json5("transport/shared_memory/enabled", "false")
    c.insert_json5("adminspace/enabled", "false")
    return c


def open_session(endpoint: str, namespace: str, listen: bool) -> zenoh.Session:
    return zenoh.open(make_config(endpoint, namespace, listen))


def pack(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def unpack(data: bytes) -> Any:
    return msgpack.unpackb(data, raw=False, strict_map_key=False)


def publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    return session.declare_publisher(key, express=True, congestion_control=zenoh.CongestionControl.BLOCK)


def queue_subscriber(session: zenoh.Session, key: str, q: queue.SimpleQueue, tag: str | None = None) -> Any:
    """Subscribe ``key``; every sample goes into ``q`` as ``(tag or key, payload bytes)``."""

    def cb(sample: zenoh.Sample) -> None:
        q.put((tag or str(sample.key_expr), sample.payload.to_bytes()))

    return session.declare_subscriber(key, cb)


def wait_matched(pub: zenoh.Publisher, timeout_s: float, what: str) -> None:
    """Block until someone subscribes to ``pub`` (start-up only; wall clock for the timeout)."""
    deadline = time.monotonic() + timeout_s
    while not pub.matching_status.matching:
        if time.monotonic() > deadline:
            raise TimeoutError(f"nobody subscribed to {what} within {timeout_s:.0f} s")
        time.sleep(0.005)

