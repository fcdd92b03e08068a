"""Faults on the UWB media (bridge.media.uwb_faults), without a session: a partition takes the two-way exchanges
across its groups and none within; burst loss takes ranging rounds in bursts (a lost report leaves the responder its
range), counted and seeded; a biased module's ranges are off by its bias whoever measures them; a dead one measures
nothing while the others range on; a stuck one holds each peer's last range; a noisy one is seeded; a fault ends
early with one event. The DeciZebro's radios lose beacons and data across a partition, a dead one hears no beacon
but still its data. A world built from a config carries the config's UWB faults and routes injected ones."""

from __future__ import annotations

import struct
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from bridge.core.config import Config, FaultCfg
from bridge.core.hub import Hub
from bridge.core.plan import make_plan
from bridge.media.uwb import UwbCfg, UwbMedium
from bridge.media.uwb_faults import UwbFaultCarrier, UwbFaults
from swarm_logic.robots.decizebro import uwb_protocol as P
from tests.media.test_uwb import Geo
from tests.robots.test_zebro_radio import Swarm as Zebros

S = 1_000_000_000
EXACT = UwbCfg(sigma_los_m=0.0, bias_sigma_m=0.0, dropout_los=0.0)  # every exchange gets through, exactly
SQUARE = [(0.0, 0.0), (3.0, 0.0), (0.0, 4.0), (3.0, 4.0)]


def ranges(med: UwbMedium, t: int, i: int, j: int) -> dict[str, Any]:
    """Module ``i`` ranges ``j`` at ``t``: the initiator's and the responder's results (None: no range)."""
    out: dict[str, Any] = {"initiator": None, "responder": None, "cause": "ok"}
    for _, r, ev in med.exchange(t, i, j):
        if not ev["ok"]:
            out["cause"] = ev["cause"]
        elif r == i:
            out["initiator"] = ev["range_m"]
        else:
            out["responder"] = ev["range_m"]
    return out


def test_a_partition_cuts_exchanges_across_groups_only_while_it_lasts() -> None:
    med = UwbMedium(EXACT, 4, 1, Geo(SQUARE))
    med.faults.impairments.partition(1 * S, 3 * S, [[0, 1], [2, 3]])
    pairs = [(0, 1), (0, 2), (3, 1), (2, 3)]
    before = [ranges(med, S // 2, i, j)["cause"] for i, j in pairs]
    during = [ranges(med, 2 * S, i, j) for i, j in pairs]
    after = [ranges(med, 3 * S, i, j)["cause"] for i, j in pairs]
    assert before == after == ["ok"] * 4
    assert [x["cause"] for x in during] == ["ok", "partitioned", "partitioned", "ok"]
    assert during[0]["initiator"] == during[0]["responder"] == 3.0 and during[1]["responder"] is None
    s = med.stats()
    assert [s["robots"][r]["partitioned"] for r in range(4)] == [1, 0, 0, 1] and s["all"]["ok"] == 10
    assert med.faults.impairments.report()["partitioned"] == 2  # each exchange ends at its poll


def test_burst_loss_takes_ranging_rounds_in_bursts_counted_and_seeded() -> None:
    def run(seed: int) -> tuple[UwbMedium, list[str]]:
        med = UwbMedium(EXACT, 2, seed, Geo(SQUARE[:2]))
        med.faults.impairments.burst_loss(0, None, p_gb=0.05, p_bg=0.25)
        return med, [ranges(med, k * S // 10, 0, 1)["cause"] for k in range(2500)]

    med, causes = run(3)
    lost = np.array([c == "burst_loss" for c in causes])
    assert set(causes) == {"ok", "burst_loss"} and 0.15 < lost.mean() < 0.6
    assert lost[1:][lost[:-1]].mean() > lost.mean() + 0.2  # a lost round makes the next one likelier lost: bursts
    s, imp = med.stats()["all"], med.faults.impairments.report()
    assert s["burst_loss"] == lost.sum() and s["ok"] == len(causes) - lost.sum()
    # rounds whose report alone was lost: the responder has its range, the initiator none
    assert 0 < s["responded"] - s["ok"] < lost.sum()
    assert imp["burst_lost"] == lost.sum() and len(causes) < imp["burst_frames"] < 4 * len(causes)  # ends at a loss
    assert run(3)[1] == causes and run(4)[1] != causes


def test_a_biased_module_biases_every_range_involving_it() -> None:
    med = UwbMedium(EXACT, 4, 1, Geo(SQUARE))
    a = med.faults.sensor(0, "bias", 1 * S, 3 * S, bias=0.5)
    med.faults.sensor(3, "bias", 1 * S, None, bias=-0.2)
    assert ranges(med, S // 2, 0, 1)["initiator"] == 3.0  # not yet
    r01, r20, r12, r03 = (ranges(med, 2 * S, i, j) for i, j in ((0, 1), (2, 0), (1, 2), (0, 3)))
    assert r01["initiator"] == r01["responder"] == pytest.approx(3.5)  # measured by the biased module, or its peer
    assert r20["initiator"] == r20["responder"] == pytest.approx(4.5)
    assert r12["initiator"] == r12["responder"] == pytest.approx(5.0)  # no biased module: exact
    assert r03["initiator"] == pytest.approx(5.3)  # both biased
    assert ranges(med, 3 * S, 0, 1)["initiator"] == 3.0 and a.ranges == 6  # over; six ranges changed


def test_a_dead_module_measures_nothing_while_the_rest_range_on() -> None:
    med = UwbMedium(EXACT, 3, 1, Geo(SQUARE[:3]))
    dead = med.faults.sensor(0, "dead", 1 * S, None)
    assert ranges(med, 2 * S, 0, 1) == {"initiator": None, "responder": None, "cause": "sensor_dead"}
    assert ranges(med, 2 * S, 2, 0) == {"initiator": None, "responder": None, "cause": "sensor_dead"}
    assert ranges(med, 2 * S, 1, 2) == {"initiator": 5.0, "responder": 5.0, "cause": "ok"}
    assert dead.failed == 2 and [r["sensor_dead"] for r in med.stats()["robots"]] == [1, 0, 1]


def test_a_stuck_module_holds_each_peer_s_last_range_and_a_noisy_one_is_seeded() -> None:
    geo = Geo(SQUARE[:3])
    med = UwbMedium(EXACT, 3, 1, geo)
    med.faults.sensor(0, "stuck", 1 * S, 4 * S)  # (as the config lists it: known before it starts)
    assert ranges(med, S // 4, 0, 1)["initiator"] == 3.0
    geo.pos[1] = (3.0, 1.0)
    assert ranges(med, S // 2, 1, 0)["responder"] == pytest.approx(3.1623, abs=1e-4)  # its last before the fault
    geo.pos[1] = (6.0, 0.0)
    geo.pos[2] = (0.0, 2.0)
    r01 = ranges(med, 2 * S, 0, 1)
    assert r01["initiator"] == pytest.approx(3.1623, abs=1e-4) and r01["responder"] == 6.0  # the peer's is right
    assert ranges(med, 2 * S, 0, 2)["initiator"] == 2.0  # no range before: its first one, then held
    geo.pos[2] = (0.0, 5.0)
    assert ranges(med, 3 * S, 2, 0)["responder"] == 2.0 and ranges(med, 4 * S, 0, 1)["initiator"] == 6.0

    def noisy(seed: int) -> np.ndarray:
        m = UwbMedium(EXACT, 2, seed, Geo(SQUARE[:2]))
        m.faults.sensor(1, "noisy", 0, None, sigma=0.4)
        return np.array([ranges(m, k * S, 0, 1)["responder"] for k in range(2000)])

    x = noisy(5)
    assert x.std() == pytest.approx(0.4, rel=0.08) and abs(x.mean() - 3.0) < 0.03
    assert np.array_equal(noisy(5), x) and not np.array_equal(noisy(6), x)


def fake_hub(faults: list[FaultCfg]) -> SimpleNamespace:
    """What a fault carrier asks of the hub: the config's faults, deliveries and events (run with ``run_to``)."""
    hub = SimpleNamespace(cfg=SimpleNamespace(faults=faults), q_ns=10_000_000, deliveries={}, events=[])
    hub.deliver_at = lambda t, h, *a: hub.deliveries.setdefault(t, []).append((h, a))
    hub.event = lambda t, p: hub.events.append((t / S, p["kind"], p.get("robot")))

    def run_to(t_end: int) -> None:
        for t in sorted(k for k in hub.deliveries if k <= t_end):
            for h, a in hub.deliveries.pop(t):
                h(t, *a)

    hub.run_to = run_to
    return hub


def test_the_config_s_faults_are_carried_and_one_ended_early_ends_once() -> None:
    listed = [FaultCfg(kind="partition", at_s=1.0, duration_s=2.0, medium="uwb", groups=[[0], [1]]),
              FaultCfg(kind="partition", at_s=1.0, groups=[[0], [1]]),  # the 2.4 GHz channel's: not this medium's
              FaultCfg(kind="sensor", robot=1, at_s=1.5, sensor="uwb", mode="bias", bias=0.3),
              FaultCfg(kind="sensor", robot=5, at_s=1.5, sensor="uwb", mode="dead")]  # no module of this medium
    hub = fake_hub(listed)
    carrier = UwbFaultCarrier(hub, UwbFaults(1, "uwb"), [0, 1], "UWB ranging")  # type: ignore[arg-type]
    assert [f for f, _ in carrier.carried] == [listed[0], listed[2]]
    stall = FaultCfg(kind="motor_stall", robot=0, at_s=2.0)
    dead = FaultCfg(kind="sensor", robot=0, at_s=2.0, duration_s=5.0, sensor="uwb", mode="dead")
    assert not carrier.take(stall) and carrier.take(dead)
    assert carrier.end(listed[0], 2 * S + 5) and carrier.end(dead, 3 * S) and not carrier.end(stall, 3 * S)
    hub.run_to(10 * S)
    assert hub.events == [(1.0, "partition", None), (1.5, "sensor", 1), (2.0, "sensor", 0),
                          (2.01, "partition_end", None), (3.0, "sensor_end", 0)]  # and none at 3 s, 7 s
    assert carrier.faults.dead(0, 3 * S - 1) is not None and carrier.faults.dead(0, 3 * S) is None
    rep = carrier.report()
    assert rep is not None and rep["impairments"]["partitioned"] == 0
    assert [(x["robot"], x["mode"], x["until_s"]) for x in rep["sensors"]] == [(1, "bias", None), (0, "dead", 3.0)]


def test_zebro_radios_lose_beacons_and_data_across_a_partition() -> None:
    s = Zebros([(0.0, 0.0), (5.0, 0.0), (0.0, 5.0)], ideal=True)
    s.hub.event = lambda t, p: None
    s.air.inject_fault(FaultCfg(kind="partition", at_s=1e-9, medium="uwb", groups=[[0], [1, 2]]), 0)
    s.modules[1].step(0, P.frame(P.SEND, b"\x01hello"), [])
    s.run(2_100_000_000)
    tx = [(int(topic[2:5]), m["kind"], m["heard"], m["lost"]) for t, topic, m in s.records if t > 0]
    assert (1, "data", [2], [0]) in tx
    heard = {(src, tuple(h)) for src, kind, h, _ in tx if kind == "beacon"}
    assert heard == {(0, ()), (1, (2,)), (2, (1,))}
    rep = s.report()["uwb_radio"]
    assert rep["beacons_impaired"] >= 4 and rep["data_impaired"] == 1
    assert rep["faults"]["impairments"]["partitioned"] == rep["beacons_impaired"] + rep["data_impaired"]


def test_a_dead_zebro_radio_hears_no_beacon_but_its_data_and_a_biased_one_is_off_both_ways() -> None:
    s = Zebros([(0.0, 0.0), (5.0, 0.0), (0.0, 4.0)], ideal=True)
    s.hub.event = lambda t, p: None
    s.air.inject_fault(FaultCfg(kind="sensor", robot=2, at_s=1e-9, sensor="uwb", mode="dead"), 0)
    s.air.inject_fault(FaultCfg(kind="sensor", robot=0, at_s=1e-9, sensor="uwb", mode="bias", bias=0.25), 0)
    s.modules[1].step(0, P.frame(P.SEND, b"\x01hello"), [])
    s.run(2_100_000_000)
    beacons = {(int(topic[2:5]), tuple(m["heard"]), tuple(m["range_m"])) for t, topic, m in s.records
               if m["kind"] == "beacon" and t > 0}
    assert beacons == {(0, (1,), (5.25,)), (1, (0,), (5.25,)), (2, (0, 1), (4.25, 6.4031))}
    assert [struct.unpack_from("<H", b)[0] for b in s.host_frames(2, P.RX_DATA)] == [1]  # its data still arrive
    sensors = s.report()["uwb_radio"]["faults"]["sensors"]
    assert [(x["robot"], x["faulty_ranges"] > 0, x["failed"] > 0) for x in sensors] == [(2, False, True),
                                                                                         (0, True, False)]


@pytest.fixture
def uwb_hub(tmp_path: Path) -> Any:
    cfg = Config.model_validate({
        "robots": [{"count": 3, "uwb": True}, {"count": 1}],
        "faults": [{"kind": "burst_loss", "at_s": 1.0, "medium": "uwb", "p_gb": 0.1, "p_bg": 0.5},
                   {"kind": "sensor", "robot": 1, "at_s": 2.0, "sensor": "uwb", "mode": "bias", "bias": 0.4}]})
    h = Hub(make_plan(cfg), str(tmp_path), str(tmp_path), "test")
    yield h
    h.rec.finish()
    h.world.close()


def test_a_world_carries_the_config_s_uwb_faults_and_routes_injected_ones(uwb_hub: Hub) -> None:
    uwb = uwb_hub.medium("uwb")
    assert [f.kind for f, _ in uwb.carrier.carried] == ["burst_loss", "sensor"]
    uwb_hub.inject_fault(FaultCfg(kind="sensor", robot=2, at_s=3.0, sensor="uwb", mode="dead"), 0)
    assert len(uwb.carrier.carried) == 3 and uwb.medium.faults.dead(2, 3 * S) is not None
    with pytest.raises(ValueError, match="robot 3 has no UWB module"):
        uwb_hub.inject_fault(FaultCfg(kind="sensor", robot=3, at_s=3.0, sensor="uwb", mode="dead"), 0)
    out: dict[str, Any] = {"per_robot": {}}
    uwb.radio_report(out)
    assert out["uwb_faults"]["impairments"]["burst_frames"] == 0
    assert [x["mode"] for x in out["uwb_faults"]["sensors"]] == ["bias", "dead"]
