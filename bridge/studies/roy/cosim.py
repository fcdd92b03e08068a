"""Chapter 3 on SonPIs in co-simulation: the thesis' hardware cases (chapter 7, Tables 7.1-7.3, digest 001 §4.5.1,
target D2) as sessions, each in two profiles.

**Cases** (``CASES``), at hardware scale: a 350 x 175 cm arena (digest §5.3), the robots starting in the west end
(x 0.25-0.70 m, y 0.55-1.20 m, at least 0.25 m apart, facing east), T = (3.10, 0.875) m; 1 unit = 0.1 m
(digest §5.4), r_s = 1.13 units (the hardware's 11.3 cm, digest §4.5.4). The thesis' layouts are lost with its
figures; ours, from the captions:

- ``ch7-open`` (case 1): no obstacle;
- ``ch7-static`` (case 2): a pillar, then a wall across the arena with a 45 cm passage (a SonPI is 18 cm across, a
  formation 2 r_s apart is not: it must file through);
- ``ch7-moving-low`` (case 3, low complexity): the open arena and one toy car (a 6 cm cylinder, 10 cm tall, the sonars'
  height) shuttling across the swarm's route at 8 cm/s;
- ``ch7-moving-high`` (case 4, high complexity): two walls with 45 cm passages at opposite sides (a zig-zag) and three
  cars shuttling across the route, one before, one between and one after the walls.

**Profiles** (``PROFILES``):

- ``simulation``: the thesis' ideal sensing: the camera in noise mode with a zero error model and the comparator's
  gains at 1 (every robot's pose exact at each frame, 20 fps), the board's ``ideal`` firing (200 Hz, no noise), an
  ideal Wi-Fi (no loss, one quantum);
- ``hardware``: the camera in tracking mode (rendered, Lucas-Kanade, 10 fps) fused with the encoders' odometry,
  sequential HC-SR04 firing (3.3 Hz per sensor) with 3 mm noise, a lossy Wi-Fi (3 +- 1 ms, 2 % loss).

Both: SonPIs (differential drive, the tracking layer, the Arduino board on I2C), ``roy_apf`` with BAT (25 x 50, every
step), v_max 1 unit/s (0.1 m/s). The study's loop functions (``[formation]``) score each session from the true poses
and end it when the swarm arrives; a session that does not arrive ends at ``timeout_s``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bridge.core.rng import stream
from bridge.experiments.sessions import run_config

UNIT_M = 0.1
R_S_UNITS = 1.13
ARENA = (3.5, 1.75)
TARGET_M = (3.10, 0.875)
V_MAX = 1.0  # units/s
START_BOX = ((0.25, 0.70), (0.55, 1.20))
START_GAP_M = 0.25
CAR = {"radius": 0.06, "height": 0.10}  # a toy car as tall as the sonars' beams (0.072 m)
WALL = 0.06  # walls' thickness (m)
PASSAGE = 0.45  # a passage's width (m)


def _wall(x: float, gap_y: float) -> list[dict[str, Any]]:
    """A wall across the arena at ``x`` with a passage of ``PASSAGE`` centred on ``gap_y``."""
    lo, hi = gap_y - PASSAGE / 2, gap_y + PASSAGE / 2
    return [{"type": "box", "x": x, "y": lo / 2, "size": [WALL, lo, 0.3]},
            {"type": "box", "x": x, "y": (hi + ARENA[1]) / 2, "size": [WALL, ARENA[1] - hi, 0.3]}]


def _car(x: float, y0: float, y1: float, speed: float) -> dict[str, Any]:
    """A toy car shuttling along x = ``x`` between ``y0`` (its start) and ``y1`` at ``speed`` (m/s), for ever."""
    leg = abs(y1 - y0) / speed
    return {"type": "cylinder", "x": x, "y": y0, **CAR,
            "motion": {"waypoints": [[round(leg, 3), x, y1], [round(2 * leg, 3), x, y0]], "repeat": True}}


@dataclass(frozen=True)
class Case:
    name: str
    title: str
    obstacles: list[dict[str, Any]] = field(default_factory=list)
    timeout_s: float = 240.0
    phases: list[dict[str, Any]] = field(default_factory=list)  # [formation] phases (Table 7.5): name, until_dist_m


APPROACH_M = 0.30  # a phase of avoiding a car starts when the centroid is this far before its lane ...
CLEAR_M = 0.15  # ... and ends this far past it (a car 6 cm in radius, a SonPI 9 cm)


def _phase(name: str, until_x: float | None = None) -> dict[str, Any]:
    """A route phase ending where the centroid, moving east, reaches x = ``until_x`` (its distance to T; None: the
    last phase, ending at arrival)."""
    return {"name": name} if until_x is None else {"name": name, "until_dist_m": round(TARGET_M[0] - until_x, 3)}


CASES = {
    "ch7-open": Case("ch7-open", "case 1: no obstacle"),
    "ch7-static": Case("ch7-static", "case 2: a pillar and a wall with a 45 cm passage",
                   [{"type": "cylinder", "x": 1.2, "y": 0.7, "radius": 0.08, "height": 0.3}, *_wall(2.1, 1.05)]),
    "ch7-moving-low": Case("ch7-moving-low", "case 3: one toy car across the route (low complexity)",
                       [_car(2.0, 0.25, 1.50, 0.08)],
                       phases=[_phase("before changing initial formation", 2.0 - APPROACH_M),
                               _phase("after changing initial formation", 2.0 + CLEAR_M),
                               _phase("achieving final formation")]),
    "ch7-moving-high": Case("ch7-moving-high", "case 4: two walls with passages at opposite sides and three toy cars "
                        "(high complexity)",
                        [*_wall(1.5, 0.45), *_wall(2.4, 1.30), _car(1.0, 1.55, 0.20, 0.06),
                         _car(1.95, 0.20, 1.55, 0.08), _car(2.8, 1.55, 0.20, 0.07)], timeout_s=360.0,
                        phases=[_phase("before changing initial formation", 1.0 - APPROACH_M),
                                _phase("avoiding 1st moving obstacle", 1.0 + CLEAR_M),
                                _phase("avoiding 2nd and 3rd moving obstacles", 2.8 + CLEAR_M),
                                _phase("achieving final formation")]),
}
PROFILES = ("simulation", "hardware")
ZERO_NOISE = {"model": {"x_mean_m": 0.0, "x_std_m": 0.0, "y_mean_m": 0.0, "y_std_m": 0.0, "yaw_mean_rad": 0.0,
                        "yaw_std_rad": 0.0, "miss": 0.0},
              "provenance": {"source": "the thesis' simulation: an exact pose at every frame (roy-apf, cosim)"}}


def deploy(n: int, seed: int) -> list[list[float]]:
    """``n`` start poses [x, y, yaw_deg] in the start box, at least ``START_GAP_M`` apart, facing east (seeded)."""
    rng = stream(seed, "roy-cosim", "deploy", n)
    (x0, x1), (y0, y1) = START_BOX
    out: list[list[float]] = []
    while len(out) < n:
        x, y = float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1))
        if all(math.hypot(x - p[0], y - p[1]) >= START_GAP_M for p in out):
            out.append([round(x, 4), round(y, 4), 0.0])
    return out


GATHERING = "gathering"  # the method that is not RoyApf's optimiser: behaviour roy_gathering (circle gathering)
# circle gathering on a SonPI's body (docs/roy-regions.md, "Chapter 7's comparisons"): the slot law as a velocity (a
# differential drive integrating the point agents' double-integrator law overshoots its slot by tens of cm and never
# settles); "in place" within half r_s (5.6 cm: a robot 18 cm across does not hold 2.8 cm while its neighbours
# settle); neighbours 2.5 r_s apart on the circle, the middle of the band eq. 7.1 scores as "in formation" (the
# default circle of radius 2 r_s puts three robots 3.46 r_s apart, outside it; 2 r_s apart their sonars, 4.6 cm from
# the next body, push them off their slots)
GATHERING_ON_SONPI = {"tracking": "velocity", "slot_tol": 0.5, "ring_spacing": 2.5}


def session_config(case: str, n: int, profile: str, seed: int, workdir: Path, max_s: float | None = None,
                   method: str = "bat") -> dict[str, Any]:
    """One session of ``case`` with ``n`` SonPIs in ``profile``, deployed from ``seed`` (the same deployment in both
    profiles); ``max_s`` cuts the session short (smoke runs). ``method``: RoyApf's optimiser, or ``GATHERING`` for
    the circle-gathering baseline in RoyApf's place."""
    if case not in CASES:
        raise ValueError(f"case: no case {case!r}; known: {', '.join(CASES)}")
    if profile not in PROFILES:
        raise ValueError(f"profile: no profile {profile!r}; known: {', '.join(PROFILES)}")
    c = CASES[case]
    ideal = profile == "simulation"
    params = {"v_max": V_MAX, "r_s": R_S_UNITS, "unit_m": UNIT_M,
              "target_x": TARGET_M[0] / UNIT_M, "target_y": TARGET_M[1] / UNIT_M}
    behaviour = "roy_gathering" if method == GATHERING else "roy_apf"
    if behaviour == "roy_apf":
        params["optimiser"] = method
    else:
        params.update(GATHERING_ON_SONPI)
    group: dict[str, Any] = {
        "count": n, "profile": "sonpi", "behaviour": behaviour, "params": params,
        "placement": {"kind": "explicit", "poses": deploy(n, seed)},
        **({"sonar_firing": "ideal", "sonar_noise_m": 0.0} if ideal else {"sonar_firing": "sequential"}),
        "devices": {"sonpi_wifi": {"url": "sitl://wifi", "localisation": "camera"}},
    }
    if ideal:
        model = workdir / "zero_noise.json"
        model.write_text(json.dumps(ZERO_NOISE))
        camera = {"mode": "noise", "fps": 20, "noise_model": str(model), "position_gain": 1.0, "heading_gain": 1.0}
        wifi: dict[str, Any] = {"mode": "ideal"}
    else:
        camera = {"mode": "tracking", "fps": 10}
        wifi = {"mode": "lossy", "latency_ms": 3.0, "jitter_ms": 1.0, "loss": 0.02}
    return {
        "session": {"name": f"roy-{case}-{n}-{profile}", "duration_s": min(c.timeout_s, max_s or c.timeout_s),
                    "seed": seed, "robots_per_process": n},
        "arena": {"width_m": ARENA[0], "length_m": ARENA[1], "wall_height_m": 0.3},
        "obstacles": c.obstacles,
        "robots": [group],
        "services": [{"kind": "overhead_camera", "name": "camera", "options": camera}],
        "wifi": wifi,
        "formation": {"target": list(TARGET_M), "r_s_m": R_S_UNITS * UNIT_M, "goal_tol_m": UNIT_M,
                      **({"phases": c.phases} if c.phases else {})},
    }


def run_session(cfg: dict[str, Any], workdir: Path) -> dict[str, Any]:
    """Write ``cfg``, run it in ``workdir``, return its summary (a failed session raises)."""
    return run_config(cfg, workdir, "roy")[0]


def _stat(d: dict[str, Any] | None, key: str) -> float | None:
    v = (d or {}).get(key)
    return None if v is None else float(v)


def session_metrics(s: dict[str, Any]) -> dict[str, Any]:
    """A trials.csv row from a session's summary: the formation's scores, the localisation's errors (broadcast and
    the camera's own fixes), the sonar windows against the truth, the Wi-Fi's losses, the cost."""
    f = s["formation"]
    cam = s["services"]["camera"]
    boards = [r["firmware"]["arduino"]["sonar_windows"] for r in s["per_robot"]]
    err = [b["error_mean_mm"] for b in boards if b.get("error_mean_mm") is not None]
    rms = [b["error_rms_mm"] for b in boards if b.get("error_rms_mm") is not None]
    valid = [b["valid_fraction"] for b in boards if b.get("valid_fraction") is not None]
    wifi = s.get("wifi") or {}
    pos, head = cam.get("position_error_m") or {}, cam.get("heading_error_deg") or {}
    fpos, fhead = cam.get("fix_position_error_m") or {}, cam.get("fix_heading_error_deg") or {}
    return {
        "success": bool(f["arrived"]), "mission_s": f["mission_s"], "fe_mean": f["fe_mean"], "fe_sd": f["fe_sd"],
        "fe_close": f["fe_close"], "fe_far": f["fe_far"],
        "path_m": f["path_m"], "nn_min_m": f["nn_min_m"], "sim_s": s["sim_time_s"],
        "loc_err_mm": _mm(_stat(pos, "mean")), "loc_err_p95_mm": _mm(_stat(pos, "p95")),
        "loc_head_deg": _stat(head, "mean"), "fix_err_mm": _mm(_stat(fpos, "mean")),
        "fix_head_deg": _stat(fhead, "mean"), "frames_without_pose": cam.get("frames_without_pose"),
        "sonar_err_mm": round(sum(err) / len(err), 2) if err else None,
        "sonar_rms_mm": round(sum(rms) / len(rms), 2) if rms else None,
        "sonar_valid": round(sum(valid) / len(valid), 4) if valid else None,
        "sonar_hz": s["per_robot"][0]["firmware"]["arduino"].get("ping_hz_per_sensor"),
        "wifi_lost": wifi.get("lost", 0), "wifi_sent": wifi.get("sent", 0),
        "alive": sum(1 for r in s["per_robot"] if r.get("alive")), "rtf": s.get("rtf"),
        "cpu_s": round(float(s.get("cpu_s_total") or 0.0), 2),
        **phase_metrics(f.get("phases") or []),
    }


def phase_metrics(phases: list[dict[str, Any]]) -> dict[str, Any]:
    """Each route phase's FE and duration as trials.csv columns ``ph<k>_fe``, ``ph<k>_s`` (k from 1)."""
    out: dict[str, Any] = {}
    for k, p in enumerate(phases, 1):
        out[f"ph{k}_fe"] = p["fe_mean"]
        out[f"ph{k}_s"] = p["duration_s"]
    return out


def _mm(v: float | None) -> float | None:
    return None if v is None else round(1000 * v, 3)
