"""The Roy study's loop functions: a session of robots running chapter 3's controllers, scored from the true poses
as the thesis' hardware experiments were (chapter 7, digest 001 §4.5.1, §5.5): the formation error of eq. 7.1
(repaired: a pair counts when 2 r_s <= x_ij <= 3 r_s), the mission time (the swarm at the target, the numerical
model's arrival test: the centroid within ``goal_tol_m`` of T and every robot within ``goal_tol_m`` + r_s sqrt(N) of
it), the mean path length, and the closest two robots came. Opt-in: a session with a ``[formation]`` section.

Every ``sample_s`` the live robots' poses are sampled (recorded on ``/world/formation``: t, FE, centroid, nearest
pair). ``phases`` splits the mission into named stretches of the route, each ending when the centroid first comes
within its ``until_dist_m`` of T (the last one at arrival), and scores each apart (Table 7.5's phase-wise FE and
durations). The session ends ``end_after_arrival_s`` after the swarm arrives, or, with ``end_on_event``
(``SERVICE/KIND``), ``end_after_event_s`` after a service logs that decision (a region controller's ``done``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from bridge.core.loop_functions import LoopFunctions
from bridge.core.recorder import register_schema
from bridge.studies.roy.config import FormationCfg

if TYPE_CHECKING:
    from bridge.core.config import Config
    from bridge.core.hub import Hub

register_schema("swarm_sitl.RoyFormation", {
    "type": "object",
    "description": "One sample of the swarm's formation (Roy ch.7): eq. 7.1's formation error, the centroid, the "
                   "closest pair's distance (m), and whether the swarm is at the target",
    "properties": {"t_s": {"type": "number"}, "fe": {"type": "number"}, "cx": {"type": "number"},
                   "cy": {"type": "number"}, "nn_min_m": {"type": "number"}, "arrived": {"type": "boolean"}},
})


def arrived(xy: np.ndarray, target: np.ndarray, r_s: float, tol: float) -> bool:
    """The swarm is at T: its centroid within ``tol``, every robot within ``tol`` + r_s sqrt(N) (the numerical
    model's test, ``docs/roy.md``)."""
    if not len(xy):
        return False
    far = np.hypot(*(xy - target).T)
    return bool(np.hypot(*(xy.mean(0) - target)) <= tol and far.max() <= tol + r_s * math.sqrt(len(xy)))


class RoyLoopFunctions(LoopFunctions):
    @classmethod
    def wanted(cls, cfg: Config) -> bool:
        return "formation" in (cfg.model_extra or {})

    def __init__(self, hub: Hub) -> None:
        from bridge.studies.roy.metrics import pair_shares  # (scipy: imported only by a world that scores a formation)

        self._pair_shares = pair_shares
        super().__init__(hub)
        self.cfg: FormationCfg = hub.cfg.section("formation")
        self.target = np.array(self.cfg.target, float)
        self.tick_ns = round(self.cfg.sample_s * 1e9)
        self.next_tick = 0
        self.fe: list[float] = []  # per sample until arrival
        self.close: list[float] = []  # its two parts: pairs closer than 2 r_s, farther than 3 r_s
        self.far: list[float] = []
        self.nn_min = math.inf
        self.arrived_s: float | None = None
        self.path_m: float | None = None  # the mean odometer at arrival
        self.end_event = tuple(self.cfg.end_on_event.split("/")) if self.cfg.end_on_event else None
        self.event_s: float | None = None  # when that event came
        self.phase = 0  # the phase the swarm is in (== len(phases): past the last one's end)
        self.phase_fe: list[list[float]] = [[] for _ in self.cfg.phases]
        self.phase_start: list[float | None] = [0.0 if k == 0 else None for k in range(len(self.cfg.phases))]
        self.phase_end: list[float | None] = [None] * len(self.cfg.phases)

    def pre_step(self, t: int) -> None:
        if t < self.next_tick:
            return
        self.next_tick += self.tick_ns
        w = self.hub.world
        xy = w.pos[w.alive]
        close, far = self._pair_shares(xy, self.cfg.r_s_m)
        fe = close + far
        d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1)) if len(xy) > 1 else np.zeros((1, 1))
        np.fill_diagonal(d, math.inf)
        nn = float(d.min()) if len(xy) > 1 else math.inf
        at = arrived(xy, self.target, self.cfg.r_s_m, self.cfg.goal_tol_m)
        c = xy.mean(0) if len(xy) else np.full(2, math.nan)
        self.hub.rec.write(t, "/world/formation", "swarm_sitl.RoyFormation",
                           {"t_s": t / 1e9, "fe": round(fe, 4), "cx": round(float(c[0]), 4),
                            "cy": round(float(c[1]), 4), "nn_min_m": round(nn, 4) if math.isfinite(nn) else -1.0,
                            "arrived": at})
        if self.arrived_s is not None:
            return
        self._phase(t / 1e9, float(np.hypot(*(c - self.target))) if len(xy) else math.inf, fe)
        self.fe.append(fe)
        self.close.append(close)
        self.far.append(far)
        self.nn_min = min(self.nn_min, nn)
        if at:
            self.arrived_s = t / 1e9
            self.path_m = float(w.odometer[w.alive].mean())
            if self.cfg.end_after_arrival_s is not None and self.end_event is None:
                self._end(t, self.cfg.end_after_arrival_s)

    def _phase(self, t_s: float, dist: float, fe: float) -> None:
        """Move on past every phase whose end the centroid has reached (``dist`` from T), then count this sample's
        FE in the phase it is in."""
        ph = self.cfg.phases
        while self.phase < len(ph) and ph[self.phase].until_dist_m is not None and dist <= ph[self.phase].until_dist_m:
            self.phase_end[self.phase] = t_s
            self.phase += 1
            if self.phase < len(ph):
                self.phase_start[self.phase] = t_s
        if self.phase < len(ph):
            self.phase_fe[self.phase].append(fe)

    def _phases(self) -> list[dict[str, Any]]:
        """Each phase's start and end (s; None: not reached), duration and FE mean and sd over its samples."""
        out = []
        for k, p in enumerate(self.cfg.phases):
            start, end = self.phase_start[k], self.phase_end[k]
            if end is None and k == self.phase and p.until_dist_m is None:
                end = self.arrived_s  # the last phase ends at arrival
            fe = np.array(self.phase_fe[k])
            out.append({"name": p.name, "start_s": start, "end_s": end,
                        "duration_s": None if start is None or end is None else round(end - start, 3),
                        "samples": len(fe), "fe_mean": round(float(fe.mean()), 4) if len(fe) else None,
                        "fe_sd": round(float(fe.std(ddof=1)), 4) if len(fe) > 1 else None})
        return out

    def _end(self, t: int, after_s: float) -> None:
        """End the session ``after_s`` after quantum ``t`` (at the next quantum at the earliest)."""
        q = self.hub.q_ns
        end = t + round(after_s * 1e9)
        self.hub.end_ns = min(self.hub.end_ns, max(t + q, -(-end // q) * q))

    def on_service_log(self, service: str, topic: str, values: dict[str, Any], t: int) -> None:
        if self.end_event is None or self.event_s is not None or topic != "event":
            return
        if (service, values.get("kind")) == self.end_event:
            self.event_s = t / 1e9
            self._end(t, self.cfg.end_after_event_s)

    def summary(self) -> dict[str, Any]:
        """``formation``: FE's mean and sd over the mission's samples (and its parts: the pairs too close, too far),
        the mission time (None: not arrived), the
        mean path length (m; at arrival, else at the end), the closest pair (m)."""
        w = self.hub.world
        fe = np.array(self.fe)
        path = self.path_m if self.path_m is not None else float(w.odometer[w.alive].mean()) if w.alive.any() else 0.0
        return {"formation": {
            "r_s_m": self.cfg.r_s_m, "target": list(self.cfg.target), "samples": len(fe),
            "fe_mean": round(float(fe.mean()), 4) if len(fe) else None,
            "fe_sd": round(float(fe.std(ddof=1)), 4) if len(fe) > 1 else None,
            "fe_close": round(float(np.mean(self.close)), 4) if self.close else None,
            "fe_far": round(float(np.mean(self.far)), 4) if self.far else None,
            "arrived": self.arrived_s is not None, "mission_s": self.arrived_s,
            "path_m": round(path, 4), "nn_min_m": round(self.nn_min, 4) if math.isfinite(self.nn_min) else None,
            **({"end_event": self.cfg.end_on_event, "end_event_s": self.event_s} if self.end_event else {}),
            **({"phases": self._phases()} if self.cfg.phases else {}),
        }}
