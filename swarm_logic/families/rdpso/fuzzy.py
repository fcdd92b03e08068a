"""Context metrics and fuzzy adaptation of the RDPSO coefficients (chapter 7, §7.2-7.3).

Each robot evaluates five context metrics in [0, 1] every iteration (eq. 7.18-7.24) and a Mamdani fuzzy system
maps them to (alpha, rho1..rho4). Inputs are fuzzified by the half bell of eq. 7.25 (centre 1):

    A_s "Active", S_n "Social", O_n "Close", P_n "Far", C_s "Connected".

All functions use plain floats; ``FuzzyAdapter.adapt`` precomputes its output universes once so that a call costs
a handful of small vector operations.
"""

from __future__ import annotations

import numpy as np


def bell(x: float, a: float = 0.5, b: float = 3.0, c: float = 1.0) -> float:
    """Generalised bell 1 / (1 + |(x - c)/a|^(2b)) (eq. 7.25, with the absolute value the extraction lost).

    With the defaults mu(1) = 1, mu(0.5) = 0.5, mu(0) = 1/65.
    """
    t = (x - c) / a
    return 1.0 / (1.0 + (t * t) ** b)


def _unit(v: float) -> float:
    return 0.0 if v < 0.0 else (1.0 if v > 1.0 else v)


def swarm_activity(v_centre_norm: float, dx_max: float) -> float:
    """A_s = |v_s| / dx_max, v_s the subgroup's centre-of-mass velocity (eq. 7.18); 1 = moving at full step."""
    return _unit(v_centre_norm / dx_max)


def socialization(dist_to_chi2: float, max_dist_to_chi2: float) -> float:
    """S_n = 1 - |chi2 - x_n| / max_i |chi2 - x_i| (eq. 7.19); 1 when every member sits on the subgroup best."""
    if max_dist_to_chi2 <= 0.0:
        return 1.0
    return _unit(1.0 - dist_to_chi2 / max_dist_to_chi2)


def obstacle_proximity(g: float, r_w: float) -> float:
    """O_n = (R_w - g)/R_w (eq. 7.21), g = distance to the nearest obstacle, R_w when nothing is sensed."""
    return _unit((r_w - g) / r_w)


def proximity_distance(d_nm: float, d_max: float) -> float:
    """P_n = 1 - d_nm/d_max if d_nm <= d_max else 0 (eq. 7.22), m the nearest neighbour; 0 = at the link limit."""
    if not d_nm <= d_max:
        return 0.0
    return _unit(1.0 - d_nm / d_max)


def proximity_rssi(q_nm_dbm: float, q_min_dbm: float) -> float:
    """P_n = 1 - q_min/q_nm if q_nm >= q_min else 0 (eq. 7.23), evaluated in mW.

    In dBm the ratio q_min/q_nm of two negative numbers is >= 1 and P_n would be <= 0; in linear power it is the
    intended 0 (at the threshold) .. 1 (very strong) scale.
    """
    if not q_nm_dbm >= q_min_dbm:
        return 0.0
    return _unit(1.0 - 10.0 ** ((q_min_dbm - q_nm_dbm) / 10.0))


class FuzzyAdapter:
    """Mamdani fuzzy adaptation of (alpha, rho1, rho2, rho3, rho4) from the context metrics (§7.3, Fig. 7.10-7.13).

    Output sets are triangles of half-width ``half_width`` centred at the given values (the thesis draws them in
    Fig. 7.12 without numbers): alpha Small/Nominal/Large = ``alpha_sets``, rho2/rho3/rho4 Small/Large. Each output's
    universe spans [lowest centre - half_width, highest centre + half_width], sampled at ``resolution`` points.

    Rules (Fig. 7.13), with Close = bell(O_n), Far = bell(1 - P_n), NotConn = 1 - bell(C_s):
      R1  IF A_s Active THEN alpha Small ELSE alpha Large
      R2  IF Close OR Far OR NotConn THEN alpha Nominal
      R3  IF S_n Social OR Close OR Far OR NotConn THEN rho2 Small ELSE rho2 Large
      R4  IF Close THEN rho3 Large ELSE-IF Far OR NotConn THEN rho3 Small
      R5  IF Far OR NotConn THEN rho4 Large ELSE-IF Close THEN rho4 Small

    Interpretations (the thesis leaves these open):
    - "Far" is the bell of 1 - P_n: P_n -> 1 means very near the neighbour, and the rules want rho4 to grow as the
      link approaches its threshold (P_n -> 0).
    - Operators: AND/implication min, OR max, NOT 1 - mu, aggregation max, centre-of-gravity defuzzification.
      ELSE fires with 1 - mu(premise); ELSE-IF p2 fires with min(1 - mu(p1), mu(p2)).
    - When no branch of an ELSE-IF chain fires, the output falls back to Small with strength
      min(1 - mu(p1), 1 - mu(p2)). For rho3 this is the thesis's rule that rho3 = 0 with no obstacle (§7.2.3);
      for rho4 it is "rho4 falls when the robot reconnects" (Fig. 7.14). Both chains then reduce to
      "IF p1 THEN ... ELSE Small", since both remaining branches point to Small.
    - O_n = 0 (nothing within the sensing radius) gives rho3 = 0 exactly (§7.2.3). The bell never reaches 0
      (mu(0) = 1/65), so the clipped Large set would otherwise leave rho3 at about 0.02.
    - rho1 = max(rho1_floor, sum_rho - rho2 - rho3 - rho4): sum_rho = 1.98 < 2 keeps the worst case inside A_p
      (eq. 7.17); the thesis's 2 - sum would sit on the open boundary. If rho2 + rho3 + rho4 alone exceed
      sum_rho - rho1_floor they are scaled down together, so sum(rho) never exceeds sum_rho.
    - Each defuzzified value is clamped to the range of its set centres (e.g. alpha in [0.40, 0.80]).
    """

    def __init__(self, alpha_sets: tuple[float, float, float] = (0.40, 0.632, 0.80), half_width: float = 0.2,
                 rho2_sets: tuple[float, float] = (0.10, 0.80), rho3_sets: tuple[float, float] = (0.0, 0.80),
                 rho4_sets: tuple[float, float] = (0.10, 0.80), sum_rho: float = 1.98, rho1_floor: float = 0.02,
                 bell: tuple[float, float, float] = (0.5, 3.0, 1.0), resolution: int = 101) -> None:
        if half_width <= 0.0:
            raise ValueError(f"half_width must be > 0, got {half_width}")
        if resolution < 3:
            raise ValueError(f"resolution must be >= 3, got {resolution}")
        if not 0.0 <= rho1_floor < sum_rho:
            raise ValueError(f"need 0 <= rho1_floor < sum_rho, got rho1_floor={rho1_floor}, sum_rho={sum_rho}")
        if len(alpha_sets) != 3 or not 0.0 < alpha_sets[0] <= alpha_sets[1] <= alpha_sets[2] <= 1.0:
            raise ValueError(f"alpha_sets must be (Small, Nominal, Large) ascending in (0, 1], got {alpha_sets}")
        for name, sets in (("rho2_sets", rho2_sets), ("rho3_sets", rho3_sets), ("rho4_sets", rho4_sets)):
            if len(sets) != 2 or not 0.0 <= sets[0] <= sets[1]:
                raise ValueError(f"{name} must be (Small, Large) ascending and >= 0, got {sets}")
        if bell[0] == 0.0:
            raise ValueError("bell width a must be non-zero")
        self.sum_rho = float(sum_rho)
        self.rho1_floor = float(rho1_floor)
        self._a, self._b, self._c = (float(v) for v in bell)
        outputs = (tuple(alpha_sets), tuple(rho2_sets), tuple(rho3_sets), tuple(rho4_sets))
        u = np.linspace(0.0, 1.0, resolution)
        rows = []
        self._lo: list[float] = []
        self._span: list[float] = []
        self._min_c: list[float] = []
        self._max_c: list[float] = []
        starts = []
        for centres in outputs:
            lo = min(centres) - half_width
            hi = max(centres) + half_width
            x = lo + (hi - lo) * u
            starts.append(len(rows))
            rows.extend(np.clip(1.0 - np.abs(x - c) / half_width, 0.0, None) for c in centres)
            self._lo.append(lo)
            self._span.append(hi - lo)
            self._min_c.append(float(min(centres)))
            self._max_c.append(float(max(centres)))
        self._mf = np.array(rows)  # (9, resolution): alpha S/N/L, rho2 S/L, rho3 S/L, rho4 S/L
        self._starts = np.array(starts)
        self._moments = np.stack([u, np.ones_like(u)], axis=1)  # agg @ moments -> (sum u mu, sum mu) per output
        self._strength = np.empty(len(rows))

    def _mu(self, x: float) -> float:
        t = (x - self._c) / self._a
        return 1.0 / (1.0 + (t * t) ** self._b)

    def adapt(self, a_s: float, s_n: float, o_n: float, p_n: float,
              c_s: float) -> tuple[float, float, float, float, float]:
        """(alpha, rho1, rho2, rho3, rho4) for the metrics A_s, S_n, O_n, P_n, C_s (each in [0, 1])."""
        mu = self._mu
        active = mu(a_s)
        social = mu(s_n)
        close = mu(o_n)
        far = mu(1.0 - p_n)
        not_conn = 1.0 - mu(c_s)
        link = far if far > not_conn else not_conn  # Far OR NOT Connected
        risk = close if close > link else link  # Close OR Far OR NOT Connected
        r3 = social if social > risk else risk
        not_close = 1.0 - close
        not_link = 1.0 - link
        # ELSE-IF branch or no branch: both give Small, strength min(1 - mu(p1), max(mu(p2), 1 - mu(p2))).
        rho3_small = min(not_close, link if link > not_link else not_link)
        rho4_small = min(not_link, close if close > not_close else not_close)
        h = self._strength
        h[0] = active          # R1 alpha Small
        h[1] = risk            # R2 alpha Nominal
        h[2] = 1.0 - active    # R1 ELSE alpha Large
        h[3] = r3              # R3 rho2 Small
        h[4] = 1.0 - r3        # R3 ELSE rho2 Large
        h[5] = rho3_small      # R4 ELSE-IF / fallback rho3 Small
        h[6] = close           # R4 rho3 Large
        h[7] = rho4_small      # R5 ELSE-IF / fallback rho4 Small
        h[8] = link            # R5 rho4 Large
        agg = np.maximum.reduceat(np.minimum(self._mf, h[:, None]), self._starts, axis=0)
        mom = (agg @ self._moments).tolist()
        out = []
        for j in range(4):
            num, den = mom[j]
            v = self._lo[j] + self._span[j] * num / den if den > 0.0 else self._min_c[j]
            lo = self._min_c[j]
            hi = self._max_c[j]
            out.append(lo if v < lo else (hi if v > hi else v))
        alpha, rho2, rho3, rho4 = out
        if o_n <= 0.0:
            rho3 = 0.0
        rest = rho2 + rho3 + rho4
        cap = self.sum_rho - self.rho1_floor
        if rest > cap:
            k = cap / rest
            rho2 *= k
            rho3 *= k
            rho4 *= k
            rest = cap
        rho1 = self.sum_rho - rest
        if rho1 < self.rho1_floor:
            rho1 = self.rho1_floor
        return alpha, rho1, rho2, rho3, rho4

