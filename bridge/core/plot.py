"""Top-down picture of a session, drawn from its recording: arena, obstacles, light field, robot paths."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from bridge.core.arena_map import occupancy
from bridge.core.config import Config
from bridge.core.plan import Plan
from bridge.core.recorder import iter_messages


def read_poses(mcap_path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], x [T, N], y [T, N], alive [T, N]) from the ``/world/poses`` channel."""
    ts, xs, ys, alive = [], [], [], []
    for topic, t, data in iter_messages(mcap_path):
        if topic == "/world/poses":
            m = json.loads(data)
            ts.append(t / 1e9)
            xs.append(m["x"])
            ys.append(m["y"])
            alive.append(m["alive"])
    return np.array(ts), np.array(xs), np.array(ys), np.array(alive, dtype=bool)


def plot_session(mcap_path: str | Path, plan: Plan, png_path: str | Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Rectangle

    cfg = Config.from_plan(plan.config)
    a = cfg.arena
    t, x, y, alive = read_poses(mcap_path)
    aspect = a.length_m / a.width_m
    fig, ax = plt.subplots(figsize=(7, min(12, max(4, 7 * aspect))), dpi=110)
    gx, gy = np.meshgrid(np.linspace(0, a.width_m, 120), np.linspace(0, a.length_m, int(120 * aspect) + 2))
    lux = cfg.light.illuminance(gx, gy)
    im = ax.imshow(lux, origin="lower", extent=(0, a.width_m, 0, a.length_m), cmap="YlOrBr", alpha=0.45)
    fig.colorbar(im, ax=ax, fraction=0.04, pad=0.02, label="illuminance [lux]")
    if a.map:
        img = occupancy(a)
        h, w = img.shape
        ax.imshow(np.where(img, 1.0, np.nan), origin="upper", cmap="Greys", vmin=0, vmax=1.2,
                  extent=(0, w * a.map_resolution_m, 0, h * a.map_resolution_m))
    ax.add_patch(Rectangle((0, 0), a.width_m, a.length_m, fill=False, lw=2.5, ec="black"))
    for ob in cfg.obstacles:
        if ob.type == "box":
            sx, sy = ob.size[0], ob.size[1]
            c, s = math.cos(math.radians(ob.yaw_deg)), math.sin(math.radians(ob.yaw_deg))
            corner = (ob.x - (c * sx - s * sy) / 2, ob.y - (s * sx + c * sy) / 2)
            ax.add_patch(Rectangle(corner, sx, sy, angle=ob.yaw_deg, color="dimgray"))
        else:
            ax.add_patch(Circle((ob.x, ob.y), ob.radius, color="dimgray"))
    cmap = plt.get_cmap("tab10" if len(plan.robots) <= 10 else "tab20")
    for r in range(len(plan.robots)):
        col = cmap(r % cmap.N)
        if len(t):
            ax.plot(x[:, r], y[:, r], lw=0.9, color=col)
            ax.plot(x[0, r], y[0, r], "o", ms=4, color=col)
            dead = not alive[-1, r]
            ax.plot(x[-1, r], y[-1, r], "X" if dead else "s", ms=7 if dead else 4, color="red" if dead else col,
                    mec="black", mew=0.5)
        else:
            ax.plot(*plan.robots[r].pose[:2], "o", ms=4, color=col)
    dur = t[-1] if len(t) else 0.0
    ax.set_title(f"{cfg.session.name}: {len(plan.robots)} robots, {dur:.1f} s simulated, seed {cfg.session.seed}\n"
                 "o start, square end, red X failed robot", fontsize=9)
    ax.set_xlim(-0.3, a.width_m + 0.3)
    ax.set_ylim(-0.3, a.length_m + 0.3)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    fig.tight_layout()
    fig.savefig(png_path)
    plt.close(fig)
