"""The paper's Fig. 3 (trajectories) and Fig. 4 (ego speeds) from Table II runs, as PNG."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

from risk_env import path as ref_path  # noqa: E402
from risk_env.scenario import Scenario  # noqa: E402

COLOURS = {"low": "tab:green", "medium": "tab:orange", "high": "tab:red"}
MARKER_STEPS = 3
"""Markers every 1.5 s (3 steps of 0.5 s), as in the paper's Fig. 3."""
OBJECT_STEP = 18
"""The object is drawn at 9 s, as in the paper's Fig. 3."""


def _pick(rows: list[dict[str, Any]], method: str, eps: float) -> list[dict[str, Any]]:
    risks = sorted({r["risk_method"] for r in rows if r["method"] == method})
    preferred = {"RMPC": "worst_case", "SMPC": "exact"}[method]
    risk = preferred if preferred in risks else (risks[0] if risks else None)
    return [r for r in rows if r["method"] == method and r["risk_method"] == risk and r["epsilon"] == eps]


def _key(r: dict[str, Any], name: str) -> str:
    return f"{r['method']}/{r['risk_method']}/{r['uncertainty']}/eps={r['epsilon']:g}/{name}"


def paper_figures(rows: list[dict[str, Any]], arrays: dict[str, np.ndarray], out: Path) -> list[Path]:
    """Write ``fig3_trajectories.png`` and ``fig4_velocities.png``; returns their paths."""
    tolerances = sorted({r["epsilon"] for r in rows})
    if not tolerances:
        return []
    shown = [tolerances[0], tolerances[-1]] if len(tolerances) > 1 else tolerances
    methods = [m for m in ("RMPC", "SMPC") if any(r["method"] == m for r in rows)]
    scenario = Scenario()
    lam = np.linspace(scenario.path.lambda_start, 5.0, 300)
    px, py, _ = ref_path.point(scenario.path, lam)

    fig, axes = plt.subplots(
        len(shown), len(methods), figsize=(6.5 * len(methods), 4.2 * len(shown)), squeeze=False
    )
    for i, eps in enumerate(shown):
        for j, method in enumerate(methods):
            ax = axes[i, j]
            ax.plot(px, py, "k--", lw=1, label="reference path")
            for r in _pick(rows, method, eps):
                ego, obj = arrays[_key(r, "ego")], arrays[_key(r, "object")]
                c = COLOURS[r["uncertainty"]]
                ax.plot(
                    ego[:, 0],
                    ego[:, 1],
                    color=c,
                    lw=1.8,
                    label=f"{r['uncertainty']} (d_min {r['d_min']:.1f} m{', COLLIDED' * r['collided']})",
                )
                ax.plot(ego[::MARKER_STEPS, 0], ego[::MARKER_STEPS, 1], "o", color=c, ms=3)
                ax.plot(obj[:, 0], obj[:, 1], color="0.5", lw=1)
                ax.plot(obj[::MARKER_STEPS, 0], obj[::MARKER_STEPS, 1], "s", color="0.5", ms=2.5)
                k = min(OBJECT_STEP, len(obj) - 1)
                ax.add_patch(Circle(obj[k, :2], scenario.object.radius, fc="none", ec="0.3", lw=1))
            ax.add_patch(
                Circle(scenario.ego.start.as_tuple()[:2], scenario.ego.radius, fc="none", ec="b", lw=1)
            )
            ax.set_title(f"{method}, epsilon = {eps:g} J")
            ax.set_aspect("equal")
            ax.set_xlim(-30, 70)
            ax.set_ylim(-12, 35)
            ax.set_xlabel("c1 [m]")
            ax.set_ylabel("c2 [m]")
            ax.legend(fontsize=7, loc="upper left")
            ax.grid(alpha=0.3)
    fig.suptitle("Fig. 3: ego trajectories (markers every 1.5 s; object disc at 9 s; ego at 0 s in blue)")
    fig.tight_layout()
    fig3 = out / "fig3_trajectories.png"
    fig.savefig(fig3, dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, len(methods), figsize=(6.5 * len(methods), 3.6), squeeze=False)
    for j, method in enumerate(methods):
        ax = axes[0, j]
        for eps, style in zip(shown, ("-", "--")):
            for r in _pick(rows, method, eps):
                v = arrays[_key(r, "actions")][:, 0]
                t = scenario.dt * np.arange(len(v))
                ax.step(
                    t,
                    v,
                    style,
                    where="post",
                    color=COLOURS[r["uncertainty"]],
                    label=f"{r['uncertainty']}, eps {eps:g}",
                )
        ax.axhline(scenario.ego.v_ref, color="k", lw=0.8, ls=":", label="v_ref")
        ax.set_title(f"{method}: ego speed")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("v [m/s]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
    fig.suptitle("Fig. 4: ego speeds")
    fig.tight_layout()
    fig4 = out / "fig4_velocities.png"
    fig.savefig(fig4, dpi=110)
    plt.close(fig)
    return [fig3, fig4]
