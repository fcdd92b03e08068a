"""``swarm-sitl run --live``: Foxglove's WebSocket server in the world serves the scene while the session runs; a
client speaking Foxglove's WebSocket protocol subscribes and receives scene updates."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from tornado.websocket import websocket_connect

from bridge.core.config import ConfigError, load_config

pytestmark = pytest.mark.session

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "hil_configs" / "demo.toml"


async def _watch(url: str, want: int) -> tuple[dict, list[dict]]:
    """Subscribe to /scene/robots as Foxglove does and return its channel and the first ``want`` updates."""
    ws = await websocket_connect(url, subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"])
    channel: dict | None = None
    got: list[dict] = []
    while len(got) < want:
        msg = await ws.read_message()
        assert msg is not None, "the server closed the connection"
        if isinstance(msg, str):
            op = json.loads(msg)
            if op["op"] == "advertise" and channel is None:
                channel = next((c for c in op["channels"] if c["topic"] == "/scene/robots"), None)
                if channel is not None:
                    await ws.write_message(json.dumps({"op": "subscribe",
                                                       "subscriptions": [{"id": 7, "channelId": channel["id"]}]}))
        elif msg[0] == 1:  # MessageData: opcode, subscription id, log time, payload
            sub, t_ns = struct.unpack_from("<IQ", msg, 1)
            assert sub == 7
            got.append({"t_ns": t_ns, **json.loads(msg[13:])})
    ws.close()
    return channel, got


def test_a_foxglove_client_watches_the_live_scene(tmp_path: Path) -> None:
    cmd = [sys.executable, "-m", "bridge.tools.cli", "run", str(DEMO), "--robots", "4", "--duration", "600",
           "--speed", "2", "--live", "--out", str(tmp_path)]
    p = subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, start_new_session=True,
                         env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        url = None
        for line in p.stderr:  # our own progress lines: the launcher prints the server's address once it listens
            if "live scene: " in line:
                url = line.split("live scene: ")[1].split()[0]
                break
        assert url is not None and url.startswith("ws://127.0.0.1:")
        channel, got = asyncio.run(_watch(url, 3))
        assert channel["schemaName"] == "foxglove.SceneUpdate" and channel["encoding"] == "json"
        assert [m["t_ns"] for m in got] == sorted(m["t_ns"] for m in got) and got[-1]["t_ns"] > got[0]["t_ns"]
        assert {e["id"] for e in got[-1]["entities"]} >= {"r000", "r001", "r002", "r003"}
    finally:
        os.killpg(p.pid, signal.SIGINT)  # stops cleanly, as Ctrl-C does
        rest = p.communicate()[1]
    assert p.returncode == 130, rest
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["interrupted"] and summary["messages"] > 0


def test_the_live_scene_is_served_on_loopback_only(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not a loopback address"):
        load_config(DEMO, {"session.live": "0.0.0.0:8765"})
    with pytest.raises(ConfigError, match="scene_hz = 0"):
        load_config(DEMO, {"session.live": "127.0.0.1:0", "session.scene_hz": 0})
    assert load_config(DEMO, {"session.live": "[::1]:0"}).session.live == "[::1]:0"
