"""Where a lookup-table run's loss comes from: its final cloth against the stage's composed
target, split into the part the fold moves and the part that should stay, each into height
(z) and table-plane (xy) error, with the error the stage inherited from its start state.

    python scripts/loss_breakdown.py SCENARIO [POINT ...] [--tables config/tables]

Without POINT: the table's best successful run. Reads the sweep directory only (settings,
start.npz, runs.jsonl and the final states); simulates nothing. Units: mm; frame: the table's
(z up, the table top z = 0); "moved" = vertices whose target lies more than 1 cm from the
previous stage's target (the flat shirt for a first fold).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from clothfold_ros.lookup import sweep_dir as layout
from clothfold_ros.loss import mean_vertex_distance
from clothfold_ros.lookup.sweep import stage_target

MOVED = 0.01  # m: a vertex whose target moved more than this belongs to the folded part


def breakdown(final: np.ndarray, target: np.ndarray, base: np.ndarray) -> dict[str, float]:
    """Loss figures (mm) of final (N, 3) against target (N, 3), the part moved from base (N, 3)
    and the part that stays: mean distance, mean |dz|, mean xy distance, mean offset (x, y, z)."""
    err = final - target
    moved = np.linalg.norm(target - base, axis=1) > MOVED
    out = {"loss": mean_vertex_distance(final, target) * 1e3, "moved_fraction": float(moved.mean())}
    for name, m in (("moved", moved), ("stayed", ~moved)):
        if not m.any():
            continue
        e = err[m]
        out[f"{name}_loss"] = mean_vertex_distance(final[m], target[m]) * 1e3
        out[f"{name}_dz"] = float(np.abs(e[:, 2]).mean() * 1e3)
        out[f"{name}_dxy"] = float(np.linalg.norm(e[:, :2], axis=1).mean() * 1e3)
        for k, axis in enumerate("xyz"):
            out[f"{name}_offset_{axis}"] = float(e[:, k].mean() * 1e3)
        out[f"{name}_z_max"] = float(final[m, 2].max() * 1e3)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario")
    ap.add_argument("points", type=int, nargs="*", help="fan points (default: the best successful run)")
    ap.add_argument("--tables", default="config/tables", help="tables root")
    args = ap.parse_args(argv)
    d = Path(args.tables) / args.scenario
    if not (d / layout.RUNS).exists():
        print(f"no runs in {d}", file=sys.stderr)
        return 2
    rows = {int(r["point"]): r for r in layout.read_runs(d)}  # a half-written last line (a sweep running) is skipped
    best = layout.best_row(list(rows.values()))
    points = args.points or ([int(best["point"])] if best else [])
    if not points:
        print(f"no successful run in {d}", file=sys.stderr)
        return 2
    target = stage_target(d)
    start = layout.start_file(d)
    if start:
        x0, base = layout.read_start(start)
        print(f"{args.scenario}: start state (the previous stage's best result) "
              f"{mean_vertex_distance(x0, base) * 1e3:.1f} mm from that stage's target (inherited)")
    else:
        from clothfold_ros.lookup.sweep import _scene

        base = x0 = _scene(layout.read_settings(d)).flat
    print(f"{args.scenario}: the loss had the cloth not moved (its start state against the target): "
          f"{mean_vertex_distance(x0, target) * 1e3:.1f} mm")
    for p in points:
        if p not in rows:
            print(f"point {p}: no run", file=sys.stderr)
            return 2
        b = breakdown(layout.load_final(d, p).astype(float), target, base)
        r = rows[p]
        print(f"point {p} (h {r['height_ratio']:.3f}, tilt {r['tilt_deg']:.1f} deg): loss {b['loss']:.1f} mm; "
              f"folded part ({b['moved_fraction']:.0%} of the vertices) {b.get('moved_loss', 0):.1f} mm "
              f"(|dz| {b.get('moved_dz', 0):.1f}, xy {b.get('moved_dxy', 0):.1f}, highest vertex "
              f"{b.get('moved_z_max', 0):.1f} mm above the table), part that stays {b.get('stayed_loss', 0):.1f} mm "
              f"(|dz| {b.get('stayed_dz', 0):.1f}, xy {b.get('stayed_dxy', 0):.1f}, mean offset "
              f"({b.get('stayed_offset_x', 0):.1f}, {b.get('stayed_offset_y', 0):.1f}, "
              f"{b.get('stayed_offset_z', 0):.1f}) mm)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
