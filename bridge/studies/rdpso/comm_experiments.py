"""Chapter 6 experiments: what the RDPSO's robots send, regular vs optimised sharing, AODV vs RDPSO-AODV.

``e6-comm`` runs the pavilion mission in the full co-simulation (every robot's XBee module, the radio medium with
CSMA-CA, acknowledgements and finite buffers) and reads the routing layer's counters from the robots' logs
(targets R8, R9, R10). ``b11-comm-ratio`` runs 60 robots in the numerical runner and follows the ratio of packets
sent, optimised over regular, per window of iterations (target B11).
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from bridge.experiments.runner import Experiment, Outcome, Target, Trial, TrialResult, register
from bridge.experiments.stats import median, ok
from bridge.numerical import runner as numerical
from bridge.numerical.objectives import LightField
from bridge.studies.rdpso.comm_stats import CONTROL, comm_metrics, comm_totals
from bridge.studies.rdpso.sessions import CONFIGS, read_rdpso_session, run_checked


def pavilion_variant(path: Path, seed: int, duration: float, comm: str, routing: str, group: int,
                     xbee: str = "one_hop") -> Path:
    """hil_configs/rdpso/rdpso_pavilion.toml (15 eSwarBots, three subgroups of 5) with the sharing mode and routing, or
    with one subgroup of 15 (``group = 15``: the three groups placed together in the pavilion's first half); ``xbee``:
    the modules' own routing (``one_hop``, or ``mesh`` as a Series 2's ZigBee firmware routes)."""
    from bridge.core.config import to_toml

    raw = tomllib.loads((CONFIGS / "rdpso_pavilion.toml").read_text())
    raw["session"] |= {"seed": seed, "duration_s": duration}
    for g in raw["robots"]:
        g["params"] |= {"comm": comm, "routing": routing, "swarm_seed": seed % (1 << 31)}
        if xbee != "one_hop":
            g["xbee"] |= {"routing": xbee}
        if group == 15:
            g["params"] |= {"subgroups_init": 1, "subgroups_max": 3}
    if group == 15:
        regions = ([0.5, 0.5, 9.5, 3.5], [0.5, 3.5, 9.5, 6.5], [0.5, 6.5, 9.5, 9.5])
        for g, region in zip(raw["robots"], regions, strict=True):
            g["placement"]["region"] = list(region)
    path.write_text(to_toml(raw))
    return path


@register
class E6Comm(Experiment):
    name = "e6-comm"
    title = "E6: information sharing and RDPSO-AODV over the XBee network, 15 eSwarBots in the pavilion (co-simulation)"
    description = (
        "Thesis chapter 6 (digest 2.10, 2.11, E6; targets R8, R9, R10), run in the full co-simulation: "
        "hil_configs/rdpso/rdpso_pavilion.toml (10 x 20 m, pillars and a box, two light spots, Table 5.1 parameters, "
        "2 s iterations as the thesis' robots' 1.9 s, q_min -75 dBm, 360 s), every robot's XBee Series 2 module "
        "on its serial port and the 802.15.4 medium (CSMA-CA, ACKs, APS retries, 202-byte module buffers). "
        "The routing layer runs in the robots' logic (swarm_logic.families.rdpso.aodv) on ordinary transmit requests: "
        "the emulated module does not route. Regular: the hello and one data packet to every subgroup mate every "
        "iteration; optimised: the hello, and data to every mate only on a personal-best improvement. A robot "
        "does not move until its radio has sent the iteration's packets (pause time). Packets are every frame "
        "the robot handed its module (hellos, its data, forwarded data, routing control). Subgroups of 5 (three, "
        "as placed by the config) or one of 15 (all placed in the first half of the pavilion). Trials are "
        "without the marsupial deployment (the scouts start placed), to keep them affordable. The targets compare "
        "the thesis' two sets (section 6.3.1): the regular RDPSO (regular sharing over AODV, as its robots used the "
        "XBee firmware's) and the optimised one (optimised sharing over RDPSO-AODV); regular sharing over "
        "RDPSO-AODV splits the two changes apart.")
    trials = 20
    smoke_trials = 1
    x_label = "time [s]"
    curves = (("packets", "packets sent per robot (cumulative)"),)
    boxes = (("packets_per_robot", "packets per robot"), ("delivery_ratio", "packet delivery ratio"),
             ("radio_busy_share", "share of the mission sending and receiving"))
    CELLS: ClassVar[list[dict[str, Any]]] = [
        {"comm": "regular", "routing": "rdpso", "group": 5},
        {"comm": "optimised", "routing": "rdpso", "group": 5},
        {"comm": "regular", "routing": "rdpso", "group": 15},
        {"comm": "optimised", "routing": "rdpso", "group": 15},
        {"comm": "regular", "routing": "aodv", "group": 5},
        {"comm": "regular", "routing": "aodv", "group": 15},
        # the thesis' two sets on modules that route, as its eSwarBots' XBee Series 2 did
        {"comm": "regular", "routing": "module", "group": 5, "xbee": "mesh"},
        {"comm": "optimised", "routing": "rdpso", "group": 5, "xbee": "mesh"},
        {"comm": "regular", "routing": "module", "group": 15, "xbee": "mesh"},
        {"comm": "optimised", "routing": "rdpso", "group": 15, "xbee": "mesh"},
    ]

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        return [{"comm": "optimised", "routing": "rdpso", "group": 5}] if smoke else list(self.CELLS)

    def run(self, trial: Trial) -> TrialResult:
        duration = 30.0 if trial.smoke else 360.0
        c = trial.cell
        cfg = pavilion_variant(Path(trial.workdir) / "pavilion.toml", trial.seed, duration, c["comm"], c["routing"],
                               c["group"], c.get("xbee", "one_hop"))
        out = Path(trial.workdir) / "session"
        run_checked(cfg, out)
        return score_comm(out, duration)

    # The thesis' two sets of 20 trials (section 6.3.1): the "regular" RDPSO of chapters 4-5 (every iteration's data
    # to every mate, routed by the AODV inside the XBee ZigBee firmware) and the "optimized" one (section 6.1's
    # sharing and 6.2's RDPSO-AODV). Every chapter 6 figure compares these two, on modules that route as the
    # eSwarBots' Series 2 did. The one-hop cells, with all routing in the logic, split the changes apart.
    REGULAR: ClassVar[dict[str, str]] = {"comm": "regular", "routing": "module", "xbee": "mesh"}
    OPTIMISED: ClassVar[dict[str, str]] = {"comm": "optimised", "routing": "rdpso", "xbee": "mesh"}
    ONE_HOP: ClassVar[list[tuple[str, dict[str, Any]]]] = [
        ("regular/AODV", {"comm": "regular", "routing": "aodv", "xbee": None}),
        ("regular/RDPSO-AODV", {"comm": "regular", "routing": "rdpso", "xbee": None}),
        ("optimised/RDPSO-AODV", {"comm": "optimised", "routing": "rdpso", "xbee": None}),
    ]

    def targets(self) -> list[Target]:
        return [
            Target("R8a", "packets per robot, regular vs optimised RDPSO (subgroups of 5)", "742 +- 24 vs 415 +- 37 "
                   "(-44 %)", "optimised 35-55 % fewer", self._packets),
            Target("R8b", "share of the mission spent sending and receiving on the radio, regular vs optimised",
                   "126 +- 4 s (35 %) vs 39 +- 7 s (10 %) of 360 s", "regular 30-40 %, optimised 8-15 %",
                   self._pause),
            Target("R9", "packet delivery ratio at 15 robots per subgroup, regular vs optimised", "about 65 % vs "
                   "above 90 % (regular about 100 % up to 10 robots)", "optimised >= 90 % and above regular",
                   self._pdr),
            Target("R10", "hop count and routing overhead, regular (the module's AODV) vs optimised (RDPSO-AODV)",
                   "not significant for small subgroups; about 20 % fewer hops and a lower overhead at 15",
                   "optimised: fewer hops and a lower overhead than regular at 15", self._routing),
        ]

    def _pair(self, outcomes: list[Outcome], metric: str, group: int) -> tuple[float, float]:
        """The metric's medians, regular vs optimised RDPSO, in subgroups of ``group``."""
        return (self._median(outcomes, self.REGULAR, group, metric),
                self._median(outcomes, self.OPTIMISED, group, metric))

    @staticmethod
    def _median(outcomes: list[Outcome], cell: dict[str, Any], group: int, metric: str) -> float:
        vals = [v for r in ok(outcomes, **cell, group=group) if (v := _trial_value(r.metrics, metric)) is not None]
        return float(np.median(vals)) if vals else math.nan

    def _split(self, outcomes: list[Outcome], metric: str, fmt: str) -> str:
        """The one-hop cells' medians (subgroups of 5): which of the two changes moves the metric."""
        parts = [f"{name} {format(v, fmt)}" for name, cell in self.ONE_HOP
                 if np.isfinite(v := self._median(outcomes, cell, 5, metric))]
        return "one-hop modules, routing in the logic: " + ", ".join(parts) if parts else ""

    def _packets(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        reg, opt = self._pair(outcomes, "packets_per_robot", 5)
        if not (np.isfinite(reg) and np.isfinite(opt)):
            return "no data", None, "needs both subgroup-of-5 cells"
        cut = 1 - opt / reg
        split = self._split(outcomes, "packets_per_robot", ".0f")
        dreg, dopt = self._pair(outcomes, "data_per_robot", 5)
        return (f"{reg:.0f} vs {opt:.0f} ({-cut:+.0%}); data packets originated {dreg:.0f} vs {dopt:.0f}"
                + (f"; {split}" if split else ""), 0.35 <= cut <= 0.55,
                "medians over trials; packets are every frame a robot handed its module (hellos, data, forwards, "
                "routing control); the thesis counted a regular robot's 4 data packets to its subgroup each iteration")

    def _pause(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        reg, opt = self._pair(outcomes, "radio_busy_share", 5)
        if not (np.isfinite(reg) and np.isfinite(opt)):
            return "no data", None, "needs both subgroup-of-5 cells"
        preg, popt = self._pair(outcomes, "pause_share", 5)
        split = self._split(outcomes, "radio_busy_share", ".0%")
        return (f"{reg:.0%} vs {opt:.0%} (the move delayed past the hello window: {preg:.0%} vs {popt:.0%})"
                + (f"; {split}" if split else ""),
                0.30 <= reg <= 0.40 and 0.08 <= opt <= 0.15,
                "medians over trials; the thesis timed its send-and-receive function, during which a robot does "
                "nothing else: here the time its radio has its packets to send (the receive reads what the module "
                "has buffered, at once)")

    def _pdr(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        reg, opt = self._pair(outcomes, "delivery_ratio", 15)
        reg5, _ = self._pair(outcomes, "delivery_ratio", 5)
        if not (np.isfinite(reg) and np.isfinite(opt)):
            return "no data", None, "needs both subgroup-of-15 cells"
        return (f"{reg:.0%} vs {opt:.0%} (regular at 5: {reg5:.0%})", bool(opt >= 0.9 and opt > reg),
                "medians over trials")

    def _routing(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        parts = []
        for g in (5, 15):
            hr, ho = self._pair(outcomes, "path_hops", g)
            orr, oo = self._pair(outcomes, "route_overhead", g)
            if not all(np.isfinite(v) for v in (hr, ho, orr, oo)):
                return "no data", None, "needs the regular and the optimised cells of both subgroup sizes"
            parts.append(f"{g}: hops {hr:.2f} vs {ho:.2f} ({ho / hr - 1:+.0%}), overhead {orr:.2f} vs {oo:.2f}")
            if g == 15:
                verdict = bool(ho < hr and oo < orr)
        split = self._split(outcomes, "path_hops", ".2f")
        return ("; ".join(parts) + (f"; {split}" if split else ""), verdict,
                "regular vs optimised RDPSO, medians over trials; hops: the transmissions a delivered packet took "
                "(the logic's hops times the modules' hops on the air), averaged over the packets delivered, as the "
                "thesis does; overhead: route requests, replies and errors per data packet, the logic's and the "
                "modules' (the requests they originate, not those they relay)")


def _trial_value(m: dict[str, Any], metric: str) -> float | None:
    """One trial's metric, or one R10 derives from its metrics: ``path_hops``, the radio transmissions a delivered
    packet took (the logic's hops, each as many on the air as the modules'), and ``route_overhead``, the modules'
    route discovery included when they route."""
    if metric == "path_hops":
        return None if m.get("hops") is None else m["hops"] * (m.get("air_hops") or 1.0)
    if metric == "route_overhead":
        metric = "overhead_all" if m.get("overhead_all") is not None else "overhead"
    v = m.get(metric)
    return None if v is None else float(v)


def module_routing(out: Path) -> dict[str, float | None]:
    """What the modules' own routing did, when they route (mesh; None for modules that deliver one hop), from the
    session's summary: the hops on the air of the unicasts they delivered to their robots (``air_hops``), and the
    route requests and replies they originated (``module_route_frames``, relays of requests not counted)."""
    per_robot = json.loads((out / "summary.json").read_text()).get("per_robot", [])
    mods = [r.get("xbee_module") or {} for r in per_robot]
    delivered = sum(m.get("nwk_data_delivered", 0) for m in mods)
    if not delivered:
        return {"air_hops": None, "module_route_frames": None}
    return {"air_hops": round(sum(m.get("nwk_data_hops", 0) for m in mods) / delivered, 4),
            "module_route_frames": sum(m.get("nwk_rreq_sent", 0) + m.get("nwk_rrep_sent", 0) for m in mods)}


def score_comm(out: Path, duration: float) -> TrialResult:
    """R8-R10 figures of one session: the robots' last routing counters, and packets over time."""
    logs, *_ = read_rdpso_session(out)
    last: dict[int, dict[str, Any]] = {}
    series: dict[int, list[tuple[float, float]]] = {}
    improved = total = 0
    for robot, recs in logs.items():
        for rec in recs:
            if "comm" in rec:
                last[robot] = rec["comm"]
                series.setdefault(robot, []).append((rec["t"], rec["comm"]["tx_frames"]))
            total += 1
            improved += bool(rec["improved"])
    if not last:
        raise RuntimeError("no routing counters in the robots' logs (comm = gossip?)")
    n = len(last)
    tot = comm_totals(last)
    metrics: dict[str, Any] = comm_metrics(tot, n, duration)
    metrics["improvement_rate"] = round(improved / max(1, total), 4)
    metrics.update(module_routing(out))
    data_frames = tot["tx_data"] + tot["tx_forward"]
    if metrics["module_route_frames"] is not None and data_frames:  # the routing overhead, the modules' included
        metrics["overhead_all"] = round((sum(tot[k] for k in CONTROL) + metrics["module_route_frames"])
                                        / data_frames, 4)
    grid = np.arange(0.0, duration + 1e-9, 10.0)
    per_robot = [np.interp(grid, [t for t, _ in s], [v for _, v in s], left=0.0) for s in series.values()]
    return TrialResult(metrics, {"packets": np.round(np.mean(per_robot, axis=0), 1).tolist()},
                       {"packets": grid.tolist()})


@register
class B11CommRatio(Experiment):
    name = "b11-comm-ratio"
    title = "B11: packets sent, optimised over regular, 60 robots in the pavilion (numerical runner)"
    description = (
        "Thesis E7 (digest 4.7; target B11): 60 robots in the 10 x 20 m pavilion with its two light spots "
        "(hil_configs/rdpso/rdpso_pavilion.toml's light field, normalised), Table 5.1 parameters (three initial "
        "subgroups of 20, dx_max 0.2 m, 2 s iterations), a 3 m link range (q_min -75 dBm in this hall), the "
        "routing layer of the co-simulation (RDPSO-AODV) on the numerical runner's point radios (a frame "
        "reaches every robot in range at the end of the round it was sent in; a unicast is acknowledged when its "
        "destination is in range). Each trial runs the regular and the optimised sharing from the same seed "
        "(same start, same field) and compares the packets every robot sent per window of 50 iterations. "
        "Fewer iterations than the thesis' 5000 steps, for time: stated in the cells.")
    trials = 30
    smoke_trials = 1
    x_label = "iteration"
    curves = (("ratio", "packets, optimised / regular (per 50-iteration window)"),)
    boxes = (("ratio_late", "optimised / regular, second half"),)
    WINDOW = 50

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        return [{"n": 20, "iterations": 100}] if smoke else [{"n": 60, "iterations": 400}]

    def run(self, trial: Trial) -> TrialResult:
        n, iterations = trial.cell["n"], trial.cell["iterations"]
        raw = tomllib.loads((CONFIGS / "rdpso_pavilion.toml").read_text())
        light = raw["light"]
        spots = [(s["x"], s["y"], s["peak_lux"], s["sigma_m"]) for s in light["sources"]]
        size = (float(raw["arena"]["width_m"]), float(raw["arena"]["length_m"]))
        base = {k: v for k, v in raw["robots"][0]["params"].items() if k not in ("n_total", "swarm_seed")}
        rng = np.random.default_rng(trial.seed)
        seed, swarm_seed = int(rng.integers(1 << 31)), int(rng.integers(1 << 31))
        windows: dict[str, np.ndarray] = {}
        metrics: dict[str, Any] = {}
        for comm in ("regular", "optimised"):
            p = {**base, "comm": comm, "link_mode": "distance", "d_max_m": 3.0, "send_jitter_s": 0.0,
                 "payload_max": 4096, "poll_s": 0.4, "swarm_seed": swarm_seed, "log_every": 1}
            res = numerical.run("rdpso", p, n, iterations, LightField(spots, size, float(light["ambient_lux"])), size,
                                link=numerical.LinkModel(range_m=3.0), seed=seed, keep_logs=True)
            per_k = np.zeros(iterations)
            last: dict[int, dict[str, Any]] = {}
            prev: dict[int, int] = {}
            k0 = min(rec["k"] for rec in res.logs if rec["topic"] == "rdpso")
            for rec in res.logs:
                if rec["topic"] != "rdpso" or "comm" not in rec:
                    continue
                k = rec["k"] - k0
                sent = rec["comm"]["tx_frames"]
                if 0 <= k < iterations:
                    per_k[k] += sent - prev.get(rec["robot"], 0)
                prev[rec["robot"]] = sent
                last[rec["robot"]] = rec["comm"]
            windows[comm] = per_k[: iterations // self.WINDOW * self.WINDOW].reshape(-1, self.WINDOW).sum(axis=1)
            m = comm_metrics(comm_totals(last), n, iterations * float(p["iteration_s"]))
            metrics[f"{comm}_packets_per_robot"] = m["packets_per_robot"]
            metrics[f"{comm}_delivery_ratio"] = m["delivery_ratio"]
            metrics[f"{comm}_improvement_rate"] = round(res.improvements / max(1, res.robot_iterations), 4)
        ratio = windows["optimised"] / np.maximum(windows["regular"], 1.0)
        half = len(ratio) // 2
        metrics |= {"ratio_first": round(float(ratio[0]), 4), "ratio_late": round(float(np.median(ratio[half:])), 4),
                    "ratio_total": round(float(windows["optimised"].sum() / max(1.0, windows["regular"].sum())), 4)}
        x = ((np.arange(len(ratio)) + 0.5) * self.WINDOW).tolist()
        return TrialResult(metrics, {"ratio": np.round(ratio, 4).tolist()}, {"ratio": x})

    def targets(self) -> list[Target]:
        return [Target("B11", "packets, optimised / regular, per window", "about 0.5 early, about 0.2 after "
                       "mid-mission, decreasing", "second-half median <= 0.3 and below the first window",
                       self._ratio)]

    def _ratio(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        rs = [o.result for o in outcomes if o.result is not None]
        if not rs:
            return "no data", None, "no successful trial"
        first, late = median(rs, "ratio_first"), median(rs, "ratio_late")
        return (f"{first:.2f} first window, {late:.2f} second-half median", bool(late <= 0.3 and late < first),
                "medians over trials")
