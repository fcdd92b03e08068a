"""The study's co-simulation sessions as its experiments use them: where its configs are, running one, and reading
and scoring its recording (the robots' RDPSO logs, the ground-truth poses, the light they found).

Shared by the experiment modules that run sessions (``experiments``, ``field_experiments``, ``comm_experiments``), so
none of them imports another.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from bridge.experiments.runner import TrialResult

REPO = Path(__file__).resolve().parents[3]
CONFIGS = REPO / "hil_configs" / "rdpso"  # the study's sessions


def run_checked(cfg: Path, out: Path) -> None:
    """Run the session of config ``cfg`` into ``out``; a session that fails raises (the trial fails with it)."""
    from bridge.core.launcher import run_session

    res = run_session(str(cfg), None, str(out), progress=None, plot=False)
    if res.code != 0:
        raise RuntimeError(f"session failed ({res.code}): {res.summary.get('error')}")


def arena_peaks(cfg_path: Path) -> tuple[tuple[float, float], float, float]:
    """The brighter spot's position and the LDR counts at the two spots' centres (the sensor's own transfer)."""
    from bridge.core.config import load_config
    from firmware_sim.board import sensors
    from firmware_sim.board.arduino import Board
    from firmware_sim.robots.eswarbot.llc import PIN_LDR

    cfg = load_config(cfg_path)
    spots = sorted(cfg.light.sources, key=lambda s: -s.peak_lux)

    board = Board()

    def counts(x: float, y: float) -> int:  # what the robot's LLC reads there (no sensor noise)
        board.analog_volts[PIN_LDR] = sensors.ldr_volts(float(cfg.light.illuminance(x, y)))
        return board.analog_read(PIN_LDR)

    best = spots[0]
    return (best.x, best.y), counts(best.x, best.y), counts(spots[1].x, spots[1].y) if len(spots) > 1 else 0.0


def read_rdpso_session(out: Path) -> tuple[dict[int, list[dict[str, Any]]], np.ndarray, np.ndarray, np.ndarray]:
    """The robots' "rdpso" log records and the ground-truth poses (t, x, y) of a session's recording."""
    from bridge.core.plot import read_poses
    from bridge.core.recorder import iter_messages

    logs: dict[int, list[dict[str, Any]]] = {}
    for topic, t_ns, data in iter_messages(out / "session.mcap"):
        if topic.endswith("/log/rdpso"):
            rec = json.loads(data)
            rec["t"] = t_ns * 1e-9
            logs.setdefault(int(topic[2:5]), []).append(rec)
    ts, xs, ys, _ = read_poses(out / "session.mcap")
    return logs, ts, xs, ys


def score_arena(out: Path, cfg: Path, n: int, duration: float) -> TrialResult:
    """R1/R2 figures of one arena session from its recording."""
    (ox, oy), peak, sub_peak = arena_peaks(cfg)
    logs, ts, xs, ys = read_rdpso_session(out)
    t_light = None
    improved = total = 0
    for recs in logs.values():
        for rec in recs:
            total += 1
            improved += bool(rec["improved"])
            if rec["sid"] and rec["ledger_h"] is not None and rec["ledger_h"] >= 0.95 * peak and \
                    (t_light is None or rec["t"] < t_light):
                t_light = rec["t"]
    curve = mission_curve(logs, int(duration), from_start=False)
    t_near = None
    if len(ts):
        d = np.hypot(xs - ox, ys - oy)
        hit = np.flatnonzero((d <= 0.25).any(axis=1))
        t_near = float(ts[hit[0]]) if len(hit) else None
    metrics = {
        "converged": t_light is not None,
        "t_converge": None if t_light is None else round(t_light, 2),
        "t_near_025": None if t_near is None else round(t_near, 2),
        "final_best": curve[-1] if curve else None,
        "peak_counts": peak,
        "suboptimal_counts": sub_peak,
        "improvement_rate": round(improved / max(1, total), 4),
        "robot_iterations": total,
        "robots": n,
    }
    return TrialResult(metrics, {"best_light": curve}, {"best_light": list(range(len(curve)))})


def mission_curve(logs: dict[int, list[dict[str, Any]]], length_s: int, from_start: bool = True) -> list[float]:
    """The swarm's best light reading (subgroup ledgers) by second, of the session or (``from_start``) of mission
    time, each robot's counted from its own START (its first ``rdpso`` record), so subgroups that start at
    different times line up as the thesis' Fig. 5.9 and 5.12 do; 0 before any reading."""
    best = np.zeros(max(0, length_s))
    for recs in logs.values():
        if not recs:
            continue
        t0 = recs[0]["t"] if from_start else 0.0
        for rec in recs:
            s = int(rec["t"] - t0)
            if rec["sid"] and rec["ledger_h"] is not None and 0 <= s < len(best):
                best[s] = max(best[s], rec["ledger_h"])
    return np.maximum.accumulate(best).tolist() if len(best) else []
