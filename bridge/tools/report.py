"""``swarm-sitl report RUN``: one self-contained HTML page about a session, from its output directory.

The page holds the run's figures (summary.json), its plots as embedded PNG images (the trajectories, the radio
network's connectivity and the robots alive over time, RSSI by distance from the frames the modules decoded), a table
per robot, the failures and events, and the config it ran. It needs nothing but a browser: no script, no file beside
it.
"""

from __future__ import annotations

import base64
import html
import io
import json
import tempfile
from pathlib import Path
from typing import Any

from bridge.core.plan import Plan
from bridge.core.recorder import NotARecording, iter_messages


class ReportError(Exception):
    """The directory holds no session's outputs to report on."""


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    return base64.b64encode(buf.getvalue()).decode()


def _series(rec: Path) -> dict[str, list]:
    """What the plots need from the recording, in one pass."""
    out: dict[str, list] = {"lambda2": [], "alive": [], "rssi": [], "events": []}
    for topic, t_ns, data in iter_messages(rec):
        if topic == "/radio/connectivity":
            out["lambda2"].append((t_ns / 1e9, json.loads(data)["lambda2"]))
        elif topic == "/world/poses":
            if not out["alive"] or t_ns / 1e9 - out["alive"][-1][0] >= 0.1:
                out["alive"].append((t_ns / 1e9, sum(json.loads(data)["alive"])))
        elif topic == "/radio/rx":
            m = json.loads(data)
            if m.get("rssi_dbm") is not None and m.get("distance_m") is not None:
                out["rssi"].append((m["distance_m"], m["rssi_dbm"]))
        elif topic == "/session/events":
            out["events"].append((t_ns / 1e9, json.loads(data)))
    return out


def _plots(run: Path, plan: Plan, series: dict[str, list]) -> list[tuple[str, str, str]]:
    """(id, title, base64 PNG) of each plot the run has data for."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bridge.core.plot import plot_session

    out = []
    with tempfile.TemporaryDirectory() as d:
        png = Path(d) / "trajectories.png"
        plot_session(run / "session.mcap", plan, png)
        out.append(("trajectories", "Trajectories", base64.b64encode(png.read_bytes()).decode()))
    if series["lambda2"] or series["alive"]:
        fig, ax = plt.subplots(figsize=(8, 3))
        if series["lambda2"]:
            t, lam = zip(*series["lambda2"], strict=True)
            ax.step(t, lam, where="post", label="algebraic connectivity λ2 (0: split)")
        ax.set_xlabel("simulated time (s)")
        if series["alive"]:
            ax2 = ax.twinx()
            t, n = zip(*series["alive"], strict=True)
            ax2.step(t, n, where="post", color="tab:red", label="robots alive")
            ax2.set_ylabel("robots alive")
            ax2.set_ylim(bottom=0)
        ax.set_ylabel("λ2")
        fig.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=2, fontsize=8, frameon=False)
        out.append(("connectivity", "Connectivity and robots alive over time", _png(fig)))
        plt.close(fig)
    if series["rssi"]:
        fig, ax = plt.subplots(figsize=(8, 3))
        d, rssi = zip(*series["rssi"], strict=True)
        ax.scatter(d, rssi, s=4, alpha=0.4)
        ax.set_xlabel("distance (m)")
        ax.set_ylabel("RSSI (dBm)")
        out.append(("rssi", f"RSSI by distance ({len(d)} frames decoded)", _png(fig)))
        plt.close(fig)
    return out


def _table(rows: list[list[Any]], head: list[str] | None = None) -> str:
    cells = "".join(f"<th>{html.escape(h)}</th>" for h in head or [])
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table>{f'<thead><tr>{cells}</tr></thead>' if head else ''}<tbody>{body}</tbody></table>"


def write_report(run: str | Path, out: str | Path | None = None) -> Path:
    """Write the page for the session in ``run`` (its output directory) to ``out`` (default ``run/report.html``)."""
    run = Path(run)
    try:
        summary = json.loads((run / "summary.json").read_text())
        plan = Plan.from_json(json.loads((run / "plan.json").read_text()))
    except (OSError, ValueError) as e:
        raise ReportError(f"{run}: not a session's output directory (summary.json, plan.json): {e}") from None
    try:
        series = _series(run / "session.mcap")
    except (OSError, NotARecording) as e:
        raise ReportError(f"{run}: its recording cannot be read: {e}") from None
    plots = _plots(run, plan, series)
    radio = (summary.get("radio") or {}).get("connectivity") or {}
    figures = [
        ["robots", summary.get("robots")], ["processes", summary.get("processes")],
        ["simulated time (s)", summary.get("sim_time_s")], ["real-time factor", summary.get("rtf")],
        ["seed", summary.get("seed")], ["digest", summary.get("digest")],
        ["radio connected share", radio.get("connected_share")], ["partition events", radio.get("partition_events")],
        ["stop", summary.get("stop_reason") or ("interrupted" if summary.get("interrupted") else "its duration")],
    ]
    robots = [[r["id"], r.get("profile"), "yes" if r.get("alive") else "no", r.get("distance_m"), r.get("battery_v"),
               ((r.get("radio") or {}).get("tx") or {}).get("frames", ""),
               ((r.get("radio") or {}).get("rx") or {}).get("delivered", ""),
               (r.get("uwb_raw") or {}).get("ok", "")] for r in summary.get("per_robot", [])]
    failures = [[f.get("t_s"), f.get("robot", f.get("service")), f.get("kind"),
                 ((f.get("detail") or "").strip().splitlines() or [""])[-1]] for f in summary.get("failures", [])]
    events = [[round(t, 3), e.get("robot", e.get("service", "")), e.get("kind"), (e.get("detail") or "")[:160]]
              for t, e in series["events"]]
    config = html.escape(json.dumps(plan.config, indent=1, sort_keys=True))
    imgs = "".join(f'<section id="{pid}"><h2>{html.escape(title)}</h2><img alt="{html.escape(title)}" '
                   f'src="data:image/png;base64,{data}"></section>' for pid, title, data in plots)
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>swarm-sitl report: {html.escape(str(summary.get("name")))}</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}}table{{border-collapse:collapse;
margin:1em 0}}td,th{{border:1px solid #ccc;padding:.2em .6em;font-size:.9em}}img{{max-width:100%}}
pre{{background:#f6f6f6;padding:1em;overflow:auto;font-size:.8em}}</style></head><body>
<h1>Session {html.escape(str(summary.get("name")))}</h1>
<section id="figures"><h2>Figures</h2>{_table(figures)}</section>
{imgs}
<section id="robots"><h2>Robots</h2>{_table(robots, ["robot", "profile", "alive", "distance (m)", "battery (V)",
                                                      "frames sent", "frames received", "UWB ranges"])}</section>
<section id="failures"><h2>Failures ({len(failures)})</h2>{_table(failures, ["t (s)", "who", "kind", "detail"])
                                                               if failures else "<p>none</p>"}</section>
<section id="events"><h2>Events ({len(events)})</h2>{_table(events, ["t (s)", "who", "kind", "detail"])
                                                       if events else "<p>none</p>"}</section>
<section id="config"><h2>Config</h2><pre>{config}</pre></section>
</body></html>
"""
    target = Path(out) if out is not None else run / "report.html"
    target.write_text(page, encoding="utf-8")
    return target
