"""Target D1's noise calibration (digest 001 §6): the sonar noise of the SonPI profile and the overhead camera's pose
noise that make the chapter 4 region's area scatter as the thesis' hardware did (COV 0.097 with 3 robots, 0.02 with
6; its simulation: 0.022 and 0.001).

The sweep scales one noise level ``s`` (``profile``): each HC-SR04 ping's 1-sigma error ``SONAR_M`` x s, the
camera's fixes (noise mode, 10 fps, the comparator's default gains) off by ``POSE_M`` x s in x and y and
``YAW_RAD`` x s in heading. At each s it runs the D3 sessions (``regions_cosim``: ``d3-ch4-3``, ``d3-ch4-6``) for
``--duration`` simulated seconds, measures the COV of the region's area over the planner's periods, and picks the s
whose COVs lie nearest the thesis' (the smallest sum of squared log ratios over the two N). With ``--write`` the
chosen profile becomes ``d1`` in ``hil_configs/sonpi/noise_profiles.toml``, with the sweep's figures as its
provenance; ``noiseless`` there (exact poses, no sonar noise) is the thesis' simulation's sensing. When no level
scatters the area at all (every COV 0: chapter 4's repaired region keeps pi a b = pi r_c^2 exactly, target A4, so
noise moves its axes but never its area), nothing is chosen, nothing is written, and the command exits 1.

``--planner KEY=VALUE`` (repeatable) overrides a parameter of the sessions' region planner for the sweep (VALUE a
TOML value, else a string: ``--planner axes_lag=0.25 --planner dynamics=literal``), to find the planner setting
under which noise scatters the area; the written profile's provenance records it (the D3 session files must then
carry the same setting for the cells to reproduce the calibration). Each row also says whether both sessions arrived
and how many failures the planner detected (a false detection shrinks the region and swamps the noise's scatter).

    python -m bridge.studies.roy.calibrate_d1 --scales 0 1 2 4 --duration 60 [--planner KEY=VALUE ...] [--write]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import tomllib
from pathlib import Path
from typing import Any

from bridge.core.config import to_toml
from bridge.experiments.sessions import run_config
from bridge.studies.roy.regions_cosim import (
    NO_SCATTER,
    NOISE_FILE,
    THESIS_COV,
    noise_profiles,
    session_config,
    session_metrics,
)

SONAR_M = 0.01  # per unit of s: the ping's 1-sigma range error (m)
POSE_M = 0.01  # ... the camera's fix error in x and y (m)
YAW_RAD = math.radians(2.0)  # ... and in heading
SCENARIOS = {3: "d3-ch4-3", 6: "d3-ch4-6"}
HEADER = """# Sensing profiles of the co-simulated roy-regions cells (bridge/studies/roy/regions_cosim.py): the
# SonPI groups' sonar options and the overhead camera's options. "ideal" is the thesis' simulation (every pose
# exact at 20 fps, the boards' ideal firing at 200 Hz without noise); "d1" is target D1's calibration (digest 001
# §6): the noise that makes the chapter 4 region's area scatter as the thesis' hardware did (COV 0.097 with 3
# robots, 0.02 with 6), written by
#   python -m bridge.studies.roy.calibrate_d1 --write
# with the sweep it measured as its provenance (docs/roy-regions.md). Change "d1" by running that again.
"""


def profile(s: float) -> dict[str, Any]:
    """The noise at level ``s``: sequential HC-SR04 firing with ``SONAR_M`` s of noise per ping, the camera in noise
    mode at 10 fps with fixes off by ``POSE_M`` s (x, y) and ``YAW_RAD`` s (heading)."""
    std = {"x_std_m": POSE_M * s, "y_std_m": POSE_M * s, "yaw_std_rad": round(YAW_RAD * s, 6)}
    zero = {"x_mean_m": 0.0, "y_mean_m": 0.0, "yaw_mean_rad": 0.0, "miss": 0.0}
    return {
        "source": f"calibrate_d1: noise level s = {s:g}",
        "sonar": {"sonar_firing": "sequential", "sonar_noise_m": round(SONAR_M * s, 6)},
        "camera": {"mode": "noise", "fps": 10, "model": {**zero, **std}},
    }


def planner_override(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` of ``--planner``: VALUE read as a TOML value (0.25, true, "x"), else kept as a string."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip() or not value.strip():
        raise argparse.ArgumentTypeError(f"{text!r}: write KEY=VALUE, e.g. axes_lag=0.25")
    try:
        parsed = tomllib.loads(f"v = {value.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        parsed = value.strip()
    return key.strip(), parsed


def overrides_text(planner: dict[str, Any]) -> str:
    """The overrides as command-line arguments (the provenance's words)."""
    return " ".join(f"--planner {k}={v if isinstance(v, str) else json.dumps(v)}" for k, v in planner.items())


def provenance(
    scales: list[float],
    duration: float,
    seed: int,
    planner: dict[str, Any],
    chosen: float,
    rows: list[tuple[float, dict[int, float | None]]],
) -> str:
    """The written profile's ``source``: the command (with its planner overrides), the level chosen and the sweep's
    COVs per level."""
    sweep = "; ".join(f"s={s:g}: {_g(c[3])}, {_g(c[6])}" for s, c in rows)
    cmd = f"calibrate_d1 --scales {' '.join(f'{s:g}' for s in scales)} --duration {duration:g} --seed {seed}"
    if planner:
        cmd += " " + overrides_text(planner)
    return f"{cmd}: s = {chosen:g} (area COV with 3, 6 robots: {sweep})"


def measure(
    n: int, prof: dict[str, Any], seed: int, duration: float, planner: dict[str, Any] | None = None
) -> dict[str, Any]:
    """One session of the D3 scenario with ``n`` robots in profile ``prof`` (``planner``: overrides of its planner's
    parameters): its region's area figures, whether it arrived and the failures its planner detected."""
    with tempfile.TemporaryDirectory(prefix="calibrate-d1-") as tmp:
        wd = Path(tmp)
        cfg = session_config(SCENARIOS[n], seed, wd, duration, profile=prof, planner=planner)
        s, out = run_config(cfg, wd, "d1")
        m, _ = session_metrics(s, out)
    got = {k: m.get(k) for k in ("area_mean", "area_sd", "area_cov", "sim_s", "arrival_s", "arrived")}
    detected = s["services"]["controller"].get("failures_detected") or []
    return got | {"failures": sum(int(d["n"]) for d in detected)}


def score(cov: dict[int, float | None]) -> float:
    """The sum over N of the squared log ratio of our COV to the thesis' (inf when one is missing or 0 to rounding:
    an area kept exactly reads 1e-16)."""
    if any(v is None or v < NO_SCATTER for v in cov.values()):
        return math.inf
    return sum(math.log(cov[n] / THESIS_COV[n]) ** 2 for n in cov)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bridge.studies.roy.calibrate_d1", description=__doc__.split("\n")[0])
    ap.add_argument("--scales", type=float, nargs="+", default=[0.0, 1.0, 2.0, 4.0], help="noise levels s to try")
    ap.add_argument("--duration", type=float, default=60.0, help="simulated seconds per session")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--planner",
        type=planner_override,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a parameter of the sessions' region planner (repeatable), e.g. axes_lag=0.25",
    )
    ap.add_argument("--write", action="store_true", help="write the chosen profile as d1 into " + NOISE_FILE.name)
    a = ap.parse_args(argv)
    if any(not (math.isfinite(s) and s >= 0) for s in a.scales) or not a.duration > 0:
        print("calibrate_d1: --scales must be finite and >= 0, --duration > 0", file=sys.stderr)
        return 2
    planner = dict(a.planner)
    try:  # a bad override is refused before any session runs
        with tempfile.TemporaryDirectory(prefix="calibrate-d1-") as tmp:
            for name in SCENARIOS.values():
                session_config(name, a.seed, Path(tmp), a.duration, profile=profile(0.0), planner=planner)
    except ValueError as e:
        print(f"calibrate_d1: --{e}", file=sys.stderr)
        return 2
    if planner:
        print(f"planner overrides: {overrides_text(planner)}")
    rows = []
    print(
        "| s | sonar sd (m) | pose sd (m) | COV N=3 | COV N=6 | arrived (3, 6) | failures (3, 6) "
        "| thesis 0.097 / 0.02: score |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for s in a.scales:
        prof = profile(s)
        got = {n: measure(n, prof, a.seed, a.duration, planner) for n in SCENARIOS}
        cov = {n: got[n]["area_cov"] for n in SCENARIOS}
        sc = score(cov)
        rows.append((sc, s, cov))
        arrived = ", ".join(_t(got[n]["arrival_s"]) for n in SCENARIOS)
        fails = ", ".join(str(got[n]["failures"]) for n in SCENARIOS)
        print(
            f"| {s:g} | {SONAR_M * s:.4f} | {POSE_M * s:.4f} | {_g(cov[3])} | {_g(cov[6])} | {arrived} | {fails} "
            f"| {sc:.3f} |",
            flush=True,
        )
    best = min(rows, key=lambda r: r[0])
    if not math.isfinite(best[0]):
        print("no level: at every s some session's region kept its area exactly (COV 0 or none); nothing chosen")
        return 1
    print(f"chosen: s = {best[1]:g} (COV {_g(best[2][3])} with 3 robots, {_g(best[2][6])} with 6)")
    if a.write:
        chosen = profile(best[1])
        chosen["source"] = provenance(a.scales, a.duration, a.seed, planner, best[1], [(s, c) for _, s, c in rows])
        profiles = noise_profiles()
        profiles["d1"] = chosen
        NOISE_FILE.write_text(HEADER + "\n" + to_toml(profiles))
        print(f"written: {NOISE_FILE.name} [d1]")
    return 0


def _g(x: float | None) -> str:
    return "-" if x is None else f"{x:.4f}"


def _t(x: float | None) -> str:
    return "no" if x is None else f"{x:.1f} s"


if __name__ == "__main__":
    sys.exit(main())
