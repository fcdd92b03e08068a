"""The fuzz corpus as regression tests: every input kept in ``fuzz/corpus/<target>/`` (the seeds, what the fuzzer
found reaching new code, and every input that once crashed a parser, ``crash-*``) runs through its target's harness,
without atheris, and must not raise. Plus the registry's bookkeeping, and the fixes the fuzzer led to, each stated."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from fuzz import targets
from fuzz.harness import Cursor

CORPUS = Path(__file__).resolve().parents[2] / "fuzz" / "corpus"


def test_every_module_holds_the_targets_the_registry_says() -> None:
    found = targets.all_targets()
    assert list(found) == list(targets.MODULE_OF)
    for name, t in found.items():
        assert t.name == name and t.about


def test_every_target_has_a_corpus_with_its_seeds() -> None:
    for name, t in targets.all_targets().items():
        kept = {f.name for f in (CORPUS / name).iterdir()} if (CORPUS / name).is_dir() else set()
        missing = [s for s in t.seeds() if hashlib.sha1(s).hexdigest() not in kept]
        assert not missing, f"{name}: {len(missing)} seeds not in fuzz/corpus/{name} (python -m fuzz seed {name})"


def test_the_committed_corpus_stays_small() -> None:
    total = sum(f.stat().st_size for f in CORPUS.rglob("*") if f.is_file())
    assert total < 600_000, f"fuzz/corpus holds {total} bytes: merge (-merge=1) rather than copy"


@pytest.mark.parametrize("name", list(targets.MODULE_OF))
def test_the_corpus_replays_without_a_crash(name: str) -> None:
    run = targets.get(name).run
    files = sorted(f for f in (CORPUS / name).iterdir() if f.is_file())
    assert files
    for f in files:
        run(f.read_bytes())  # a crash raises here, naming the exception; the file is in the traceback's locals


def test_a_cursor_reads_any_input_to_its_end() -> None:
    c = Cursor(b"\x05\x02ab\x03x")
    assert (c.u8(), c.chunk(), c.chunk(), c.more(), c.u8(), c.u16(), c.chunk()) == (5, b"ab", b"x", False, 0, 0, b"")


# -- the fixes ---------------------------------------------------------------------------------------------------------
def test_a_region_agent_holds_on_a_plan_whose_law_refuses_its_parameters() -> None:
    """sonpi_plan's first find: a plan datagram that decodes, naming a law but not the parameters it needs (or ones it
    cannot take), made ``RegionAgent.step`` raise TypeError from the law and so ended the robot's program. It now holds
    the robot (reason ``bad_plan``), checking each plan once."""
    from swarm_logic.families.roy.regions.agent import plan_error
    from swarm_logic.robots.sonpi import pose_packet as pp

    agents = (pp.PlanAgent(1, None, False, 0.0, 0.0), pp.PlanAgent(2, None, False, 1.0, 0.0))
    desired = [[0.0, 1.0], [1.0, 0.0]]
    assert plan_error(pp.PlanPacket(agents, "formation", {"desired": desired, "k_c": 1.0, "k_f": 1.0}, 0.1)) is None
    assert "TypeError" in plan_error(pp.PlanPacket(agents, "formation", {}, 0.1))
    assert plan_error(pp.PlanPacket(agents, "scalable", {"k_c": "x", "k_f": 1.0, "r_s": 1.0}, 0.1)) is not None
    crash = next((CORPUS / "sonpi_plan").glob("crash-*"))
    targets.get("sonpi_plan").run(crash.read_bytes())


def test_the_plans_the_project_s_planners_send_pass_the_agent_s_check() -> None:
    """What ``bad_plan`` holds on is only what a law refuses: every planner's plan, over the wire, is followed."""
    import numpy as np

    from swarm_logic.families.roy.regions import formation as fm
    from swarm_logic.families.roy.regions.agent import plan_error, to_packet
    from swarm_logic.families.roy.regions.ch4 import Ch4Planner
    from swarm_logic.families.roy.regions.ch5 import Ch5Planner
    from swarm_logic.families.roy.regions.ch6 import Ch6Planner
    from swarm_logic.families.roy.regions.planner import Observation
    from swarm_logic.robots.sonpi import pose_packet as pp

    ids, x = np.array([3, 5, 8, 13, 21, 34]), fm.tri_coordinates(1.0) + 5.0
    obs = Observation(0.0, ids, x, np.zeros(6), np.full((6, 8), 2.0), np.arange(8) * np.pi / 4, np.array([35.0, 35.0]))
    for planner in (Ch4Planner(centre0=[5.0, 5.0]), Ch5Planner(), Ch6Planner(r_s=0.5, r_robot=0.3)):
        plan = planner.plan(obs)
        packet = pp.decode(pp.encode_plan(1, plan.t, to_packet(plan, 0.1)))[1]
        assert plan_error(packet) is None, (type(planner).__name__, plan_error(packet))


def test_a_zebro_radio_drops_a_data_frame_no_dw1000_frame_carries() -> None:
    """zebro_radio's find: a data frame from the air longer than ``MAX_PAYLOAD`` (the medium checks only that it is
    bytes: another participant's malformed item) made the module's RX_DATA frame overflow, and ``uwb_protocol.frame``
    raised ValueError in the receiving robot's firmware. It is now dropped and counted (``rx_data_oversize``)."""
    from firmware_sim.robots.decizebro.uwb_radio import UwbRadio
    from swarm_logic.robots.decizebro import uwb_protocol as P

    radio = UwbRadio(robot=0, slot=0, n_slots=2)
    radio.step(0, b"", [])
    big = {"ev": "data", "src": 1, "t_ns": 0, "seq": 1, "data": bytes(P.MAX_PAYLOAD + 1)}
    fits = {"ev": "data", "src": 1, "t_ns": 0, "seq": 2, "data": bytes(P.MAX_PAYLOAD)}
    radio.step(1_000_000, b"", [big, fits])
    assert radio.counters["rx_data_oversize"] == 1 and radio.counters["rx_data"] == 1
    crash = next((CORPUS / "zebro_radio").glob("crash-*"))
    targets.get("zebro_radio").run(crash.read_bytes())
