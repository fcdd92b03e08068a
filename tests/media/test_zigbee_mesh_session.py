"""Acceptance (mesh routing on the simulated 2.4 GHz channel): six eSwarBots in a line 8 m apart, a thin wall
between each two (3 dB each), so that each XBee (PL 4, +3 dBm) hears its neighbours with about 7 dB to spare and
the next but one not at all (2.7 dB below the sensitivity, before shadowing). Robot 0's unicasts reach robot 5
through the four routers between, the first transmit status reporting the discovery it took; a partition between
robots 2 and 3 makes them fail (network ACK failure, address or route not found), and they get through again once
it ends. One hop, none arrives."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bridge.core.recorder import iter_messages
from tests.core.test_session import run

pytestmark = pytest.mark.session

CFG = """
[session]
name = "mesh-line"
duration_s = 42
seed = 3
[arena]
width_m = 44
length_m = 4
{walls}
[[robots]]
count = 1
behaviour = "tests.support.mesh_probe:MeshSender"
xbee = {{ series = 2, baud = 115200, routing = "{routing}" }}
[robots.placement]
kind = "explicit"
poses = [[1.0, 2.0, 0.0]]
[[robots]]
count = 4
behaviour = "tests.support.xbee_probe:Idle"
xbee = {{ series = 2, baud = 115200, routing = "{routing}" }}
[robots.placement]
kind = "explicit"
poses = [[9.0, 2.0, 0.0], [17.0, 2.0, 0.0], [25.0, 2.0, 0.0], [33.0, 2.0, 0.0]]
[[robots]]
count = 1
behaviour = "tests.support.mesh_probe:MeshSink"
xbee = {{ series = 2, baud = 115200, routing = "{routing}" }}
[robots.placement]
kind = "explicit"
poses = [[41.0, 2.0, 0.0]]
[[faults]]
kind = "partition"
at_s = 20
duration_s = 8
groups = [[0, 1, 2], [3, 4, 5]]
"""


WALLS = "\n".join(f'[[obstacles]]\ntype = "box"\nx = {x}\ny = 2\nsize = [0.1, 4.0, 0.8]' for x in (5, 13, 21, 29, 37))


def logs(mcap: Path, topic: str) -> list[tuple[float, dict]]:
    return [(t / 1e9, json.loads(d)) for tp, t, d in iter_messages(mcap) if tp == topic]


def test_a_unicast_crosses_five_hops_and_a_partition_breaks_and_heals_it(tmp_path: Path) -> None:
    cfg = tmp_path / "mesh.toml"
    cfg.write_text(CFG.format(routing="mesh", walls=WALLS))
    code, s = run(cfg, tmp_path / "out")
    assert code == 0, s.get("error")
    tx = logs(tmp_path / "out" / "session.mcap", "/r000/log/mesh_tx")
    rx = logs(tmp_path / "out" / "session.mcap", "/r005/log/mesh_rx")
    before = [m for t, m in tx if t < 20]
    during = [m for t, m in tx if 22 <= t < 28]
    after = [m for t, m in tx if t >= 32]
    ok_before = [m for m in before if m["status"] == 0]
    assert len(ok_before) >= 3 and ok_before[0]["discovery"] != 0  # the first found an address and/or a route
    assert during and all(m["status"] in (0x21, 0x24, 0x25) for m in during)  # partitioned: nothing gets through
    assert after and sum(m["status"] == 0 for m in after) >= 0.8 * len(after)  # healed
    delivered = {m["data"] for _, m in rx}
    assert {f"m{m['seq']}" for _, m in tx if m["status"] == 0} <= delivered
    relays = [s["per_robot"][i]["xbee_module"]["nwk_relayed"] for i in range(1, 5)]
    assert all(r > 0 for r in relays), relays


def test_one_hop_the_far_end_is_out_of_reach(tmp_path: Path) -> None:
    cfg = tmp_path / "one_hop.toml"
    cfg.write_text(CFG.format(routing="one_hop", walls=WALLS))
    code, s = run(cfg, tmp_path / "out", "--duration", "15")
    assert code == 0, s.get("error")
    tx = logs(tmp_path / "out" / "session.mcap", "/r000/log/mesh_tx")
    assert tx and all(m["status"] != 0 for _, m in tx)
