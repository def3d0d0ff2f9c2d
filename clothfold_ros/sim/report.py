"""Write a fold outcome to disk: loss summary, final mesh, per-step statistics, picture."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import trimesh

from .episode import FoldOutcome


def write_step_stats(outcome: FoldOutcome, path: Path) -> None:
    """CSV with one row per step: time, Newton iterations, contacts, wall time, phases."""
    phases = sorted({k for s in outcome.step_stats for k in s.phases})
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time_s", "newton_iterations", "line_search_halvings", "contacts", "min_distance_m",
                    "kappa", "residual_m_per_s", "wall_time_s", "analyses", "solver_fallbacks"]
                   + [f"{p}_s" for p in phases])
        for s in outcome.step_stats:
            w.writerow([f"{s.time:.4f}", s.newton_iterations, s.line_search_halvings, s.contacts,
                        f"{s.min_distance:.6g}", f"{s.kappa:.6g}", f"{s.residual:.6g}", f"{s.wall_time:.4f}",
                        s.analyses, s.solver_fallbacks]
                       + [f"{s.phases.get(p, 0.0):.4f}" for p in phases])


def phase_totals(outcome: FoldOutcome) -> dict[str, float]:
    """Seconds spent per solver phase over the whole run."""
    tot: dict[str, float] = {}
    for s in outcome.step_stats:
        for k, v in s.phases.items():
            tot[k] = tot.get(k, 0.0) + v
    return dict(sorted(tot.items(), key=lambda kv: -kv[1]))


def plot_result(outcome: FoldOutcome, triangles: np.ndarray, path: Path, title: str = "") -> None:
    """Top-down PNG: simulated cloth (coloured by height) next to the target."""
    loss = f"loss {outcome.loss * 1000:.2f} mm" if outcome.success else f"FAILED: {outcome.reason}"
    plot_top_down(outcome.vertices, outcome.target, triangles, path, f"{title}  {loss}")


def plot_top_down(vertices: np.ndarray, target: np.ndarray, triangles: np.ndarray, path: Path, title: str = "") -> None:
    """Top-down PNG of the cloth vertices (N, 3) beside the target (N, 3), coloured by height."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 5), sharex=True, sharey=True)
    top = 1000 * max(float(np.max(vertices[:, 2])), float(np.max(target[:, 2])))  # one colour scale for both
    for ax, verts, name in ((axes[0], vertices, "simulated"), (axes[1], target, "target")):
        order = np.argsort(verts[triangles].mean(axis=1)[:, 2])  # draw higher triangles last
        tpc = ax.tripcolor(verts[:, 0], verts[:, 1], triangles[order], facecolors=verts[triangles[order]].mean(axis=1)[:, 2] * 1000,
                           cmap="viridis", edgecolors="none", vmin=0.0, vmax=top)
        ax.set_title(name)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("y (m)")
    fig.colorbar(tpc, ax=axes, label="height z (mm)", shrink=0.8)
    fig.suptitle(title)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_outcome(outcome: FoldOutcome, triangles: np.ndarray, out_dir: Path, meta: dict, title: str = "") -> dict:
    """Write summary.json, final.ply, target.ply, steps.csv and result.png into out_dir."""
    out_dir.mkdir(parents=True, exist_ok=True)
    trimesh.Trimesh(outcome.vertices, triangles, process=False).export(out_dir / "final.ply")
    trimesh.Trimesh(outcome.target, triangles, process=False).export(out_dir / "target.ply")
    write_step_stats(outcome, out_dir / "steps.csv")
    plot_result(outcome, triangles, out_dir / "result.png", title)
    summary = dict(meta)
    summary.update(
        success=outcome.success,
        reason=outcome.reason,
        loss_m=None if not outcome.success else outcome.loss,
        steps=outcome.steps,
        newton_iterations=outcome.newton_iterations,
        wall_time_s=round(outcome.wall_time, 3),
        phase_seconds={k: round(v, 3) for k, v in phase_totals(outcome).items()},
    )
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary
