"""``swarm-sitl bench``'s physical limits beside each case: the bare barrier over as many processes and the bare
physics of the same world, as the real-time factors they allow, and the table that sets them beside the RTF."""

from __future__ import annotations

import math

import pytest

from bridge.tools import bench


def test_the_bare_physics_of_a_sessions_world_is_stepped_alone() -> None:
    rtf = bench.physics_limit(str(bench.DEMO), {"robots.count": 3}, quanta=50)
    assert math.isfinite(rtf) and rtf > 0
    assert bench.quantum_s(str(bench.DEMO), {}) == pytest.approx(0.01)


def test_the_bare_barrier_over_n_processes_as_a_real_time_factor() -> None:
    rtf = bench.barrier_limit(2, 0.01, quanta=50)
    assert math.isfinite(rtf) and rtf > 0


def test_the_table_sets_the_limits_and_the_share_beside_the_rtf(capsys: pytest.CaptureFixture[str]) -> None:
    s = {"processes": 21, "rtf": 2.5, "barrier_us_median": 2400.0, "barrier_us_p99": 6000.0,
         "cpu_s_per_robot_per_sim_s": 0.1, "rss_mb_per_robot": 250.0, "startup_s": 9.0}
    rows = [(bench.Case("radio demo", 10, 1, goal=5.0), s, (5.0, 40.0)),
            (bench.Case("radio demo", 10, 5), {**s, "rtf": None}, (None, None))]
    bench._print_table(rows, 30.0, markdown=True)
    out = capsys.readouterr().out
    assert "| goal | bare barrier | bare physics | of the limit |" in out
    assert "| radio demo | 10 | 1 | 21 | 2.50x | >= 5x | 5.0x | 40.0x | 50 % |" in out  # 2.5 of the barrier's 5
    assert "| radio demo | 10 | 5 | 21 | - |  | - | - | - |" in out


def test_the_scale_cases_are_the_goals_configs() -> None:
    """Each scale case names a config that exists and loads with the case's robot count and packing."""
    for case in bench.SCALE:
        assert case.config.exists() and case.goal
        bench.quantum_s(str(case.config), {"session.robots_per_process": case.per_process})


def test_the_barrier_at_ten_robots_is_set_beside_the_bare_round_trip(capsys: pytest.CaptureFixture[str]) -> None:
    s = {"barrier_us_median": 2400.0}
    bench._print_round_trip([(bench.Case("radio demo", 10, 1), s, (None, None)),
                             (bench.Case("radio demo", 25, 5), s, (None, None))])
    out = capsys.readouterr().out
    assert "bare zenoh round trip (world and one participant process): median" in out
    assert "radio demo, 10 robots, 1 per process: barrier median 2400 us = " in out and "25 robots" not in out
