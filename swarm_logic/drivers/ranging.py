"""Per-neighbour range tracking: one filterpy ``KalmanFilter`` on [range, range rate] per peer.

Constant-velocity model with white-acceleration process noise (``Q_discrete_white_noise``), predicted to each
measurement's own time. A measurement is gated by its Mahalanobis distance to the prediction
(d^2 = y^2 / S above ``gate`` is rejected: NLOS outliers, multipath), unless ``reinit_after`` rejections in a
row say the track itself is wrong (a real jump), which re-initialises it at the measurement. Ranges the
module flags as NLOS (DW1000 RX - first-path power above 10 dB, Decawave APS006 Part 2) enter with the larger
``sigma_nlos_m``; "possibly NLOS" with the mean of both variances. Tracks not updated for ``stale_s`` are
dropped. filterpy is imported on first use (it costs about a second), so importing this module is cheap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


def _filterpy() -> tuple[Any, Any]:
    from filterpy.common import Q_discrete_white_noise
    from filterpy.kalman import KalmanFilter

    return KalmanFilter, Q_discrete_white_noise


@dataclass(frozen=True)
class RangeEstimate:
    peer: int
    range_m: float
    rate_mps: float
    sigma_m: float  # standard deviation of the range estimate
    t: float  # time of the estimate
    updated: float  # time of the last accepted measurement


class _Track:
    __slots__ = ("kf", "rejects", "t", "updated")

    def __init__(self, kf: Any, t: float) -> None:
        self.kf = kf
        self.t = t
        self.updated = t
        self.rejects = 0


class RangeTracker:
    """Kalman-filtered ranges and range rates to every neighbour, fed by ``update`` with (peer, range, time)."""

    def __init__(self, *, sigma_range_m: float = 0.10, sigma_nlos_m: float = 0.60, nlos_bias_m: float = 0.0,
                 accel_sigma: float = 0.2, init_rate_sigma: float = 1.0, gate: float = 9.0, reinit_after: int = 4,
                 stale_s: float = 5.0) -> None:
        self.sigma_range_m = sigma_range_m
        self.sigma_nlos_m = sigma_nlos_m
        self.nlos_bias_m = nlos_bias_m  # expected positive NLOS excess, removed from flagged ranges (half if possible)
        self.accel_sigma = accel_sigma  # m/s^2, white acceleration of the range
        self.init_rate_sigma = init_rate_sigma
        self.gate = gate  # chi-square, 1 dof: 9 = 3 sigma
        self.reinit_after = reinit_after
        self.stale_s = stale_s
        self.tracks: dict[int, _Track] = {}
        self.counters: dict[str, int] = {k: 0 for k in ("accepted", "gated", "reinit", "new", "late", "dropped")}

    def _r(self, nlos: bool, nlos_possible: bool) -> float:
        if nlos:
            return self.sigma_nlos_m**2
        if nlos_possible:
            return 0.5 * (self.sigma_range_m**2 + self.sigma_nlos_m**2)
        return self.sigma_range_m**2

    def _new(self, peer: int, z: float, t: float, r: float) -> None:
        kf_cls, _ = _filterpy()
        kf = kf_cls(dim_x=2, dim_z=1)
        kf.x = np.array([[z], [0.0]])
        kf.P = np.diag([r, self.init_rate_sigma**2])
        kf.H = np.array([[1.0, 0.0]])
        kf.R = np.array([[r]])
        self.tracks[peer] = _Track(kf, t)

    def _predict(self, tr: _Track, t: float) -> None:
        dt = t - tr.t
        if dt <= 0:
            return
        _, qdwn = _filterpy()
        tr.kf.F = np.array([[1.0, dt], [0.0, 1.0]])
        tr.kf.Q = qdwn(dim=2, dt=dt, var=self.accel_sigma**2)
        tr.kf.predict()
        tr.t = t

    def update(self, peer: int, range_m: float, t: float, *, nlos: bool = False,
               nlos_possible: bool = False) -> bool:
        """Feed one measurement taken at ``t``; returns whether it was accepted into the track."""
        if not math.isfinite(range_m):
            self.counters["gated"] += 1
            return False
        r = self._r(nlos, nlos_possible)
        range_m -= self.nlos_bias_m if nlos else (0.5 * self.nlos_bias_m if nlos_possible else 0.0)
        tr = self.tracks.get(peer)
        if tr is None:
            self._new(peer, range_m, t, r)
            self.counters["new"] += 1
            return True
        if t < tr.t:
            self.counters["late"] += 1
            return False
        self._predict(tr, t)
        kf = tr.kf
        y = range_m - float(kf.x[0, 0])
        s = float(kf.P[0, 0]) + r
        if y * y / s > self.gate:
            tr.rejects += 1
            if tr.rejects < self.reinit_after:
                self.counters["gated"] += 1
                return False
            self.counters["reinit"] += 1
            self._new(peer, range_m, t, r)
            return True
        kf.update(np.array([[range_m]]), R=np.array([[r]]))
        tr.rejects = 0
        tr.updated = t
        self.counters["accepted"] += 1
        return True

    def update_reading(self, peer: int, reading: Any) -> bool:
        """Feed a ``swarm_logic.drivers.uwb.RangeReading`` (its time, range and NLOS flags)."""
        return self.update(peer, reading.range_m, reading.t, nlos=reading.nlos, nlos_possible=reading.nlos_possible)

    def estimate(self, peer: int, t: float | None = None) -> RangeEstimate | None:
        """The track of ``peer`` predicted to ``t`` (without changing it); None if there is none."""
        tr = self.tracks.get(peer)
        if tr is None:
            return None
        x, p = tr.kf.x, tr.kf.P
        te = tr.t if t is None or t < tr.t else t
        dt = te - tr.t
        if dt > 0:
            _, qdwn = _filterpy()
            f = np.array([[1.0, dt], [0.0, 1.0]])
            x = f @ x
            p = f @ p @ f.T + qdwn(dim=2, dt=dt, var=self.accel_sigma**2)
        return RangeEstimate(peer, float(x[0, 0]), float(x[1, 0]), math.sqrt(max(0.0, float(p[0, 0]))), te,
                             tr.updated)

    def prune(self, t: float) -> list[int]:
        """Drop tracks whose last accepted measurement is older than ``stale_s``; returns the dropped peers."""
        gone = [p for p, tr in self.tracks.items() if t - tr.updated > self.stale_s]
        for p in gone:
            del self.tracks[p]
        self.counters["dropped"] += len(gone)
        return gone

    def estimates(self, t: float) -> dict[int, RangeEstimate]:
        """Every live track predicted to ``t`` (stale ones are dropped first)."""
        self.prune(t)
        out = {}
        for p in self.tracks:
            e = self.estimate(p, t)
            if e is not None:
                out[p] = e
        return out
