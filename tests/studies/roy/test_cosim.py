"""Chapter 3 on SonPIs in co-simulation (target D2): the formation error of eq. 7.1 and the arrival test, the cases'
session configs in both profiles (the same deployment, the profiles' sensing), the experiment's co-simulated cells
and their judgement, and one short session scored by the study's loop functions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bridge.core.config import load_config, to_toml
from bridge.experiments.runner import Outcome, Trial, TrialResult, get_experiment, trial_seed
from bridge.studies.roy import cosim
from bridge.studies.roy.experiments import COSIM_CASES, RoyApfExperiment, cosim_sections
from bridge.studies.roy.loop_functions import arrived
from bridge.studies.roy.metrics import formation_error, pair_shares

R = 0.113


def test_the_formation_error_counts_pairs_between_2_and_3_r_s() -> None:
    """Eq. 7.1 repaired: an equilateral triangle of side 2.5 r_s is perfect (0), one of side 1.5 r_s worst (1); a
    line of three 2.5 r_s apart has its end pair at 5 r_s (FE 1/3)."""
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]])
    assert formation_error(tri * 2.5 * R, R) == 0.0
    assert formation_error(tri * 1.5 * R, R) == 1.0
    line = np.array([[0.0, 0.0], [2.5 * R, 0.0], [5.0 * R, 0.0]])
    assert formation_error(line, R) == pytest.approx(1 / 3)
    assert pair_shares(line, R) == pytest.approx((0.0, 1 / 3)) and pair_shares(tri * R, R) == (1.0, 0.0)
    assert formation_error(line[:1], R) == 0.0
    t = np.array([3.0, 1.0])
    assert arrived(t + np.array([[0.05, 0.0], [-0.05, 0.0]]), t, R, 0.1)
    assert not arrived(t + np.array([[0.5, 0.0], [-0.5, 0.0]]), t, R, 0.1)  # centred, but a robot too far out
    assert not arrived(np.zeros((0, 2)), t, R, 0.1)


def test_both_profiles_share_the_deployment_and_differ_in_sensing(tmp_path: Path) -> None:
    sim = cosim.session_config("ch7-moving-high", 4, "simulation", 7, tmp_path)
    hw = cosim.session_config("ch7-moving-high", 4, "hardware", 7, tmp_path)
    assert sim["robots"][0]["placement"] == hw["robots"][0]["placement"]
    poses = sim["robots"][0]["placement"]["poses"]
    assert len(poses) == 4 and all(np.hypot(a[0] - b[0], a[1] - b[1]) >= cosim.START_GAP_M
                                   for i, a in enumerate(poses) for b in poses[i + 1:])
    assert cosim.session_config("ch7-moving-high", 4, "simulation", 8, tmp_path)["robots"][0]["placement"] != \
        sim["robots"][0]["placement"]
    assert sim["robots"][0]["sonar_firing"] == "ideal" and hw["robots"][0]["sonar_firing"] == "sequential"
    assert sim["services"][0]["options"]["mode"] == "noise" and hw["services"][0]["options"]["mode"] == "tracking"
    assert sim["wifi"]["mode"] == "ideal" and hw["wifi"]["loss"] > 0
    assert sum(1 for o in sim["obstacles"] if "motion" in o) == 3 and sim["session"]["duration_s"] == 360.0
    for cfg in (sim, hw):  # every case loads as a session config (the cars' loops close)
        path = tmp_path / "c.toml"
        path.write_text(to_toml(cfg))
        load_config(path)
    for case, _ in COSIM_CASES:
        path.write_text(to_toml(cosim.session_config(case, 3, "hardware", 1, tmp_path, max_s=5.0)))
        assert load_config(path).session.duration_s == 5.0
    with pytest.raises(ValueError, match="case"):
        cosim.session_config("ch7-maze", 3, "hardware", 1, tmp_path)
    with pytest.raises(ValueError, match="profile"):
        cosim.session_config("ch7-open", 3, "real", 1, tmp_path)


def test_the_experiment_runs_each_case_in_both_profiles_one_session_per_task() -> None:
    exp = get_experiment("roy-apf")()
    cells = [c for c in exp.cells(smoke=False) if c["kind"] == "cosim"]
    assert {(c["scenario"], c["n"]) for c in cells} == set(COSIM_CASES)
    assert {c["profile"] for c in cells} == set(cosim.PROFILES) and len(cells) == 2 * len(COSIM_CASES)
    assert all(exp.cell_trials(c, 100) == 5 and exp.cell_batch(c) == 1 for c in cells)
    smoke = [c for c in exp.cells(smoke=True) if c["kind"] == "cosim"]
    assert len(smoke) == 2 and smoke[0]["scenario"] == "ch7-open"
    ignore = RoyApfExperiment.seed_ignores
    seeds = {trial_seed(0, "roy-apf", {k: v for k, v in c.items() if k not in ignore}, 0) for c in smoke}
    assert len(seeds) == 1  # the profiles' sessions are paired


def _cell(sc: str, n: int, p: str, i: int, **m: object) -> Outcome:
    cell = {"kind": "cosim", "scenario": sc, "n": n, "method": "bat", "profile": p}
    return Outcome(Trial("roy-apf", cell, i, i, False, ""), TrialResult(dict(m)), None)


def test_d2_is_judged_on_the_thesis_figures_and_a_reversed_one_fails() -> None:
    """The thesis' own figures pass D2; hardware formations better than simulation's fail D2-FE; the report's
    tables list every case and the sessions that did not arrive."""
    figs = {  # (simulation, hardware): time, FE, path (m)
        ("ch7-open", 3): ((35, 0.09, 5.05), (71, 0.21, 0.512)),
        ("ch7-static", 3): ((98, 0.13, 5.2), (249, 0.25, 0.53)),
        ("ch7-static", 4): ((100, 0.26, 5.4), (245, 0.32, 0.58)),
        ("ch7-moving-low", 4): ((150, 0.3, 5.0), (304, 0.37, 0.62)),
        ("ch7-moving-high", 4): ((280, 0.4, 6.0), (575, 0.47, 0.695)),
    }

    def outcomes(swap_fe: bool) -> list[Outcome]:
        out = []
        for (sc, n), prof in figs.items():
            for p, (t, fe, path) in zip(cosim.PROFILES, prof, strict=True):
                fe = (0.5 - fe if swap_fe else fe)
                out += [_cell(sc, n, p, i, success=True, mission_s=t, fe_mean=fe, fe_sd=0.1, path_m=path)
                        for i in range(3)]
        out.append(_cell("ch7-open", 3, "hardware", 3, success=False, sim_s=240.0, fe_mean=0.8, path_m=1.0,
                         nn_min_m=0.18, alive=3))
        return out

    targets = {t.id: t for t in RoyApfExperiment().targets()}
    for tid in ("D2-FE", "D2-time", "D2-dyn"):
        assert targets[tid].evaluate(outcomes(False))[1] is True, tid
    assert targets["D2-FE"].evaluate(outcomes(True))[1] is False
    assert targets["D2-FE"].evaluate([])[1] is None
    text = "\n".join(cosim_sections(outcomes(False)))
    assert text.count("| 7.") == 5 and "ch7-open N=3 hardware, trial 3" in text


@pytest.mark.long
@pytest.mark.session
def test_a_short_session_of_each_profile_is_scored(tmp_path: Path) -> None:
    """6 s of the moving-obstacle case in both profiles: the loop functions score the formation from the true
    poses, the simulation profile's poses are exact, the hardware profile's sonars fire sequentially."""
    rows = {}
    for p in cosim.PROFILES:
        wd = tmp_path / p
        wd.mkdir()
        s = cosim.run_session(cosim.session_config("ch7-moving-low", 4, p, 3, wd, max_s=6.0), wd)
        rows[p] = cosim.session_metrics(s)
        # (the centroid moves some 0.08 m a second in both profiles: 0.39-0.43 m by 6 s, 0.81-0.86 m by 10 s)
        assert s["formation"]["samples"] == 6 and s["formation"]["path_m"] > 0.3
    sim, hw = rows["simulation"], rows["hardware"]
    assert sim["loc_err_mm"] == 0.0 and sim["sonar_hz"] == pytest.approx(200, rel=0.01) and sim["wifi_lost"] == 0
    assert 0.0 < hw["loc_err_mm"] < 5.0 and hw["sonar_hz"] == pytest.approx(3.33, rel=0.01)
    assert hw["sonar_err_mm"] is not None and abs(hw["sonar_err_mm"]) < 10 and hw["alive"] == 4


def test_the_bench_s_camera_sessions_are_valid_configs(tmp_path: Path) -> None:
    """``bench --study roy``'s sessions: six SonPIs tracked, thirty in noise mode; a session without ``[formation]``
    is not the study's to score."""
    from bridge.studies.roy.bench import SWARM_N, camera_sessions
    from bridge.studies.roy.loop_functions import RoyLoopFunctions

    (m1, six), (m2, many) = camera_sessions(5.0)
    assert (m1, m2) == ("tracking", "noise") and many["robots"][0]["count"] == SWARM_N
    for raw in (six, many):
        path = tmp_path / "b.toml"
        path.write_text(to_toml(raw))
        cfg = load_config(path)
        assert cfg.session.duration_s == 5.0 and not RoyLoopFunctions.wanted(cfg)


def test_route_phases_split_the_mission_where_the_centroid_nears_the_target(tmp_path: Path) -> None:
    """Table 7.5's phases: each ends where the centroid first comes within its distance of T, the next starts there,
    every sample before arrival counts in exactly one, and a phase not reached has no times."""
    # 10 s: the first two phases end by 5 s (0.05 m and 0.25 m closer, at a region speed of some 0.05 m/s), the third
    # (0.2 m of T, over 2 m away) cannot, so the last is never reached
    cfg = cosim.session_config("ch7-open", 3, "simulation", 3, tmp_path, max_s=10.0)
    start = float(np.hypot(*(np.mean([p[:2] for p in cfg["robots"][0]["placement"]["poses"]], 0) - cosim.TARGET_M)))
    cfg["formation"]["phases"] = [{"name": "first", "until_dist_m": round(start - 0.05, 3)},
                                  {"name": "second", "until_dist_m": round(start - 0.25, 3)},
                                  {"name": "far", "until_dist_m": 0.2}, {"name": "last"}]
    s = cosim.run_session(cfg, tmp_path)
    f = s["formation"]
    first, second, far, last = f["phases"]
    assert first["start_s"] == 0.0 and 0 < first["end_s"] == second["start_s"] < second["end_s"] == far["start_s"]
    assert far["end_s"] is None and far["duration_s"] is None and last["start_s"] is None and last["samples"] == 0
    assert first["duration_s"] == first["end_s"] and second["duration_s"] == pytest.approx(
        second["end_s"] - second["start_s"])
    assert sum(p["samples"] for p in f["phases"]) == f["samples"] and not f["arrived"]
    overall = sum(p["fe_mean"] * p["samples"] for p in f["phases"] if p["samples"]) / f["samples"]
    assert overall == pytest.approx(f["fe_mean"], abs=1e-3)
    m = cosim.session_metrics(s)
    assert m["ph1_s"] == first["duration_s"] and m["ph4_fe"] is None and m["ph3_s"] is None


@pytest.mark.parametrize(("phases", "says"), [
    ([{"name": "a"}, {"name": "b", "until_dist_m": 1.0}], "only the last phase may leave out until_dist_m"),
    ([{"name": "a", "until_dist_m": 1.0}, {"name": "b", "until_dist_m": 1.5}], "must fall from phase to phase"),
    ([{"name": "a", "until_dist_m": -1.0}], "until_dist_m"),
])
def test_route_phases_out_of_order_are_refused_naming_the_field(tmp_path: Path, phases: list, says: str) -> None:
    from bridge.core.config import ConfigError

    cfg = cosim.session_config("ch7-open", 3, "simulation", 3, tmp_path)
    cfg["formation"]["phases"] = phases
    path = tmp_path / "p.toml"
    path.write_text(to_toml(cfg))
    with pytest.raises(ConfigError) as e:
        load_config(path)
    assert "formation" in str(e.value) and "phases" in str(e.value) and says in str(e.value)
