"""The numerical runner at scale: a 1000-robot RDPSO cell (the wide hello), and the k-d tree neighbour search against
the dense distance matrix it replaces for large swarms."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bridge.core.config import ConfigError, load_config
from bridge.numerical import runner as numerical
from bridge.numerical.objectives import make_field, random_obstacles
from swarm_logic.families.rdpso.controller import Rdpso, colour, new_subgroup_id
from swarm_logic.families.rdpso.messages import Hello, decode, encode
from tests.conftest import ROOT


def test_a_1000_robot_rdpso_cell_runs_a_few_iterations_with_the_wide_hello() -> None:
    n, iterations = 1000, 3
    rng = np.random.default_rng(7)
    field = make_field("peaks", 300.0, seed=int(rng.integers(1 << 31)))
    obs = random_obstacles(300.0, rng=rng, keep_clear=[(*field.optimum(), 15.0)])
    params = {
        "alpha": 0.632,
        "rho1": 0.1,
        "rho2": 0.3,
        "rho3": 0.79,
        "rho4": 0.79,
        "d_max_m": 30.0,
        "dx_max_m": 0.5,
        "subgroups_min": 0,
        "subgroups_init": 5,
        "subgroups_max": 8,
        "sc_max": 30,
        "r_w_m": 5.0,
        "payload_max": 4096,
        "log_every": 1,
        "send_jitter_s": 0.0,
    }
    res = numerical.run(
        Rdpso, params, n, iterations, field, (300.0, 300.0), obs, numerical.LinkModel(range_m=30.0), seed=3
    )
    assert res.robot_iterations == n * iterations  # every robot logged every iteration
    assert res.subgroups[-1] == 5 and res.excluded[-1] == 0  # five initial subgroups of 200 (ids beyond 255)
    assert res.packets == n * iterations and res.deliveries > n * iterations
    assert np.all(np.isfinite(res.best)) and res.best[-1] <= 1.0 + 1e-9


def test_beyond_255_robots_needs_the_wide_hello_and_gossip() -> None:
    with pytest.raises(ValueError, match=r"n_total: must lie in \[1, 255\]"):
        Rdpso.resolve({"n_total": 300})  # what real robots and the co-simulation run
    with pytest.raises(ValueError, match=r"first_id: must lie in \[0, 255\]"):
        Rdpso.resolve({"first_id": 256})
    assert Rdpso.resolve({"n_total": 1000, "id_width": 2})["n_max"] == 2 * (1000 // 2)
    with pytest.raises(ValueError, match="id_width: 2 needs comm = gossip"):
        Rdpso.resolve({"n_total": 300, "id_width": 2, "comm": "regular"})
    with pytest.raises(ValueError, match="id_width"):
        Rdpso.resolve({"id_width": 3})


def test_a_session_config_beyond_255_robots_is_still_refused(tmp_path: Path) -> None:
    text = (ROOT / "hil_configs" / "rdpso" / "rdpso_arena.toml").read_text().replace("n_total = 12", "n_total = 300")
    cfg = tmp_path / "big.toml"
    cfg.write_text(text)
    with pytest.raises(ConfigError, match=r"big\.toml: .*n_total: must lie in \[1, 255\], got 300"):
        load_config(cfg)


def test_the_wide_hello_carries_16_bit_robot_ids_and_32_bit_subgroup_ids() -> None:
    sid = new_subgroup_id(999, 300)
    h = Hello(
        robot=999,
        sid=sid,
        k=70000,
        x=1.5,
        y=-2.0,
        hbest=0.5,
        ledger_h=0.75,
        ledger_x=3.0,
        ledger_y=4.0,
        sc=3,
        n_kill=1,
        flags=1,
        target=new_subgroup_id(998, 12),
        chosen=(300, 65535),
        members=((256, 9, 0, 0.25), (1000, 7, 2, -1.0)),
    )
    back = decode(encode(h, 4096, id_width=2))
    assert (back.robot, back.sid, back.k, back.target) == (999, sid, 70000 & 0xFFFF, h.target)
    assert back.chosen == (300, 65535)
    assert back.members == h.members
    assert colour(sid) in {colour(s) for s in range(1, 9)}  # a wide subgroup id has a palette colour too
    with pytest.raises(Exception):  # noqa: B017 - struct.error: the ZigBee hello has no room for such ids
        encode(h)


@pytest.mark.parametrize("mode", ["distance", "rssi"])
def test_the_kd_tree_neighbours_are_the_dense_matrix_ones(mode: str) -> None:
    rng = np.random.default_rng(11)
    pos = rng.uniform(0, 300, (1200, 2))
    pos[5] = pos[4] + (30.0, 0.0)  # exactly at the range
    senders = rng.permutation(1200)[:900]
    link = numerical.LinkModel(mode=mode, range_m=30.0, exponent=2.5)
    rows, cols, rssi = numerical._reach(pos, senders, link)
    d = np.hypot(pos[senders, None, 0] - pos[None, :, 0], pos[senders, None, 1] - pos[None, :, 1])
    if mode == "distance":
        want_rows, want_cols = np.nonzero(d <= 30.0)
        assert rssi is None
    else:
        full = link.rssi(d)
        want_rows, want_cols = np.nonzero(full >= link.sensitivity_dbm)
        assert np.array_equal(rssi, full[want_rows, want_cols])
    assert np.array_equal(rows, want_rows) and np.array_equal(cols, want_cols)
    assert len(rows) > len(senders)  # a crowd: most senders reach several robots
