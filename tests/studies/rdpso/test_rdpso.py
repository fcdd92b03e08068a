"""The RDPSO controller: its hello frame, its parameters, and its behaviour in the numerical runner (the same
controller the co-simulation runs), including the targets U8, U11 and the subgroup bookkeeping."""

from __future__ import annotations

import math
import random
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import pytest

from bridge.core.config import ConfigError, config_warnings, load_config
from bridge.numerical import runner as numerical
from bridge.numerical.objectives import LightField
from bridge.studies.rdpso.parameter_sets import SETS
from firmware_sim.modules.xbee import rssi_pwm_formula
from swarm_logic.families.rdpso.controller import Rdpso, chance, colour, new_subgroup_id
from swarm_logic.families.rdpso.messages import F_CALL, F_IMPROVED, HEADER, ZIGBEE_BROADCAST_MAX, Hello, decode, encode

ROOT = Path(__file__).resolve().parents[3]


def hello(members: int = 3, chosen: tuple[int, ...] = (4,)) -> Hello:
    return Hello(robot=7, sid=2, k=70000, x=1.25, y=-0.5, hbest=812.0, ledger_h=830.0, ledger_x=2.0, ledger_y=1.95,
                 sc=4, n_kill=1, flags=F_IMPROVED | F_CALL, target=0, chosen=chosen,
                 members=tuple((10 + i, (70000 - i) & 0xFF, i, 700.0 + i) for i in range(members)))


# -- the frame ------------------------------------------------------------------------------------------------

def test_hello_round_trip() -> None:
    h = hello()
    data = encode(h)
    assert len(data) == HEADER.size + 1 + 5 * 3
    back = decode(data)
    assert back is not None
    assert (back.robot, back.sid, back.k, back.sc, back.n_kill, back.flags, back.chosen) == (
        7, 2, 70000 & 0xFFFF, 4, 1, F_IMPROVED | F_CALL, (4,))
    assert back.x == pytest.approx(1.25) and back.ledger_h == pytest.approx(830.0)
    assert back.members == h.members  # (id, iteration mod 256, relays, best) survive (bests are half floats)


def test_hello_fits_a_zigbee_broadcast_keeping_the_nearest_members() -> None:
    h = hello(members=20)
    data = encode(h)
    assert len(data) <= ZIGBEE_BROADCAST_MAX
    kept = decode(data).members
    assert len(kept) == (ZIGBEE_BROADCAST_MAX - HEADER.size - 1) // 5 == 11
    assert [m[2] for m in kept] == sorted(m[2] for m in h.members)[:11]  # fewest relays first
    assert len(encode(h, limit=4096)) == HEADER.size + 1 + 5 * 20


@pytest.mark.parametrize("data", [b"", b"R", bytes([0x52]) + bytes(38), b"hello world" * 5, encode(hello())[:-2],
                                  b"H\x01\x00\x02\x00"])
def test_foreign_or_truncated_frames_are_not_hellos(data: bytes) -> None:
    assert decode(data) is None


# -- parameters -------------------------------------------------------------------------------------------------

@pytest.mark.parametrize(("params", "field"), [
    ({"rho2": -0.1}, "rho2"),
    ({"alpha": 0.0}, "alpha"),
    ({"alpha": 1.2}, "alpha"),
    ({"subgroups_init": 5, "subgroups_max": 6, "n_total": 4}, "more subgroups than robots"),
    ({"subgroups_min": 3, "subgroups_init": 2}, "subgroups_min/init/max"),
    ({"link_mode": "telepathy"}, "link_mode"),
    ({"comm_window_s": 2.0}, "comm_window_s"),
    ({"send_jitter_s": 0.5, "comm_window_s": 0.25}, "send_jitter_s"),
    ({"n_total": 300}, "n_total"),
    ({"colour": 1}, "unknown parameters"),
])
def test_parameters_outside_their_meaning_are_refused(params: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        Rdpso.resolve(params)


def test_a_config_with_a_bad_parameter_names_file_field_and_reason(tmp_path: Path) -> None:
    text = (ROOT / "hil_configs" / "rdpso" / "rdpso_arena.toml").read_text().replace("rho2 = 0.4", "rho2 = -0.4")
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    with pytest.raises(ConfigError, match=r"bad\.toml: robots\[0\]\.params\.rho2: must be >= 0, got -0\.4"):
        load_config(cfg)


def test_the_arena_config_is_warned_about_its_stability_bound() -> None:
    # U4: the thesis' chapter 4-6 set (sum rho = 2.2) leaves the particular attraction domain in the worst case
    (w,) = config_warnings(load_config(ROOT / "hil_configs" / "rdpso" / "rdpso_arena.toml"))
    assert "sum(rho) = 2.2" in w and "eq. 7.14/7.17" in w
    assert Rdpso.warnings(SETS["S1"]) == [] and Rdpso.warnings(SETS["S2"]) == []


# -- targets -----------------------------------------------------------------------------------------------------

def test_u8_rssi_pwm_duty() -> None:
    assert rssi_pwm_formula(-94.0, -94.0) == pytest.approx(0.288, abs=0.001)
    assert rssi_pwm_formula(-75.0, -94.0) == pytest.approx(0.613, abs=0.001)


def test_u11_listing_draw_happens_with_half_the_probability() -> None:
    rng = random.Random(3)
    for p in (1.0, 0.5, 0.2):
        freq = sum(chance(rng, p) for _ in range(1_000_000)) / 1e6
        assert freq == pytest.approx(p / 2, abs=0.005)


def test_subgroup_ids_and_colours() -> None:
    assert colour(0) == (255, 255, 255)  # excluded robots are white (Fig. 4.12)
    assert len({colour(s) for s in range(1, 9)}) == 8
    ids = {new_subgroup_id(r, k) for r in range(255) for k in range(256)}
    assert len(ids) == 255 * 256 and min(ids) >= 256 and max(ids) <= 0xFFFF  # never an initial subgroup's id


# -- behaviour in the numerical runner -------------------------------------------------------------------------

ARENA = (2.55, 2.45)
SPOTS = LightField([(2.0, 1.95, 1.0, 0.45), (0.5, 0.5, 0.4, 0.45)], ARENA)


def arena_run(n: int = 8, iterations: int = 80, seed: int = 1, deaths: dict[int, float] | None = None,
              **params: object) -> numerical.RunResult:
    p = {**SETS["ch4"], "dx_max_m": 0.1, "d_max_m": 0.5, "subgroups_init": 2, "subgroups_max": 3,
         "r_w_m": 0.3, "send_jitter_s": 0.0, "swarm_seed": seed, **params}
    return numerical.run(Rdpso, p, n, iterations, SPOTS, ARENA, link=numerical.LinkModel(range_m=10.0), seed=seed,
                         keep_logs=True, deaths=deaths)


def by_iteration(res: numerical.RunResult) -> dict[int, list[dict]]:
    out: dict[int, list[dict]] = defaultdict(list)
    for rec in res.logs:
        if rec["topic"] == "rdpso":
            out[rec["k"]].append(rec)
    return out


def test_same_seed_same_run_other_seed_other_run() -> None:
    a, b, c = arena_run(seed=4), arena_run(seed=4), arena_run(seed=5)
    assert np.array_equal(a.final_positions, b.final_positions) and a.logs == b.logs
    assert not np.array_equal(a.final_positions, c.final_positions)


def test_the_swarm_mostly_finds_the_brighter_spot() -> None:
    found = searched = 0
    for seed in range(6):
        res = arena_run(n=8, iterations=100, seed=seed)
        searched += res.best[0] < 0.9  # it had to search
        found += res.best[-1] >= 0.95
    assert searched >= 4
    assert found >= 4  # the thesis' swarm converged in about 90 % of its trials


def test_one_hop_subgroups_keep_one_ledger() -> None:
    """Every member of a subgroup that hears every other takes the same decisions from the same hellos: ledger
    values, stagnancy and punish counters agree at every iteration (digest 6.1 item 6), except in the iteration a
    subgroup is founded, when each joiner brings its own best until the next hellos."""
    res = arena_run(n=8, iterations=120, seed=3, rho2=0.1)
    disagreements = checked = 0
    for recs in by_iteration(res).values():
        groups: dict[int, list[dict]] = defaultdict(list)
        for r in recs:
            if r["sid"]:
                groups[r["sid"]].append(r)
        for members in groups.values():
            if len(members) < 2 or any(e.startswith(("joined", "founded")) for m in members for e in m["events"]):
                continue
            checked += 1
            ledgers = {(round(m["ledger_h"], 3), m["sc"], m["n_kill"]) for m in members}
            disagreements += len(ledgers) > 1
    assert checked > 100
    assert disagreements == 0


def test_a_flat_world_punishes_one_robot_at_a_time_then_dismantles() -> None:
    """With nothing to improve on, each subgroup stagnates: after SC_max iterations it excludes its worst robot
    (only that one leaves), and at N_min it is dismantled (Table 4.1)."""
    flat = LightField([(1.0, 1.0, 1e-9, 10.0)], ARENA, ambient=1.0)
    p = {**SETS["ch4"], "dx_max_m": 0.1, "d_max_m": 0.5, "subgroups_init": 1, "subgroups_max": 1, "sc_max": 10,
         "n_min": 2, "r_w_m": 0.3, "send_jitter_s": 0.0}
    res = numerical.run(Rdpso, p, 4, 80, flat, ARENA, link=numerical.LinkModel(range_m=10.0), seed=1, keep_logs=True)
    events = [(r["k"], r["robot"], e) for r in res.logs if r["topic"] == "rdpso" for e in r["events"]]
    left = [(k, rob) for k, rob, e in events if e == "punished"]
    assert len(left) >= 1
    first_k = left[0][0]
    assert [rob for k, rob in left if k == first_k] == [left[0][1]]  # exactly one robot left at that iteration
    assert any(e == "dismantled" for _, _, e in events)
    assert res.excluded.max() == 4


def test_a_dead_robot_is_noticed_within_three_hellos_and_the_subgroup_goes_on() -> None:
    it = 1.0
    res = arena_run(n=8, iterations=60, seed=6, deaths={2: 20.0 * it, 5: 20.0 * it}, sc_max=1000)
    iters = by_iteration(res)
    dead = {2, 5}
    first = min(iters)
    k_death = first + 19  # phase A of this iteration is the first the dead robots miss
    noticed: dict[int, int] = {}
    for k in sorted(iters):
        for r in iters[k]:
            if r["robot"] in dead or k < k_death:
                continue
            if r["robot"] not in noticed and r["n_s"] == len(
                    [q for q in iters[k_death - 2] if q["sid"] == r["sid"] and q["robot"] not in dead]):
                noticed[r["robot"]] = k - k_death + 1
    assert set(noticed) == set(range(8)) - dead
    assert max(noticed.values()) <= 3  # the link breaks after three missed hellos
    last = max(iters)
    assert {r["robot"] for r in iters[last]} == set(range(8)) - dead  # the survivors carry on
    assert res.best[-1] > res.best[20]  # and keep searching


def test_excluded_robots_are_recruited_or_found_subgroups() -> None:
    res = arena_run(n=12, iterations=150, seed=8, sc_max=8)
    events = Counter(e.split()[0] for r in res.logs if r["topic"] == "rdpso" for e in r["events"])
    assert events["punished"] + events["dismantled"] > 0
    assert events["joined"] > 0  # CALL/SPAWN answered, or a founder's subgroup joined
    joined = [r["sid"] for r in res.logs if r["topic"] == "rdpso" and any(
        e.startswith("joined") for e in r["events"])]
    assert joined and 0 not in joined


@pytest.mark.parametrize("seed", [8, 9, 10])
def test_a_call_recruits_one_robot_and_a_founder_at_most_n_i_minus_one(seed: int) -> None:
    """Everyone hears everyone here (one excluded cluster): candidates rank themselves against the candidates
    they hear, so a CALL takes the best one and a founder's subgroup the best N_I - 1 (section 4.5.2)."""
    res = arena_run(n=12, iterations=150, seed=seed, sc_max=8)
    joins: dict[tuple[int, int, str], int] = Counter()
    for r in res.logs:
        if r["topic"] == "rdpso":
            how = [e for e in r["events"] if e.startswith("by ")]
            if how:
                joins[(r["k"], r["sid"], how[0])] += 1
    assert joins
    n_init = 12 // 2
    for (_, _, how), count in joins.items():
        assert count <= {"by call": 1, "by founder": n_init - 1, "by spawn": n_init}[how], joins


def test_the_controller_cannot_tell_the_runners_apart() -> None:
    """It only touches the device protocols: the numerical runner's devices offer nothing else it uses."""
    import swarm_logic.families.rdpso.controller as mod

    assert_device_protocols_only(mod)
    assert math.isfinite(arena_run(n=4, iterations=10).best[-1])


def test_rssi_link_mode_spaces_the_robots_by_q_min() -> None:
    """The q_min problem (eq. 5.12 with RSSI): a weaker threshold lets neighbours drift further apart."""
    size = (20.0, 20.0)
    spot = LightField([(10.0, 10.0, 1.0, 8.0)], size)
    link = numerical.LinkModel(mode="rssi")  # log-distance, -75 dBm at about 3.2 m
    spacing = {}
    for q_min in (-65.0, -75.0):
        p = {**SETS["ch4"], "link_mode": "rssi", "q_min_dbm": q_min, "dx_max_m": 0.2,
             "subgroups_init": 1, "subgroups_max": 1, "sc_max": 10000, "n_min": 1, "send_jitter_s": 0.0}
        start = np.array([[9.0, 9.0], [9.5, 9.0], [9.0, 9.5], [9.5, 9.5]])
        res = numerical.run(Rdpso, p, 4, 150, spot, size, link=link, seed=2, start=start)
        d = np.hypot(*(res.final_positions[:, None, :] - res.final_positions[None, :, :]).transpose(2, 0, 1))
        np.fill_diagonal(d, np.inf)
        spacing[q_min] = float(np.median(d.min(axis=1)))
    for q_min, d in spacing.items():  # the distance at which the link model gives q_min
        target = 10 ** ((link.tx_dbm - link.pl0_db - q_min) / (10 * link.exponent))
        assert 0.7 * target < d < 1.1 * target, (q_min, d, target)  # the bests pull the robots a little closer
    assert spacing[-75.0] > spacing[-65.0] * 1.3, spacing


class NoisyRdpso(Rdpso):
    """An RDPSO robot whose radio also carries another application's frames."""

    def _send(self) -> None:
        super()._send()
        self.robot.xbee.send_nowait(None, b"not a hello")


def test_frames_that_are_not_hellos_are_counted_and_dropped() -> None:
    p = {**SETS["ch4"], "dx_max_m": 0.1, "d_max_m": 0.5, "subgroups_init": 1, "subgroups_max": 1,
         "send_jitter_s": 0.0}
    res = numerical.run(NoisyRdpso, p, 3, 20, SPOTS, ARENA, link=numerical.LinkModel(range_m=10.0), seed=1,
                        keep_logs=True)
    last = [r for r in res.logs if r["topic"] == "rdpso" and r["k"] == max(q["k"] for q in res.logs)]
    assert all(r["dropped"]["foreign"] >= 2 * 19 for r in last)  # two neighbours' junk every iteration
    assert all(r["heard"] == 2 for r in last)  # the hellos still get through


def assert_device_protocols_only(mod: object) -> None:
    """A controller module imports nothing of the simulator and uses of its robot's LLC and radio only what the
    numerical runner's point devices offer too."""
    import ast
    import inspect

    tree = ast.parse(inspect.getsource(mod))
    names = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not any(m.startswith(("bridge", "firmware_sim")) for m in names if m)
    used = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Attribute)
            and n.value.attr in ("llc", "xbee")}
    assert used <= {"state", "move", "set_led", "stop", "set_odometry", "send_nowait", "recv"}


def test_an_infinite_communication_range_is_a_valid_d_max() -> None:
    """E1's infrastructure cell (d_max = inf: no communication constraint) passes the parameter checks."""
    from swarm_logic.families.rdpso.controller import Rdpso

    assert Rdpso.param_error("d_max_m", math.inf) is None
    assert Rdpso.param_error("d_max_m", 0.0) is not None and Rdpso.param_error("d_max_m", math.nan) is not None
    Rdpso.resolve({"d_max_m": math.inf})
