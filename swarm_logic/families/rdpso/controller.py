"""The Robotic Darwinian PSO (Couceiro 2013, Algorithm 4.4), one controller per robot, fully distributed.

Every iteration (``iteration_s``, aligned on the clock so all robots agree on the iteration number ``k``) has
two phases:

A. at ``k * iteration_s``: read the pose (odometry, or ground truth when the LLC is set up so), sense the
   objective (the light sensor) and obstacles (the sonar, g = min(range, R_w)), update the personal best
   chi_1 and the last obstacle-free position chi_3, and broadcast one hello (``messages.Hello``);
B. ``comm_window_s`` later: read the hellos of iteration k, update the subgroup ledger (best chi_2,
   stagnancy SC_s, punish counter N_kill) and run punish/reward (Table 4.1), or, when socially excluded,
   answer CALL/SPAWN offers; choose k neighbours for the connectivity term chi_4 (eq. 5.12, Algorithm 5.2);
   compute the velocity of eq. 4.11 (or exact Grunwald-Letnikov), clamp it to dx_max and hand the
   displacement to the LLC as rotate-then-go.

Subgroup bookkeeping is redundant: every member runs it from the same inputs (the hellos of iteration k carry
each member's ledger as it stood after k-1; members take SC_s and N_kill from the lowest-id member they hear,
the best value from anyone), and the random draws of the reward rules come from a generator seeded with
(``swarm_seed``, subgroup, k), so members that heard the same hellos take the same decisions. Subgroup
information crosses hops by gossip, one hop per iteration. Membership and link breaks: a member is dropped
after ``miss_limit`` (3) missed hellos, counted across relays.

The controller knows only its robot's devices (``swarm_logic.hal``): the same code runs in the co-simulation
(emulated LLC over CAN, emulated XBee) and in the numerical runner (point robots, the thesis' link model).
"""

from __future__ import annotations

import math
import random
import struct
import zlib
from typing import Any, ClassVar

from swarm_logic.controller import DBM_RANGE, MAX_SPEED_MPS, Controller
from swarm_logic.families.rdpso import fuzzy, graph, motion
from swarm_logic.families.rdpso.aodv import ROUTING_MODES, Router
from swarm_logic.families.rdpso.est import ScoutDeployment
from swarm_logic.families.rdpso.messages import (
    F_CALL,
    F_CANDIDATE,
    F_FOUNDER,
    F_IMPROVED,
    F_SPAWN,
    MAX_ID,
    Hello,
    decode,
    encode,
)
from swarm_logic.iteration import IterationSchedule
from swarm_logic.robot import Robot

WHITE = (255, 255, 255)
PALETTE = ((255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 160, 0), (160, 0, 255), (0, 220, 220), (255, 0, 160),
           (140, 255, 0))


def colour(sid: int) -> tuple[int, int, int]:
    """The LED colour of a subgroup (white: socially excluded), as on the real robots (Fig. 4.12)."""
    if sid == 0:
        return WHITE
    if sid <= len(PALETTE):
        return PALETTE[(sid - 1) % len(PALETTE)]
    return PALETTE[zlib.crc32(sid.to_bytes(2 if sid < 1 << 16 else 4)) % 8]  # 4 bytes: the wide hello's ids


def chance(rng: random.Random, p: float) -> bool:
    """The listing's ``U() * p > U()`` with two independent uniforms: true with probability p/2 (p in [0, 1])."""
    return rng.random() * p > rng.random()


def new_subgroup_id(decider: int, k: int) -> int:
    """The id of a subgroup founded by robot ``decider`` (an excluded founder, or the lowest-id member of a
    spawning subgroup, which every member agrees on) at iteration ``k``: unique while no robot founds two within
    256 iterations, and never one of the initial ids 1..15."""
    return ((decider + 1) << 8) | (k & 0xFF)


def half(v: float) -> float:
    """``v`` as a half float: personal bests are compared at the precision they travel with."""
    return _HALF.unpack(_HALF.pack(max(-65504.0, min(65504.0, v))))[0]


_HALF = struct.Struct("<e")
SHARE = struct.Struct("<HHfB")  # a data packet's payload: subgroup, iteration, personal best, improved


class Rdpso(IterationSchedule, Controller):
    """One robot of the RDPSO swarm. Parameters (``defaults``) follow the digest's master table (4.1)."""

    needs_radio = True  # a config must give its robots an XBee
    iteration_log = "rdpso"

    defaults: ClassVar[dict[str, Any]] = {
        "iteration_s": 1.0,  # RDPSO iteration period (A13)
        "comm_window_s": 0.25,  # phase A -> phase B: time for the hellos of an iteration to arrive
        "send_jitter_s": 0.1,  # each hello goes out U(0, this) after phase A: unsynchronised, as real robots are
        "alpha": 0.5,
        "rho1": 0.2,
        "rho2": 0.4,
        "rho3": 0.8,
        "rho4": 0.8,
        "fractional_form": "thesis",  # thesis (eq. 4.11) | exact_gl
        "truncation_r": 4,
        "dx_max_m": 0.1,
        "r_w_m": 0.5,  # obstacle sensing radius R_w
        "sc_max": 30,
        "stagnation_on_improve": "decrement",  # decrement (Algorithm 4.4) | reset (section 9.3.4), A5
        "link_mode": "distance",  # distance (d_max) | rssi (q_min)
        "d_max_m": 0.5,
        "q_min_dbm": -75.0,
        "k_q": 1.0,  # m per dB in the q_min problem (A8)
        "k_conn": 1,  # k-connectivity: neighbours chosen for chi_4
        "n_total": 12,  # N_T, known to every robot
        "subgroups_init": 2,
        "subgroups_min": 0,
        "subgroups_max": 3,
        "n_init": 0,  # N_I; 0: n_total // subgroups_init
        "n_min": 0,  # 0: max(1, N_I // 2) (A28)
        "n_max": 0,  # 0: 2 * N_I (A28)
        "miss_limit": 3,  # missed hellos that break a link (section 6.2)
        "speed_mps": 0.2,  # wheel speed of the rotate-then-go moves
        "min_move_m": 0.003,  # shorter displacements are not sent (about one encoder pulse)
        "wander_turn_deg": 90.0,  # excluded robots: heading change U(-x, x) per iteration (A11)
        "fuzzy": False,  # chapter 7 fuzzified parameter adjustment
        "swarm_seed": 0,  # shared by every robot: seeds the subgroups' common draws
        "log_every": 1,  # iterations between "rdpso" log records (0: none)
        "payload_max": 92,  # bytes per hello: a ZigBee broadcast's limit (more members than fit: nearest sent)
        "id_width": 1,  # bytes per robot id in the hello: 1 (ZigBee, ids < 256) | 2 (wide, beyond 255 robots)
        "first_id": 0,  # the robot id of the swarm's first scout (rangers or other robots may come before)
        "deployed": False,  # dropped by a ranger (swarm_logic.families.rdpso.est): start at its START, from its pose
        # information sharing (chapter 6): gossip (one hello per iteration, subgroup state spreads hop by hop),
        # regular (the hello, and position and solution to every mate every iteration, routed multi-hop) or
        # optimised (the hello; position and solution to every mate only when the personal best improved)
        "comm": "gossip",
        "routing": "rdpso",  # rdpso (geographic next hop, eq. 6.3, AODV as fallback) | aodv | module (the XBee's mesh)
        "route_buffer": 16,  # packets the routing layer holds for the radio; more are dropped
        "route_ttl": 10,  # hops a route request or data packet may travel
        "discovery_timeout_s": 1.0,  # wait for a route reply (doubled on each of two retries)
        "poll_s": 0.02,  # with routing: how often the radio is served (forwarding, TX statuses)
        "pause_on_radio": True,  # with routing: do not move until the radio has sent this iteration's packets
    }
    ranges: ClassVar[dict[str, str]] = {
        "iteration_s": "(0, inf)",
        "comm_window_s": "(0, inf)",  # and < iteration_s
        "send_jitter_s": "[0, inf)",  # and < comm_window_s
        "alpha": "(0, 1]",  # fractional order (eq. 4.8)
        "rho1": "[0, inf)",  # coefficients (eq. 4.5; 0 allowed, e.g. rho3 = 0 in an obstacle-free world)
        "rho2": "[0, inf)",
        "rho3": "[0, inf)",
        "rho4": "[0, inf)",
        "truncation_r": "[1, inf)",  # and 4 for the thesis' form
        "dx_max_m": "(0, inf)",
        "r_w_m": "(0, inf)",
        "sc_max": "[1, inf)",
        "d_max_m": "(0, inf]",  # inf: no communication constraint (infrastructure, E1)
        "q_min_dbm": DBM_RANGE,
        "k_q": "(0, inf)",
        "k_conn": "[1, inf)",
        "n_total": "[1, 65535]",  # robot ids travel as one byte: at most 255 unless id_width = 2 (resolve)
        "subgroups_init": "[0, 15]",  # and subgroups_min <= subgroups_init <= subgroups_max
        "subgroups_min": "[0, 255]",
        "subgroups_max": "[0, 255]",
        "n_init": "[0, 65535]",  # 0: derived; like n_total, at most 255 unless id_width = 2
        "n_min": "[0, 65535]",
        "n_max": "[0, 65535]",
        "miss_limit": "[1, inf)",
        "speed_mps": f"(0, {MAX_SPEED_MPS:g}]",
        "min_move_m": "[0, inf)",
        "wander_turn_deg": "[0, 180]",
        "swarm_seed": "[0, inf)",
        "log_every": "[0, inf)",
        "payload_max": "[42, 65535]",
        "first_id": "[0, 65535]",  # at most 255 unless id_width = 2
        "id_width": "[1, 2]",
        "route_buffer": "[1, inf)",
        "route_ttl": "[1, 255]",  # one byte in the routing layer's frames
        "discovery_timeout_s": "(0, inf)",
        "poll_s": "(0, inf)",
    }
    # read only at init and reset: the iteration clock every robot shares, the swarm's size and its initial split
    static_params = frozenset({"iteration_s", "n_total", "subgroups_init", "n_init", "n_min", "n_max", "fuzzy",
                               "first_id", "deployed"})

    # -- parameters -----------------------------------------------------------------------------------------
    @classmethod
    def resolve(cls, params: dict[str, Any]) -> dict[str, Any]:
        """Defaults merged with ``params``, checked; ValueError names the parameter and the reason."""
        p = cls.with_defaults(params)  # each value of its kind and in its range
        cls._check_ids(p)
        if p["fractional_form"] not in ("thesis", "exact_gl"):
            raise ValueError(f"fractional_form: {p['fractional_form']!r} is not one of thesis, exact_gl")
        if p["link_mode"] not in ("distance", "rssi"):
            raise ValueError(f"link_mode: {p['link_mode']!r} is not one of distance, rssi")
        if p["stagnation_on_improve"] not in ("decrement", "reset"):
            raise ValueError(f"stagnation_on_improve: {p['stagnation_on_improve']!r} is not decrement or reset")
        if not 0 < p["comm_window_s"] < p["iteration_s"]:
            raise ValueError(f"comm_window_s: must lie in (0, iteration_s = {p['iteration_s']}), "
                             f"got {p['comm_window_s']!r}")
        if p["comm"] not in ("gossip", "regular", "optimised"):
            raise ValueError(f"comm: {p['comm']!r} is not one of gossip, regular, optimised")
        if p["routing"] not in ROUTING_MODES:
            raise ValueError(f"routing: {p['routing']!r} is not one of {', '.join(ROUTING_MODES)}")
        if not 0 <= p["send_jitter_s"] < p["comm_window_s"]:
            raise ValueError(f"send_jitter_s: must lie in [0, comm_window_s = {p['comm_window_s']}), "
                             f"got {p['send_jitter_s']!r}")
        g_min, g_init, g_max = p["subgroups_min"], p["subgroups_init"], p["subgroups_max"]
        if not 0 <= g_min <= g_init <= g_max:
            raise ValueError(f"subgroups_min/init/max: need 0 <= min <= init <= max, got {g_min}/{g_init}/{g_max}")
        if g_init > p["n_total"]:
            raise ValueError(f"subgroups_init: {g_init} subgroups for {p['n_total']} robots (more subgroups than "
                             "robots)")
        motion.memory_weights(p["alpha"], p["fractional_form"], int(p["truncation_r"]))  # form and r must fit
        n_i = p["n_init"] or (p["n_total"] // g_init if g_init else max(2, p["n_total"] // max(1, g_max)))
        p["n_init"] = n_i
        p["n_min"] = p["n_min"] or max(1, n_i // 2)
        p["n_max"] = p["n_max"] or 2 * n_i
        if not 1 <= p["n_min"] <= p["n_max"]:
            raise ValueError(f"n_min/n_max: need 1 <= n_min <= n_max, got {p['n_min']}/{p['n_max']}")
        return p

    @classmethod
    def _check_ids(cls, p: dict[str, Any]) -> None:
        """Robot counts and ids within what the hello's id width carries: one byte (the ZigBee hello, what real
        robots and the co-simulation run) unless ``id_width`` is 2; the routing layer's frames carry one byte."""
        top = MAX_ID[int(p["id_width"])]
        for name in ("n_total", "first_id", "n_init", "n_min", "n_max"):
            low = 1 if name == "n_total" else 0
            if not low <= p[name] <= top:
                why = " (robot ids travel as one byte; id_width = 2 carries up to 65535)" if top == 0xFF else ""
                raise ValueError(f"{name}: must lie in [{low}, {top}], got {p[name]!r}{why}")
        if p["id_width"] != 1 and p["comm"] != "gossip":
            raise ValueError(f"id_width: {p['id_width']} needs comm = gossip (the routing layer's frames carry "
                             f"one-byte ids), got comm = {p['comm']!r}")

    @classmethod
    def warnings(cls, params: dict[str, Any]) -> list[str]:
        """Stability warnings (chapter 7) for a valid parameter set: each names the bound it breaks."""
        p = cls.resolve(params)
        if p["fuzzy"]:
            return []  # the fuzzy system keeps alpha <= 0.8 and sum(rho) <= 1.98 itself
        return motion.check_parameters(p["alpha"], (p["rho1"], p["rho2"], p["rho3"], p["rho4"]),
                                       p["fractional_form"])

    # -- life cycle -----------------------------------------------------------------------------------------
    def init(self, robot: Robot) -> None:
        super().init(robot)
        if robot.xbee is None:
            raise ValueError("rdpso needs a radio (robots.xbee in the session config)")
        self.p = self.resolve(robot.params)
        self.reset()
        # deployed by a ranger: on board until it drops the robot and tells it its pose, then beaconing until
        # START (swarm_logic.families.rdpso.est); otherwise the mission starts now, from the start pose
        self.deployment = ScoutDeployment(robot) if self.p["deployed"] else None
        if self.deployment is None:
            if robot.start_pose is not None:
                robot.llc.set_odometry(*robot.start_pose)
            self._begin()
        else:
            self.period_s = 0.1

    def reset(self) -> None:
        p = self.p
        self.alpha = float(p["alpha"])
        self.rho = [float(p["rho1"]), float(p["rho2"]), float(p["rho3"]), float(p["rho4"])]
        self.weights = motion.memory_weights(self.alpha, p["fractional_form"], int(p["truncation_r"]))
        self.history: list[tuple[float, float]] = []  # executed displacements, newest first
        self.adapter = fuzzy.FuzzyAdapter() if p["fuzzy"] else None
        rid = self.robot.id
        g_init, n_total = int(p["subgroups_init"]), int(p["n_total"])
        # the initial subgroups: consecutive blocks of the swarm's robots (ids from first_id, as rangers load them)
        self.sid = 1 + (rid - int(p["first_id"])) * g_init // n_total if g_init else 0
        self.x = self.y = self.theta = 0.0
        self.prev: tuple[float, float] | None = None
        self.h = -math.inf
        self.hbest = -math.inf
        self.chi1 = (0.0, 0.0)
        self.g_best = -math.inf
        self.chi3 = (0.0, 0.0)
        self.improved = False
        # the subgroup ledger (H_best, chi_2, SC_s, N_kill) as this robot holds it
        self.ledger_h = -math.inf
        self.chi2 = (0.0, 0.0)
        self.sc = 0
        self.n_kill = 0
        self.worst = rid
        # group member -> (iteration of its newest hello heard of, relays it came over, its personal best)
        self.table: dict[int, tuple[int, int, float]] = {}
        self.departed: dict[int, int] = {}  # robot -> iteration it was last heard in another group
        self.chosen: tuple[int, ...] = ()
        self.offer_flags = 0  # CALL / SPAWN / FOUNDER to announce in the next hello
        self.offer_target = 0  # SPAWN: the new subgroup's id (a CALL is for the sender's own subgroup)
        self.candidate: tuple[int, int, int, Hello | None] | None = None  # (target, kind flags, k applied, offer)
        self.wander_heading = float(self.robot.rng.uniform(-math.pi, math.pi))
        self.g = float(p["r_w_m"])
        self.rssi: dict[int, float] = {}
        self.heard: dict[int, Hello] = {}
        self.mate_rssi: list[int] = []  # dBm of this iteration's hellos from subgroup mates (logged)
        self.last_centre: tuple[float, float] | None = None
        self.led: tuple[int, int, int] | None = None
        self.events: list[str] = []
        self.dropped = {"late": 0, "foreign": 0}  # received frames not used, by cause (logged)
        # chapter 6 information sharing over a routing layer (None: gossip only)
        self.router = None if p["comm"] == "gossip" else Router(
            rid, self.robot.xbee, self.robot.clock, mode=p["routing"], buffer=int(p["route_buffer"]),
            ttl=int(p["route_ttl"]), miss_limit=int(p["miss_limit"]), discovery_timeout_s=p["discovery_timeout_s"],
            predict=self._predict)
        self.data_heard: dict[int, tuple[float, float, float, bool]] = {}  # this iteration's data: x, y, best, improved
        self.paused_s = 0.0  # time this robot waited for its radio before moving
        self.pause_from: float | None = None

    def destroy(self) -> None:
        self.robot.llc.stop()

    def set_param(self, name: str, value: Any) -> None:
        """As ``Controller.set_param``; the fractional order and the rho coefficients take effect at once (unless
        the fuzzy system sets them)."""
        super().set_param(name, value)
        if name in ("alpha", "rho1", "rho2", "rho3", "rho4", "truncation_r") and self.adapter is None:
            p = self.p
            self.alpha = float(p["alpha"])
            self.rho = [float(p["rho1"]), float(p["rho2"]), float(p["rho3"]), float(p["rho4"])]
            self.weights = motion.memory_weights(self.alpha, p["fractional_form"], int(p["truncation_r"]))

    def telemetry(self) -> dict[str, float | int]:
        """Iteration, subgroup (0: excluded), group size, stagnancy and punish counters, personal and group
        bests (-3e38: none yet)."""
        return {"k": self.k, "sid": self.sid, "excluded": int(self.sid == 0), "group_n": self._group_size(),
                "sc": self.sc, "n_kill": self.n_kill, "hbest": _f(self.hbest), "ledger_h": _f(self.ledger_h)}

    def step(self) -> None:
        """Phase A at k * iteration_s, phase B comm_window_s later; ``period_s`` tells the runner when to call."""
        if self.deployment is not None and not self.deployment.started:
            self.deployment.step()
            if self.deployment.started:
                self._begin()
            return
        router = self.router
        if router is None:
            self._iterate()
            return
        router.poll()
        now = self.robot.clock.now()
        poll = self.p["poll_s"]
        due_b = self.phase == "B" and now >= self.next_t - 1e-6
        if due_b and router.busy and self.p["pause_on_radio"] and now < (self.k + 1) * self.p["iteration_s"] - 2 * poll:
            if self.pause_from is None:
                self.pause_from = self.next_t  # paused: the move waits until the radio has sent everything
            self.period_s = poll
            return
        if due_b and self.pause_from is not None:
            self.paused_s += now - self.pause_from
            self.pause_from = None
        self._iterate()
        router.poll()  # hand what this phase queued to the radio now
        self.period_s = min(self.period_s, poll)

    def _receive(self) -> Any:
        return self.router.recv() if self.router is not None else self.robot.xbee.recv(timeout=0)

    # -- phase A: sense and tell --------------------------------------------------------------------------------
    def _phase_a(self) -> None:
        r = self.robot
        st = r.llc.state
        self.x, self.y, self.theta = float(st.x), float(st.y), float(st.theta)
        if self.prev is not None:
            self.history.insert(0, (self.x - self.prev[0], self.y - self.prev[1]))
            del self.history[len(self.weights):]
        self.prev = (self.x, self.y)
        self.h = float(st.light_raw)
        r_w = self.p["r_w_m"]
        self.g = min(st.sonar_m, r_w) if st.sonar_valid else r_w
        self.improved = self.h > self.hbest
        if self.improved:
            self.hbest = self.h
            self.chi1 = (self.x, self.y)
        if self.g >= self.g_best:
            self.g_best = self.g
            self.chi3 = (self.x, self.y)
        if self.sid != 0 and self.ledger_h == -math.inf:  # a new subgroup's ledger starts from what it has
            self.ledger_h, self.chi2 = self.hbest, self.chi1
        flags = self.offer_flags | (F_IMPROVED if self.improved else 0)
        target = self.offer_target
        if self.candidate is not None and self.candidate[2] == self.k:
            flags |= F_CANDIDATE
            target = self.candidate[0]
        members = tuple((m, *v) for m, v in self.table.items())  # pruned to the fresh ones in the last phase B
        hello = Hello(r.id, self.sid, self.k, self.x, self.y, _f(self.hbest), _f(self.ledger_h), self.chi2[0],
                      self.chi2[1], self.sc, self.n_kill, flags, target, self.chosen, members)
        self.outgoing = encode(hello, int(self.p["payload_max"]), int(self.p["id_width"]))
        self.offer_flags = 0
        self.offer_target = 0

    def _send(self) -> None:
        router = self.router
        if router is None:
            self.robot.xbee.send_nowait(None, self.outgoing, radius=1)  # a local broadcast: the neighbours
            return
        router.hello(self.outgoing)
        # regular: position and solution to every mate every iteration; optimised: only on an improvement, or
        # (excluded) when applying for a CALL/SPAWN, as the thesis' rules (section 6.1)
        applying = self.candidate is not None and self.candidate[2] == self.k
        if self.p["comm"] == "regular" or self.improved or applying:
            payload = SHARE.pack(self.sid, self.k & 0xFFFF, _f(self.hbest), int(self.improved))
            for m in sorted(self.table):
                router.send(m, payload, self.x, self.y)

    # -- phase B: listen, decide, move ---------------------------------------------------------------------------
    def _phase_b(self) -> None:
        self._listen()
        self.events = []
        if self.sid != 0:
            self._bookkeeping()
        else:
            self._excluded()
        vx, vy = self._velocity()
        self._move(vx, vy)
        self._show()
        every = int(self.p["log_every"])
        if every and (self.k % every == 0 or self.events):
            self.robot.log("rdpso", k=self.k, sid=self.sid, x=self.x, y=self.y, h=_f(self.h), hbest=_f(self.hbest),
                           improved=self.improved, ledger_h=_f(self.ledger_h), chi2=self.chi2, sc=self.sc,
                           n_kill=self.n_kill, n_s=self._group_size(), heard=len(self.heard), chosen=self.chosen,
                           mate_rssi=self.mate_rssi,
                           alpha=self.alpha, rho=self.rho, events=self.events, worst=self.worst,
                           dropped=self.dropped, **({"comm": self.comm_stats()} if self.router else {}))

    def _listen(self) -> None:
        """Drain the radio; keep this iteration's hellos, refresh the group table (direct and relayed)."""
        r = self.robot
        heard: dict[int, Hello] = {}
        addrs: dict[int, int | None] = {}  # each hello's sender's radio address
        rssi: dict[int, float] = {}  # this iteration's
        for msg, pkt in self._frames_of_iteration(decode, "foreign"):
            heard[msg.robot] = msg
            addrs[msg.robot] = pkt.src64
            if pkt.rssi_dbm is not None:
                rssi[msg.robot] = self.rssi[msg.robot] = float(pkt.rssi_dbm)
        self.heard = heard
        # the signal quality of this iteration's one-hop links within the subgroup (Table 5.2 measures it so)
        self.mate_rssi = [round(v) for rid, v in sorted(rssi.items()) if self.sid and heard[rid].sid == self.sid]
        table = self.table
        k = self.k
        if self.router is not None:
            self._take_data(heard, addrs)
        for rid, msg in heard.items():
            if msg.sid != self.sid:
                table.pop(rid, None)  # it says it is elsewhere now
                self.departed[rid] = k
                continue
            table[rid] = (k, 0, half(msg.hbest))
            self.departed.pop(rid, None)
        departed = self.departed
        me = r.id
        for msg in heard.values():
            if msg.sid != self.sid:
                continue
            for m, o8, hops, best in msg.members:
                if m in heard or m == me:
                    continue
                origin = k - ((k - o8) & 0xFF)  # unwrap the iteration number (mod 256)
                old = table.get(m)
                if old is not None and (origin < old[0] or (origin == old[0] and hops + 1 >= old[1])):
                    continue
                if origin <= departed.get(m, -1):
                    continue  # older than the news that it left
                table[m] = (origin, hops + 1, best)
        limit = k - self.p["miss_limit"]
        for m in [m for m, v in table.items() if v[0] + v[1] <= limit]:
            del table[m]

    def _group_size(self) -> int:
        return 1 + len(self.table)

    def _mates(self) -> list[Hello]:
        """Hellos of this iteration from my own group (subgroup, or excluded cluster)."""
        return [h for h in self.heard.values() if h.sid == self.sid]

    def _bookkeeping(self) -> None:
        """Ledger merge and Table 4.1 / Algorithm 4.4 punish-reward, the same on every member."""
        p = self.p
        mates = self._mates()
        # the ledger as it stood after the last iteration: SC_s and N_kill from the lowest-id member heard
        auth = min([self.robot.id] + [h.robot for h in mates])
        if auth != self.robot.id:
            a = self.heard[auth]
            self.sc, self.n_kill = a.sc, a.n_kill
        prev_best = self.ledger_h
        for h in mates:  # the previous best as anyone knew it
            if h.ledger_h > prev_best:
                prev_best, self.chi2 = h.ledger_h, (h.ledger_x, h.ledger_y)
        # this iteration's solutions H: mine and the mates' (improvements carry the position they were sensed at),
        # from their hellos and, with routing, from their data packets (members beyond one hop)
        best, where = self.h, (self.x, self.y)
        for h in mates:
            if h.flags & F_IMPROVED and h.hbest > best:
                best, where = h.hbest, (h.x, h.y)
        for dx, dy, dbest, improved in self.data_heard.values():
            if improved and dbest > best:
                best, where = dbest, (dx, dy)
        # the worst personal best in the group (ties: the higher id), from the member table, which holds each
        # member's value as of its newest hello heard of
        worst = min([(half(self.hbest), -self.robot.id)] + [(v[2], -m) for m, v in self.table.items()])
        self.worst = -worst[1]
        n_s = self._group_size()
        if best > prev_best:
            self.ledger_h, self.chi2 = best, where
            if p["stagnation_on_improve"] == "reset":
                self.sc = 0
            elif self.sc > 0:
                self.sc -= 1
            if self.sc == 0:  # may be rewarded; both draws as in the listing, from the subgroup's common stream
                rng = random.Random(zlib.crc32(f"{p['swarm_seed']}/{self.sid}/{self.k}".encode()))
                if n_s < p["n_max"] and chance(rng, 1.0 / (self.n_kill + 1)):
                    self.offer_flags |= F_CALL
                    self.n_kill = max(0, self.n_kill - 1)
                    self.events.append("call")
                if chance(rng, n_s / p["n_max"]) and self._subgroups_known() < p["subgroups_max"]:
                    self.offer_flags |= F_SPAWN
                    self.offer_target = new_subgroup_id(min([self.robot.id, *self.table]), self.k)
                    self.n_kill = max(0, self.n_kill - 1)
                    self.events.append("spawn")
        else:
            self.ledger_h = prev_best
            self.sc += 1
            if self.sc >= p["sc_max"]:
                if n_s > p["n_min"]:
                    self.n_kill += 1
                    self.sc = int(p["sc_max"] * (1 - 1 / (self.n_kill + 1)))  # eq. 4.3
                    if self.worst == self.robot.id:
                        self.events.append("punished")
                        self._leave()
                    else:
                        self.events.append("punish")
                elif self._subgroups_known() > p["subgroups_min"]:
                    self.events.append("dismantled")
                    self._leave()
                else:  # dismantling would leave fewer subgroups than N_s^min (as far as this robot knows)
                    self.sc = int(p["sc_max"] * (1 - 1 / (self.n_kill + 1)))
                    self.events.append("spared")

    def _subgroups_known(self) -> int:
        return len({h.sid for h in self.heard.values() if h.sid} | ({self.sid} if self.sid else set()))

    def _leave(self) -> None:
        self.sid = 0
        self.table = {}
        self.ledger_h = -math.inf
        self.sc = self.n_kill = 0
        self.worst = self.robot.id

    def _join(self, sid: int, offer: Hello | None, spawn: bool) -> None:
        self.sid = sid
        self.table = {}
        self.candidate = None
        if offer is not None and not spawn:  # recruited: take the caller's ledger
            self.ledger_h, self.chi2 = offer.ledger_h, (offer.ledger_x, offer.ledger_y)
            self.sc, self.n_kill = offer.sc, offer.n_kill
            self.table[offer.robot] = (self.k, 0, half(offer.hbest))
        else:  # a new subgroup: N_kill = 0, SC_s = 0, its best is what its members bring
            self.ledger_h, self.chi2 = self.hbest, self.chi1
            self.sc = self.n_kill = 0
        self.events.append(f"joined {sid}")

    def _excluded(self) -> None:
        """Socially excluded (section 4.5.2): answer CALL/SPAWN offers best-first, or found a subgroup."""
        p = self.p
        rid = self.robot.id
        cluster = self._mates()
        n_x = self._group_size()
        self.worst = rid
        # a candidacy placed last iteration is decided now, among the candidates for the same offer
        if self.candidate is not None and self.candidate[2] == self.k:  # candidates flagged in this iteration's hellos
            target, kind, _, offer = self.candidate
            rivals = [(-self.hbest, rid)] + [(-h.hbest, h.robot) for h in self.heard.values()
                                              if h.sid == 0 and h.flags & F_CANDIDATE and h.target == target]
            rivals.sort()
            rank = rivals.index((-self.hbest, rid))
            if kind & F_CALL:
                slots, needed = 1, 1
            elif kind & F_FOUNDER:
                slots, needed = p["n_init"] - 1, 1
            else:
                slots, needed = p["n_init"], p["n_init"]
            self.candidate = None
            if len(rivals) >= needed and rank < slots:
                self._join(target, offer, spawn=not kind & F_CALL)
                self.events.append("by call" if kind & F_CALL else "by founder" if kind & F_FOUNDER else "by spawn")
                return
        # offers heard this iteration: a CALL (to the caller's subgroup), a SPAWN from an active subgroup, or a
        # founder's SPAWN; a CALL is preferred, then the offer of the best ledger
        offers = []
        for h in self.heard.values():
            if h.flags & F_CALL and h.sid:
                offers.append((1, h.ledger_h, -h.robot, h.sid, F_CALL, h))
            if h.flags & F_SPAWN and h.target:
                offers.append((0, h.ledger_h, -h.robot, h.target, h.flags & (F_SPAWN | F_FOUNDER), h))
        if offers:
            _, _, _, target, kind, offer = max(offers, key=lambda o: o[:3])
            self.candidate = (target, kind, self.k + 1, offer)
            self.events.append(f"candidate {target}")
            return
        # no offer: found a subgroup with probability N_X / (2 N_T) if among the N_I best of the cluster
        if n_x >= p["n_init"] and self._subgroups_known() < p["subgroups_max"]:
            better = sum(1 for h in cluster if h.hbest > self.hbest)
            if better < p["n_init"] and chance(self.robot.rng_py, n_x / p["n_total"]):
                sid = new_subgroup_id(rid, self.k)
                self._join(sid, None, spawn=True)
                self.offer_flags = F_SPAWN | F_FOUNDER
                self.offer_target = sid
                self.events.append("founded")

    def _take_data(self, heard: dict[int, Hello], addrs: dict[int, int | None]) -> None:
        """With routing: tell the router who was heard (its hellos), read the data packets that reached this robot:
        a mate's packet of this iteration counts in this iteration's solutions and refreshes the member table."""
        router = self.router
        k = self.k
        for rid, msg in heard.items():
            router.heard(rid, addrs[rid], k, msg.x, msg.y, (msg.ledger_x, msg.ledger_y), self._is_link(msg))
        router.tick(k)
        self.data_heard = {}
        for src, hops, x, y, payload in router.take_delivered():
            if len(payload) != SHARE.size:
                self.dropped["foreign"] += 1
                continue
            sid, k16, best, improved = SHARE.unpack(payload)
            if improved:
                router.note_best(src, x, y)
            if k16 != k & 0xFFFF:
                self.dropped["late"] += 1
                continue
            if sid != self.sid or src in heard:
                continue
            self.data_heard[src] = (x, y, best, bool(improved))
            self.table[src] = (k, hops - 1, half(best))
            self.departed.pop(src, None)

    def _predict(self, track: Any, chi1: tuple[float, float] | None,
                 chi2: tuple[float, float] | None) -> tuple[float, float]:
        """A neighbour's next position (section 6.2): one deterministic RDPSO step (r = 1/2) from its last
        positions (newest first), with only the cognitive and social terms."""
        x, y = track[0]
        history = [(track[j][0] - track[j + 1][0], track[j][1] - track[j + 1][1]) for j in range(len(track) - 1)]
        vx, vy = motion.memory_term(self.weights, history)
        for rho, c in ((self.rho[0], chi1), (self.rho[1], chi2)):
            if c is not None:
                vx += 0.5 * rho * (c[0] - x)
                vy += 0.5 * rho * (c[1] - y)
        vx, vy = motion.clamp(vx, vy, self.p["dx_max_m"])
        return (x + vx, y + vy)

    def comm_stats(self) -> dict[str, float | int]:
        """The routing layer's counters, with the time the radio was busy and the time this robot paused."""
        if self.router is None:
            return {}
        return {**self.router.stats, "busy_s": round(self.router.blocked_s, 3), "paused_s": round(self.paused_s, 3)}

    # -- motion ---------------------------------------------------------------------------------------------
    def _velocity(self) -> tuple[float, float]:
        p = self.p
        x, y = self.x, self.y
        rng = self.robot.rng_py
        dx_max = p["dx_max_m"]
        if self.sid == 0:
            return self._wander()
        chi4 = self._connectivity()
        if self.adapter is not None:
            self._adapt()
        mx, my = motion.memory_term(self.weights, self.history)
        vx, vy = mx, my
        for rho, (cx, cy) in zip(self.rho, (self.chi1, self.chi2, self.chi3, chi4), strict=True):
            if rho:
                vx += rho * rng.random() * (cx - x)
                vy += rho * rng.random() * (cy - y)
        return motion.clamp(vx, vy, dx_max)

    def _wander(self) -> tuple[float, float]:
        """Excluded robots wander (A11): a random turn each iteration, a step of dx_max, pulled back to chi_3 near
        obstacles and toward the excluded cluster by the connectivity term."""
        p = self.p
        rng = self.robot.rng_py
        turn = math.radians(p["wander_turn_deg"])
        self.wander_heading += rng.uniform(-turn, turn)
        step = p["dx_max_m"]
        vx, vy = step * math.cos(self.wander_heading), step * math.sin(self.wander_heading)
        if self.g < p["r_w_m"]:
            vx += self.rho[2] * rng.random() * (self.chi3[0] - self.x)
            vy += self.rho[2] * rng.random() * (self.chi3[1] - self.y)
            self.wander_heading += math.pi  # turn away from the obstacle
        cx, cy = self._connectivity()
        vx += self.rho[3] * rng.random() * (cx - self.x)
        vy += self.rho[3] * rng.random() * (cy - self.y)
        return motion.clamp(vx, vy, step)

    def _link(self, h: Hello) -> float | None:
        if self.p["link_mode"] == "distance":
            return math.hypot(h.x - self.x, h.y - self.y)
        return self.rssi.get(h.robot)

    def _is_link(self, h: Hello) -> bool:
        """Whether ``h`` came over a link of the MANET as the RDPSO judges it (q_min, or d_max from positions):
        the routing layer's one-hop neighbours are those, so a robot heard only faintly is reached through relays.
        A hello with no measure (a module that reports no RSSI) counts."""
        link = self._link(h)
        mode = self.p["link_mode"]
        return link is None or bool(graph.linked(link, mode, self.p["d_max_m" if mode == "distance" else "q_min_dbm"]))

    def _connectivity(self) -> tuple[float, float]:
        """chi_4 (eq. 5.12, Algorithm 5.2): k mates that did not choose me, nearest (or strongest) first."""
        p = self.p
        rid = self.robot.id
        if p["link_mode"] == "distance" and not math.isfinite(p["d_max_m"]):
            self.chosen = ()
            return (self.x, self.y)  # no communication constraint (infrastructure, d_max = infinity)
        cands = []
        for h in self._mates():
            if rid in h.chosen:
                continue
            link = self._link(h)
            if link is not None:
                cands.append((h.robot, link))
        k_eff = min(int(p["k_conn"]), self._group_size() - 1)
        ids = graph.choose_neighbours(cands, k_eff, p["link_mode"]) if k_eff > 0 else []
        self.chosen = tuple(ids)
        if not ids:
            return (self.x, self.y)
        links = dict(cands)
        chosen = [(self.heard[i].x, self.heard[i].y, links[i]) for i in ids]
        qx, qy = graph.connectivity_vector(self.x, self.y, chosen, p["link_mode"], p["d_max_m"], p["q_min_dbm"],
                                           p["k_q"])
        return (self.x + qx, self.y + qy)

    def _adapt(self) -> None:
        """Chapter 7: context metrics of this robot and its subgroup -> fuzzy -> alpha, rho (A17)."""
        p = self.p
        mates = self._mates()
        pts = [(self.x, self.y)] + [(h.x, h.y) for h in mates]
        cx = sum(q[0] for q in pts) / len(pts)
        cy = sum(q[1] for q in pts) / len(pts)
        if self.last_centre is None:
            a_s = 0.0
        else:
            a_s = fuzzy.swarm_activity(math.hypot(cx - self.last_centre[0], cy - self.last_centre[1]),
                                       p["dx_max_m"])
        self.last_centre = (cx, cy)
        dists = [math.hypot(self.chi2[0] - q[0], self.chi2[1] - q[1]) for q in pts]
        s_n = fuzzy.socialization(dists[0], max(dists))
        o_n = fuzzy.obstacle_proximity(self.g, p["r_w_m"])
        if p["link_mode"] == "distance":
            near = min((math.hypot(h.x - self.x, h.y - self.y) for h in mates), default=math.inf)
            p_n = fuzzy.proximity_distance(near, p["d_max_m"]) if near < math.inf else 0.0
        else:
            best = max((self.rssi[h.robot] for h in mates if h.robot in self.rssi), default=None)
            p_n = fuzzy.proximity_rssi(best, p["q_min_dbm"]) if best is not None else 0.0
        c_s = self._group_connectivity(pts) if len(pts) > 1 else 1.0  # alone: nothing to reconnect to
        self.alpha, r1, r2, r3, r4 = self.adapter.adapt(a_s, s_n, o_n, p_n, c_s)
        self.rho = [r1, r2, r3, r4]
        self.weights = motion.memory_weights(self.alpha, p["fractional_form"], int(p["truncation_r"]))

    def _group_connectivity(self, pts: list[tuple[float, float]]) -> float:
        """C_s = lambda_2 / N_s (eq. 7.24) of the mates this robot hears, linked within d_max."""
        import numpy as np

        a = np.asarray(pts)
        d = np.hypot(a[:, None, 0] - a[None, :, 0], a[:, None, 1] - a[None, :, 1])
        return graph.connectivity_metric(graph.adjacency(d, "distance", self.p["d_max_m"]))

    def _move(self, vx: float, vy: float) -> None:
        dist = math.hypot(vx, vy)
        if dist < self.p["min_move_m"]:
            return
        rot = math.atan2(vy, vx) - self.theta
        rot = math.atan2(math.sin(rot), math.cos(rot))
        self.robot.llc.move(rot, dist, self.p["speed_mps"])

    def _show(self) -> None:
        rgb = colour(self.sid)
        if rgb != self.led:
            self.led = rgb
            self.robot.llc.set_led(*rgb)


def _f(v: float) -> float:
    """A value for the wire: -inf (nothing sensed yet) as a very low float32."""
    return v if math.isfinite(v) else -3.0e38
