"""The figure of ``python -m benchmarks.prediction``: both predictors' boxes over one episode.

One recorded episode of ``intersection-v2`` (the benchmark's first seed), three moments of it as
columns, one predictor per row. Each panel shows the lanes, every vehicle (the ego in blue), each
other vehicle's true path over the next 3 s (black, dashed) and the truncation boxes of its modes
of weight at least the mode threshold at 1.5 s and 3 s (one colour per vehicle, in each mode's own
frame; opacity grows with the mode's weight), with each mode's mean path. The y axis points down,
as highway-env draws its roads, so that left and right turns look as they are named.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Polygon, Rectangle  # noqa: E402

SHOWN_STEPS = (3, 6)
"""The prediction steps whose boxes are drawn (1.5 s and 3 s at T = 0.5 s)."""
MOMENTS = 3
"""Columns: moments of the episode."""
VIEW = 45.0
"""Half width [m] of the view around the junction's centre."""
COLORS = plt.get_cmap("tab10").colors


def _box(mode: Any, n: int) -> np.ndarray:
    """The corners ``(4, 2)`` [m] of ``mode``'s truncation box at step ``n``, in its frame."""
    from risk_env.models.frame import from_frame

    b = mode.beliefs[n]
    hx, hy = float(b.half_x), float(b.half_y)
    dx, dy = from_frame(np.array([-hx, hx, hx, -hx]), np.array([-hy, -hy, hy, hy]), float(b.frame))
    return np.column_stack([float(b.x) + dx, float(b.y) + dy])


def _road(ax: Any, network: Any) -> None:
    from risk_env.highway.lanes.routes import lane_points

    for lane in network.lanes_list():
        s = np.linspace(0.0, float(lane.length), 60)
        width = float(lane.width_at(0.0))
        for r, style in (
            (0.0, {"color": "0.8", "lw": 0.6, "ls": ":"}),
            (width / 2, {"color": "0.6", "lw": 0.5}),
            (-width / 2, {"color": "0.6", "lw": 0.5}),
        ):
            p = lane_points(lane, s, r)
            ax.plot(p[:, 0], p[:, 1], zorder=1, **style)


def _vehicle(ax: Any, m: np.ndarray, color: str) -> None:
    x, y, theta = (float(c) for c in m[:3])
    c, s = np.cos(theta), np.sin(theta)
    corners = np.array([[-2.5, -1.0], [2.5, -1.0], [2.5, 1.0], [-2.5, 1.0]]) @ np.array([[c, s], [-s, c]])
    ax.add_patch(Polygon(corners + [x, y], closed=True, facecolor=color, edgecolor="k", lw=0.5, zorder=4))


def draw(
    steps: list[dict[str, Any]],
    network: Any,
    predictors: dict[str, Any],
    horizon: int,
    threshold: float,
    seed: int,
    path: Path,
) -> Path:
    """Draw ``predictors``' predictions over ``horizon`` steps at :data:`MOMENTS` moments of the
    recorded episode ``steps`` (:func:`benchmarks.prediction.record_episode` of seed ``seed``, on
    ``network``) to ``path``."""
    names = list(predictors)
    last = max(len(steps) - 1 - horizon, 0)
    moments = sorted({int(round(x)) for x in np.linspace(min(2, last), last, MOMENTS)})
    fig, axes = plt.subplots(
        len(names), len(moments), figsize=(4.2 * len(moments), 4.4 * len(names)), squeeze=False
    )
    for row, name in enumerate(names):
        for col, t in enumerate(moments):
            ax = axes[row, col]
            step = steps[t]
            kwargs = {"signals": step["signal"]} if name == "lane+signal" else {}
            mixtures = predictors[name].predict_scene(step["m"], horizon, **kwargs)
            _road(ax, network)
            for k, vid in enumerate(step["ids"]):
                if step["ego"][k]:
                    _vehicle(ax, step["m"][k], "tab:blue")
                    continue
                color = COLORS[k % len(COLORS)]
                _vehicle(ax, step["m"][k], "0.85")
                future = [
                    s["m"][s["ids"].index(vid), :2] for s in steps[t : t + horizon + 1] if vid in s["ids"]
                ]
                future = np.array(future)
                ax.plot(future[:, 0], future[:, 1], "k--", lw=0.8, zorder=5)
                for mode in mixtures[k].above(threshold):
                    alpha = 0.1 + 0.5 * float(mode.weight)
                    for n in (n for n in SHOWN_STEPS if n <= horizon):
                        ax.add_patch(
                            Polygon(_box(mode, n), closed=True, facecolor=color, alpha=alpha, lw=0, zorder=2)
                        )
                        ax.add_patch(
                            Polygon(
                                _box(mode, n),
                                closed=True,
                                fill=False,
                                edgecolor=color,
                                lw=0.6,
                                alpha=min(1.0, 2 * alpha),
                                zorder=3,
                            )
                        )
                    b = mode.beliefs
                    ax.plot(
                        np.asarray(b.x),
                        np.asarray(b.y),
                        color=color,
                        lw=1.0,
                        alpha=min(1.0, 2 * alpha),
                        zorder=3,
                    )
            ax.set_xlim(-VIEW, VIEW)
            ax.set_ylim(VIEW, -VIEW)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"{name}, t = {0.5 * t:g} s", fontsize=10)
    handles = [
        Line2D([], [], color="k", ls="--", lw=0.8, label="true path (3 s)"),
        Rectangle((0, 0), 1, 1, facecolor="tab:orange", alpha=0.4, label="mode boxes at 1.5 s and 3 s"),
        Line2D([], [], color="tab:orange", lw=1.0, label="mode mean"),
        Rectangle((0, 0), 1, 1, facecolor="tab:blue", edgecolor="k", label="ego (highway-env IDM)"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=4, frameon=False, fontsize=9)
    fig.suptitle(
        f"intersection-v2, seed {seed}: truncation boxes of the modes of weight >= {threshold:g}"
        " (opacity: weight)",
        fontsize=11,
    )
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
