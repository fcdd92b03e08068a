"""roy-regions' co-simulated cells (``regions_cosim``): the sessions they build (robots, seeded start poses, sensing
profiles), the figures read from a recording's decisions, and the D1, D3-D5 judges on synthetic outcomes both ways.
(A whole session of each kind runs in tests/services: the region controller's sessions.)"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from bridge.core.config import Config, to_toml
from bridge.experiments.runner import Outcome, Trial, TrialResult
from bridge.studies.roy import regions_cosim as rc
from bridge.studies.roy.calibrate_d1 import main as calibrate_d1
from bridge.studies.roy.calibrate_d1 import overrides_text, planner_override, profile, provenance, score
from bridge.studies.roy.regions_experiments import RoyRegionsExperiment


def test_a_cells_session_is_its_file_with_n_robots_seeded_poses_and_its_sensing_profile(tmp_path: Path) -> None:
    cfg = rc.session_config("d3-ch4-6", 11, tmp_path, max_s=20.0)
    (group,) = cfg["robots"]
    assert group["count"] == 6 and len(group["placement"]["poses"]) == 6
    assert cfg["session"]["seed"] == 11 and cfg["session"]["duration_s"] == 20.0
    assert cfg["session"]["name"] == "sonpi-regions-ch4-d3-6-d3-ch4-6" and cfg["session"]["robots_per_process"] == 6
    file_poses = np.array([[0.25 + 0.3 * (i // 3), 0.6 + 0.275 * (i % 3), 0.0] for i in range(6)])
    d = np.abs(np.array(group["placement"]["poses"]) - file_poses)
    assert (d[:, :2] <= rc.JITTER_M).all() and (d[:, 2] <= rc.JITTER_DEG).all() and d.max() > 0
    assert rc.session_config("d3-ch4-6", 11, tmp_path) == {**cfg, "session": {**cfg["session"], "duration_s": 400}}
    assert rc.session_config("d3-ch4-6", 12, tmp_path)["robots"][0]["placement"] != group["placement"]
    four = rc.session_config("d4-ch6-4", 11, tmp_path)  # the two-lane file's first four robots, not jittered
    assert four["robots"][0]["count"] == 4 and "sonar_noise_m" not in four["robots"][0]  # the file's sensing
    assert four["robots"][0]["placement"]["poses"] == [
        [0.4, 0.55, 0.0],
        [0.4, 0.85, 0.0],
        [0.4, 1.15, 0.0],
        [0.75, 0.55, 0.0],
    ]
    Config.model_validate(tomllib_roundtrip(cfg))  # a valid session config
    noisy = rc.session_config("d3-ch4-3", 1, tmp_path)
    assert noisy["robots"][0]["sonar_noise_m"] == rc.noise_profiles()["d1"]["sonar"]["sonar_noise_m"]
    (cam,) = [s for s in noisy["services"] if s["kind"] == "overhead_camera"]
    assert cam["options"]["mode"] == "noise" and Path(cam["options"]["noise_model"]).parent == tmp_path
    ideal = rc.session_config("d1-ch4-6-noiseless", 1, tmp_path)
    assert ideal["robots"][0]["count"] == 6 and ideal["robots"][0]["sonar_noise_m"] == 0.0
    model = json.loads(Path(ideal["services"][0]["options"]["noise_model"]).read_text())["model"]
    assert model["x_std_m"] == 0.0 and ideal["services"][0]["options"]["position_gain"] == 1.0
    d5 = rc.session_config("d5-ch5-3", 1, tmp_path)["formation"]  # a file without one: ended 1 s after "done"
    assert d5 == {
        "target": [2.4, 2.4],
        "r_s_m": pytest.approx(0.15),
        "end_on_event": "controller/done",
        "end_after_event_s": 1.0,
    }
    assert four["formation"]["end_after_event_s"] == 0.5  # the file's own
    with pytest.raises(ValueError, match="scenario: no co-simulated scenario 'd9'; known: d3-ch4-3"):
        rc.session_config("d9", 1, tmp_path)


def tomllib_roundtrip(cfg: dict) -> dict:
    import tomllib

    return tomllib.loads(to_toml(cfg))


def test_the_calibration_profiles_scale_both_noises_and_score_by_log_ratio() -> None:
    p0, p2 = profile(0.0), profile(2.0)
    assert p0["sonar"]["sonar_noise_m"] == 0.0 and p0["camera"]["model"]["x_std_m"] == 0.0
    assert p2["sonar"]["sonar_noise_m"] == pytest.approx(0.02) and p2["camera"]["model"]["y_std_m"] == 0.02
    assert score({3: 0.097, 6: 0.02}) == pytest.approx(0.0)
    assert score({3: 0.0, 6: 0.02}) == score({3: 1e-16, 6: 0.02}) == math.inf and score({3: 0.05, 6: 0.02}) > score(
        {3: 0.09, 6: 0.02}
    )


def test_the_calibrations_planner_overrides_reach_the_session_and_bad_ones_are_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert planner_override("axes_lag=0.25") == ("axes_lag", 0.25)
    assert planner_override(" dynamics = literal") == ("dynamics", "literal")  # not TOML: a string
    assert planner_override("barrier=false") == ("barrier", False)
    over = dict([planner_override("axes_lag=0.5"), planner_override("dynamics=literal")])
    assert overrides_text(over) == "--planner axes_lag=0.5 --planner dynamics=literal"
    cfg = rc.session_config("d3-ch4-6", 1, tmp_path, 20.0, planner=over)
    (ctl,) = [s["options"]["params"] for s in cfg["services"] if s["kind"] == "global_controller"]
    file_params = rc.session_config("d3-ch4-6", 1, tmp_path, 20.0)["services"][1]["options"]["params"]
    assert ctl["planner_params"] == {**file_params["planner_params"], "axes_lag": 0.5, "dynamics": "literal"}
    Config.model_validate(tomllib_roundtrip(cfg))  # still a valid session config
    assert provenance([0.0, 1.0], 70.0, 1, over, 1.0, [(0.0, {3: 0.5, 6: None}), (1.0, {3: 0.1, 6: 0.02})]) == (
        "calibrate_d1 --scales 0 1 --duration 70 --seed 1 --planner axes_lag=0.5 --planner dynamics=literal: s = 1 "
        "(area COV with 3, 6 robots: s=0: 0.5000, -; s=1: 0.1000, 0.0200)"
    )
    with pytest.raises(ValueError, match=r"planner: 'axes_lgg' is not a parameter of planner 'ch4' \(regions_ch4_d3"):
        rc.session_config("d3-ch4-3", 1, tmp_path, planner={"axes_lgg": 0.5})
    with pytest.raises(
        ValueError,
        match=r"planner: regions_ch4_d3\.toml: dynamics = .wobbly.: params\.planner_params: dynamics: expected",
    ):
        rc.session_config("d3-ch4-3", 1, tmp_path, planner={"dynamics": "wobbly"})
    with pytest.raises(ValueError, match=r"axes_lag = 'x=1': params\.planner_params: must be real number"):
        rc.session_config("d3-ch4-3", 1, tmp_path, planner={"dynamics": "literal", "axes_lag": "x=1"})
    for bad in ("axes_lag", "=0.5", "axes_lag="):
        with pytest.raises(SystemExit):
            calibrate_d1(["--planner", bad])
        assert f"{bad!r}: write KEY=VALUE" in capsys.readouterr().err
    assert calibrate_d1(["--scales", "0", "--planner", "axes_lag=0.5", "--planner", "k_vcirr=1"]) == 2
    assert "calibrate_d1: --planner: 'k_vcirr' is not a parameter of planner 'ch4'" in capsys.readouterr().err


def _plan(t: float, *areas: float, a: float = 2.0, b: float = 1.0) -> dict:
    return {"t": t, "regions": [{"kind": "ellipse", "area": x, "a": a, "b": b} for x in areas]}


def test_the_figures_read_from_the_decisions_split_merge_circles_formations() -> None:
    plans = [{"t": 0.0, "regions": []}, _plan(0.25, 24.0, a=3.0, b=2.5), _plan(10.0, 12.0, 12.0), _plan(20.0, 24.0)]
    ser = rc.region_series(plans)
    assert ser["t"].tolist() == [0.25, 10.0, 20.0] and ser["area"].tolist() == [24.0, 24.0, 24.0]
    events = [
        {"kind": "split", "t": 5.0, "sizes": [3, 3], "parent_area": 24.0, "areas": [12.5, 11.5]},
        {"kind": "merge", "t": 15.0, "areas": [12.5, 11.5], "area": 24.0},
    ]
    sm = rc.split_merge_figures(events, ser)
    assert sm["split_sizes"] == "3+3" and sm["pre_split_cm2"] == 2400.0 and sm["split_sum_cm2"] == 2400.0
    assert sm["pre_split_a_cm"] == 30.0 and sm["pre_split_b_cm"] == 25.0 and sm["merge_s"] == 15.0
    ch5 = [
        {"kind": "region", "t": 0.5},
        {"kind": "barrier", "t": 4.0, "reason": "all in circles"},
        {"kind": "region", "t": 4.0},
        {"kind": "barrier", "t": 9.0, "reason": "timeout"},
        {"kind": "barrier", "t": 12.0, "reason": "all in circles"},
        {"kind": "region", "t": 12.25},
    ]
    c = rc.circle_figures(ch5)
    assert (c["circle_releases"], c["region_updates"]) == (2, 3)
    assert (c["circles_1_s"], c["circles_2_s"], c["boundary_s"]) == (4.0, 12.0, 12.25)
    form = [
        {"kind": "formation", "t": 1.0, "from": "triangle", "to": "row"},
        {"kind": "formation", "t": 8.0, "to": "column"},
    ]
    narrow = {"t": np.array([1.0, 9.0, 20.0]), "b": np.array([2.0, 0.5, 2.0])}
    f = rc.formation_figures(form, narrow)
    assert f["formation_at_narrowest"] == "column" and f["line_seen"] and f["formation_first"] == "triangle"
    assert f["formation_sequence"] == "triangle@0 > row@1 > column@8" and f["formation_changes"] == 2


def _out(scenario: str, i: int, smoke: bool = False, **metrics: object) -> Outcome:
    trial = Trial("roy-regions", {"kind": "cosim", "scenario": scenario}, i, i, smoke, "")
    return Outcome(trial, TrialResult(dict(metrics)), None)


def test_the_d_targets_pass_and_fail_on_synthetic_outcomes() -> None:
    targets = {t.id: t for t in RoyRegionsExperiment().targets()}
    for tid in ("D1", "D3", "D4", "D5"):
        assert targets[tid].evaluate([])[1] is None
        smoke = targets[tid].evaluate([_out("d3-ch4-3", 0, True), _out("d4-ch6-6", 0, True), _out("d5-ch5-3", 0, True)])
        assert smoke[1] is None and smoke[2].startswith("smoke run")

    def d1(c3: float, c6: float, i3: float = 0.02, i6: float = 0.001) -> list[Outcome]:
        cells = {"d3-ch4-3": c3, "d3-ch4-6": c6, "d1-ch4-3-noiseless": i3, "d1-ch4-6-noiseless": i6}
        return [_out(s, 0, area_cov=v) for s, v in cells.items()]

    assert targets["D1"].evaluate(d1(0.09, 0.025))[1] is True
    assert targets["D1"].evaluate(d1(0.03, 0.025))[1] is False  # 3 robots scatter far less than the hardware
    assert targets["D1"].evaluate(d1(0.09, 0.025, i6=0.03))[1] is False  # noiseless above noisy
    assert targets["D1"].evaluate(d1(0.09, 0.025)[:2])[1] is None  # the noiseless cells missing
    exact = targets["D1"].evaluate(d1(0.0, 0.0, 0.0, 0.0))
    assert exact[1] is False and "keeps pi a b" in exact[2]

    def d3(g3: float, g6: float, line: str = "line") -> list[Outcome]:
        return [
            _out("d3-ch4-3", 0, arrival_s=g3, formation_at_narrowest=line),
            _out("d3-ch4-6", 0, arrival_s=g6, formation_at_narrowest="column"),
        ]

    assert targets["D3"].evaluate(d3(50.0, 120.0))[1] is True  # 120 / 50 x 251 = 602 s against 615
    assert targets["D3"].evaluate(d3(50.0, 70.0))[1] is False
    assert targets["D3"].evaluate(d3(50.0, 120.0, line="triangle"))[1] is False

    def d4(merge: float, pre: float = 3000.0, g4: float = 80.0) -> list[Outcome]:
        six = dict(arrival_s=100.0, pre_split_cm2=pre, final_cm2=2407.0, merge_s=merge, split_sizes="3+3")
        return [_out("d4-ch6-6", 0, **six), _out("d4-ch6-5", 0, arrival_s=90.0), _out("d4-ch6-4", 0, arrival_s=g4)]

    assert targets["D4"].evaluate(d4(57.0))[1] is True  # 57 x 386.77 / 100 = 220 s
    assert "overlap time" in targets["D4"].evaluate(d4(80.0))[2]
    assert "pre-split area" in targets["D4"].evaluate(d4(57.0, pre=2407.0))[2]
    assert "rising with N" in targets["D4"].evaluate(d4(57.0, g4=95.0))[2]

    def d5(c1: float, c2: float, boundary: float, goal: float = 100.0) -> list[Outcome]:
        m = dict(arrival_s=goal, circles_1_s=c1, circles_2_s=c2, boundary_s=boundary, circle_releases=5)
        return [_out("d5-ch5-3", 0, **m)]

    assert targets["D5"].evaluate(d5(11.5, 27.0, 30.5))[1] is True  # x 3.67: 42, 99, 112 s
    assert targets["D5"].evaluate(d5(5.0, 27.0, 30.5))[1] is False
    assert targets["D5"].evaluate(d5(11.5, 31.0, 30.5))[1] is False  # the boundary before the release
    # a run that never arrived (the session ended first): judged, and failed, never an error
    stuck = _out("d5-ch5-3", 1, arrival_s=None, circles_1_s=2.0, circles_2_s=8.0, boundary_s=8.0)
    _, good, why = targets["D5"].evaluate([*d5(11.5, 27.0, 30.5), stuck])
    assert good is False and "arrived 1/2" in why and "order" in why


def test_a_bad_end_on_event_is_refused_naming_the_field(tmp_path: Path) -> None:
    from bridge.core.config import ConfigError, load_config

    text = (rc.SONPI_DIR / "regions_ch6.toml").read_text()
    assert 'end_on_event = "controller/done"' in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace('end_on_event = "controller/done"', 'end_on_event = "done"'))
    with pytest.raises((ConfigError, ValueError), match=r"formation.*end_on_event"):
        load_config(path).section("formation")
