"""`clothfold shirt`: draw a shirt, one fold and its 134 candidate trajectories to a PNG."""
from __future__ import annotations

import argparse

import numpy as np

from ..folding import FOLD_NAMES, fold_spec
from ..garment import DEFAULT_MAX_AREA, SHAPES, make_shirt
from ..loss import fold_target
from ..materials import material
from ..trajectory import FoldTrajectory, fan


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("shirt", help="draw a shirt mesh, a fold and its trajectory fan to a PNG")
    p.add_argument("--shape", type=int, choices=sorted(SHAPES), default=1, help="shirt shape preset (docs/method.md section 1)")
    p.add_argument("--fold", choices=FOLD_NAMES, default="left_sleeve")
    p.add_argument("--out", default="shirt.png", help="PNG path")
    p.add_argument("--max-area", type=float, default=DEFAULT_MAX_AREA, help="max triangle area (m^2)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = material("cotton").thickness
    g = make_shirt(args.shape, args.max_area, z=2 * t)
    kp = g.keypoints()
    spec = fold_spec(args.fold, kp)
    target = fold_target(g.vertices, spec, t)
    fan_rows = fan()
    trajs = [FoldTrajectory(spec, h, tilt) for h, tilt in fan_rows]
    times = np.linspace(0.0, 4.0, 81)
    cmap = plt.get_cmap("viridis")

    fig, (top, side, front) = plt.subplots(1, 3, figsize=(20, 6.5), gridspec_kw={"width_ratios": [1.5, 1, 1]},
                                           layout="constrained")
    top.triplot(g.vertices[:, 0], g.vertices[:, 1], g.triangles, color="0.75", lw=0.15)
    loop = np.append(g.boundary_loop(), 0)
    top.plot(g.vertices[loop, 0], g.vertices[loop, 1], color="0.3", lw=1.0, label="shirt")
    top.plot(target[loop, 0], target[loop, 1], "r--", lw=1.5, label="target outline")
    for name, p in kp.items():
        top.plot(*p[:2], "k.", ms=5)
        top.annotate(name, p[:2], fontsize=7, xytext=(3, 3), textcoords="offset points")
    span = np.ptp(g.vertices[:, :2], axis=0).max()
    ends = spec.line_point + np.outer([-span, span], spec.line_direction)
    top.plot(ends[:, 0], ends[:, 1], "m-", lw=1.5, label="fold line")

    for tr, (h, _) in zip(trajs, fan_rows):
        colour = cmap(h)
        for path in tr.paths:
            p = path.position(times)
            top.plot(p[:, 0], p[:, 1], color=colour, lw=0.4, alpha=0.6)
            side.plot(spec.side_of_line(p), p[:, 2], color=colour, lw=0.4, alpha=0.6)
            front.plot((p - spec.line_point) @ spec.line_direction, p[:, 2], color=colour, lw=0.4, alpha=0.6)
    for i, (a, b) in enumerate(zip(spec.start_poses, spec.end_poses)):
        approach = a.matrix[:, 2] * 0.06
        top.arrow(*(a.position[:2] - approach[:2]), *approach[:2], width=0.004, color="tab:green",
                  length_includes_head=True)
        top.plot(*a.position[:2], "o", color="tab:green", ms=8, label="gripper start" if i == 0 else None)
        top.plot(*b.position[:2], "s", color="tab:red", ms=8, label="gripper end" if i == 0 else None)
        for ax, x in ((side, spec.side_of_line), (front, lambda q: (q - spec.line_point) @ spec.line_direction)):
            ax.plot(x(a.position), a.position[2], "o", color="tab:green", ms=7)
            ax.plot(x(b.position), b.position[2], "s", color="tab:red", ms=7)

    lo, hi = g.vertices[:, :2].min(axis=0) - 0.05, g.vertices[:, :2].max(axis=0) + 0.05
    top.set_xlim(lo[0], hi[0])
    top.set_ylim(lo[1], hi[1])
    top.set_aspect("equal")
    top.set_title(f"shape {args.shape}, {args.fold}: {len(g.vertices)} vertices, {len(g.triangles)} triangles")
    top.set_xlabel("x (m)")
    top.set_ylabel("y (m)")
    top.legend(loc="lower left", fontsize=8, framealpha=0.9)
    side.axvline(0.0, color="m", lw=1)
    side.set_title("side view: across the fold line")
    side.set_xlabel("distance from fold line, + = grippers' side (m)")
    front.set_title("front view: along the fold line (tilt)")
    front.set_xlabel("position along fold line (m)")
    for ax in (side, front):
        ax.axhline(0.0, color="0.3", lw=1)
        ax.set_ylabel("z (m)")
        ax.set_aspect("equal")
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0.0, 1.0))
    fig.colorbar(sm, ax=[side, front], label="height ratio h", shrink=0.7)
    fig.savefig(args.out, dpi=130)
    plt.close(fig)
    print(f"wrote {args.out}: {len(fan_rows)} trajectories, fold line through {np.round(spec.line_point, 4)} "
          f"along {np.round(spec.line_direction, 4)}")
    return 0
