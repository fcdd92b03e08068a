"""Config validation: good configs load; bad ones name the file, the field and the reason."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.config import ConfigError, load_config
from bridge.core.plan import make_plan
from bridge.tools.cli import main
from swarm_logic.behaviours import BEHAVIOURS
from swarm_logic.controller import MAX_SPEED_MPS, MAX_TURN_RATE_RPS, Range
from swarm_logic.robots.eswarbot import eswarbot_llc_db

MINIMAL = """
[session]
duration_s = 5
[[robots]]
count = 3
"""


def write(tmp_path: Path, text: str, name: str = "c.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_demo_config_is_valid(demo_config: Path) -> None:
    cfg = load_config(demo_config)
    assert cfg.robot_count == 10
    assert (cfg.arena.width_m, cfg.arena.length_m) == (10, 20)
    assert cfg.session.duration_s == 120
    plan = make_plan(cfg)
    assert len(plan.procs) == 20


def test_overrides_apply(demo_config: Path) -> None:
    cfg = load_config(demo_config, {"robots.count": 4, "session.seed": 99, "session.robots_per_process": 2})
    plan = make_plan(cfg)
    assert cfg.session.seed == 99
    assert len(plan.robots) == 4
    assert [p.robots for p in plan.procs if p.kind == "firmware"] == [(0, 1), (2, 3)]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (MINIMAL.replace("count = 3", "count = 0"), "robots[0].count: Input should be greater than or equal to 1"),
        (MINIMAL.replace("duration_s = 5", "duration_s = -1"), "session.duration_s: Input should be greater than 0"),
        (MINIMAL + "colour = 'red'\n", "robots[0].colour: Extra inputs are not permitted"),
        (MINIMAL.replace("[[robots]]", "[[robots]]\nprofile = 'rover'"),
         "robots[0].profile: unknown robot profile 'rover'"),
        (MINIMAL.replace("[session]", "[session]\nspeed = 'fast'"), "session.speed"),
        (MINIMAL + "[[obstacles]]\ntype = 'box'\nx = 50\ny = 1\nsize = [1, 1, 1]\n",
         "obstacles[0]: centre (50.0, 1.0)"),
        (MINIMAL + "[[obstacles]]\ntype = 'cone'\nx = 1\ny = 1\n", "obstacles[0]"),
        (MINIMAL.replace("[session]", "[session]\nquantum_ms = 1"), "shorter than one physics step"),
        (MINIMAL.replace("[session]", "[session]\nquantum_ms = 25"), "longer than the eswarbot LLC loop period"),
        ("[session\n", "not valid TOML"),
    ],
)
def test_errors_name_file_field_reason(tmp_path: Path, text: str, expected: str) -> None:
    p = write(tmp_path, text)
    with pytest.raises(ConfigError) as e:
        load_config(p)
    msg = str(e.value)
    assert msg.startswith(str(p)), msg
    assert expected in msg, msg


def test_missing_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no such file"):
        load_config(tmp_path / "nope.toml")


def test_explicit_poses_must_match_count_and_arena(tmp_path: Path) -> None:
    bad = MINIMAL + "[robots.placement]\nkind = 'explicit'\nposes = [[1, 1, 0]]\n"
    with pytest.raises(ConfigError, match=r"robots\[0\]\.placement\.poses: 1 poses for count = 3"):
        load_config(write(tmp_path, bad))
    outside = MINIMAL + "[robots.placement]\nkind = 'explicit'\nposes = [[1, 1, 0], [2, 1, 0], [11, 1, 0]]\n"
    with pytest.raises(ConfigError, match=r"robots\[0\]\.placement\.poses\[2\]: \(11.0, 1.0\) is outside"):
        load_config(write(tmp_path, outside))
    in_obstacle = (MINIMAL + "[robots.placement]\nkind = 'explicit'\nposes = [[1, 1, 0], [2, 1, 0], [5, 5, 0]]\n"
                   "[[obstacles]]\ntype = 'cylinder'\nx = 5\ny = 5\nradius = 0.3\n")
    with pytest.raises(ConfigError, match=r"robots\[0\]\.placement\.poses\[2\]: \(5.0, 5.0\) is inside"):
        make_plan(load_config(write(tmp_path, in_obstacle)), "c.toml")
    near_wall = MINIMAL + "[robots.placement]\nkind = 'explicit'\nposes = [[1, 1, 0], [2, 1, 0], [0.01, 5, 0]]\n"
    with pytest.raises(ConfigError, match=r"poses\[2\]"):
        make_plan(load_config(write(tmp_path, near_wall)), "c.toml")


@pytest.mark.parametrize(("extra", "expected"), [
    ("behaviour = 'dance'\n", "robots[0].behaviour: unknown behaviour 'dance'"),
    ("behaviour = 'nosuchmodule:Thing'\n", "robots[0].behaviour: No module named 'nosuchmodule'"),
    ("[robots.params]\nsped_mps = 0.2\n", "robots[0].params: unknown parameters ['sped_mps'] for random_walk"),
    ("[robots.params]\nspeed_mps = 'fast'\n", "robots[0].params.speed_mps: expected a number, got 'fast'"),
    ("[robots.params]\nspeed_mps = 50\n", "robots[0].params.speed_mps: must lie in [0, 2], got 50"),
    ("[robots.params]\nturn_rate_rps = 0.0\n", "robots[0].params.turn_rate_rps: must lie in (0, 20], got 0.0"),
    ("[robots.params]\nmean_run_s = -1\n", "robots[0].params.mean_run_s: must be > 0, got -1"),
    ("behaviour = 'rssi_keeper'\nxbee = { series = 2 }\n[robots.params]\nq_min_dbm = 20\n",
     "robots[0].params.q_min_dbm: must lie in [-128, 0], got 20"),
    ("behaviour = 'rssi_keeper'\nxbee = { series = 2 }\n[robots.params]\nk = 1.5\n",
     "robots[0].params.k: must be an integer, got 1.5"),
    ("behaviour = 'rdpso'\nxbee = { series = 2 }\n[robots.params]\nroute_ttl = 300\n",
     "robots[0].params.route_ttl: must lie in [1, 255], got 300"),
    ("[robots.placement]\nkind = 'grid'\nposes = [[1, 1, 0]]\n", "poses do(es) not apply to kind = 'grid'"),
    ("[robots.placement]\nkind = 'explicit'\nposes = [[1, 1, 0], [2, 1, 0], [3, 1, 0]]\nyaw_deg = 0\n",
     "yaw_deg do(es) not apply to kind = 'explicit'"),
])
def test_behaviour_and_placement_errors(tmp_path: Path, extra: str, expected: str) -> None:
    p = write(tmp_path, MINIMAL + extra)
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value).startswith(str(p)) and expected in str(e.value), str(e.value)


def test_map_must_be_an_image(tmp_path: Path) -> None:
    (tmp_path / "m.png").write_text("not an image")
    with pytest.raises(ConfigError, match=r"arena\.map: cannot read m\.png as an image"):
        load_config(write(tmp_path, MINIMAL + "[arena]\nmap = 'm.png'\n"))


def test_random_placement_avoids_map_obstacles(tmp_path: Path) -> None:
    import numpy as np
    from PIL import Image

    img = np.full((80, 80), 255, np.uint8)
    img[10:70, 10:70] = 0  # a 3 x 3 m block in a 4 x 4 m map, leaving a 0.5 m border free
    Image.fromarray(img).save(tmp_path / "m.png")
    text = (MINIMAL.replace("count = 3", "count = 6") + "[robots.placement]\nkind = 'random'\nmin_separation_m = 0.3\n"
            "[arena]\nwidth_m = 4\nlength_m = 4\nmap = 'm.png'\n")
    plan = make_plan(load_config(write(tmp_path, text)), "c.toml")
    for r in plan.robots:
        x, y, _ = r.pose
        assert not (0.5 - 0.08 < x < 3.5 + 0.08 and 0.5 - 0.08 < y < 3.5 + 0.08), r.pose


def test_random_placement_is_seeded_and_collision_free(demo_config: Path) -> None:
    a = make_plan(load_config(demo_config))
    b = make_plan(load_config(demo_config))
    c = make_plan(load_config(demo_config, {"session.seed": 8}))
    assert [r.pose for r in a.robots] == [r.pose for r in b.robots]
    assert [r.pose for r in a.robots] != [r.pose for r in c.robots]
    pts = [r.pose[:2] for r in a.robots]
    for i, p in enumerate(pts):
        for q in pts[i + 1:]:
            assert ((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2) ** 0.5 >= 0.6


def test_grid_into_obstacle_is_rejected(tmp_path: Path) -> None:
    text = MINIMAL + "[[obstacles]]\ntype = 'cylinder'\nx = 1.5\ny = 1\nradius = 0.3\n"
    with pytest.raises(ConfigError, match=r"robots\[0\]\.placement: grid position 1"):
        make_plan(load_config(write(tmp_path, text)), "c.toml")


def test_map_path_must_exist(tmp_path: Path) -> None:
    text = MINIMAL + "[arena]\nmap = 'missing.png'\n"
    with pytest.raises(ConfigError, match=r"arena\.map: no such file 'missing\.png'"):
        load_config(write(tmp_path, text))


def test_plan_config_round_trips(demo_config: Path) -> None:
    from bridge.core.config import Config

    cfg = load_config(demo_config)
    again = Config.model_validate(make_plan(cfg).config)  # what every process of a session does
    assert again == cfg


SPIRAL = """
[arena]
width_m = {w}
length_m = 2.45
[[robots]]
count = 12
behaviour = "random_walk"
[robots.placement]
kind = "spiral"
centres = [[0.9, 1.25], [1.55, 0.8]]
spacing_m = 0.25
"""


def test_spiral_placement_puts_each_block_on_a_spiral_of_theodorus(tmp_path: Path) -> None:
    import itertools
    import math

    for seed in range(5):
        cfg = load_config(write(tmp_path, SPIRAL.format(w=2.55)), {"session.seed": seed})
        poses = [r.pose for r in make_plan(cfg).robots]
        for block, centre in ((poses[:6], (0.9, 1.25)), (poses[6:], (1.55, 0.8))):
            steps = [math.dist(a[:2], b[:2]) for a, b in itertools.pairwise(block)]
            assert steps == pytest.approx([0.25] * 5)  # eq. 5.1-5.2: consecutive robots one leg apart
            radii = [math.dist(p[:2], centre) for p in block]
            assert radii == pytest.approx([0.25 * math.sqrt(n + 1) for n in range(1, 7)])


def test_a_spiral_that_cannot_fit_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"robots\[0\]\.placement: spiral 1 of 6 robots .* does not fit"):
        make_plan(load_config(write(tmp_path, SPIRAL.format(w=1.2))))


def test_unreadable_files_are_config_errors(tmp_path: Path) -> None:
    binary = tmp_path / "blob.toml"
    binary.write_bytes(bytes(range(256)) * 4)  # not UTF-8
    for p, expected in ((binary, "not a text file"), (tmp_path, "is a directory"),
                        (tmp_path / "nope.toml", "no such file")):
        with pytest.raises(ConfigError) as e:
            load_config(p)
        assert str(e.value).startswith(f"{p}: ") and expected in str(e.value), str(e.value)


@pytest.mark.parametrize("hal", ["eswarbot_real.toml", "eswarbot_rdpso_real.toml", "eswarbot_sitl_ports.toml",
                                 "decizebro_real.toml", "decizebro_sitl_ports.toml"])
def test_a_hal_config_is_named_as_one(hal: str) -> None:
    p = Path(__file__).resolve().parents[2] / "hil_configs" / "robots" / hal
    with pytest.raises(ConfigError) as e:
        load_config(p)
    msg = str(e.value)
    assert msg.startswith(f"{p}: a HAL config for a real robot"), msg
    assert f"python -m swarm_logic --hal {p}" in msg, msg
    assert "Extra inputs" not in msg, msg


@pytest.mark.parametrize("cmd", ["run", "validate", "devices"])
def test_cli_exits_2_naming_an_unusable_config(tmp_path: Path, cmd: str, capsys: pytest.CaptureFixture) -> None:
    from bridge.tools.cli import main

    binary = tmp_path / "blob.toml"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00" * 20)
    hal = Path(__file__).resolve().parents[2] / "hil_configs" / "robots" / "eswarbot_real.toml"
    for p, expected in ((binary, "not a text file"), (tmp_path, "is a directory"),
                        (tmp_path / "nope.toml", "no such file"), (hal, "a HAL config for a real robot")):
        with pytest.raises(SystemExit) as e:
            main([cmd, str(p), *(["--out", str(tmp_path / "out")] if cmd in ("run", "devices") else [])])
        err = capsys.readouterr().err
        assert e.value.code == 2, (p, err)
        assert err.startswith(f"config error: {p}: ") and expected in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("cmd", ["validate", "run"])
def test_a_parameter_out_of_its_range_is_a_config_error_with_exit_2(tmp_path: Path, cmd: str,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    p = write(tmp_path, MINIMAL + "[robots.params]\nspeed_mps = 50\n")
    with pytest.raises(SystemExit) as e:
        main([cmd, str(p), "--quiet", "--out", str(tmp_path / "out")] if cmd == "run" else [cmd, str(p)])
    assert e.value.code == 2
    assert f"config error: {p}: robots[0].params.speed_mps: must lie in [0, 2], got 50" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == [p]  # refused before anything ran


@pytest.mark.parametrize("name", BEHAVIOURS.names())
def test_every_numeric_parameter_of_a_behaviour_has_a_declared_range(name: str) -> None:
    cls = BEHAVIOURS.get(name)
    numeric = {k for k, v in cls.defaults.items() if isinstance(v, int | float) and not isinstance(v, bool)}
    assert set(cls.ranges) == numeric  # every tunable number, and nothing else
    for k, r in cls.ranges.items():
        assert isinstance(r, Range) and cls.defaults[k] in r and cls.param_error(k, cls.defaults[k]) is None


def test_speed_and_turn_rate_ranges_are_what_drive_cmd_carries() -> None:
    drive = eswarbot_llc_db().get_message_by_name("DRIVE_CMD")
    assert drive.get_signal_by_name("v_mm_s").maximum / 1000 == MAX_SPEED_MPS
    assert drive.get_signal_by_name("w_mrad_s").maximum / 1000 == MAX_TURN_RATE_RPS


def test_floor_patches_paint_the_arena_and_a_reversed_one_is_named(tmp_path) -> None:
    """``arena.floor``: grey patches ground sensors read (a later one covers an earlier); a patch with its corners
    swapped is refused naming the field."""
    import numpy as np

    p = tmp_path / "floor.toml"
    p.write_text('[arena]\nwidth_m = 5.0\nlength_m = 5.0\n'
                 '[[arena.floor]]\nx_min = 0.0\ny_min = 0.0\nx_max = 1.0\ny_max = 5.0\ngrey = 0.5\n'
                 '[[arena.floor]]\nx_min = 0.0\ny_min = 0.0\nx_max = 0.5\ny_max = 0.5\ngrey = 0.0\n'
                 '[[robots]]\ncount = 1\n')
    a = load_config(p).arena
    assert a.grey_at(np.array([0.2, 0.7, 3.0]), np.array([0.2, 0.2, 3.0])).tolist() == [0.0, 0.5, 1.0]
    p.write_text('[arena]\n[[arena.floor]]\nx_min = 2.0\ny_min = 0.0\nx_max = 1.0\ny_max = 5.0\ngrey = 0.5\n'
                 '[[robots]]\ncount = 1\n')
    with pytest.raises(ConfigError, match=r"arena\.floor\[0\]: a floor patch needs x_min < x_max"):
        load_config(p)


def test_overrides_reach_nested_values_and_name_a_wrong_path(demo_config: Path) -> None:
    DEMO = demo_config
    cfg = load_config(DEMO, {"robots.0.count": 3, "session.seed": 9, "services": []})
    assert cfg.robots[0].count == 3 and cfg.session.seed == 9 and cfg.services == []
    with pytest.raises(ConfigError, match=r"demo\.toml: override robots\.2\.count: robots has no entry '2'"):
        load_config(DEMO, {"robots.2.count": 3})
    with pytest.raises(ConfigError, match=r"override session\.seed\.x: session\.seed is a value, not a table"):
        load_config(DEMO, {"session.seed.x": 1})
