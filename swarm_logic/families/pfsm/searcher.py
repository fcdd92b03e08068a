"""The searcher: Khan's Algorithm 1, a three-state PFSM (SEARCH, RETURN, TIMEOUT) with per-state time bounds and
transition probabilities P_T = {P_SR, P_RS, P_TS} drawn at random and updated by the neighbours (digest 2.1-2.5).

One ``step`` is one pass of Algorithm 1's loop, in its order (digest 5.1.4): apply the motion vector computed in the
previous step (a one-step lag), update P_T from the range-and-bearing readings, evaluate the state (a transition
falls through to the new state's motion, as lines 14-27 do), compute the new motion vector, send the payload.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

from swarm_logic.families.pfsm import messages as msg
from swarm_logic.families.pfsm.base import FootbotController
from swarm_logic.families.pfsm.potential import classic_lj, generalised_lj, lj_vector
from swarm_logic.robots.footbot.interfaces import RabPacket

COLOURS = {msg.SEARCH: (0, 255, 0), msg.RETURN: (255, 0, 0), msg.TIMEOUT: (0, 0, 255)}


def search_stays(literal: bool, t_s: float, max_s: float, p_rs: float, p_sr: float, u: float) -> bool:
    """SEARCH's guard (line 7). Literal (K-1): stay while T_S < MaxTime and P_RS > P_SR. Sampled (the standard PFSM
    of ARGoS foraging): stay until T_S >= MaxTime, then leave with probability P_SR per step (``u`` ~ U(0, 1))."""
    if literal:
        return t_s < max_s and p_rs > p_sr
    return t_s < max_s or u >= p_sr


def timeout_stays(literal: bool, t_t: float, max_t: float, p_sr: float, p_ts: float, u: float) -> bool:
    """TIMEOUT's guard (line 23). Literal (K-1): stay while T_T < MaxTime and P_SR > P_TS, as printed. Sampled: stay
    until T_T >= MaxTime, then leave with probability P_TS per step."""
    if literal:
        return t_t < max_t and p_sr > p_ts
    return t_t < max_t or u >= p_ts


class PfsmSearcher(FootbotController):
    """A search foot-bot: Lennard-Jones spacing with the searchers it hears, pulled to the closest target it hears,
    back to the light when its time or its probabilities say so, resting in the base."""

    defaults: ClassVar[dict[str, Any]] = {
        **FootbotController.defaults,
        "pfsm_mode": "literal",  # K-1: literal (guards compare probabilities, as printed) | sampled (ARGoS foraging)
        "p_init": "uniform",  # K-1: P_ij ~ U(0, 1) i.i.d. (literal, digest 2.9) | fixed (ARGoS foraging's 0.1 each)
        "p_fixed": 0.1,  # the fixed reading's P_ij (ARGoS foraging explore/rest probabilities)
        # K-1 (with line 25): P_T redrawn on entering TIMEOUT too (the document's section 3.1: TIMEOUT "does a
        # clean-up of the transition probabilities"; "regenerated in TIMEOUT") | staying (line 25 alone: a robot in
        # the base with P_RS <= P_SR <= P_TS then passes SEARCH -> RETURN -> TIMEOUT -> SEARCH within every step,
        # never redrawing: trapped for good unless its neighbours' finds move P_SR)
        "timeout_redraw": "entry",
        "social": "foraging",  # K-2: foraging (Delta updates, digest 5.3) | none (the document gives no rule)
        "social_delta": 0.01,  # ARGoS foraging social_rule_*_delta_prob (digest 2.9)
        "max_search_s": 60.0,  # MaxTime_SEARCH,RETURN: ARGoS foraging minimum_unsuccessful_explore_time, 600 ticks
        "max_timeout_s": 5.0,  # MaxTime_TIMEOUT,SEARCH: ARGoS foraging minimum_resting_time, 50 ticks
        "global_time_s": math.inf,  # the swarm-wide time boundary: every searcher returns after it (digest 2.3)
        "lj_form": "generalised",  # K-3: generalised (ARGoS flocking, zero at delta) | classic (eq. 1's epsilon, sigma)
        "lj_delta_m": 0.75,  # the target distance: ARGoS flocking's 75 cm (digest 2.9)
        "lj_gain": 0.1,  # G, m^2/s: ARGoS flocking's 1000 in cm and cm/s
        "lj_exponent": 6.0,  # k: 6 gives eq. 1's 12-6 shape (K-3); ARGoS flocking's 2 is the alternative
        "lj_epsilon": 0.1 / 12,  # classic: eps = G/12 and sigma = delta / 2^(1/6) give the generalised k = 6 force
        "lj_sigma_m": 0.75 / 2 ** (1 / 6),
        "lj_cutoff": 1.8,  # neighbours within cutoff x delta (classic: x 2^(1/6) sigma): ARGoS flocking
        "lj_peers": "searching",  # searchers in the LJ sum: searching (the document's "neighbouring searchers") | all
        "target_weight": 1.0,  # the pull to the closest target, x max speed: "targets have the higher potential" [R]
        "near_target_m": 0.30,  # K-5: "near target" = centre distance below this (~2 body radii) [R]
        "search_vector": "zero",  # K-4: zero with no target heard (literal) | diffusion (straight ahead, a deviation)
    }
    ranges: ClassVar[dict[str, str]] = {
        **FootbotController.ranges,
        "p_fixed": "[0, 1]", "social_delta": "[0, 1]", "max_search_s": "[0, inf)", "max_timeout_s": "[0, inf)",
        "global_time_s": "(0, inf]", "lj_delta_m": "(0, inf)", "lj_gain": "[0, inf)", "lj_exponent": "(0, 24]",
        "lj_epsilon": "[0, inf)", "lj_sigma_m": "(0, inf)", "lj_cutoff": "(0, inf)", "target_weight": "[0, inf)",
        "near_target_m": "[0, inf)",
    }
    choices: ClassVar[dict[str, tuple[str, ...]]] = {
        "pfsm_mode": ("literal", "sampled"), "timeout_redraw": ("entry", "staying"), "p_init": ("uniform", "fixed"),
        "social": ("foraging", "none"),
        "lj_form": ("generalised", "classic"), "lj_peers": ("searching", "all"), "search_vector": ("zero", "diffusion"),
    }

    def reset(self) -> None:
        self.state = msg.SEARCH
        self.entered = self.robot.clock.now()
        self.motion = (0.0, 0.0)
        self.acquired = 0  # TargetAcquired: targets this searcher gave energy to
        self.last_given: int | None = None
        self.avoiding = False
        self.found: int | None = None  # the target given energy this step
        self.draw()
        self.leds.set_all_colors(COLOURS[self.state])

    # -- P_T ------------------------------------------------------------------------------------------------------

    def draw(self) -> None:
        """A new P_T (line 1, line 25): i.i.d. U(0, 1), or the fixed reading."""
        if self.p["p_init"] == "fixed":
            self.p_sr = self.p_rs = self.p_ts = float(self.p["p_fixed"])
        else:
            r = self.robot.rng_py.random
            self.p_sr, self.p_rs, self.p_ts = r(), r(), r()

    def update_probabilities(self, heard: list[tuple[RabPacket, msg.Payload]]) -> None:
        """Line 5 (K-2): with the foraging rule, each searcher heard giving a target energy makes resting shorter and
        searching longer (P_TS += Delta, P_SR -= Delta); last step's avoidance makes returning likelier
        (P_SR += Delta). Clipped to [0, 1]. Without a rule, nothing."""
        if self.p["social"] == "none":
            return
        d = float(self.p["social_delta"])
        finds = sum(1 for _, m in heard if m.kind == msg.SEARCHER and m.found)
        dsr = d * (int(self.avoiding) - finds)
        self.p_sr = min(1.0, max(0.0, self.p_sr + dsr))
        self.p_ts = min(1.0, max(0.0, self.p_ts + d * finds))

    # -- motion ---------------------------------------------------------------------------------------------------

    def lj_force(self, d: float) -> float:
        p = self.p
        if p["lj_form"] == "classic":
            return classic_lj(d, float(p["lj_epsilon"]), float(p["lj_sigma_m"]))
        return generalised_lj(d, float(p["lj_delta_m"]), float(p["lj_gain"]), float(p["lj_exponent"]))

    def lj_cutoff_m(self) -> float:
        p = self.p
        r = p["lj_sigma_m"] * 2 ** (1 / 6) if p["lj_form"] == "classic" else p["lj_delta_m"]
        return float(p["lj_cutoff"] * r)

    def search_motion(self, heard: list[tuple[RabPacket, msg.Payload]]) -> tuple[float, float]:
        """Lines 8-13: the mean LJ vector over the searchers heard, plus ``target_weight`` x max speed towards the
        closest waiting target (K-4: nothing, or straight ahead, when none is heard); a target within
        ``near_target_m`` is given energy."""
        vmax = float(self.p["max_speed_mps"])
        peers = [(r.range_m, r.bearing_rad) for r, m in heard if m.kind == msg.SEARCHER
                 and (self.p["lj_peers"] == "all" or m.state == msg.SEARCH)]
        vx, vy = lj_vector(peers, self.lj_force, self.lj_cutoff_m())
        closest: tuple[RabPacket, msg.Payload] | None = None
        for r, m in heard:
            if m.kind == msg.TARGET and m.state == msg.WAITING and (closest is None or r.range_m < closest[0].range_m):
                closest = (r, m)
        if closest is not None:
            w = float(self.p["target_weight"]) * vmax
            vx += w * math.cos(closest[0].bearing_rad)
            vy += w * math.sin(closest[0].bearing_rad)
            if closest[0].range_m < self.p["near_target_m"]:
                self.found = closest[1].target_id
                if self.found != self.last_given:
                    self.acquired += 1
                    self.last_given = self.found
                    self.robot.log("pfsm_found", target=self.found)
        elif self.p["search_vector"] == "diffusion":
            vx += vmax
        return vx, vy

    # -- the loop -------------------------------------------------------------------------------------------------

    def enter(self, state: int, now: float) -> None:
        self.state, self.entered = state, now
        self.leds.set_all_colors(COLOURS[state])
        self.robot.log("pfsm_state", state=msg.STATE_NAMES[msg.SEARCHER][state])

    def step(self) -> None:
        p = self.p
        self.set_wheels_from_vector(*self.motion)  # line 4: last step's vector
        now = self.robot.clock.now()
        heard = [(r, m) for r in self.rab.readings() if (m := msg.decode(r.data)) is not None]
        self.update_probabilities(heard)  # line 5
        literal = p["pfsm_mode"] == "literal"
        u = self.robot.rng_py.random
        self.found = None
        avoid = self.avoidance()
        self.avoiding = avoid is not None
        if now >= p["global_time_s"] and self.state == msg.SEARCH:
            self.enter(msg.RETURN, now)
        if self.state == msg.SEARCH:
            if search_stays(literal, now - self.entered, float(p["max_search_s"]), self.p_rs, self.p_sr,
                            0.0 if literal else u()):
                m = self.search_motion(heard)
                self.motion = avoid if avoid is not None else m
            else:
                self.enter(msg.RETURN, now)
        if self.state == msg.RETURN:
            if self.in_base():
                self.enter(msg.TIMEOUT, now)
                if not literal or p["timeout_redraw"] == "entry":
                    self.draw()  # a clean P_T on entering the rest
            else:
                lx, ly = self.to_light()
                vmax = float(p["max_speed_mps"])
                self.motion = avoid if avoid is not None else (vmax * lx, vmax * ly)
        if self.state == msg.TIMEOUT:
            if now < p["global_time_s"] and timeout_stays(literal, now - self.entered, float(p["max_timeout_s"]),
                                                          self.p_sr, self.p_ts, 0.0 if literal else u()):
                self.motion = (0.0, 0.0)
                if literal:
                    self.draw()  # line 25: redrawn on every step it stays
            elif now < p["global_time_s"]:
                self.enter(msg.SEARCH, now)
                self.motion = (0.0, 0.0)  # the search vector comes with the next step's readings
            else:
                self.motion = (0.0, 0.0)
        found = self.found is not None
        self.rab.send(msg.encode(msg.Payload(msg.SEARCHER, self.state, found, self.found or 0)))

    def telemetry(self) -> dict[str, float | int]:
        return {"state": self.state, "acquired": self.acquired}
