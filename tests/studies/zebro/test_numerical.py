"""The Zebro model's tick semantics (random sequential activation, walking in one's turn, delivery within the tick,
error-free sensing), its scenarios (SRC / LRC radii, particles sensed at launch), the split test (A-13), Z-U6
(silent is silent), Z-U7 (the sum rule) and determinism."""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import pytest

from bridge.studies.zebro.experiments import decision_trial
from bridge.studies.zebro.numerical import (
    Model,
    Particle,
    PointUtility,
    Swarm,
    U,
    ZebroWorld,
    make_scenario,
    mst_longest_edge,
    run,
)
from swarm_logic.controller import Controller
from swarm_logic.families.zebro.immature import ZebroImmature
from swarm_logic.families.zebro.mature import ZebroMature
from swarm_logic.families.zebro.silent import ZebroSilent
from swarm_logic.graph import components
from swarm_logic.robots.decizebro.interfaces import (
    IMU,
    LEGS,
    UTILITY,
    UWB_RADIO,
    Imu,
    Locomotion,
    UtilitySensor,
    ZebroRadio,
)

from .helpers import UP, line, scenario


class Recorder(Controller):
    """Each step: note the tick, what arrived, then broadcast its id and walk straight."""

    seen: ClassVar[list[tuple[int, int, list[int], float]]] = []

    def init(self, robot) -> None:
        super().init(robot)
        self.radio = robot.device(UWB_RADIO)
        self.legs = robot.device(LEGS)

    def step(self) -> None:
        got = [m.src for m in self.radio.receive()]
        nb = {n.id: n.range_m for n in self.radio.neighbours()}
        Recorder.seen.append((round(self.robot.clock.now()), self.robot.id, got, nb.get(0, math.nan)))
        self.radio.broadcast(bytes((0x01, self.robot.id)))
        self.legs.walk(0.0)


def test_devices_implement_the_zebro_protocols() -> None:
    s = Swarm(ZebroSilent, {}, line(3, {0: 20}), 0)
    dev = s.ctls[0].robot.devices
    assert isinstance(dev[UWB_RADIO], ZebroRadio) and isinstance(dev[UTILITY], UtilitySensor)
    assert isinstance(dev[IMU], Imu) and isinstance(dev[LEGS], Locomotion)
    assert s.ctls[0].robot.llc is None


def test_one_step_per_robot_per_tick_in_a_seeded_random_order_with_delivery_within_the_tick() -> None:
    Recorder.seen = []
    s = Swarm(Recorder, {}, line(6, {}, r=100.0), seed=3)
    for _ in range(5):
        s.tick()
    by_tick: dict[int, list[int]] = {}
    steps = [i for _, i, _, _ in Recorder.seen]
    for k, (t, i, got, _) in enumerate(Recorder.seen):
        by_tick.setdefault(t, []).append(i)
        last = max((q for q in range(k) if steps[q] == i), default=-1)
        assert got == steps[last + 1:k]  # every frame sent since my last step, at once, in order
    assert all(sorted(v) == list(range(6)) for v in by_tick.values())
    assert len({tuple(v) for v in by_tick.values()}) > 1  # the order is drawn afresh
    Recorder.seen = []
    s2 = Swarm(Recorder, {}, line(6, {}, r=100.0), seed=3)
    for _ in range(5):
        s2.tick()
    assert [v[:2] for v in Recorder.seen] == [(t, i) for t, v in by_tick.items() for i in v]  # same seed, same order


def test_next_tick_delivery_is_one_hop_per_tick() -> None:
    Recorder.seen = []
    s = Swarm(Recorder, {}, line(4, {}, r=100.0), seed=1, model=Model(delivery="next_tick"))
    s.tick()
    assert all(got == [] for t, _, got, _ in Recorder.seen if t == 1)
    s.tick()
    assert all(len(got) == 3 for t, _, got, _ in Recorder.seen if t == 2)


def test_a_robot_walks_in_its_turn() -> None:
    """Ranges read by a later robot in the tick include the earlier robot's walk of that tick."""
    Recorder.seen = []
    sc = line(2, {}, r=100.0)
    sc.heading[:] = [math.pi, 0.0]  # robot 0 walks away from robot 1
    s = Swarm(Recorder, {}, sc, seed=5)
    s.tick()
    order = [i for t, i, _, _ in Recorder.seen if t == 1]
    d1 = next(d for t, i, _, d in Recorder.seen if t == 1 and i == 1)
    step = 0.2 * U
    assert d1 == pytest.approx(1 * U + (step if order[0] == 0 else 0.0))


def test_sensing_is_exact() -> None:
    sc = scenario([(0, 0), (3, 4)], [0.0, 1.0], [], r=10.0)
    w = ZebroWorld(sc.pos, sc.heading, sc.r_comm, [], Model())
    (nb,) = w.neighbours(0)
    assert nb.id == 1 and nb.range_m == pytest.approx(5 * U) and nb.heading_rad == 1.0
    assert nb.bearing_rad == pytest.approx(math.atan2(4, 3))
    assert w.neighbours(0) and not ZebroWorld(sc.pos, sc.heading, 4.9, [], Model()).neighbours(0)


def test_the_sum_rule_and_the_cone() -> None:
    """Z-U7: two particles in one cone read as u1 + u2; the cone is +-30 degrees and 3 u (A-15, A-16)."""
    parts = [Particle(2 * U, 0.5 * U, 15), Particle(2.5 * U, -0.5 * U, 95), Particle(2 * U, 2 * U, 40),
             Particle(3.2 * U, 0.0, 7)]
    w = ZebroWorld(np.zeros((1, 2)), np.zeros(1), 1.0, parts, Model())
    sensor = PointUtility(w, 0)
    assert sensor.read() == 15 + 95  # 45 degrees off and 3.2 u away are outside
    assert sensor.bearing() == pytest.approx(math.atan2(15 * math.sin(math.atan2(0.5, 2)) + 95 * math.sin(
        math.atan2(-0.5, 2.5)), 15 * math.cos(math.atan2(0.5, 2)) + 95 * math.cos(math.atan2(-0.5, 2.5))))
    assert sensor.consumed() == 0


def test_a_particle_is_eaten_by_the_first_robot_to_reach_it() -> None:
    sc = scenario([(0, 0), (0, 1)], [0.0, 0.0], [(0.6, 0.0, 50)], r=5.0)
    s = Swarm(ZebroSilent, {}, sc, seed=0)
    s.tick()
    p = s.world.particles[0]
    assert p.eaten_by == 0 and p.tick == 1 and s.ctls[0].eaten == 0  # read by its next step
    s.tick()
    assert s.ctls[0].eaten == 50 and s.world.eat_count == 1


@pytest.mark.parametrize(("n", "p"), [(5, 1), (5, 2), (20, 2)])
def test_scenarios(n: int, p: int) -> None:
    for seed in range(5):
        sc = make_scenario(n, p, False, np.random.default_rng(seed))
        d = np.hypot(*(sc.pos[:, None, :] - sc.pos[None, :, :]).transpose(2, 0, 1))
        assert components(d <= sc.r_comm) == 1 and components(d <= 0.99 * mst_longest_edge(sc.pos)) > 1
        assert d[np.triu_indices(n, 1)].min() >= 1.0
        lr = make_scenario(n, p, True, np.random.default_rng(seed))
        assert lr.r_comm >= d.max()
        w = ZebroWorld(sc.pos, sc.heading, sc.r_comm, [Particle(x * U, y * U, u) for x, y, u in sc.particles],
                       Model())
        for f, (_, _, u) in zip(sc.finders, sc.particles, strict=True):
            assert PointUtility(w, f).read() >= u  # sensed at launch
        if p == 2:
            assert sorted(u for *_, u in sc.particles) == [15, 95]


def test_silent_is_silent() -> None:
    """Z-U6: the silent swarm layer sends no frame."""
    sc = make_scenario(20, 2, False, np.random.default_rng(1))
    res = run(ZebroSilent, {}, sc, seed=1, max_ticks=60)
    assert res.tx == {} and res.rx_bytes == 0


def test_split_needs_ten_ticks_apart_or_the_end() -> None:
    """A-13: two robots walking apart split; two walking together do not."""
    apart = scenario([(0, 0), (1, 0)], [math.pi, 0.0], [], r=1.5)
    assert run(ZebroSilent, {}, apart, seed=0, max_ticks=40).split
    together = scenario([(0, 0), (1, 0)], [UP, UP], [], r=1.5)
    res = run(ZebroSilent, {}, together, seed=0, max_ticks=40)
    assert not res.split and res.max_components == 1 and res.ticks_run == 40
    brief = scenario([(0, 0), (1.4, 0)], [math.pi, 0.0], [], r=1.5)
    res = run(ZebroSilent, {}, brief, seed=0, max_ticks=12, split_ticks=20)
    assert res.split  # in pieces at the end


@pytest.mark.parametrize("algo", ["silent", "immature", "mature"])
def test_same_seed_same_metrics(algo: str) -> None:
    a = decision_trial("E5", algo, 1234)
    b = decision_trial("E5", algo, 1234)
    assert a.metrics == b.metrics
    assert decision_trial("E5", algo, 99).metrics != a.metrics


@pytest.mark.parametrize("cls", [ZebroImmature, ZebroMature])
def test_controllers_log_their_frames_by_type(cls) -> None:
    """What the controllers log (zebro_tx, at the end) is what the radio carried."""
    sc = make_scenario(5, 2, False, np.random.default_rng(4))
    res = run(cls, {}, sc, seed=4, max_ticks=80, keep_logs=True)
    logged: dict[str, int] = {}
    for r in res.logs:
        if r["topic"] == "zebro_tx":
            for k, v in r.items():
                if k not in ("tick", "robot", "topic", "refused"):
                    logged[k] = logged.get(k, 0) + v
    assert logged == res.tx and sum(logged.values()) > 0
