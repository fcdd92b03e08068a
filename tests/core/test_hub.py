"""The hub's handling of participants' replies: malformed ones are counted and cost only their robot."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.config import Config
from bridge.core.entities import entity, robot_of
from bridge.core.hub import Hub
from bridge.core.plan import make_plan
from bridge.core.recorder import file_digest

Q = 10_000_000


@pytest.fixture
def hub(tmp_path: Path) -> Hub:
    cfg = Config.model_validate({"robots": [{"count": 3}]})
    h = Hub(make_plan(cfg), str(tmp_path), str(tmp_path), "test")
    yield h
    h.rec.finish()
    h.world.close()


def reply(**ents) -> dict:
    return {"k": 0, "ents": ents}


@pytest.mark.parametrize("bad", [
    {"out": None},
    {"out": [], "wake": "soon"},
    {"out": [], "wake": 1.5},
    {"out": [], "err": 1},
    "not a dict",
])
def test_malformed_reply_fails_only_its_robot(hub: Hub, bad) -> None:
    good = {"out": [["can0", 0x181, bytes(8), False]], "wake": Q, "wom": False}
    due = {"fw0": [entity(0, "llc")], "fw1": [entity(1, "llc")]}
    hub._outputs(0, {"fw0": reply(**{entity(0, "llc"): bad}), "fw1": reply(**{entity(1, "llc"): good})}, {}, due)
    assert hub.dead == {0} or (bad == "not a dict" and hub.dead == set())
    assert hub.counts["malformed_done"] == 1
    assert hub.next_wake[entity(1, "llc")] == Q and hub.medium("can").buses[1].frames == 1


def test_malformed_frames_and_pins_are_counted_and_dropped(hub: Hub) -> None:
    res = {"out": [["can0", 0x800, b"", False], ["can0", 0x100, bytes(9), False], ["can1", 1, b"", False],
                   ["can0", 0x100, b"\x01", "yes"], "junk", ["can0", 0x100, b"\x01", False]],
           "pins": {"pwm": [300, 0], "led": [0, 0, 0]}, "wake": Q}
    hub._outputs(0, {"fw0": reply(**{entity(0, "llc"): res})}, {entity(0, "llc"): {"enc": [0, 0]}},
                 {"fw0": [entity(0, "llc")]})
    assert hub.counts["malformed_frames"] == 3 and hub.counts["malformed_pins"] == 1
    assert hub.counts["malformed_items"] == 2  # a bus the robot does not have, and not a list at all
    assert hub.medium("can").buses[0].frames == 1 and not hub.dead


def test_reply_for_an_entity_that_was_not_ticked_is_ignored(hub: Hub) -> None:
    hub._outputs(0, {"fw0": reply(**{entity(2, "llc"): {"out": [], "wake": Q}})}, {}, {"fw0": [entity(0, "llc")]})
    assert hub.counts["malformed_done"] == 1
    assert hub.next_wake[entity(2, "llc")] != Q


def test_a_participant_that_floods_or_answers_late_fails_alone(hub: Hub) -> None:
    """What a misbehaving participant can do is bounded: wrong answers (stale, garbage) beyond a cap, or one huge
    answer, fail its process alone; a late answer before the right one costs nothing; the others' answers stand."""
    from bridge.core import hub as hub_mod
    from bridge.core import transport

    good = {"out": [], "wake": Q}
    for _ in range(hub_mod.MAX_WRONG_ANSWERS + 1):
        hub.q.put(("done/fw0", transport.pack({"k": 7, "ents": {}})))  # answers to another quantum
    hub.q.put(("done/fw1", transport.pack({"k": 3, "ents": {}})))  # one late answer, then its own
    hub.q.put(("done/fw1", transport.pack(reply(**{entity(1, "llc"): good}))))
    hub.q.put(("done/fw2", b"\x92" + b"\x00" * (hub_mod.MAX_ANSWER_BYTES + 1)))  # one huge answer
    results = hub._collect({"fw0", "fw1", "fw2"}, 0)
    assert set(results) == {"fw1"} and hub.dead == {0, 2}
    assert [(f["robot"], f["kind"]) for f in hub.failures] == [(0, "flooding"), (2, "flooding")]
    assert "answers to the quantum at t=0.000 s that were not its own" in hub.failures[0]["detail"]
    assert hub.counts["stale_done"] == hub_mod.MAX_WRONG_ANSWERS + 2
    # a run with more outputs than any sound firmware or logic writes in a quantum fails its entity alone
    flood = {"out": [["can0", 0x181, bytes(8), False]] * (hub_mod.MAX_RUN_ITEMS + 1), "wake": Q}
    hub._outputs(0, {"fw1": reply(**{entity(1, "llc"): flood})}, {}, {"fw1": [entity(1, "llc")]})
    assert hub.dead == {0, 1, 2} and hub.counts["flooded_runs"] == 1 and hub.medium("can").buses[1].frames == 0


def test_malformed_control_messages_are_counted(hub: Hub) -> None:
    from bridge.core import transport

    assert hub._control(b"\xc1garbage", 0) is None
    assert hub._control(transport.pack([1, 2]), 0) is None
    assert hub._control(transport.pack({"op": "launch"}), 0) is None
    assert hub.counts["malformed_control"] == 3
    assert hub._control(transport.pack({"op": "dead", "proc": "fw9"}), 0) is None  # no such live process
    assert hub._control(transport.pack({"op": "dead", "proc": "fw1", "detail": "exit code -9"}), 0) == "fw1"


def test_events_are_recorded(hub: Hub, tmp_path: Path) -> None:
    hub.robot_failed(1, 5 * Q, "died", "exit code -9", proc="fw1")
    hub.rec.finish()
    _, n = file_digest(tmp_path / "session.mcap")
    assert n == 2 and hub.failures[0]["process"] == "fw1"  # /session/events, and its line in the scene's /log


def test_entity_ids_beyond_999_robots() -> None:
    assert robot_of(entity(3, "llc")) == 3
    assert robot_of(entity(1234, "logic")) == 1234


def test_a_service_log_is_recorded_with_the_registered_schema_it_names(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    from bridge.core.recorder import iter_messages
    from bridge.services.global_controller.scene import SCENE_SCHEMA

    cfg = Config.model_validate({"robots": [{"count": 1}], "services": [{"kind": "global_controller", "name": "ctl"}]})
    h = Hub(make_plan(cfg), str(tmp_path), str(tmp_path), "test")
    try:
        out = [
            ["log", "plain", {"a": 1}],
            ["log", "scene", {"entities": [], "deletions": []}, SCENE_SCHEMA],
            ["log", "unknown", {"a": 1}, "no.SuchSchema"],
            ["log", "extra", {"a": 1}, SCENE_SCHEMA, "more"],
        ]
        h._outputs(0, {"svc-ctl": reply(**{"svc/ctl": {"out": out, "wake": Q}})}, {}, {"svc-ctl": ["svc/ctl"]})
        assert h.counts["malformed_items"] == 2 and not h.dead_services
    finally:
        h.rec.finish()
        h.world.close()
    with open(tmp_path / "session.mcap", "rb") as f:
        got = {c.topic: s.name for s, c, _ in make_reader(f).iter_messages()}
    # a plain log record also goes to the scene's log panel (/log); a scene does not
    assert got == {"/svc/ctl/log/plain": "swarm_sitl.Log", "/log": "foxglove.Log", "/svc/ctl/log/scene": SCENE_SCHEMA}
    assert [t for t, _, _ in iter_messages(tmp_path / "session.mcap")] == ["/svc/ctl/log/plain", "/log",
                                                                            "/svc/ctl/log/scene"]


def test_an_unplugged_module_is_off_the_air_and_its_port_cannot_be_opened_again(tmp_path: Path) -> None:
    """Even before its robot program touches the port (and dies of it), a pulled-out module neither hears, answers
    nor acknowledges: the radio switches its node off and drops it from the graph; the UWB medium answers nothing."""
    from bridge.hosts.sim_context import RobotRuntime

    cfg = Config.model_validate({"robots": [{"count": 3, "xbee": {"series": 2}, "uwb": True}]})
    h = Hub(make_plan(cfg), str(tmp_path), str(tmp_path), "test")
    try:
        radio, uwb = h.medium("radio"), h.medium("uwb")
        for r in range(3):  # the modules announce themselves, as they do at power-up
            radio.node(entity(r, "xbee"), r, 0, ["node", {"channel": 12, "pan_id": 0x3332, "addr64": 100 + r,
                                                          "addr16": 0xFFFE, "tx_power_dbm": 3.0,
                                                          "sensitivity_dbm": -96.0, "series": 2}])
        assert radio.radio_graph(0)[1].sum() == 6  # three robots a few metres apart: all linked
        assert uwb.medium.exchange(0, 0, 2)[-1][2]["peer"] == 2
        h._unplug(0, 1, "xbee")
        h._unplug(0, 2, "uwb")
        assert radio.medium._chan[1] < 0 and radio.radio_graph(0)[1][1].sum() == 0
        assert uwb.medium.exchange(0, 0, 2)[0][2]["cause"] == "no_response" and uwb.medium.exchange(0, 2, 0) == []
        assert h.inbox[entity(1, "logic")] == [["uart:xbee", None]] and h.next_wake[entity(1, "xbee")] is None
    finally:
        h.rec.finish()
        h.world.close()
    rt = RobotRuntime(1)
    rt.open_bus("uart:xbee")
    rt.deliver("uart:xbee", None)
    rt.close_bus("uart:xbee")
    with pytest.raises(OSError, match="unplugged"):
        rt.open_bus("uart:xbee")


def test_barrier_quantiles_are_kept_in_fixed_memory_to_a_bin() -> None:
    """A soak's hours of quanta keep 1601 counters, not a float each (the world's memory stayed flat but for it)."""
    import numpy as np

    from bridge.core.stats import LogHistogram

    h = LogHistogram()
    assert h.quantile(0.5) is None
    values = np.random.default_rng(3).lognormal(mean=np.log(300.0), sigma=0.8, size=20_000)
    for v in values:
        h.add(float(v))
    assert h.counts.size == 1601 and h.n == 20_000
    for q in (0.5, 0.99):
        assert abs(h.quantile(q) / float(np.quantile(values, q)) - 1) < 0.015


def test_a_paced_session_s_lag_is_summarised_in_fixed_memory() -> None:
    """The wall-clock lag of every quantum of a paced session: counters, not a float per quantum."""
    import numpy as np

    from bridge.core.hub import WallLag

    assert WallLag().summary() is None
    lags = np.where(np.arange(10_000) % 10 == 0, np.linspace(0.001, 0.05, 10_000), 0.0)
    w = WallLag()
    for v in lags:
        w.add(float(v))
    s = w.summary()
    assert s["quanta"] == 10_000 and s["late_share"] == 0.1 and s["final_ms"] == 0.0
    assert s["max_ms"] == round(float(lags.max()) * 1e3, 2) and s["mean_ms"] == round(float(lags.mean()) * 1e3, 3)
    assert abs(s["p99_ms"] / (float(np.quantile(lags, 0.99)) * 1e3) - 1) < 0.015
    calm = WallLag()
    for v in [0.0] * 999 + [0.2]:
        calm.add(v)
    assert calm.summary()["p99_ms"] == 0.0 and calm.summary()["max_ms"] == 200.0
