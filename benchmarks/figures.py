"""The paper's Fig. 3 (trajectories) and Fig. 4 (ego speeds) from Table II runs, as PNG.

Each panel names its agent and risk method. Every mark is in the legend: the reference path, the
ego's start, each run's trajectory (a colour, line style and marker per uncertainty level), each
object's path, each object where it is at each run's last step, and a cross where a run collided.
Scenes with several objects (``--scene``) draw every one of them.
Runs that coincide are labelled ``(same as ...)`` and stay visible through their line styles.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

from risk_env.models import path as ref_path  # noqa: E402
from risk_env.scenario.scenario import Scenario  # noqa: E402

STYLES = {
    "low": {"color": "tab:green", "ls": "-", "marker": "o", "cross": 13},
    "medium": {"color": "tab:orange", "ls": "--", "marker": "s", "cross": 9.5},
    "high": {"color": "tab:red", "ls": ":", "marker": "^", "cross": 6},
}
"""Colour, line style, marker and collision-cross size of each uncertainty level, so that runs
that coincide, and collisions at the same place, stay visible."""
DASHES = {"low": (0, (5, 2)), "medium": (0, (3, 1, 1, 1)), "high": (0, (1, 1))}
"""Line styles of the highest tolerance's speeds in Fig. 4, one per level."""
MARKER_STEPS = 3
"""Markers every 1.5 s (3 steps of 0.5 s), as in the paper's Fig. 3."""
VIEW_LIMITS = (-30.0, 50.0)
"""Fig. 3 shows c2 [m] within these at most, however far the objects run."""
PREFERRED = {"RMPC": "worst_case", "SMPC": "exact"}
"""The risk method drawn for each MPC when the runs hold several."""


def _pick(rows: list[dict[str, Any]], method: str, eps: float) -> tuple[str | None, list[dict[str, Any]]]:
    """The risk method drawn for ``method`` and its runs at tolerance ``eps``, by uncertainty level."""
    risks = sorted({r["risk_method"] for r in rows if r["method"] == method})
    preferred = PREFERRED[method]
    risk = preferred if preferred in risks else (risks[0] if risks else None)
    runs = [r for r in rows if r["method"] == method and r["risk_method"] == risk and r["epsilon"] == eps]
    order = list(STYLES)
    return risk, sorted(runs, key=lambda r: order.index(r["uncertainty"]))


def _key(r: dict[str, Any], name: str) -> str:
    return f"{r['method']}/{r['risk_method']}/{r['uncertainty']}/eps={r['epsilon']:g}/{name}"


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.allclose(a, b, atol=1e-6))


def _twins(series: list[np.ndarray], names: list[str]) -> list[str]:
    """For each series, ``" (same as NAME)"`` when an earlier one coincides with it, else ``""``."""
    out = []
    for i, s in enumerate(series):
        twin = next((names[j] for j in range(i) if _same(series[j], s)), None)
        out.append(f" (same as {twin})" if twin else "")
    return out


def _legend_extras() -> list[Line2D]:
    """Legend entries for the marks that have no line of their own."""
    return [
        Line2D([], [], ls="none", marker="o", mfc="none", mec="b", ms=8, label="ego at 0 s"),
        Line2D(
            [],
            [],
            ls="none",
            marker="o",
            mfc="none",
            mec="0.3",
            ms=8,
            label="object at each run's last step (dashed, in the run's colour)",
        ),
        Line2D([], [], ls="none", marker="x", color="k", ms=8, mew=2, label="collision"),
    ]


def _objects(arrays: dict[str, np.ndarray], r: dict[str, Any]) -> np.ndarray:
    """The run's objects ``(steps+1, M, 4)``: ``objects`` when stored (several), else ``object``."""
    key = _key(r, "objects")
    return arrays[key] if key in arrays else arrays[_key(r, "object")][:, None, :]


def trajectories(
    rows: list[dict[str, Any]], arrays: dict[str, np.ndarray], out: Path, scenario: Scenario | None = None
) -> Path:
    """Fig. 3: ego trajectories of each MPC at the lowest and highest tolerance (``scenario``: the
    runs' path, discs and objects; default the paper's)."""
    tolerances = sorted({r["epsilon"] for r in rows})
    shown = [tolerances[0], tolerances[-1]] if len(tolerances) > 1 else tolerances
    methods = [m for m in ("RMPC", "SMPC") if any(r["method"] == m for r in rows)]
    scenario = Scenario() if scenario is None else scenario
    radii = [o.radius for o in scenario.objects]
    lam = np.linspace(scenario.path.lambda_start, 5.0, 300)
    px, py, _ = ref_path.point(scenario.path, lam)
    drawn = [_objects(arrays, r) for r in rows if r["method"] in methods]
    ends = [o[-1, i, 1] + radii[i] for o in drawn for i in range(o.shape[1])]
    # the view: the paper's, grown to the objects' paths up to VIEW_LIMITS (objects run on beyond)
    top = max(38.0, max(ends, default=0.0) + 3.0, *(o[:, :, 1].max() + 3.0 for o in drawn))
    bottom = min(-12.0, *(o[:, :, 1].min() - 3.0 for o in drawn))
    bottom, top = max(bottom, VIEW_LIMITS[0]), min(top, VIEW_LIMITS[1])
    height = 6.4 * (top - bottom) / 100.0 + 0.9  # equal aspect over c1 in [-30, 70], plus labels
    fig, axes = plt.subplots(
        len(shown),
        len(methods),
        figsize=(6.8 * len(methods), height * len(shown) + 0.4),
        squeeze=False,
        layout="constrained",
    )
    for i, eps in enumerate(shown):
        for j, method in enumerate(methods):
            ax = axes[i, j]
            risk, runs = _pick(rows, method, eps)
            ax.plot(px, py, "k--", lw=1, label="reference path")
            egos = [arrays[_key(r, "ego")] for r in runs]
            objects = [_objects(arrays, r) for r in runs]
            if objects:
                longest = max(objects, key=len)
                for k in range(longest.shape[1]):
                    ax.plot(
                        longest[:, k, 0],
                        longest[:, k, 1],
                        color="0.5",
                        lw=1,
                        marker="sDv^"[k % 4],
                        ms=2.5,
                        markevery=MARKER_STEPS,
                        label="object path" if longest.shape[1] == 1 else f"object {k} path",
                    )
            twins = _twins(egos, [r["uncertainty"] for r in runs])
            for r, ego, obj, twin in zip(runs, egos, objects, twins):
                style = STYLES[r["uncertainty"]]
                collided = ", collided" if r["collided"] else ""
                ax.plot(
                    ego[:, 0],
                    ego[:, 1],
                    color=style["color"],
                    ls=style["ls"],
                    lw=2.2 if not twin else 1.4,
                    marker=style["marker"],
                    ms=3.5,
                    mfc="none" if twin else style["color"],
                    markevery=MARKER_STEPS,
                    label=f"{r['uncertainty']}{twin}: d_min {r['d_min']:.1f} m{collided}",
                    zorder=3 if twin else 2,
                )
                for k in range(obj.shape[1]):
                    if np.any(obj[-1, k]):  # an absent object's row is zeros
                        at, colour = obj[-1, k, :2], style["color"]
                        ax.add_patch(Circle(at, radii[k], fc="none", ec=colour, ls="--", lw=1.2))
                if r["collided"]:
                    ax.plot(*ego[-1, :2], "x", color=style["color"], ms=style["cross"], mew=2, zorder=4)
            ax.add_patch(
                Circle(scenario.ego.start.as_tuple()[:2], scenario.ego.radius, fc="none", ec="b", lw=1)
            )
            handles, _ = ax.get_legend_handles_labels()
            ax.legend(handles=handles + _legend_extras(), fontsize=7, loc="upper right")
            ax.set_title(f"{method}, {risk} risk, epsilon = {eps:g} J")
            ax.set_aspect("equal")
            ax.set_xlim(-30, 70)
            ax.set_ylim(bottom, top)
            ax.set_xlabel("c1 [m]")
            ax.set_ylabel("c2 [m]")
            ax.grid(alpha=0.3)
    count = len(scenario.objects)
    fig.suptitle(
        "Fig. 3: ego trajectories by uncertainty level (marks every 1.5 s); "
        + ("the object where it is" if count == 1 else f"the {count} objects where they are")
        + " at each run's last step"
    )
    path = out / "fig3_trajectories.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def velocities(
    rows: list[dict[str, Any]], arrays: dict[str, np.ndarray], out: Path, scenario: Scenario | None = None
) -> Path:
    """Fig. 4: the ego's applied speed over time, at the lowest and highest tolerance."""
    tolerances = sorted({r["epsilon"] for r in rows})
    shown = [tolerances[0], tolerances[-1]] if len(tolerances) > 1 else tolerances
    methods = [m for m in ("RMPC", "SMPC") if any(r["method"] == m for r in rows)]
    scenario = Scenario() if scenario is None else scenario
    fig, axes = plt.subplots(1, len(methods), figsize=(6.8 * len(methods), 4.0), squeeze=False)
    for j, method in enumerate(methods):
        ax = axes[0, j]
        risk = None
        for level, style in STYLES.items():
            runs, speeds = [], []
            for eps in shown:
                risk, picked = _pick(rows, method, eps)
                for r in picked:
                    if r["uncertainty"] == level:
                        runs.append(r)
                        speeds.append(arrays[_key(r, "actions")][:, 0])
            twins = _twins(speeds, [f"eps {r['epsilon']:g}" for r in runs])
            for k, (r, v, twin) in enumerate(zip(runs, speeds, twins)):
                t = scenario.dt * np.arange(len(v))
                ax.step(
                    t,
                    v,
                    where="post",
                    color=style["color"],
                    ls="-" if k == 0 else DASHES[level],
                    lw=2.2 if k == 0 else 1.3,
                    label=f"{level}, eps {r['epsilon']:g}{twin}",
                    zorder=3 if twin else 2,
                )
                if r["collided"]:
                    ax.plot(t[-1], v[-1], "x", color=style["color"], ms=style["cross"], mew=2, zorder=4)
        ax.axhline(scenario.ego.v_ref, color="k", lw=0.8, ls=":", label="v_ref")
        handles, _ = ax.get_legend_handles_labels()
        collision = Line2D([], [], ls="none", marker="x", color="k", ms=8, mew=2, label="collision")
        ax.legend(handles=[*handles, collision], fontsize=7, ncol=2)
        ax.set_title(f"{method}, {risk} risk: ego speed")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("v [m/s]")
        ax.grid(alpha=0.3)
    fig.suptitle("Fig. 4: the ego's applied speed (solid: lowest epsilon; dashed or dotted: highest)")
    fig.tight_layout()
    path = out / "fig4_velocities.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def at_a_glance(rows: list[dict[str, Any]], out: Path) -> Path:
    r"""Table II at a glance: d_min and e_acc over $\epsilon$, ours (lines) beside the paper's (hollow)."""
    methods = [m for m in ("RMPC", "SMPC") if any(r["method"] == m for r in rows)]
    method_style = {"RMPC": "--", "SMPC": "-"}
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 3.9), layout="constrained")
    for ax, column, unit in zip(axes, ("d_min", "e_acc"), (" [m]", "")):
        for method in methods:
            risk = _pick(rows, method, 0.0)[0]
            for level, style in STYLES.items():
                runs = sorted(
                    (
                        r
                        for r in rows
                        if (r["method"], r["risk_method"], r["uncertainty"]) == (method, risk, level)
                    ),
                    key=lambda r: r["epsilon"],
                )
                if not runs:
                    continue
                eps = [r["epsilon"] for r in runs]
                ax.plot(
                    eps,
                    [r[column] for r in runs],
                    color=style["color"],
                    ls=method_style[method],
                    marker=style["marker"],
                    ms=5,
                    lw=1.8,
                )
                paper = [r[f"paper_{column}"] for r in runs]
                ax.plot(
                    eps,
                    paper,
                    color=style["color"],
                    ls=method_style[method],
                    lw=0.8,
                    alpha=0.6,
                    marker=style["marker"],
                    mfc="none",
                    ms=8,
                )
                hits = [r for r in runs if r["collided"]]
                ax.plot(
                    [r["epsilon"] for r in hits],
                    [r[column] for r in hits],
                    "x",
                    color="k",
                    ms=7,
                    mew=1.8,
                    zorder=4,
                )
        ax.set_xlabel("risk tolerance epsilon [J]")
        ax.set_ylabel(f"{column}{unit}")
        ax.grid(alpha=0.3)
    handles = [
        *(
            Line2D([], [], color="0.3", ls=method_style[m], label=f"ours: {m}, {_pick(rows, m, 0.0)[0]} risk")
            for m in methods
        ),
        Line2D(
            [],
            [],
            color="0.3",
            lw=0.8,
            alpha=0.6,
            marker="o",
            mfc="none",
            ms=8,
            label="the paper's (thin, hollow)",
        ),
        *(
            Line2D([], [], color=s["color"], marker=s["marker"], ls="none", label=f"{level} uncertainty")
            for level, s in STYLES.items()
        ),
        Line2D([], [], ls="none", marker="x", color="k", ms=7, mew=1.8, label="collision"),
    ]
    axes[0].set_ylim(bottom=0)
    axes[1].set_ylim(bottom=0)
    fig.legend(handles=handles, loc="outside right center", fontsize=8)
    fig.suptitle("Table II at a glance: closest distance d_min and path error e_acc over the tolerance")
    path = out / "table2_at_a_glance.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def paper_figures(
    rows: list[dict[str, Any]], arrays: dict[str, np.ndarray], out: Path, scenario: Scenario | None = None
) -> list[Path]:
    """Write ``fig3_trajectories.png``, ``fig4_velocities.png`` and ``table2_at_a_glance.png``
    (``scenario``: the runs' scene, default the paper's); returns their paths."""
    if not rows or not any(r["method"] in PREFERRED for r in rows):
        return []
    return [
        trajectories(rows, arrays, out, scenario),
        velocities(rows, arrays, out, scenario),
        at_a_glance(rows, out),
    ]
