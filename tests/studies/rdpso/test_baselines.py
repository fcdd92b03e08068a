"""The chapter 8 baselines (EPSO, PPSO, GSO, AFS; swarm_logic/baselines): their update rules against hand-computed
values, their frames, their parameters, and each one searching the peaks field in the numerical runner (the same
controller the co-simulation runs), plus one short co-simulation."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bridge.core.config import to_toml
from bridge.numerical import runner as numerical
from bridge.numerical.objectives import make_field
from swarm_logic.behaviours import load_behaviour
from swarm_logic.clock import SteppedClock
from swarm_logic.drivers.llc_client import LlcState
from swarm_logic.families.baselines import afs, common, epso, gso, ppso
from swarm_logic.families.baselines.afs import Afs
from swarm_logic.families.baselines.epso import Epso
from swarm_logic.families.baselines.gso import Gso
from swarm_logic.families.baselines.ppso import Ppso
from swarm_logic.families.rdpso.messages import Hello
from swarm_logic.families.rdpso.messages import encode as rdpso_encode
from swarm_logic.robot import Robot
from tests.studies.rdpso.test_rdpso import assert_device_protocols_only

ROOT = Path(__file__).resolve().parents[3]
CLASSES = {"epso": Epso, "ppso": Ppso, "gso": Gso, "afs": Afs}


# -- a robot on the bench: the controller's devices, recording what it commands ---------------------------------

class BenchLlc:
    def __init__(self) -> None:
        self.state = LlcState(odom_t=0.0)
        self.moves: list[tuple[float, float]] = []
        self.led: tuple[int, int, int] | None = None

    def poll(self) -> int:
        return 0

    def drive(self, v: float, w: float) -> None:
        raise AssertionError("the baselines move by rotate-then-go only")

    def move(self, rot_rad: float, dist_m: float, speed_mps: float) -> int:
        self.moves.append((rot_rad, dist_m))
        return 0

    def stop(self) -> None:
        pass

    def set_led(self, r: int, g: int, b: int) -> None:
        self.led = (r, g, b)

    def set_odometry(self, x: float, y: float, theta: float) -> None:
        pass


class BenchRadio:
    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def send_nowait(self, dest64: int | None, data: bytes, *, options: int = 0, radius: int = 0) -> int:
        self.sent.append(bytes(data))
        return 0

    def recv(self, timeout: float | None = 0.0) -> None:
        return None

    def poll(self) -> None:
        pass


def bench(cls: type, rid: int = 0, **params: Any) -> Any:
    """A controller on a bench robot at (1, 1) heading 0, in phase B of iteration k with nothing heard yet."""
    robot = Robot(rid, SteppedClock(), BenchLlc(), np.random.default_rng(0), dict(params), xbee=BenchRadio())
    c = cls()
    c.init(robot)
    c.x, c.y, c.theta, c.h = 1.0, 1.0, 0.0, 0.5
    return c


class Draws:
    """A stand-in for the robot's random stream that returns given numbers in turn."""

    def __init__(self, *values: float) -> None:
        self.values = list(values)

    def random(self) -> float:
        return self.values.pop(0)


# -- shared rules ---------------------------------------------------------------------------------------------------

def test_pso_velocity_hand_computed() -> None:
    # v = w v + c1 r1 o (chi1 - x) + c2 r2 o (chi2 - x), draws r1x r1y r2x r2y
    v = common.pso_velocity((0.1, -0.2), (1.0, 1.0), 0.5, ((2.0, (2.0, 3.0)), (1.5, (0.0, 1.0))),
                            Draws(0.5, 0.25, 1.0, 0.2).random)
    assert v == pytest.approx((0.05 + 2 * 0.5 * 1 + 1.5 * 1.0 * -1, -0.1 + 2 * 0.25 * 2 + 0.0))
    assert v == pytest.approx((-0.45, 0.9))


def test_braitenberg_turns_away_more_the_closer_the_echo() -> None:
    half = math.pi / 2
    assert common.braitenberg(0.3, 0.0, math.inf, 0.3, half) == (0.3, False)  # no echo
    assert common.braitenberg(0.3, 0.0, 0.5, 0.3, half) == (0.3, False)  # echo beyond the radius
    assert common.braitenberg(2.0, 0.0, 0.1, 0.3, half) == (2.0, False)  # moving away from what the sonar sees
    heading, hit = common.braitenberg(0.2, 0.0, 0.15, 0.3, half)  # half-way in: half the turn, to the side it leans
    assert hit and heading == pytest.approx(0.2 + math.pi / 4)
    heading, _ = common.braitenberg(-0.2, 0.0, 0.0, 0.3, half)  # at contact: the full turn
    assert heading == pytest.approx(-0.2 - half)
    assert common.braitenberg(0.0, 0.0, 0.0, 0.3, half, tie=-1.0)[0] == pytest.approx(-half)


# -- EPSO -------------------------------------------------------------------------------------------------------

def test_epso_social_best_only_from_robots_heard_in_range() -> None:
    c = bench(Epso, range_m=2.0)
    c.tell()  # personal best 0.5 at (1, 1)
    c.heard = {1: epso.Frame(1, c.k, 2.0, 1.0, 0.7, 2.5, 1.5),  # 1 m away: counts
               2: epso.Frame(2, c.k, 9.0, 1.0, 0.9, 9.0, 1.0)}  # 8 m away: out of range
    assert c.neighbourhood_best() == (pytest.approx(0.7), (2.5, 1.5))
    c.robot.rng_py = Draws(0.5, 0.5, 0.5, 0.5, 0.5)
    c.decide()
    # v = 0.6 * 0 + 2 * 0.5 * (1 - 1, 1 - 1) + 2 * 0.5 * (2.5 - 1, 1.5 - 1) = (1.5, 0.5), clamped to 0.1
    assert c.v == pytest.approx((0.1 * 1.5 / math.hypot(1.5, 0.5), 0.1 * 0.5 / math.hypot(1.5, 0.5)))
    assert c.robot.llc.moves == [(pytest.approx(math.atan2(0.5, 1.5)), pytest.approx(0.1))]


def test_epso_avoidance_deflects_the_move_but_not_the_pso_velocity() -> None:
    c = bench(Epso, avoid_m=0.3, avoid_turn_deg=90.0)
    c.tell()
    c.pbest_at = (2.0, 1.0)  # straight ahead, where the sonar looks
    c.sonar = 0.15
    c.robot.rng_py = Draws(0.5, 0.5, 0.5, 0.5, 0.9)  # the last draw breaks the tie: turn left
    c.decide()
    assert c.v == pytest.approx((0.1, 0.0))  # the PSO's own velocity still points at the obstacle
    rot, dist = c.robot.llc.moves[-1]
    assert rot == pytest.approx(math.pi / 4) and dist == pytest.approx(0.1)  # driven 45 degrees off


# -- PPSO -------------------------------------------------------------------------------------------------------

def test_cone_constraint() -> None:
    cone = math.radians(45)
    assert ppso.constrain_heading(math.pi / 2, 0.0, cone) == pytest.approx(cone)
    assert ppso.constrain_heading(-math.pi / 2, 0.0, cone) == pytest.approx(-cone)
    assert ppso.constrain_heading(0.3, 0.0, cone) == pytest.approx(0.3)
    assert ppso.constrain_heading(-3.0, 3.0, cone) == pytest.approx(-3.0)  # across +-pi: 0.28 rad apart
    assert ppso.constrain_heading(0.0, 3.0, cone) == pytest.approx(3.0 - cone)


def test_ppso_only_the_local_best_shares_its_position_one_frame_later() -> None:
    c = bench(Ppso)
    first = c.tell()
    assert len(first) == ppso.HEAD.size  # nobody knows yet who is best: no position
    c.heard = {1: ppso.Frame(1, c.k, 0.4), 2: ppso.Frame(2, c.k, 0.3, best=(0.9, 5.0, 5.0))}
    c.social_update()
    assert c.is_best  # 0.5 beats 0.4 and 0.3
    assert c.H_best == pytest.approx(0.9) and c.chi2 == (5.0, 5.0)  # robot 2's shared best beats my 0.5
    nxt = ppso.decode(c.tell())
    assert nxt.best == pytest.approx((0.5, 1.0, 1.0))
    c.heard = {1: ppso.Frame(1, c.k, 0.8)}
    c.social_update()
    assert not c.is_best and c.tell()[4] == 0  # not the best now: the next frame carries no position


def test_ppso_moves_within_the_cone_and_goes_back_and_turns_right_on_collision() -> None:
    c = bench(Ppso, cone_deg=45.0, collide_m=0.1, back_m=0.05, turn_deg=90.0)
    c.tell()
    c.chi1 = c.chi2 = (1.0, 3.0)  # straight left of the robot's heading
    c.H_best = 1.0  # (nothing this robot senses displaces chi_2)
    c.robot.rng_py = Draws(*[0.5] * 4)
    c.decide()
    rot, _ = c.robot.llc.moves[-1]
    assert rot == pytest.approx(math.radians(45))  # wanted 90 degrees, the cone allows 45
    c.sonar = 0.05  # collision
    c.robot.rng_py = Draws(*[0.5] * 4)
    c.decide()
    assert c.robot.llc.moves[-1] == (pytest.approx(math.pi), pytest.approx(0.05))  # back off along -heading
    assert c.reference == pytest.approx(-math.pi / 2)  # then face right of where it was going
    c.theta, c.sonar = math.pi, math.inf  # after backing off it faces backwards
    c.chi1 = c.chi2 = (3.0, 1.0)  # now ahead of where it was going
    c.robot.rng_py = Draws(*[0.5] * 4)
    c.decide()
    rot, _ = c.robot.llc.moves[-1]
    # the cone is centred on the right turn (-90 degrees): east is 90 degrees off it, so -45 degrees it is
    assert common.wrap(math.pi + rot) == pytest.approx(-math.pi / 4)


# -- GSO --------------------------------------------------------------------------------------------------------

def test_luciferin_and_decision_range_updates() -> None:
    assert gso.luciferin(5.0, 0.8, 0.4, 0.6) == pytest.approx(0.6 * 5.0 + 0.6 * 0.8)  # 3.48
    lum = 5.0
    for _ in range(200):
        lum = gso.luciferin(lum, 0.8, 0.4, 0.6)
    assert lum == pytest.approx(0.6 * 0.8 / 0.4)  # the fixed point gamma J / rho
    assert gso.decision_range(1.0, 2, 3.0, 0.08, 5) == pytest.approx(1.24)  # too few neighbours: widen
    assert gso.decision_range(1.0, 9, 3.0, 0.08, 5) == pytest.approx(0.68)  # too many: narrow
    assert gso.decision_range(2.9, 0, 3.0, 0.08, 5) == 3.0  # capped at r_s
    assert gso.decision_range(0.1, 10, 3.0, 0.08, 5) == 0.0  # floored at 0
    probs = gso.leader_probabilities(1.0, [2.0, 4.0])
    assert probs == pytest.approx([0.25, 0.75])
    assert [gso.pick(probs, u) for u in (0.0, 0.2, 0.3, 0.99)] == [0, 0, 1, 1]


def test_gso_steps_s_toward_a_brighter_neighbour_in_its_decision_range() -> None:
    c = bench(Gso, step_m=0.05, r_s_m=2.0, r_d0_m=1.5, beta=0.1, n_t=5, l0=5.0, rho=0.4, gamma=0.6)
    c.outgoing = c.tell()
    mine = c.luciferin
    assert mine == pytest.approx(0.6 * 5.0 + 0.6 * 0.5)
    c.heard = {1: gso.Frame(1, c.k, 1.0, 2.0, mine + 1.0),  # brighter, 1 m away: the only neighbour
               2: gso.Frame(2, c.k, 1.0, 3.0, mine + 5.0),  # brighter but 2 m away, beyond r_d = 1.5
               3: gso.Frame(3, c.k, 2.0, 1.0, mine - 1.0)}  # near but dimmer
    c.robot.rng_py = Draws(0.7, 0.5)
    fields = c.decide()
    assert fields["leader"] == 1 and fields["n_brighter"] == 1
    assert c.robot.llc.moves[-1] == (pytest.approx(math.pi / 2), pytest.approx(0.05))
    assert c.r_d == pytest.approx(1.5 + 0.1 * (5 - 1))
    c.heard = {}
    c.decide()  # nobody brighter: a local leader stays put
    assert len(c.robot.llc.moves) == 1 and c.leader is None


# -- AFS --------------------------------------------------------------------------------------------------------

def test_afs_attraction_repulsion_hand_computed() -> None:
    a, b, c = 1.0, 20.0, 0.2
    far = 1.0 - 20.0 * math.exp(-1.0 / 0.2)  # 0.86524: attraction dominates at 1 m
    near = 1.0 - 20.0 * math.exp(-0.01 / 0.2)  # -18.0246: repulsion dominates at 0.1 m
    assert afs.attraction_repulsion((0.0, 0.0), [(1.0, 0.0)], a, b, c) == pytest.approx((far, 0.0))
    assert afs.attraction_repulsion((0.0, 0.0), [(0.0, 0.1)], a, b, c) == pytest.approx((0.0, 0.1 * near))
    both = afs.attraction_repulsion((0.0, 0.0), [(1.0, 0.0), (0.0, 0.1)], a, b, c)
    assert both == pytest.approx((0.86524, -1.80246), abs=1e-5)
    d = afs.equilibrium_distance(a, b, c)
    assert d == pytest.approx(math.sqrt(0.2 * math.log(20.0)))  # 0.774
    assert afs.attraction_repulsion((0.0, 0.0), [(d, 0.0)], a, b, c) == pytest.approx((0.0, 0.0), abs=1e-12)


def test_afs_descent_step_hand_computed() -> None:
    # dt (rho grad h - gamma grad g + J): 0.1 (2 * 0.1 - 0 + 1, 0 - 0.5 * 1 - 1) = (0.12, -0.15)
    assert afs.descent_step((0.1, 0.0), (0.0, 1.0), (1.0, -1.0), 2.0, 0.5, 0.1, 1.0) == pytest.approx((0.12, -0.15))
    vx, vy = afs.descent_step((0.1, 0.0), (0.0, 1.0), (1.0, -1.0), 2.0, 0.5, 0.1, 0.05)
    assert math.hypot(vx, vy) == pytest.approx(0.05) and vx / vy == pytest.approx(0.12 / -0.15)


def test_afs_gradient_estimate_from_samples() -> None:
    def h(x: float, y: float) -> float:
        return 2.0 + 3.0 * x - 1.0 * y

    pts = [(0.0, 0.0), (0.3, 0.1), (-0.2, 0.4), (0.1, -0.3)]
    assert afs.plane_gradient([(x, y, h(x, y)) for x, y in pts]) == pytest.approx((3.0, -1.0))
    line = [(x, 0.5 * x, h(x, 0.5 * x)) for x in (0.0, 0.1, 0.2)]  # on a line: only the slope along it
    g = afs.plane_gradient(line)
    along = (3.0 - 0.5) / math.hypot(1.0, 0.5)  # directional derivative along (1, 0.5)
    assert g == pytest.approx((along / math.hypot(1.0, 0.5), 0.5 * along / math.hypot(1.0, 0.5)))
    assert afs.plane_gradient([(1.0, 1.0, 5.0)]) == (0.0, 0.0)
    assert afs.plane_gradient([(1.0, 1.0, 5.0), (1.0, 1.0, 6.0)]) == (0.0, 0.0)  # no spread: no gradient


def test_afs_positions_flood_over_hops_and_age_out() -> None:
    c = bench(Afs, max_age=3, n_total=8)
    k = c.k
    c.table = {5: (k - 2, 1, 4.0, 4.0), 6: (k - 4, 0, 6.0, 6.0)}
    relayed = ((5, (k - 1) & 0xFF, 2, 4.5, 4.5), (7, (k - 1) & 0xFF, 0, 7.0, 7.0), (0, k & 0xFF, 0, 9.0, 9.0))
    c.heard = {1: afs.Frame(1, k, 2.0, 1.0, 0.3, table=relayed)}
    c.merge()
    assert c.table[1] == (k, 0, 2.0, 1.0)  # heard directly
    assert c.table[5] == (k - 1, 3, 4.5, 4.5)  # newer news over more relays still wins
    assert c.table[7] == (k - 1, 1, 7.0, 7.0)  # relayed: one more relay than the sender had
    assert 6 not in c.table and 0 not in c.table  # too old; and a robot does not list itself


# -- frames -----------------------------------------------------------------------------------------------------

def test_frames_round_trip() -> None:
    f = epso.Frame(7, 70000 & 0xFFFF, 1.25, -0.5, 812.0, 2.0, 1.75)
    assert epso.decode(epso.encode(f)) == f and len(epso.encode(f)) == 24
    for best in (None, (0.75, 1.5, -2.25)):
        p = ppso.Frame(3, 12, 0.5, best)
        assert ppso.decode(ppso.encode(p)) == p
    assert len(ppso.encode(ppso.Frame(3, 12, 0.5))) == 9 and len(ppso.encode(ppso.Frame(3, 12, 0.5, (1, 2, 3)))) == 21
    g = gso.Frame(9, 65535, 0.125, 2.5, 3.0)
    assert gso.decode(gso.encode(g)) == g and len(gso.encode(g)) == 16
    table = tuple((10 + i, (300 - i) & 0xFF, i, 1.23 + i, -4.56) for i in range(4))
    a = afs.Frame(2, 300, 1.5, 2.5, 0.25, table)
    back = afs.decode(afs.encode(a))
    assert (back.robot, back.k, back.x, back.y, back.h) == (2, 300, 1.5, 2.5, 0.25)
    assert [v for e in back.table for v in e] == pytest.approx([v for e in table for v in e])  # to the cm
    assert len(afs.encode(a)) == afs.HEAD.size + 4 * afs.ENTRY.size


def test_afs_table_is_sent_in_turns_when_it_does_not_fit() -> None:
    table = tuple((i, 0, 0, float(i), 0.0) for i in range(25))
    frame = afs.Frame(30, 1, 0.0, 0.0, 0.0, table)
    sent: set[int] = set()
    for turn in range(3):
        data = afs.encode(frame, limit=92, start=turn * 10)
        assert len(data) <= 92
        sent |= {e[0] for e in afs.decode(data).table}
    assert sent == set(range(25))  # ten entries a frame, every entry within three frames


RDPSO_HELLO = rdpso_encode(Hello(1, 1, 5, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0, 0, 0, 0))
MALFORMED = [b"", b"\x00", b"hello world, not a frame", RDPSO_HELLO]


@pytest.mark.parametrize(("decode", "good"), [
    (epso.decode, epso.encode(epso.Frame(1, 2, 0.0, 0.0, 1.0, 0.0, 0.0))),
    (ppso.decode, ppso.encode(ppso.Frame(1, 2, 1.0, (1.0, 0.0, 0.0)))),
    (gso.decode, gso.encode(gso.Frame(1, 2, 0.0, 0.0, 1.0))),
    (afs.decode, afs.encode(afs.Frame(1, 2, 0.0, 0.0, 1.0, ((3, 1, 0, 1.0, 1.0),)))),
], ids=["epso", "ppso", "gso", "afs"])
def test_malformed_frames_are_refused(decode: Any, good: bytes) -> None:
    assert decode(good) is not None
    bad = [*MALFORMED, good[:-1], good + b"\x00", bytes([good[0] ^ 0xFF]) + good[1:]]
    # a NaN where a number should be
    bad.append(good[:4] + bytes.fromhex("0000c07f") + good[8:])
    for d in (epso.decode, ppso.decode, gso.decode, afs.decode):  # another algorithm's frame
        if d is not decode:
            bad.append(next(g for g in OTHERS if d(g) is not None))
    for data in bad:
        assert decode(data) is None, data


OTHERS = [epso.encode(epso.Frame(1, 2, 0.0, 0.0, 1.0, 0.0, 0.0)), ppso.encode(ppso.Frame(1, 2, 1.0)),
          gso.encode(gso.Frame(1, 2, 0.0, 0.0, 1.0)), afs.encode(afs.Frame(1, 2, 0.0, 0.0, 1.0))]


def test_ppso_and_afs_lengths_must_agree_with_their_headers() -> None:
    head = ppso.encode(ppso.Frame(1, 2, 1.0))
    assert ppso.decode(head[:-1] + b"\x01") is None  # says BEST, carries no position
    assert ppso.decode(head[:-1] + b"\x02") is None  # an unknown flag
    one = afs.encode(afs.Frame(1, 2, 0.0, 0.0, 1.0, ((3, 1, 0, 1.0, 1.0),)))
    assert afs.decode(one[:afs.HEAD.size - 1] + b"\x02" + one[afs.HEAD.size:]) is None  # says 2 entries, has 1


# -- parameters -------------------------------------------------------------------------------------------------

@pytest.mark.parametrize(("cls", "params", "field"), [
    (Epso, {"w": 1.0}, "w"),
    (Epso, {"c2": -1.0}, "c2"),
    (Epso, {"range_m": 0.0}, "range_m"),
    (Epso, {"dx_max_m": 0.0}, "dx_max_m"),
    (Epso, {"comm_window_s": 1.5}, "comm_window_s"),
    (Epso, {"n_total": 300}, "n_total"),
    (Epso, {"rho1": 0.2}, "unknown parameters"),
    (Ppso, {"cone_deg": 0.0}, "cone_deg"),
    (Ppso, {"turn_deg": 200.0}, "turn_deg"),
    (Ppso, {"w": -0.1}, "w"),
    (Gso, {"rho": 1.0}, "rho"),
    (Gso, {"gamma": 0.0}, "gamma"),
    (Gso, {"n_t": 2.5}, "n_t"),
    (Gso, {"r_d0_m": 5.0, "r_s_m": 1.0}, "r_d0_m"),
    (Gso, {"step_m": math.nan}, "step_m"),
    (Afs, {"b": 0.5}, "b"),
    (Afs, {"c_m2": 0.0}, "c_m2"),
    (Afs, {"dt_s": -0.1}, "dt_s"),
    (Afs, {"grad_memory": 0}, "grad_memory"),
    (Afs, {"payload_max": 10}, "payload_max"),
])
def test_parameters_outside_their_meaning_are_refused(cls: type, params: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        cls.resolve(params)


def test_stability_warnings_name_their_bound() -> None:
    (w,) = Epso.warnings({})  # Pugh & Martinoli's w = 0.6, c1 = c2 = 2 lie just outside Poli's region
    assert "c1 + c2 = 4 >= 3.84" in w and "Poli 2009" in w
    assert Epso.warnings({"w": 0.7298, "c1": 1.4962, "c2": 1.4962}) == [] and Ppso.warnings({}) == []
    assert Afs.warnings({}) == []
    assert "dt_s * a * n_total = 2.4 >= 2" in Afs.warnings({"n_total": 120})[0]


def test_behaviours_are_registered_with_complete_defaults() -> None:
    for name, cls in CLASSES.items():
        assert load_behaviour(name) is cls and cls.needs_radio
        assert cls.resolve({}) == {**cls.defaults}  # the defaults are a valid parameter set
        assert {"iteration_s", "dx_max_m", "n_total"} <= set(cls.defaults)


@pytest.mark.parametrize("mod", [common, epso, ppso, gso, afs], ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_the_controllers_use_only_the_device_protocols(mod: Any) -> None:
    assert_device_protocols_only(mod)


# -- searching peaks in the numerical runner -------------------------------------------------------------------

SIZE = 30.0  # m: peaks' 6 x 6 canonical domain on a 30 m arena (5 m per unit)
UNIT = SIZE / 6.0
NUMERIC = {"dx_max_m": 0.5, "send_jitter_s": 0.0, "log_every": 0}
RUN_PARAMS: dict[str, dict[str, Any]] = {
    "epso": {**NUMERIC, "range_m": 10.0},
    "ppso": {**NUMERIC},
    # GSO's s = 0.03 and beta = 0.08 are in the papers' units of the same 6-unit peaks domain: scaled to the arena
    "gso": {**NUMERIC, "step_m": 0.03 * UNIT, "beta": 0.08 * UNIT, "r_s_m": 10.0},
    "afs": {**NUMERIC, "c_m2": 1.0, "rho": 250.0, "grad_radius_m": 3.0, "payload_max": 4096},
}


def peaks_run(name: str, seed: int, n: int = 20, iterations: int = 200) -> tuple[float, numerical.RunResult]:
    """``n`` robots dropped in a 7 x 7 m patch 6-12 m from the optimum, where the field reads 0.35-0.72 (the
    optimum reads 1); returns the best reading at the start and the run."""
    field = make_field("peaks", SIZE)
    start = np.random.default_rng(seed).uniform((20.0, 7.0), (27.0, 14.0), (n, 2))
    f0 = float(field.value(start[:, 0], start[:, 1]).max())
    res = numerical.run(name, RUN_PARAMS[name], n, iterations, field, (SIZE, SIZE),
                        link=numerical.LinkModel(range_m=10.0), seed=seed, start=start)
    return f0, res


@pytest.mark.parametrize("name", list(CLASSES))
def test_each_baseline_climbs_peaks_from_a_deployment_patch(name: str) -> None:
    starts, finals = [], []
    for seed in range(5):
        f0, res = peaks_run(name, seed)
        starts.append(f0)
        finals.append(float(res.best[-1]))
    assert max(starts) < 0.75
    assert sum(f >= 0.95 for f in finals) >= 4, (starts, finals)  # AFS may settle on a plateau (no escape)
    assert np.median(finals) >= np.median(starts) + 0.3, (starts, finals)


@pytest.mark.parametrize("name", list(CLASSES))
def test_same_seed_same_run(name: str) -> None:
    (_, a), (_, b), (_, c) = peaks_run(name, 3, iterations=60), peaks_run(name, 3, iterations=60), \
        peaks_run(name, 4, iterations=60)
    assert np.array_equal(a.final_positions, b.final_positions) and np.array_equal(a.best, b.best)
    assert not np.array_equal(a.final_positions, c.final_positions)


class NoisyGso(Gso):
    """A GSO robot whose radio also carries another application's frame and an EPSO frame every iteration."""

    def _send(self) -> None:
        super()._send()
        self.robot.xbee.send_nowait(None, b"not a frame")
        self.robot.xbee.send_nowait(None, OTHERS[0])


def test_foreign_frames_are_counted_and_dropped() -> None:
    field = make_field("peaks", SIZE)
    start = np.array([[10.0, 10.0], [11.0, 10.0], [10.0, 11.0]])
    res = numerical.run(NoisyGso, {**RUN_PARAMS["gso"], "log_every": 1}, 3, 20, field, (SIZE, SIZE),
                        link=numerical.LinkModel(range_m=10.0), seed=1, start=start, keep_logs=True)
    last_k = max(r["k"] for r in res.logs)
    last = [r for r in res.logs if r["topic"] == "gso" and r["k"] == last_k]
    assert len(last) == 3
    assert all(r["dropped"]["malformed"] >= 2 * 2 * 19 for r in last)  # two neighbours' two extra frames a turn
    assert all(r["heard"] == 2 for r in last)  # the GSO frames still get through


# -- co-simulation smoke -----------------------------------------------------------------------------------------

@pytest.mark.session
def test_a_baseline_runs_in_the_co_simulation(tmp_path: Path) -> None:
    """GSO on four emulated eSwarBots in the light arena for 10 s: all alive, one frame per robot per iteration."""
    from tests.core.test_session import run

    raw = tomllib.loads((ROOT / "hil_configs" / "rdpso" / "rdpso_arena.toml").read_text())
    raw["session"] |= {"seed": 3, "duration_s": 10.0, "name": "gso-smoke"}
    group = raw["robots"][0]
    group |= {"count": 4, "behaviour": "gso",
              "params": {"n_total": 4, "iteration_s": 1.5, "comm_window_s": 0.3, "speed_mps": 0.25},
              "placement": {"kind": "spiral", "centres": [[1.2, 1.0]], "spacing_m": 0.3}}
    cfg = tmp_path / "gso.toml"
    cfg.write_text(to_toml(raw))
    out = tmp_path / "run"
    code, s = run(cfg, out, "--duration", "10", timeout=600)
    assert code == 0, s.get("error")
    assert s["failures"] == [] and [r["alive"] for r in s["per_robot"]] == [True] * 4
    assert s["radio"]["totals"]["tx"]["frames"] >= 4 * 5  # iterations at 1.5, 3.0, ... 9.0 s
    from bridge.core.recorder import iter_messages

    records = [json.loads(data) for topic, _, data in iter_messages(out / "session.mcap")
               if topic.endswith("/log/gso")]
    assert {r["k"] for r in records} >= {2, 3, 4, 5}
    assert any(r["heard"] == 3 for r in records)  # the robots hear each other
    assert any(r["leader"] >= 0 for r in records)  # and follow brighter ones
