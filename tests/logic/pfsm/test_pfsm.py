"""Khan's PFSM searcher and target, device by device: the guards of Algorithm 1 (K-U1), the Lennard-Jones shape
(K-U2), linear cost in the neighbours (K-U3), the payloads (K-11) and the parameters' readings."""

from __future__ import annotations

import math

import pytest

from swarm_logic.families.pfsm import messages as msg
from swarm_logic.families.pfsm import searcher as searcher_mod
from swarm_logic.families.pfsm.potential import classic_lj, generalised_lj, lj_vector
from swarm_logic.families.pfsm.searcher import PfsmSearcher, search_stays, timeout_stays
from swarm_logic.families.pfsm.target import PfsmTarget
from swarm_logic.robots.footbot.interfaces import RabPacket, check_payload
from tests.logic.pfsm.fakes import started, tick


def pin(c: PfsmSearcher, sr: float, rs: float, ts: float) -> None:
    c.p_sr, c.p_rs, c.p_ts = sr, rs, ts


# -- K-U1: guards ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize(("t", "rs", "sr", "stays"), [(0.0, 0.8, 0.2, True), (59.9, 0.8, 0.2, True),
                                                        (60.0, 0.8, 0.2, False), (0.0, 0.2, 0.8, False),
                                                        (0.0, 0.5, 0.5, False)])
def test_search_guard_literal(t: float, rs: float, sr: float, stays: bool) -> None:
    assert search_stays(True, t, 60.0, rs, sr, 0.0) is stays


def test_timeout_guard_literal_compares_p_sr_with_p_ts_as_printed() -> None:
    assert timeout_stays(True, 1.0, 5.0, 0.6, 0.4, 0.0)
    assert not timeout_stays(True, 1.0, 5.0, 0.4, 0.6, 0.0)
    assert not timeout_stays(True, 5.0, 5.0, 0.6, 0.4, 0.0)


def test_sampled_guards_wait_for_the_bound_then_draw() -> None:
    assert search_stays(False, 10.0, 60.0, 0.0, 1.0, 0.0)  # before the bound: stays whatever P_SR
    assert not search_stays(False, 60.0, 60.0, 0.0, 0.3, 0.2)  # u < P_SR: leaves
    assert search_stays(False, 60.0, 60.0, 0.0, 0.3, 0.5)
    assert not timeout_stays(False, 5.0, 5.0, 0.0, 0.3, 0.1)


def test_searcher_stays_in_search_iff_the_literal_guard_holds() -> None:
    c, _dev, clock = started(PfsmSearcher, {"social": "none"})
    pin(c, 0.2, 0.8, 0.5)
    for _ in range(20):
        tick(c, clock)
    assert c.state == msg.SEARCH
    pin(c, 0.8, 0.2, 0.5)
    tick(c, clock)
    assert c.state == msg.RETURN


def test_search_ends_at_its_time_bound() -> None:
    c, _dev, clock = started(PfsmSearcher, {"social": "none", "max_search_s": 1.0})
    pin(c, 0.2, 0.8, 0.5)
    states = []
    for _ in range(12):
        tick(c, clock)
        states.append(c.state)
    assert states[:9] == [msg.SEARCH] * 9 and msg.RETURN in states


def test_timeout_stops_the_wheels_and_redraws_p_t_every_step() -> None:
    c, dev, clock = started(PfsmSearcher, {"social": "none", "max_timeout_s": 100.0, "timeout_redraw": "staying"})
    pin(c, 0.9, 0.1, 0.5)
    dev.grey = True  # in the base: RETURN -> TIMEOUT at once
    tick(c, clock)
    assert c.state == msg.TIMEOUT
    seen = []
    while c.state == msg.TIMEOUT and len(seen) < 50:
        before = (c.p_sr, c.p_rs, c.p_ts)
        tick(c, clock)
        assert dev.speeds == (0.0, 0.0)
        if c.state == msg.TIMEOUT:
            assert (c.p_sr, c.p_rs, c.p_ts) != before
            seen.append(before)
    assert c.state == msg.SEARCH  # P_SR <= P_TS happens (probability 1/2 per step)


def test_return_heads_for_the_light_and_rests_in_the_base() -> None:
    c, dev, clock = started(PfsmSearcher, {"social": "none", "timeout_redraw": "staying"})
    pin(c, 0.9, 0.1, 0.5)
    tick(c, clock)
    assert c.state == msg.RETURN
    tick(c, clock)
    left, right = dev.speeds
    assert left == right == pytest.approx(0.1)  # the light straight ahead (fake ring): full speed ahead
    dev.grey = True
    tick(c, clock)
    assert c.state == msg.TIMEOUT


# -- K-U2: Lennard-Jones shape -----------------------------------------------------------------------------------

def test_generalised_lj_matches_argos_flocking_reference_values() -> None:
    f = [100 * generalised_lj(d / 100, 0.75, 0.1, 2) for d in (40, 50, 60, 75, 90, 100, 120, 135)]
    assert f == pytest.approx([-221.1, -56.25, -14.65, 0.0, 2.36, 2.46, 1.98, 1.58], abs=0.01)


def test_12_6_zero_crossing_and_signs() -> None:
    sigma, eps = 0.5, 0.01
    rm = 2 ** (1 / 6) * sigma
    assert classic_lj(rm, eps, sigma) == pytest.approx(0.0, abs=1e-12)
    assert classic_lj(0.95 * rm, eps, sigma) < 0 < classic_lj(1.05 * rm, eps, sigma)
    d = 0.8
    assert classic_lj(d, eps, sigma) == pytest.approx(generalised_lj(d, rm, 12 * eps, 6))
    assert generalised_lj(0.75, 0.75, 0.1, 6) == pytest.approx(0.0, abs=1e-12)


def test_searcher_defaults_make_the_classic_and_generalised_forms_agree() -> None:
    p = PfsmSearcher.defaults
    for d in (0.3, 0.7, 1.2):
        assert classic_lj(d, p["lj_epsilon"], p["lj_sigma_m"]) == pytest.approx(
            generalised_lj(d, p["lj_delta_m"], p["lj_gain"], p["lj_exponent"]))


# -- K-U3: linear in the neighbours, constant memory -------------------------------------------------------------

def searcher_packets(n: int) -> list[RabPacket]:
    data = msg.encode(msg.Payload(msg.SEARCHER, msg.SEARCH))
    return [RabPacket(0.5 + 0.8 * (k % 3) / 3, 2 * math.pi * k / n, data) for k in range(n)]


@pytest.mark.parametrize("n", [1, 5, 20, 80])
def test_one_force_evaluation_per_neighbour_and_one_payload_per_step(n: int, monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []

    def counting(*a: float) -> float:
        calls.append(a)
        return generalised_lj(*a)

    monkeypatch.setattr(searcher_mod, "generalised_lj", counting)
    c, dev, clock = started(PfsmSearcher, {"social": "none"})
    pin(c, 0.2, 0.8, 0.5)
    dev.heard = searcher_packets(n)
    tick(c, clock)
    assert len(calls) == n  # every neighbour is within 1.8 delta here
    assert len(dev.sent) == 1 and len(dev.sent[0]) <= 10  # one broadcast per step, whatever the neighbourhood


def test_memory_does_not_grow_with_the_neighbourhood() -> None:
    sizes = []
    for n in (2, 60):
        c, dev, clock = started(PfsmSearcher, {"social": "none"})
        pin(c, 0.2, 0.8, 0.5)
        dev.heard = searcher_packets(n)
        for _ in range(5):
            tick(c, clock)
        sizes.append(sorted(vars(c)))
    assert sizes[0] == sizes[1]


def test_lj_vector_is_the_mean_within_the_cutoff() -> None:
    v = lj_vector([(1.0, 0.0), (1.0, math.pi), (5.0, 0.0)], lambda d: 1.0, 2.0)
    assert v == pytest.approx((0.0, 0.0), abs=1e-12)
    assert lj_vector([], lambda d: 1.0, 2.0) == (0.0, 0.0)


# -- targets, payloads, parameters -------------------------------------------------------------------------------

def test_a_searcher_near_a_target_gives_it_energy_and_the_target_goes_home() -> None:
    s, sdev, sclock = started(PfsmSearcher, {"social": "none"})
    pin(s, 0.2, 0.8, 0.5)
    t, tdev, tclock = started(PfsmTarget, robot_id=42)
    assert msg.decode(tdev.sent[-1]) == msg.Payload(msg.TARGET, msg.WAITING, False, 42)
    sdev.heard = [RabPacket(0.25, 0.0, tdev.sent[-1])]
    tick(s, sclock)
    assert s.acquired == 1 and msg.decode(sdev.sent[-1]) == msg.Payload(msg.SEARCHER, msg.SEARCH, True, 42)
    tdev.heard = [RabPacket(0.25, math.pi, sdev.sent[-1])]
    tick(t, tclock)
    assert t.state == msg.HOMING and tdev.speeds[0] > 0
    tdev.grey = True
    tick(t, tclock)
    assert t.state == msg.HOME and tdev.speeds == (0.0, 0.0)


def test_a_target_ignores_energy_given_to_another() -> None:
    t, tdev, tclock = started(PfsmTarget, robot_id=7)
    tdev.heard = [RabPacket(0.25, 0.0, msg.encode(msg.Payload(msg.SEARCHER, msg.SEARCH, True, 8)))]
    tick(t, tclock)
    assert t.state == msg.WAITING and tdev.speeds == (0.0, 0.0)


def test_payloads_fit_the_board_and_round_trip() -> None:
    for p in (msg.Payload(msg.SEARCHER, msg.TIMEOUT, True, 65535), msg.Payload(msg.TARGET, msg.HOMING, False, 3)):
        b = msg.encode(p)
        assert len(b) <= 10 and msg.decode(b) == p
    assert msg.decode(b"") is None and msg.decode(b"\x09abc") is None


def test_a_payload_longer_than_ten_bytes_is_refused() -> None:
    assert check_payload(b"0123456789") == b"0123456789"
    with pytest.raises(ValueError, match="11 bytes: at most 10"):
        check_payload(b"0123456789A")
    _c, dev, _clock = started(PfsmSearcher)
    with pytest.raises(ValueError, match="at most 10"):
        dev.send(bytes(11))


@pytest.mark.parametrize(("name", "value"), [("pfsm_mode", "stochastic"), ("social", "gossip"),
                                             ("lj_form", "morse"), ("search_vector", "spiral")])
def test_readings_are_validated(name: str, value: str) -> None:
    with pytest.raises(ValueError, match=name):
        PfsmSearcher.resolve({name: value})
    c, _dev, _clock = started(PfsmSearcher)
    with pytest.raises(ValueError, match=name):
        c.set_param(name, value)


def test_numeric_ranges_and_thresholds_are_validated() -> None:
    with pytest.raises(ValueError, match="near_target_m"):
        PfsmSearcher.resolve({"near_target_m": -1.0})
    with pytest.raises(ValueError, match="turning thresholds"):
        PfsmSearcher.resolve({"soft_turn_deg": 95.0})


def test_line_25_alone_traps_a_robot_in_the_base_and_the_entry_redraw_frees_it() -> None:
    """With P_RS <= P_SR <= P_TS in the base, SEARCH -> RETURN -> TIMEOUT -> SEARCH happens within every step and
    line 25 never runs; redrawing on entering TIMEOUT (the document's "clean-up") breaks the loop."""
    c, dev, clock = started(PfsmSearcher, {"social": "none", "timeout_redraw": "staying"})
    dev.grey = True
    pin(c, 0.5, 0.2, 0.8)
    for _ in range(50):
        tick(c, clock)
        assert c.state == msg.SEARCH and (c.p_sr, c.p_rs, c.p_ts) == (0.5, 0.2, 0.8)
    c, dev, clock = started(PfsmSearcher, {"social": "none"})
    dev.grey = True
    pin(c, 0.5, 0.2, 0.8)
    tick(c, clock)
    assert (c.p_sr, c.p_rs, c.p_ts) != (0.5, 0.2, 0.8)
