"""The roy-regions report's figures: the region's area and axes, the formation, D(t) and the execution time against
N, each saved as a PNG under the report's plots and returned as its report line. Apart from the experiment so the
chapters' own figure modules (``regions_ch56``) draw with the same helpers."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bridge.experiments.runner import TrialResult

NAME = "roy-regions"  # the experiment, in each figure's title
# the planner's formation (and the agents' observed shape) as a curve: its index here, ``len(SHAPES)`` for another
SHAPES = ("line", "column", "row", "triangle", "quadrilateral", "pentagon", "hexagon")


def file_name(label: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-." else "-" for ch in label).strip("-")


def finish(fig: Any, axes: list[Any], title: str, path: Path, what: str) -> list[str]:
    """Grid and legend on each axes, the title on the first, the figure saved to ``path``; its report line."""
    import matplotlib.pyplot as plt

    for ax in axes:
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    axes[0].set_title(f"{NAME}: {title}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return [f"![{what}](plots/{path.name})"]


def region_plot(label: str, res: TrialResult, path: Path) -> list[str]:
    """The region's area (top) and semi-axes a, b (bottom) over a mission."""
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7.0, 5.0), dpi=110, sharex=True)
    t = res.curve_x["area"]
    ax1.plot(t, res.curves["area"], lw=1.2)
    ax1.set_ylabel("area pi a b (unit^2)")
    ax2.plot(t, res.curves["a"], lw=1.2, label="a")
    ax2.plot(t, res.curves["b"], lw=1.2, label="b")
    ax2.set_ylabel("semi-axes (unit)")
    ax2.set_xlabel("t (s)")
    return finish(fig, [ax1, ax2], f"region of {label}", path, f"region, {label}")


def formation_plot(runs: dict[str, TrialResult], path: Path) -> list[str]:
    """Per cell, the planner's formation (a step) and the shape the agents made (dots) over a mission."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(runs), 1, figsize=(7.0, 2.6 * len(runs)), dpi=110, squeeze=False)
    for ax, (label, res) in zip(axes[:, 0], runs.items(), strict=True):
        ax.step(res.curve_x["formation"], res.curves["formation"], where="post", lw=1.4, label=f"{label}: planned")
        ax.plot(res.curve_x["shape"], res.curves["shape"], ".", ms=2, alpha=0.5, label="the agents' shape")
        ax.set_yticks(range(len(SHAPES) + 1), [*SHAPES, "other"], fontsize=7)
        ax.set_xlabel("t (s)")
    return finish(fig, list(axes[:, 0]), "formation over time", path, "formations")


def density_plot(runs: dict[str, TrialResult], path: Path) -> list[str]:
    """D(t) over a mission, one trial per cell."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 4.0), dpi=110)
    for label, res in runs.items():
        ax.plot(res.curve_x["density"], res.curves["density"], lw=1.0, label=label)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("structural density D(t)")
    return finish(fig, [ax], "D(t), one trial per cell", path, "D(t)")


def exec_plot(
    by_n: dict[float, np.ndarray],
    fit: Any,
    path: Path,
    label: str = "",
    ylabel: str = "execution time (s, planner + world, wall clock)",
) -> list[str]:
    """Execution time per mission against N: each run, the means and the line through them; ``label`` names the
    runs in the title (e.g. one scenario's), ``ylabel`` the time measured."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 4.0), dpi=110)
    for n, v in by_n.items():
        ax.plot(np.full(len(v), n), v, "o", ms=3, alpha=0.5, color="C0")
    ax.plot(list(by_n), [float(np.mean(v)) for v in by_n.values()], "s", color="C1", label="mean")
    if fit is not None:
        xs = np.linspace(0, max(by_n) * 1.05, 50)
        line = f"{fit.intercept:.3f} + {fit.slope:.4f} N (R^2 {fit.r2:.3f})"
        ax.plot(xs, fit.intercept + fit.slope * xs, "--", color="C2", label=line)
    ax.set_xlabel("agents N")
    ax.set_ylabel(ylabel)
    what = f"execution time against N{', ' + label if label else ''}"
    return finish(fig, [ax], what, path, what)
