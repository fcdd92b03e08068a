"""The 802.15.4 radio medium: PHY curve, timing, CSMA-CA, ACKs and retries, collisions, propagation, determinism."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from pydantic import ValidationError

from bridge.media.radio import (
    SNR_AT_SENSITIVITY_DB,
    RadioCfg,
    RadioMedium,
    airtime_ns,
    ber_oqpsk,
    path_loss_db,
    per_oqpsk,
)
from bridge.tools.radio_fit import ObstacleGeometry

US = 1_000
MS = 1_000_000
A64 = 0x0013A200_40000000

# a quiet, deterministic channel: no shadowing, no fading
CALM = {"shadowing_sigma_db": 0.0, "fading": "none"}


def node(r: int, **kw: object) -> dict:
    return {"channel": 12, "pan_id": 0x3332, "addr64": A64 + r, "addr16": r + 1, "tx_power_dbm": 3.0,
            "sensitivity_dbm": -94.0, "series": 2, **kw}


def frame(handle: int, src: int, dst: int | None = None, psdu_len: int = 30, **kw: object) -> dict:
    return {"handle": handle, "src64": A64 + src, "src16": src + 1, "dst": "bcast" if dst is None else "64",
            "dst_addr": 0xFFFF if dst is None else A64 + dst, "pan_id": 0x3332, "channel": 12,
            "ack": dst is not None, "mac_retries": 3, "psdu_len": psdu_len, "seq": handle & 0xFF,
            "payload": b"hello", "opts": 0, **kw}


class CountingGeometry(ObstacleGeometry):
    def __init__(self, positions: list[tuple[float, float]], obstacles: list[dict] | None = None) -> None:
        super().__init__(obstacles or [], len(positions))
        self.pos[:] = positions
        self.calls = 0

    def positions(self) -> np.ndarray:
        self.calls += 1
        return self.pos


def medium(positions: list[tuple[float, float]], seed: int = 1, obstacles: list[dict] | None = None,
           **cfg: object) -> tuple[RadioMedium, CountingGeometry]:
    g = CountingGeometry(positions, obstacles)
    m = RadioMedium(RadioCfg(**cfg), len(positions), seed, g)
    for r in range(len(positions)):
        m.set_node(r, node(r))
    return m, g


def run(m: RadioMedium, until_ns: int, step_ns: int = 10 * MS, start_ns: int = 0) -> list[tuple[int, int, dict]]:
    out = []
    for h in range(start_ns + step_ns, until_ns + 1, step_ns):
        out += m.advance(h)
    return out


# ------------------------------------------------------------------------------------------------ PHY


def test_ber_curve_matches_the_standards_formula() -> None:
    assert float(ber_oqpsk(1e-6)) == pytest.approx(0.5, abs=1e-3)  # no signal: coin toss
    s = 10 ** (np.linspace(-10, 10, 81) / 10)
    b = ber_oqpsk(s)
    assert np.all(np.diff(b) <= 1e-15)
    assert float(ber_oqpsk(1.0)) == pytest.approx(1.6153e-4, rel=1e-3)  # 0 dB, the Annex E curve
    assert float(per_oqpsk(10 ** (SNR_AT_SENSITIVITY_DB / 10), 26)) == pytest.approx(0.01, rel=1e-3)
    assert 0.0 < SNR_AT_SENSITIVITY_DB < 1.5


def test_airtime_and_path_loss() -> None:
    cfg = RadioCfg()
    assert airtime_ns(cfg, 20) == 26 * 32 * US
    assert airtime_ns(cfg, cfg.ack_psdu_len) == 352 * US
    assert float(path_loss_db(cfg, np.array([1.0]))[0]) == pytest.approx(cfg.path_loss_d0_db)
    pl10 = float(path_loss_db(cfg, np.array([10.0]))[0])
    assert pl10 == pytest.approx(cfg.path_loss_d0_db + 10 * cfg.path_loss_exponent)
    dual = RadioCfg(breakpoint_m=5.0, path_loss_exponent_far=4.0)
    pl = path_loss_db(dual, np.array([5.0, 50.0]))
    assert pl[1] - pl[0] == pytest.approx(40.0)


def test_config_is_strict_and_says_why() -> None:
    with pytest.raises(ValidationError, match="extra"):
        RadioCfg(bogus=1)
    with pytest.raises(ValidationError, match="min_be = 5 is larger than max_be = 4"):
        RadioCfg(min_be=5, max_be=4)
    with pytest.raises(ValidationError, match="needs breakpoint_m"):
        RadioCfg(path_loss_exponent_far=3.0)
    for name, f in RadioCfg.model_fields.items():
        assert f.description, f"{name} has no description"


# --------------------------------------------------------------------------------------- timing and MAC


def test_broadcast_timing_is_backoff_cca_turnaround_airtime() -> None:
    m, _ = medium([(0, 0), (2, 0), (0, 2)], **CALM)
    f = frame(7, 0, psdu_len=30)
    t0 = 5 * MS
    m.submit(0, t0, f)
    ev = run(m, 50 * MS)
    rx = [(t, r, e) for t, r, e in ev if e["ev"] == "rx"]
    done = [(t, r, e) for t, r, e in ev if e["ev"] == "done"]
    assert sorted(r for _, r, _ in rx) == [1, 2]
    assert all(e["frame"] is f and e["rssi_dbm"] >= -94 and isinstance(e["rssi_dbm"], int) for _, _, e in rx)
    (td, rd, d), = done
    assert rd == 0 and d == {"ev": "done", "t_ns": td, "handle": 7, "status": "ok", "attempts": 1}
    allowed = {t0 + k * 320 * US + 128 * US + 192 * US + 36 * 32 * US for k in range(8)}
    assert {t for t, _, _ in rx} == {td} and td in allowed
    assert all(e["t_ns"] == t for t, _, e in ev)


def test_unicast_is_acknowledged_after_turnaround_and_ack_airtime() -> None:
    m, _ = medium([(0, 0), (3, 0)], **CALM)
    m.submit(0, 0, frame(1, 0, dst=1))
    ev = run(m, 30 * MS)
    (t_rx, r_rx, e_rx), (t_done, r_done, e_done) = ev
    assert (r_rx, e_rx["ev"], r_done, e_done["ev"]) == (1, "rx", 0, "done")
    assert e_done["status"] == "ok" and e_done["attempts"] == 1
    assert t_done - t_rx == 192 * US + 352 * US
    s = m.stats()
    assert s["robots"][0]["tx"]["ok"] == 1 and s["robots"][1]["tx"]["acks_sent"] == 1
    assert s["robots"][1]["rx"]["delivered"] == 1 and s["robots"][1]["rx"]["intended"] == 1


def test_unreachable_unicast_exhausts_mac_retries() -> None:
    m, _ = medium([(0, 0), (200, 0)], **CALM)
    m.submit(0, 0, frame(3, 0, dst=1))
    ev = run(m, 100 * MS)
    assert [e["ev"] for _, _, e in ev] == ["done"]
    _, r, e = ev[0]
    assert r == 0 and e["status"] == "no_ack" and e["attempts"] == 4
    s = m.stats()["robots"]
    assert s[0]["tx"]["retries_exhausted"] == 1 and s[0]["tx"]["attempts"] == 4
    assert s[1]["rx"]["below_sensitivity"] == 4 and s[1]["rx"]["delivered"] == 0


def test_busy_channel_gives_cca_failure_without_transmitting() -> None:
    m, _ = medium([(0, 0), (1, 0)], cca_threshold_dbm=-110.0, **CALM)  # the noise floor alone is "busy"
    m.submit(0, 0, frame(4, 0, dst=1))
    ev = run(m, 100 * MS)
    assert [(r, e["status"], e["attempts"]) for _, r, e in ev] == [(0, "cca_fail", 0)]
    assert m.stats()["robots"][0]["tx"]["cca_fail"] == 1


def test_frames_from_one_module_are_sent_in_order_with_ifs() -> None:
    m, _ = medium([(0, 0), (2, 0)], **CALM)
    for h in range(5):
        m.submit(0, 0, frame(h, 0, psdu_len=60))
    ev = run(m, 100 * MS)
    rx_t = [t for t, r, e in ev if e["ev"] == "rx"]
    assert [e["handle"] for _, _, e in ev if e["ev"] == "done"] == list(range(5))
    gaps = np.diff(rx_t)
    assert np.all(gaps >= 640 * US + 320 * US + 66 * 32 * US)  # LIFS + CCA/turnaround + the next frame


def test_csma_keeps_neighbours_from_colliding() -> None:
    delivered = 0
    rounds = 40
    m, _ = medium([(0, 0), (1, 0), (0.5, 1)], **CALM)
    for k in range(rounds):
        t = k * 20 * MS
        m.submit(0, t, frame(2 * k, 0, psdu_len=80))
        m.submit(1, t, frame(2 * k + 1, 1, psdu_len=80))
        delivered += sum(1 for _, r, e in m.advance(t + 20 * MS) if e["ev"] == "rx" and r == 2)
    assert delivered >= 0.8 * 2 * rounds  # only equal backoff slots (~1/8 of rounds) collide


def test_hidden_terminal_collides_and_strong_frame_can_capture() -> None:
    # n = 4: A at 0 and C at 7 m cannot hear each other at all (-97 dBm, so neither energy nor carrier sense
    # helps); B at 5 m hears A at -91 dBm and C 16 dB stronger.
    m, _ = medium([(0, 0), (5, 0), (7, 0)], path_loss_exponent=4.0, **CALM)
    from_a = from_c = 0
    for k in range(40):
        t = k * 20 * MS
        m.submit(0, t, frame(2 * k, 0, psdu_len=100))
        m.submit(2, t, frame(2 * k + 1, 2, psdu_len=100))
        for _, r, e in m.advance(t + 20 * MS):
            if e["ev"] == "rx" and r == 1:
                from_a += e["frame"]["src16"] == 1
                from_c += e["frame"]["src16"] == 3
    assert from_a == 0  # 16 dB under its interferer: always lost
    assert 0 < from_c < 40  # captured when B locked onto C first, lost when it was busy with A
    assert m.stats()["robots"][1]["rx"]["collision"] >= 40


def test_nothing_is_decoded_below_sensitivity_and_nodes_off_hear_nothing() -> None:
    rng = np.random.default_rng(3)
    pos = [tuple(p) for p in rng.uniform(0, 25, (12, 2))]
    m, _ = medium(pos, seed=5)
    m.set_node(11, None)
    sens = {r: -94.0 for r in range(12)}
    m.set_node(10, node(10, sensitivity_dbm=-92.0))
    sens[10] = -92.0
    for k in range(60):
        m.submit(k % 10, k * 10 * MS, frame(k, k % 10))
    m.submit(11, 0, frame(999, 11))  # radio off: ignored
    ev = run(m, 700 * MS)
    rx = [(r, e) for _, r, e in ev if e["ev"] == "rx"]
    assert rx and all(e["rssi_dbm"] >= sens[r] for r, e in rx)
    assert all(r != 11 for r, _ in rx) and all(e["handle"] != 999 for _, _, e in ev if e["ev"] == "done")
    assert len([1 for _, _, e in ev if e["ev"] == "done"]) == 60


# ------------------------------------------------------------------------------------------- propagation


def test_mean_rssi_is_reciprocal_and_counts_walls() -> None:
    pillar = [{"type": "cylinder", "x": 5.0, "y": 0.0, "radius": 0.3}]
    m, _ = medium([(0, 0), (10, 0), (5, 5)], obstacles=pillar, shadowing_sigma_db=0.0)
    mr = m.mean_rssi()
    assert np.isnan(np.diag(mr)).all()
    np.testing.assert_allclose(mr, mr.T)
    cfg = m.cfg
    assert mr[0, 1] == pytest.approx(3.0 - float(path_loss_db(cfg, np.array([10.0]))[0]) - cfg.wall_loss_db)
    m2, _ = medium([(0, 0), (10, 0), (5, 5)], seed=9)
    mr2 = m2.mean_rssi()
    np.testing.assert_allclose(mr2, mr2.T)  # shadowing is reciprocal too


def test_shadowing_has_configured_spread_and_spatial_correlation() -> None:
    n = 80
    rng = np.random.default_rng(0)
    g = CountingGeometry([tuple(p) for p in rng.uniform(0, 50, (n, 2))])
    m = RadioMedium(RadioCfg(), n, 11, g)
    iu = np.triu_indices(n, 1)

    def shadow() -> np.ndarray:
        d = np.hypot(*(g.pos[:, None, :] - g.pos[None, :, :]).transpose(2, 0, 1))
        return (m.mean_rssi() - (3.0 - path_loss_db(m.cfg, d)))[iu]

    s0 = shadow()
    assert np.std(s0) == pytest.approx(m.cfg.shadowing_sigma_db, rel=0.15)
    g.pos += rng.normal(0, 1, (n, 2)) * 0.1 / np.sqrt(2)  # ~0.1 m steps
    near = np.corrcoef(s0, shadow())[0, 1]
    g.pos += rng.uniform(-20, 20, (n, 2))
    far = np.corrcoef(s0, shadow())[0, 1]
    assert near > 0.8 and abs(far) < 0.3


def test_fading_is_correlated_in_time_and_decorrelated_by_motion() -> None:
    m, g = medium([(0, 0), (6, 0)], seed=2, shadowing_sigma_db=0.0, fading="rayleigh")

    def reading(k: int) -> float:
        t = k * 5 * MS
        m.submit(0, t, frame(k, 0))
        rs = [e["rssi_dbm"] for _, r, e in m.advance(t + 5 * MS) if e["ev"] == "rx"]
        return float(rs[0]) if rs else np.nan

    static = np.array([reading(k) for k in range(200)])  # 5 ms apart, coherence 200 ms
    moving = []
    for k in range(200, 400):
        g.pos[1, 1] = 0.25 * (k % 2)  # 2 wavelengths between frames, same distance within 5 mm
        moving.append(reading(k))
    d_static = np.nanmedian(np.abs(np.diff(static)))
    d_moving = np.nanmedian(np.abs(np.diff(np.array(moving))))
    assert d_static <= 1.0 and d_moving >= 3.0


def test_determinism_and_mean_rssi_draws_nothing() -> None:
    def session(seed: int, peek: bool) -> list:
        rng = np.random.default_rng(1)
        pos = [tuple(p) for p in rng.uniform(0, 15, (8, 2))]
        m, g = medium(pos, seed=seed)
        out = []
        for k in range(100):
            t = k * 10 * MS
            if k % 3 == 0:
                m.submit(k % 8, t, frame(k, k % 8, dst=(k + 1) % 8))
            if k % 4 == 0:
                m.submit((k + 3) % 8, t, frame(1000 + k, (k + 3) % 8))
            if peek:
                m.mean_rssi()
            g.pos += 0.01
            out += m.advance(t + 10 * MS)
        return [(t, r, msgpack.packb(e)) for t, r, e in out] + [msgpack.packb(m.stats())]

    a = session(1, False)
    assert a == session(1, False)
    assert a == session(1, True)
    assert a != session(2, False)


def test_idle_quanta_query_no_geometry() -> None:
    # (what quanta cost is measured by the benchmarks, not asserted here: a test must not depend on the machine)
    m, g = medium([(float(i), 0.0) for i in range(50)])
    for k in range(1, 20001):
        assert m.advance(k * 10 * MS) == []
    assert g.calls == 0 and m.next_event_ns() is None


def test_busy_swarm_takes_every_frame() -> None:
    rng = np.random.default_rng(4)
    n = 30
    m, _ = medium([tuple(p) for p in rng.uniform(0, 20, (n, 2))], seed=3)
    k_frames = 0
    for q in range(500):  # 5 s: every robot sends 2 frames/s (unicast to its neighbour in index)
        t = q * 10 * MS
        for r in range(n):
            if (q + r * 7) % 50 == 0:
                m.submit(r, t, frame(q * n + r, r, dst=(r + 1) % n))
                k_frames += 1
        m.advance(t + 10 * MS)
    tx = m.stats()["totals"]["tx"]
    assert tx["frames"] == k_frames and tx["attempts"] >= k_frames


def test_stats_layout_is_msgpack_friendly() -> None:
    m, _ = medium([(0, 0), (2, 0)])
    m.submit(0, 0, frame(1, 0, dst=1))
    run(m, 30 * MS)
    s = m.stats()
    msgpack.packb(s)
    assert set(s) == {"robots", "totals", "rssi_hist_lo_dbm", "rssi_hist_bin_db"}
    r = s["robots"][1]
    assert set(r["rx"]) == {"decoded", "intended", "delivered", "below_sensitivity", "collision", "corrupt"}
    assert set(r["tx"]) == {"frames", "attempts", "ok", "cca_fail", "retries_exhausted", "acks_sent"}
    assert sum(r["rssi_hist"]) == r["rx"]["decoded"] >= 1
    assert s["totals"]["rx"]["decoded"] == sum(x["rx"]["decoded"] for x in s["robots"])


def test_bad_frames_are_refused() -> None:
    m, _ = medium([(0, 0), (2, 0)])
    with pytest.raises(ValueError, match="lacks handle"):
        m.submit(0, 0, {"dst": "bcast", "psdu_len": 10, "channel": 12})
    with pytest.raises(ValueError, match="psdu_len 200 outside"):
        m.submit(0, 0, frame(1, 0, psdu_len=200))
    with pytest.raises(ValueError, match="dst 'x'"):
        m.submit(0, 0, frame(1, 0, dst=None) | {"dst": "x"})
