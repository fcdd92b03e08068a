"""``swarm-sitl radio-survey CONFIG``: the thesis' RSSI-versus-distance experiment (Couceiro 2013, Fig. 3.7).

Two eSwarBots wander among the obstacles of CONFIG's arena; one sends a unicast packet to the other every
``interval`` seconds through its XBee (API frames, the MAC's acknowledgement and retries; on Series 2 no
APS retries unless ``--aps-retries``), and the receiver's module measures the RSSI of each packet it decodes.
The session is a normal SITL run (its recording holds every frame); the survey reads the recording and writes

- ``survey.csv``: one row per message (its retries folded in): time, ground-truth distance and walls in
  between, delivered or not, the RSSI the receiving module measured, the air transmissions it took and the
  last transmit status;
- ``survey.png``: RSSI box plots per 1 m of distance with the received/sent counts, the -75 dBm connectivity
  threshold and the receiver's sensitivity;
- ``calibration.json``: the figures the thesis states (median RSSI near 3 m, delivery beyond 10 m, the
  weakest packet received, the furthest delivery), each with its target and verdict.

``swarm-sitl radio-fit survey.csv`` fits a path-loss model to such a file, or to a real radio's log.
"""

from __future__ import annotations

import copy
import csv
import json
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from bridge.core.recorder import iter_messages

CSV_FIELDS = ("t_s", "src", "dst", "distance_m", "walls", "delivered", "rssi_dbm", "attempts", "status")
Q_MIN_DBM = -75.0  # the thesis' connectivity threshold, "about 3 m" (section 3.2.3)
RETRY_WINDOW_NS = 6_000_000_000  # attempts of one message (same MAC sequence number) come within this


def survey_config(config: str | Path, duration_s: float, interval_s: float, seed: int | None,
                  series: int | None, aps_retries: bool = False) -> dict[str, Any]:
    """CONFIG's session, world and arena with the survey's two robots in place of its own."""
    path = Path(config)
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        from bridge.core.config import ConfigError

        raise ConfigError(f"{path}: no such file") from None
    raw = copy.deepcopy(raw)
    if raw.get("arena", {}).get("map"):
        raw["arena"]["map"] = str((path.parent / raw["arena"]["map"]).resolve())
    groups = raw.get("robots") or [{}]
    xbee = dict(groups[0].get("xbee") or {})
    xbee.pop("pty", None)
    if series is not None:
        xbee["series"] = series
    session = raw.setdefault("session", {})
    session.update(name=f"{session.get('name', path.stem)}-radio-survey", duration_s=duration_s, speed="max")
    if seed is not None:
        session["seed"] = seed
    raw["robots"] = [{
        "profile": groups[0].get("profile", "eswarbot"), "count": 2, "behaviour": "radio_survey",
        "params": {"interval_s": interval_s, "aps_retries": int(aps_retries)}, "xbee": xbee,
        "placement": {"kind": "random", "min_separation_m": 0.6},
    }]
    return raw


def rows_from_recording(mcap: str | Path) -> list[dict[str, Any]]:
    """One row per survey message: the sender's attempts (a module's retries keep the frame's MAC sequence
    number) joined with the addressee's decodes; delivered if any attempt got through, with the RSSI of the
    first copy the addressee decoded."""
    rx: dict[tuple[int, int, int], dict] = {}
    tx: list[dict] = []
    for topic, _t, data in iter_messages(mcap):
        if topic not in ("/radio/rx", "/radio/tx"):
            continue
        msg = json.loads(data)
        if topic == "/radio/rx":
            rx.setdefault((msg["src"], msg["handle"], msg["dst"]), msg)
        elif msg.get("dst") is not None:
            tx.append(msg)
    tx.sort(key=lambda m: (m["t_ns"], m["src"], m["handle"]))
    rows: list[dict[str, Any]] = []
    last: dict[tuple[int, int], dict] = {}  # (src, dst) -> the message being retried
    for m in tx:
        key = (m["src"], m["dst"])
        got = rx.get((m["src"], m["handle"], m["dst"]))
        row = last.get(key)
        if row is None or row["_seq"] != m.get("seq") or m["t_ns"] - row["_t_ns"] > RETRY_WINDOW_NS:
            row = {"t_s": round(m["t_ns"] / 1e9, 4), "src": m["src"], "dst": m["dst"],
                   "distance_m": m.get("distance_m"), "walls": m.get("walls"), "delivered": 0, "rssi_dbm": "",
                   "attempts": 0, "status": m.get("status"), "_seq": m.get("seq"), "_t_ns": m["t_ns"]}
            rows.append(row)
            last[key] = row
        row["attempts"] += m.get("attempts") or 0
        row["status"] = m.get("status")
        row["_t_ns"] = m["t_ns"]
        if got is not None and not row["delivered"]:
            row.update(delivered=1, rssi_dbm=got["rssi_dbm"])
    for row in rows:
        del row["_seq"], row["_t_ns"]
    return rows


def write_csv(rows: list[dict[str, Any]], path: str | Path) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in CSV_FIELDS})


def calibration(rows: list[dict[str, Any]], sensitivity_dbm: float) -> dict[str, Any]:
    """The thesis' radio figures (section 3.2.3; reproduction target N1/N2) from survey rows."""
    d = np.array([r["distance_m"] for r in rows], dtype=float)
    ok = np.array([r["delivered"] for r in rows], dtype=bool)
    rssi = np.array([r["rssi_dbm"] if r["rssi_dbm"] != "" else np.nan for r in rows], dtype=float)
    near = ok & (d >= 2.0) & (d <= 4.0)
    far = d > 10.0
    med3 = float(np.median(rssi[near])) if near.any() else None
    pdr_far = float(ok[far].mean()) if far.any() else None
    weakest = float(np.nanmin(rssi)) if ok.any() else None
    furthest = float(d[ok].max()) if ok.any() else None
    # where the median RSSI crosses -75 dBm: the first 0.5 m bin whose median is below it
    crossing = None
    for lo in np.arange(0.0, max(float(d.max(initial=0)), 1.0), 0.5):
        sel = ok & (d >= lo) & (d < lo + 0.5)
        if sel.sum() >= 5 and np.median(rssi[sel]) < Q_MIN_DBM:
            crossing = float(lo + 0.25)
            break
    return {
        "messages": len(rows), "delivered": int(ok.sum()),
        "median_rssi_2_4m_dbm": {"ours": med3, "thesis": -75.0, "tolerance": 3.0,
                                 "pass": None if med3 is None else abs(med3 + 75.0) <= 3.0},
        "median_crosses_q_min_at_m": {"ours": crossing, "thesis": "2-4", "pass": crossing is not None
                                      and 2.0 <= crossing <= 4.0},
        "delivery_beyond_10m": {"ours": pdr_far, "n": int(far.sum()), "thesis": 0.67, "range": [0.55, 0.8],
                                "pass": None if pdr_far is None else 0.55 <= pdr_far <= 0.8},
        "weakest_received_dbm": {"ours": weakest, "floor": sensitivity_dbm,
                                 "pass": weakest is not None and weakest >= sensitivity_dbm},
        "furthest_delivery_m": {"ours": furthest},
    }


def plot(rows: list[dict[str, Any]], path: str | Path, sensitivity_dbm: float, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = np.array([r["distance_m"] for r in rows], dtype=float)
    ok = np.array([r["delivered"] for r in rows], dtype=bool)
    rssi = np.array([r["rssi_dbm"] if r["rssi_dbm"] != "" else np.nan for r in rows], dtype=float)
    top = math.ceil(d.max()) if len(d) else 1
    bins = list(range(0, top))
    data, labels, counts = [], [], []
    for lo in bins:
        sel = (d >= lo) & (d < lo + 1)
        data.append(rssi[sel & ok])
        labels.append(f"{lo}-{lo + 1}")
        counts.append((int((sel & ok).sum()), int(sel.sum())))
    fig, ax = plt.subplots(figsize=(max(8, 0.45 * len(bins)), 4.8), dpi=110)
    pos = [i + 1 for i, v in enumerate(data) if len(v)]
    if pos:
        ax.boxplot([v for v in data if len(v)], positions=pos, widths=0.6, showfliers=True,
                   flierprops={"markersize": 2, "alpha": 0.5})
    ax.axhline(Q_MIN_DBM, color="tab:green", ls="--", lw=1, label="q_min = -75 dBm (thesis)")
    ax.axhline(sensitivity_dbm, color="tab:red", ls=":", lw=1, label=f"sensitivity {sensitivity_dbm:g} dBm")
    ax.set_xticks(range(1, len(bins) + 1), labels, rotation=60, fontsize=7)
    ax.set_xlim(0.3, len(bins) + 0.7)
    lo_y = sensitivity_dbm - 6
    ax.set_ylim(lo_y, -35)
    for i, (got, sent) in enumerate(counts):
        if sent:
            ax.text(i + 1, lo_y + 1, f"{got}/{sent}", ha="center", va="bottom", fontsize=6, rotation=90)
    ax.set_xlabel("distance between the robots [m] (received/sent below each bin)")
    ax.set_ylabel("RSSI of received packets [dBm]")
    ax.set_title(title, fontsize=10)
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def run_survey(config: str, out_dir: str, duration_s: float = 3600.0, interval_s: float = 2.0,
               seed: int | None = None, series: int | None = None, progress: Any = None,
               aps_retries: bool = False) -> dict[str, Any]:
    from bridge.core.config import XBeeCfg, to_toml
    from bridge.core.launcher import run_session

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    raw = survey_config(config, duration_s, interval_s, seed, series, aps_retries)
    cfg_path = out / "survey.toml"
    cfg_path.write_text(to_toml(raw))
    res = run_session(str(cfg_path), None, str(out / "session"), progress=progress, plot=False)
    if res.code != 0:
        raise RuntimeError(f"the survey session failed (exit {res.code}): {res.summary.get('error')}")
    rows = rows_from_recording(out / "session" / "session.mcap")
    if not rows:
        raise RuntimeError("the survey session recorded no messages")
    series_used = XBeeCfg.model_validate(raw["robots"][0]["xbee"]).series
    sens = -94.0 if series_used == 2 else -92.0
    write_csv(rows, out / "survey.csv")
    cal = calibration(rows, sens)
    cal.update(config=str(config), duration_s=duration_s, interval_s=interval_s, series=series_used,
               seed=raw["session"].get("seed"), aps_retries=aps_retries)
    (out / "calibration.json").write_text(json.dumps(cal, indent=1))
    plot(rows, out / "survey.png", sens, f"XBee Series {series_used} RSSI vs distance, {Path(config).name}: "
         f"{cal['delivered']}/{cal['messages']} messages received")
    return cal
