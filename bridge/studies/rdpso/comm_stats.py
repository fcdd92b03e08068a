"""The chapter 6 communication figures from the RDPSO routing layer's counters (``Rdpso.comm_stats``): packets per
robot, time paused on the radio, delivery ratio, routing overhead and hop count. Used by the session summary and
the communication experiments."""

from __future__ import annotations

import collections
from typing import Any

CONTROL = ("rreq_sent", "rreq_forwarded", "rrep_sent", "rerr_sent")


def comm_totals(last: dict[int, dict[str, Any]]) -> collections.Counter:
    """Each robot's latest counters, summed over robots."""
    tot: collections.Counter = collections.Counter()
    for c in last.values():
        tot.update(c)
    return tot


def comm_metrics(tot: collections.Counter, n: int, duration_s: float) -> dict[str, float | None]:
    """Per-robot packets and pause time, delivery ratio, routing overhead (control frames per data frame sent)
    and mean hop count of delivered data, from summed counters of ``n`` robots over ``duration_s``."""
    data_frames = tot["tx_data"] + tot["tx_forward"]
    return {
        "packets_per_robot": round(tot["tx_frames"] / n, 1),
        "data_per_robot": round(tot["data_originated"] / n, 1),
        "pause_s": round(tot["paused_s"] / n, 2),
        "pause_share": round(tot["paused_s"] / n / duration_s, 4),
        "radio_busy_s": round(tot["busy_s"] / n, 2),
        "radio_busy_share": round(tot["busy_s"] / n / duration_s, 4),
        "delivery_ratio": round(tot["data_delivered"] / tot["data_originated"], 4) if tot["data_originated"] else None,
        "overhead": round(sum(tot[k] for k in CONTROL) / data_frames, 4) if data_frames else None,
        "discoveries_per_data": round(tot["route_discoveries"] / tot["data_originated"], 4)
        if tot["data_originated"] else None,
        "hops": round(tot["hops_delivered"] / tot["data_delivered"], 4) if tot["data_delivered"] else None,
        "dropped_buffer": tot["data_dropped_buffer"],
        "malformed": tot["malformed"],
    }


def comm_report(last: dict[int, dict[str, Any]], duration_s: float) -> dict[str, Any]:
    """The session summary's ``comm``: the swarm's figures, and each robot's counters."""
    return {**comm_metrics(comm_totals(last), len(last), duration_s),
            "per_robot": {str(r): c for r, c in sorted(last.items())}}
