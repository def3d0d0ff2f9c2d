"""The five-fold sequence headless at one resolution; prints the per-stage table and writes a PNG per stage.

    python scripts/sequence_headless.py [--max-area 2e-4] [--out out/sequence]

Every stage's (height ratio, tilt) is what the planner node picks for the flat shirt's keypoints:
the TableSelector over config/tables (the node's default, the 12K tables). On the flat shirt's
keypoints the side folds take shape2's table, nearer to them than both_sides' start state; the
middle fold takes the middle table's choice.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--max-area", type=float, default=2e-4)
    ap.add_argument("--out", type=Path, default=Path("out/sequence"))
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from clothfold_ros.sim.report import plot_top_down
    from clothfold_ros.sim.scene import SceneSettings, build_scene
    from clothfold_ros.sim.sequence import run_sequence, stage_table

    from clothfold_ros.folding import FOLD_SEQUENCE
    from clothfold_ros.lookup.planner_selector import TableSelector

    scene = build_scene(SceneSettings(max_area=args.max_area))
    selector = TableSelector([ROOT / "config" / "tables"])  # the node's default
    choices = {}
    for i, fold in enumerate(FOLD_SEQUENCE):
        sel = selector.select(fold_name=fold, keypoints=scene.garment.keypoints(scene.flat), material="cotton",
                              friction=scene.friction, duration=4.0, stage=i)
        choices[fold] = (float(sel.height_ratio), float(sel.tilt_deg))
        print(f"  {fold}: (h {sel.height_ratio:.3f}, tilt {sel.tilt_deg:.1f}) from table {sel.scenario}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"{len(scene.garment.triangles)} triangles, max area {args.max_area:g} m^2", flush=True)
    tic = time.perf_counter()

    def progress(r) -> None:
        o = r.outcome
        i = FOLD_SEQUENCE.index(r.fold)
        verdict = f"loss {o.loss * 1000:.1f} mm" if o.success else f"FAILED: {o.reason}"
        print(f"  stage {i} {r.fold}: {verdict} ({time.perf_counter() - tic:.0f} s so far)", flush=True)
        plot_top_down(o.vertices, o.target, scene.garment.triangles, args.out / f"stage{i}-{r.fold}.png",
                      f"stage {i}: {r.fold.replace('_', ' ')} (h {r.height_ratio:.2f}, tilt {r.tilt_deg:.0f} deg) - {verdict}")

    results = run_sequence(scene, choices, progress=progress)
    print(stage_table(results))
    return 0 if all(r.outcome.success for r in results) and len(results) == len(choices) else 1


if __name__ == "__main__":
    sys.exit(main())
