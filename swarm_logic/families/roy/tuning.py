"""One control step of chapter 3's agent, for one agent (``RoyApf``) or many at once (the numerical model's batched
runner): which optimiser runs (``kind``), the uniforms it takes from the agent's generator (``draw``), the gains it
finds on Theta (``tune``), the PSOABG deadlock test (``deadlocked``) and the commanded velocity (``command``).

Arrays carry a leading batch dimension B (1 on a robot). Each agent draws its uniforms from its own generator in one
call per optimiser per step, so an agent's gains do not depend on which other agents share its batch.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarm_logic.families.roy import potential
from swarm_logic.families.roy.bat import bat_batch, bat_draws
from swarm_logic.families.roy.bfo import bfo_batch, bfo_draws
from swarm_logic.families.roy.binary_bat import binary_bat_batch, binary_bat_draws
from swarm_logic.families.roy.objective import AgentState, theta
from swarm_logic.families.roy.pso import pso_batch, pso_draws

DIM = 4  # (k_a, k_v, k_r, k_OA)


def kind(p: dict[str, Any], deadlock: bool) -> str:
    """The optimiser this step: ``p["optimiser"]``, PSOABG's BFO or, while the swarm is stuck, PSO (Fig. 3.9)."""
    name = p["optimiser"]
    if name == "psoabg":
        return "pso" if deadlock else "bfo"
    return name


def draw_sizes(p: dict[str, Any], k: str) -> dict[str, int]:
    """The uniforms optimiser ``k`` takes per step, by component (BGPSO: BFO's, then PSO's)."""
    sizes = {"bat": bat_draws(int(p["bat_pop"]), int(p["bat_iters"]), DIM),
             "pso": pso_draws(int(p["pso_particles"]), int(p["pso_iters"]), DIM),
             "bfo": bfo_draws(int(p["bfo_bacteria"]), int(p["bfo_nc"]), int(p["bfo_nre"]), int(p["bfo_ned"]), DIM),
             "binary_bat": binary_bat_draws(int(p["bat_pop"]), int(p["bat_iters"]), DIM, int(p["bbat_bits"]))}
    if k == "fixed":
        return {}
    if k == "bgpso":
        return {"bfo": sizes["bfo"], "pso": sizes["pso"]}
    return {k: sizes[k]}


def draw(p: dict[str, Any], k: str, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """One agent's uniforms for this step, one generator call per component."""
    return {c: rng.random(n) for c, n in draw_sizes(p, k).items()}


def take(s: AgentState, idx: np.ndarray) -> AgentState:
    """The states of the agents ``idx`` of a flat batch."""
    def cut(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[idx]
    return AgentState(s.x_i[idx], s.v_i[idx], s.x_bar[idx], s.v_bar[idx], s.n, s.others[idx], s.points[idx],
                      s.d_near[idx], s.basis[idx], s.extra[idx], s.target, s.r_s, s.dt, s.d_max, s.v_max,
                      cut(s.near), s.horizon, s.progress)


def tune(p: dict[str, Any], k: str, s: AgentState, gains: np.ndarray, u: dict[str, np.ndarray]) -> np.ndarray:
    """The gains (B, 4) optimiser ``k`` finds on Theta at the states ``s`` (batch B), warm-started at ``gains``,
    from the uniforms ``u`` (component -> (B, n))."""
    if k == "fixed":
        return gains
    lo = np.full(DIM, float(p["gain_min"]))
    hi = np.full(DIM, float(p["gain_max"]))
    mode = p["objective"]

    def f(c: np.ndarray) -> np.ndarray:
        return theta(c, s, mode)

    def run_pso(init: np.ndarray | None = None) -> np.ndarray:
        return pso_batch(f, lo, hi, u["pso"], int(p["pso_particles"]), int(p["pso_iters"]), p["pso_c1"],
                         p["pso_c2"], p["pso_w"], x0=gains, init=init)[0]

    def run_bfo() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return bfo_batch(f, lo, hi, u["bfo"], int(p["bfo_bacteria"]), int(p["bfo_nc"]), int(p["bfo_ns"]),
                         int(p["bfo_nre"]), int(p["bfo_ned"]), p["bfo_ped"], p["bfo_step"], p["bfo_d_att"],
                         p["bfo_w_att"], p["bfo_h_rep"], p["bfo_w_rep"], x0=gains)

    if k == "bat":
        return bat_batch(f, lo, hi, u["bat"], int(p["bat_pop"]), int(p["bat_iters"]), p["bat_f_min"],
                         p["bat_f_max"], p["bat_a0"], p["bat_alpha"], p["bat_gamma"], p["bat_mode"], x0=gains)[0]
    if k == "binary_bat":  # BAT's population and iterations: the comparison at equal evaluations
        return binary_bat_batch(f, lo, hi, u["binary_bat"], int(p["bat_pop"]), int(p["bat_iters"]), int(p["bbat_bits"]),
                                p["bat_f_min"], p["bat_f_max"], p["bat_a0"], p["bbat_alpha"], p["bbat_gamma"],
                                p["bbat_transfer"], x0=gains)[0]
    if k == "pso":
        return run_pso()
    if k == "bfo":
        return run_bfo()[0]
    if k == "bgpso":  # Fig. 3.8: PSO after BFO's elimination-dispersal, from its population
        return run_pso(init=run_bfo()[2])
    raise ValueError(f"optimiser: no tuning step for {k!r}")


def deadlocked(first: np.ndarray, last: np.ndarray, x_bar: np.ndarray, target: np.ndarray,
               p: dict[str, Any]) -> np.ndarray:
    """Erratum #7: the centroid moved less than ``deadlock_move`` r_s from ``first`` to ``last`` (the ends of the
    ``deadlock_window_s`` window), away from the target. Arrays (..., 2) -> (...)."""
    m = last - first
    e = x_bar - target
    far = np.hypot(e[..., 0], e[..., 1]) > p["goal_tol"]
    return far & (np.hypot(m[..., 0], m[..., 1]) < p["deadlock_move"] * p["r_s"])


def command(gains: np.ndarray, s: AgentState) -> tuple[np.ndarray, np.ndarray]:
    """The law's u = gains . basis + extra and the velocity to command, v + u dt saturated at ``v_max`` (B, 2)."""
    u0, u1 = potential.control_xy(gains, s.basis, s.extra)
    v = potential.saturate_xy(s.v_i[..., 0] + u0 * s.dt, s.v_i[..., 1] + u1 * s.dt, s.v_max)
    return np.stack([u0, u1], axis=-1), np.stack(v, axis=-1)
