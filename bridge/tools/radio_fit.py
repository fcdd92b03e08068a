"""Fit and check the radio propagation model.

``fit_csv``: fit PL(d0), the path loss exponent n and the spread sigma of the log-distance model from an
RSSI-vs-distance CSV (columns ``distance_m`` and ``rssi_dbm``, empty when the packet was lost; an optional
``walls`` column also fits the loss per obstacle). Lost packets are censored observations below the
receiver's sensitivity (Tobit model, maximum likelihood):

    log L = sum_received log phi((y - mu) / s) - log s  +  sum_lost log Phi((sens - mu) / s)
    mu = P_tx - PL(d0) - 10 n log10(d / d0) - walls * L_wall

The fitted ``s`` is the total spread of one RSSI reading (shadowing and fast fading); ``to_cfg_fields``
splits it using the configured fading's own dB spread, and moves the fading's dB mean into PL(d0), so that
the medium reproduces the measured readings. Packets lost to collisions are also taken as "below
sensitivity": measure on a quiet channel.

``calibrate``: the calibration table of ``docs/radio.md``: Monte-Carlo of two robots in a synthetic copy
of a session's arena and obstacles (straight-line obstacle crossings, like the world's geometry), sending
unicast frames (with MAC retries) and broadcast frames (one attempt) at random placements, as in the
thesis' RSSI experiment (Couceiro 2013, §3.2.3: two robots wandering, 30 messages every 2 s).

Command line::

    python -m bridge.tools.radio_fit fit data.csv -o radio.toml [--tx-power 3] [--sensitivity -94]
    python -m bridge.tools.radio_fit calibrate [hil_configs/demo.toml] [--trials 4000]
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
from scipy import optimize, stats

from bridge.core.rng import stream
from bridge.media.radio import RadioCfg, RadioMedium, complex_normal, fading_gain_db, path_loss_db

# ------------------------------------------------------------------------------------------------ fit


def read_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(distance_m, rssi_dbm with NaN for lost packets, walls or None) from a CSV file."""
    d, y, w = [], [], []
    with open(path, newline="") as f:
        rd = csv.DictReader(f)
        cols = set(rd.fieldnames or [])
        if not {"distance_m", "rssi_dbm"} <= cols:
            raise ValueError(f"{path}: needs columns distance_m and rssi_dbm, has {sorted(cols)}")
        has_walls = "walls" in cols
        for i, row in enumerate(rd, start=2):
            try:
                d.append(float(row["distance_m"]))
                cell = (row["rssi_dbm"] or "").strip()
                y.append(float(cell) if cell else math.nan)
                if has_walls:
                    w.append(float(row["walls"] or 0))
            except ValueError as e:
                raise ValueError(f"{path}: line {i}: {e}") from None
    return np.array(d), np.array(y), (np.array(w) if has_walls else None)


def fit(distance_m: np.ndarray, rssi_dbm: np.ndarray, *, walls: np.ndarray | None = None,
        tx_power_dbm: float = 3.0, sensitivity_dbm: float = -94.0, d0_m: float = 1.0) -> dict[str, Any]:
    """Censored (Tobit) maximum-likelihood fit; ``rssi_dbm`` is NaN where the packet was lost.

    Returns path_loss_d0_db, path_loss_exponent, sigma_db (total spread), wall_loss_db (when walls are
    given), standard errors (``*_se``, from the inverse Hessian), counts and the log-likelihood."""
    d = np.maximum(np.asarray(distance_m, dtype=float), 1e-3)
    y = np.asarray(rssi_dbm, dtype=float)
    got = ~np.isnan(y)
    if got.sum() < 3:
        raise ValueError(f"need at least 3 received packets to fit, got {int(got.sum())}")
    x = 10.0 * np.log10(d / d0_m)
    w = np.zeros_like(d) if walls is None else np.asarray(walls, dtype=float)
    fit_walls = walls is not None and bool(np.any(w > 0))

    def unpack(p: np.ndarray) -> tuple[float, float, float, float]:
        return p[0], p[1], (p[3] if fit_walls else 0.0), math.exp(p[2])

    def nll(p: np.ndarray) -> tuple[float, np.ndarray]:
        """Negative log-likelihood and its gradient in (PL0, n, log s[, L_wall])."""
        pl0, n, lw, s = unpack(p)
        mu = tx_power_dbm - pl0 - n * x - lw * w
        z = (y[got] - mu[got]) / s
        c = (sensitivity_dbm - mu[~got]) / s
        logcdf = stats.norm.logcdf(c)
        ll = float(np.sum(-0.5 * z * z - math.log(s) - 0.5 * math.log(2 * math.pi)) + logcdf.sum())
        mills = np.exp(stats.norm.logpdf(c) - logcdf)  # phi / Phi
        dmu = np.zeros_like(mu)  # d ll / d mu
        dmu[got] = z / s
        dmu[~got] = -mills / s
        dlogs = float(np.sum(z * z - 1.0) + np.sum(-mills * c))
        grad = [-dmu.sum(), -(dmu * x).sum(), dlogs] + ([-(dmu * w).sum()] if fit_walls else [])
        return -ll, -np.array(grad)

    # start from least squares on what was received
    cols = [np.ones(got.sum()), x[got]] + ([w[got]] if fit_walls else [])
    a = np.stack(cols, axis=1)
    coef, *_ = np.linalg.lstsq(a, tx_power_dbm - y[got], rcond=None)
    resid = tx_power_dbm - y[got] - a @ coef
    p0 = [coef[0], coef[1], math.log(max(float(np.std(resid)), 0.5))] + ([coef[2]] if fit_walls else [])
    res = optimize.minimize(nll, np.array(p0), jac=True, method="BFGS", options={"gtol": 1e-6})
    pl0, n, lw, s = unpack(res.x)
    cov = np.asarray(res.hess_inv)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    out: dict[str, Any] = {
        "path_loss_d0_db": float(pl0), "path_loss_exponent": float(n), "sigma_db": float(s),
        "path_loss_d0_db_se": float(se[0]), "path_loss_exponent_se": float(se[1]),
        "sigma_db_se": float(s * se[2]),
        "d0_m": d0_m, "tx_power_dbm": tx_power_dbm, "sensitivity_dbm": sensitivity_dbm,
        "received": int(got.sum()), "lost": int((~got).sum()), "log_likelihood": -float(res.fun),
        "converged": bool(res.success),
    }
    if fit_walls:
        out["wall_loss_db"] = float(lw)
        out["wall_loss_db_se"] = float(se[3])
    return out


def fading_db_moments(cfg: RadioCfg) -> tuple[float, float]:
    """Mean and variance (dB, dB^2) of the configured fast fading's power gain in dB (numerical quadrature)."""
    if cfg.fading == "none":
        return 0.0, 0.0
    if cfg.fading == "rayleigh":
        dist = stats.expon()
    else:
        k = 10.0 ** (cfg.rician_k_db / 10.0)
        dist = stats.ncx2(df=2, nc=2.0 * k, scale=1.0 / (2.0 * (k + 1.0)))  # unit-mean power gain
    m1 = dist.expect(lambda g: 10.0 * np.log10(g))
    m2 = dist.expect(lambda g: (10.0 * np.log10(g)) ** 2)
    return float(m1), float(m2 - m1 * m1)


def to_cfg_fields(result: dict[str, Any], cfg: RadioCfg | None = None) -> dict[str, float]:
    """``[radio]`` fields from a fit: the fading's dB mean moves into PL(d0) and its variance out of sigma."""
    cfg = cfg or RadioCfg()
    mean_db, var_db = fading_db_moments(cfg)
    fields = {
        "d0_m": float(result["d0_m"]),
        "path_loss_d0_db": round(result["path_loss_d0_db"] + mean_db, 2),
        "path_loss_exponent": round(result["path_loss_exponent"], 3),
        "shadowing_sigma_db": round(math.sqrt(max(result["sigma_db"] ** 2 - var_db, 0.0)), 2),
    }
    if "wall_loss_db" in result:
        fields["wall_loss_db"] = round(max(result["wall_loss_db"], 0.0), 2)
    return fields


def toml_fragment(fields: dict[str, float], comment: str = "") -> str:
    """A ``[radio]`` TOML section with ``fields``."""
    lines = [f"# {line}" for line in comment.splitlines()] + ["[radio]"]
    lines += [f"{k} = {float(v)!r}" for k, v in fields.items()]
    return "\n".join(lines) + "\n"


def fit_csv(path: str | Path, out_toml: str | Path | None = None, *, cfg: RadioCfg | None = None,
            tx_power_dbm: float = 3.0, sensitivity_dbm: float = -94.0, d0_m: float = 1.0) -> dict[str, Any]:
    """Fit a CSV file; write the ``[radio]`` fragment to ``out_toml`` when given. Returns the fit with the
    config fields under ``"radio"``."""
    d, y, w = read_csv(path)
    result = fit(d, y, walls=w, tx_power_dbm=tx_power_dbm, sensitivity_dbm=sensitivity_dbm, d0_m=d0_m)
    result["radio"] = to_cfg_fields(result, cfg)
    if out_toml is not None:
        note = (f"fitted by bridge.tools.radio_fit from {Path(path).name}: {result['received']} received, "
                f"{result['lost']} lost (censored below {sensitivity_dbm} dBm), P_tx {tx_power_dbm} dBm;\n"
                f"total spread {result['sigma_db']:.2f} dB, of which the configured fading takes its share")
        Path(out_toml).write_text(toml_fragment(result["radio"], note))
    return result


# ------------------------------------------------------------------------------------ synthetic arena


class ObstacleGeometry:
    """Straight-line obstacle crossings among cylinders and (rotated) boxes, with settable robot positions:
    a stand-in for the world's pybullet geometry in tests and in ``calibrate``."""

    def __init__(self, obstacles: list[dict[str, Any]], n: int) -> None:
        self.cyl = [(o["x"], o["y"], o["radius"]) for o in obstacles if o["type"] == "cylinder"]
        self.box = [(o["x"], o["y"], o["size"][0] / 2, o["size"][1] / 2, math.radians(o.get("yaw_deg", 0.0)))
                    for o in obstacles if o["type"] == "box"]
        self.pos = np.zeros((n, 2))
        self.alive_mask = np.ones(n, dtype=bool)

    def positions(self) -> np.ndarray:
        return self.pos

    def alive(self) -> np.ndarray:
        return self.alive_mask

    def walls(self, src: int, dsts: np.ndarray) -> np.ndarray:
        dsts = np.asarray(dsts, dtype=np.int64)
        return self.crossings(np.broadcast_to(self.pos[src], (len(dsts), 2)), self.pos[dsts])

    def inside(self, p: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Which points lie within ``margin`` of an obstacle."""
        hit = np.zeros(len(p), dtype=bool)
        for cx, cy, r in self.cyl:
            hit |= np.hypot(p[:, 0] - cx, p[:, 1] - cy) <= r + margin
        for cx, cy, hx, hy, yaw in self.box:
            c, s = math.cos(yaw), math.sin(yaw)
            lx = (p[:, 0] - cx) * c + (p[:, 1] - cy) * s
            ly = -(p[:, 0] - cx) * s + (p[:, 1] - cy) * c
            hit |= (np.abs(lx) <= hx + margin) & (np.abs(ly) <= hy + margin)
        return hit

    def crossings(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Obstacles each segment a[k]-b[k] touches."""
        d = b - a
        count = np.zeros(len(a), dtype=np.int64)
        dd = np.maximum((d * d).sum(1), 1e-18)
        for cx, cy, r in self.cyl:  # distance from the centre to the segment
            f = np.array([cx, cy]) - a
            t = np.clip((f * d).sum(1) / dd, 0.0, 1.0)
            count += np.hypot(*(a + d * t[:, None] - [cx, cy]).T) <= r
        for cx, cy, hx, hy, yaw in self.box:  # slab clipping in the box frame
            c, s = math.cos(yaw), math.sin(yaw)
            rot = np.array([[c, s], [-s, c]])
            p = (a - [cx, cy]) @ rot.T
            q = d @ rot.T
            t0 = np.zeros(len(a))
            t1 = np.ones(len(a))
            ok = np.ones(len(a), dtype=bool)
            for ax, h in ((0, hx), (1, hy)):
                par = np.abs(q[:, ax]) < 1e-12
                qs = np.where(par, 1.0, q[:, ax])
                ta, tb = (-h - p[:, ax]) / qs, (h - p[:, ax]) / qs
                ok &= ~(par & (np.abs(p[:, ax]) > h))
                t0 = np.where(par, t0, np.maximum(t0, np.minimum(ta, tb)))
                t1 = np.where(par, t1, np.minimum(t1, np.maximum(ta, tb)))
            count += ok & (t0 <= t1)
        return count


def arena_from_config(path: str | Path) -> tuple[float, float, list[dict[str, Any]]]:
    """(width_m, length_m, obstacles) of a session config (defaults 10 x 20 m as in bridge.core.config)."""
    raw = tomllib.loads(Path(path).read_text())
    arena = raw.get("arena", {})
    return float(arena.get("width_m", 10.0)), float(arena.get("length_m", 20.0)), list(raw.get("obstacles", []))


# ---------------------------------------------------------------------------------------- calibration


def _node(r: int, cfg: RadioCfg) -> dict[str, Any]:
    return {"channel": 12, "pan_id": 0x3332, "addr64": 0x0013A200_40000000 + r, "addr16": r + 1,
            "tx_power_dbm": cfg.tx_power_dbm, "sensitivity_dbm": cfg.sensitivity_dbm, "series": 2}


def _frame(handle: int, src: int, dst: int | None, psdu_len: int) -> dict[str, Any]:
    return {"handle": handle, "src64": 0x0013A200_40000000 + src, "src16": src + 1,
            "dst": "bcast" if dst is None else "64",
            "dst_addr": 0xFFFF if dst is None else 0x0013A200_40000000 + dst, "pan_id": 0x3332, "channel": 12,
            "ack": dst is not None, "mac_retries": 3, "psdu_len": psdu_len, "seq": handle & 0xFF,
            "payload": b"", "opts": 0}


def link_trials(cfg: RadioCfg, geom: ObstacleGeometry, placements: np.ndarray, *, seed: int = 1,
                gap_s: float = 2.0, psdu_len: int = 40) -> dict[str, np.ndarray]:
    """Robot 0 sends one unicast (acknowledged, MAC retries) and one broadcast frame to robot 1 at each
    placement ((k, 2, 2) positions), ``gap_s`` apart, through the real medium. Returns per trial: distance,
    walls, RSSI of the first decoded attempt of the unicast (NaN if none) and of the broadcast, delivered flags,
    attempts."""
    med = RadioMedium(cfg, 2, seed, geom)
    for r in range(2):
        med.set_node(r, _node(r, cfg))
    k = len(placements)
    out = {k2: np.full(k, np.nan) for k2 in ("distance_m", "walls", "rssi_uni", "rssi_bc")}
    out |= {k2: np.zeros(k, dtype=bool) for k2 in ("ok_uni", "ok_bc")}
    out["attempts"] = np.zeros(k, dtype=np.int64)
    gap = int(gap_s * 1e9)
    for i, pl in enumerate(placements):
        geom.pos[:] = pl
        t = (i + 1) * gap
        out["distance_m"][i] = float(np.hypot(*(pl[1] - pl[0])))
        out["walls"][i] = float(geom.walls(0, np.array([1]))[0])
        med.submit(0, t, _frame(2 * i, 0, 1, psdu_len))
        med.submit(0, t, _frame(2 * i + 1, 0, None, psdu_len))
        for _, r, ev in med.advance(t + gap // 2):
            if ev["ev"] == "rx" and r == 1:
                key = "uni" if ev["frame"]["dst"] == "64" else "bc"
                if np.isnan(out[f"rssi_{key}"][i]):
                    out[f"rssi_{key}"][i] = ev["rssi_dbm"]
                out[f"ok_{key}"][i] = True
            elif ev["ev"] == "done" and ev["handle"] == 2 * i:
                out["attempts"][i] = ev["attempts"]
    return out


def random_placements(rng: np.random.Generator, geom: ObstacleGeometry, k: int, width: float, length: float,
                      margin: float = 0.5) -> np.ndarray:
    """``k`` pairs of positions uniform in the arena, clear of obstacles (robot radius ~0.1 m)."""
    out = np.zeros((k, 2, 2))
    filled = 0
    while filled < k:
        p = rng.uniform([margin, margin], [width - margin, length - margin], (4 * k, 2, 2))
        good = ~geom.inside(p[:, 0], 0.15) & ~geom.inside(p[:, 1], 0.15)
        p = p[good][: k - filled]
        out[filled:filled + len(p)] = p
        filled += len(p)
    return out


def calibrate(config: str | Path | None = None, *, cfg: RadioCfg | None = None, trials: int = 4000,
              seed: int = 1) -> dict[str, Any]:
    """The calibration figures of docs/radio.md for ``cfg`` (default RadioCfg()) in the arena of ``config``
    (default: a 10 x 20 m pavilion with the obstacles of hil_configs/demo.toml if it exists, else none), plus
    a 30 m open corridor (2 m wide, no obstacles)."""
    cfg = cfg or RadioCfg()
    if config is None:
        demo = Path(__file__).resolve().parents[2] / "hil_configs" / "demo.toml"
        width, length, obstacles = arena_from_config(demo) if demo.is_file() else (10.0, 20.0, [])
    else:
        width, length, obstacles = arena_from_config(config)
    rng = stream(seed, "radio_fit", "placements")
    geom = ObstacleGeometry(obstacles, 2)
    res = link_trials(cfg, geom, random_placements(rng, geom, trials, width, length), seed=seed)
    # short links are rare among uniform placements: add trials at 1-5 m
    near = np.zeros((trials // 2, 2, 2))
    a = random_placements(rng, geom, trials // 2, width, length)[:, 0]
    r = rng.uniform(1.0, 5.0, trials // 2)
    ang = rng.uniform(0, 2 * np.pi, trials // 2)
    b = a + np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)
    keep = (b[:, 0] > 0.3) & (b[:, 0] < width - 0.3) & (b[:, 1] > 0.3) & (b[:, 1] < length - 0.3)
    keep &= ~geom.inside(b, 0.15)
    near[:, 0], near[:, 1] = a, b
    res2 = link_trials(cfg, geom, near[keep], seed=seed + 1)
    allr = {k: np.concatenate([res[k], res2[k]]) for k in res}
    d = allr["distance_m"]
    rows = []
    for lo, hi in ((0, 2), (2, 4), (4, 6), (6, 8), (8, 10), (10, 15), (15, 25)):
        m = (d >= lo) & (d < hi)
        if m.sum() == 0:
            continue
        rssi = allr["rssi_bc"][m]
        rows.append({"range_m": [lo, hi], "n": int(m.sum()), "walls_mean": round(float(allr["walls"][m].mean()), 2),
                     "median_rssi_dbm": round(float(np.nanmedian(rssi)), 1) if np.isfinite(rssi).any() else None,
                     "pdr_single": round(float(allr["ok_bc"][m].mean()), 3),
                     "pdr_unicast": round(float(allr["ok_uni"][m].mean()), 3)})
    # 30 m corridor
    cg = ObstacleGeometry([], 2)
    kc = max(trials // 4, 200)
    y0 = rng.uniform(0.5, 1.5, (kc, 2))
    xs = rng.uniform(0.0, 2.0, kc)
    dist = rng.uniform(28.0, 30.0, kc)
    corridor = np.stack([np.stack([xs, y0[:, 0]], 1), np.stack([xs + dist, y0[:, 1]], 1)], axis=1)
    rc = link_trials(cfg, cg, corridor, seed=seed + 2)
    lowest = np.nanmin(np.concatenate([allr["rssi_bc"], allr["rssi_uni"], rc["rssi_bc"], rc["rssi_uni"]]))
    m24, m10 = (d >= 2) & (d <= 4), d > 10
    return {
        "median_rssi_2_4m_dbm": float(np.nanmedian(allr["rssi_bc"][m24])),
        "pdr_beyond_10m_unicast": float(allr["ok_uni"][m10].mean()),
        "pdr_beyond_10m_single": float(allr["ok_bc"][m10].mean()),
        "pdr_corridor_28_30m_unicast": float(rc["ok_uni"].mean()),
        "pdr_corridor_28_30m_single": float(rc["ok_bc"].mean()),
        "lowest_rssi_decoded_dbm": float(lowest),
        "rows": rows,
        "trials": len(d),
    }


def _mean_curve(cfg: RadioCfg, d: np.ndarray) -> np.ndarray:
    """Mean RSSI (dBm) without walls or shadowing, fading's dB mean included (for the docs' table)."""
    rng = np.random.default_rng(0)
    return cfg.tx_power_dbm - path_loss_db(cfg, d) + float(np.mean(fading_gain_db(cfg, complex_normal(rng, 100_000))))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bridge.tools.radio_fit", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fit", help="fit PL(d0), n, sigma from an RSSI-vs-distance CSV")
    f.add_argument("csv")
    f.add_argument("-o", "--out", help="write the [radio] TOML fragment here")
    f.add_argument("--tx-power", type=float, default=3.0)
    f.add_argument("--sensitivity", type=float, default=-94.0)
    f.add_argument("--d0", type=float, default=1.0)
    c = sub.add_parser("calibrate", help="calibration table of the default model in a session's arena")
    c.add_argument("config", nargs="?")
    c.add_argument("--trials", type=int, default=4000)
    c.add_argument("--seed", type=int, default=1)
    a = ap.parse_args(argv)
    if a.cmd == "fit":
        res = fit_csv(a.csv, a.out, tx_power_dbm=a.tx_power, sensitivity_dbm=a.sensitivity, d0_m=a.d0)
        for k, v in res.items():
            print(f"{k}: {v}")
        return 0
    res = calibrate(a.config, trials=a.trials, seed=a.seed)
    print("| distance (m) | trials | mean walls | median RSSI (dBm) | PDR single attempt | PDR unicast |")
    print("|---|---|---|---|---|---|")
    for row in res["rows"]:
        lo, hi = row["range_m"]
        print(f"| {lo}-{hi} | {row['n']} | {row['walls_mean']} | {row['median_rssi_dbm']} | "
              f"{row['pdr_single']:.2f} | {row['pdr_unicast']:.2f} |")
    for k, v in res.items():
        if k != "rows":
            print(f"{k}: {v:.3f}" if isinstance(v, float) else f"{k}: {v}")
    print("mean RSSI curve (no walls/shadowing):",
          {d: round(float(_mean_curve(RadioCfg(), np.array([d]))[0]), 1) for d in (1, 3, 10, 15, 20, 30)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
