"""Newton convergence over the fan points that used to fail for solver reasons.

Runs, on the current simulator, every tilt-60 fan point and every point of the 12-point
subsets of the first coarse tables (`config/tables_1k2/shape1`, `config/tables_1k2/both_sleeves`,
whose start state is the table's own `start.npz`) at the tables' resolution, and prints
per point whether the run completed, its mean Newton iterations per step and, for a run
that stopped, its reason. A solver failure ("Newton did not converge",
"line search stalled", "linear solve failed") is a bug; only a physical failure (the
grippers force the cloth into itself) may be reported as a result.

    python scripts/solver_convergence.py [--tables config/tables_1k2] [--workers 2] [--points tilt60,table]
                                         [--also shape1:2e-4:2 ...]

--also SCENARIO:MAX_AREA:POINT adds one fan point of a scenario at a mesh resolution (with
its shipped table's settings, else the sweep's defaults). Default: shape1 fan point 2 (h 0.169,
tilt 60) at 3K triangles, which stalled in a contact limit cycle at t = 2.32 s during the
resolution study, and T1 (1-s motion) fan point 1 (h 0.1, tilt 0) at 3K, which hit the Newton
cap at t = 0.28 s (a vertex sliding back and forth past its sticking point) before the
friction overshoot damping.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SOLVER_FAILURES = ("did not converge", "line search stalled", "linear solve failed", "not finite",
                   "CCD allows no step", "non-positive")


def _run(args: tuple[str, dict, int, float, float, str | None]) -> dict:
    from clothfold_ros.lookup.sweep import Job, run_job
    from clothfold_ros.lookup.sweep_dir import LEGACY_END_ANGLE_DEG, SweepSettings

    scenario, settings, point, h, tilt, start = args
    s = SweepSettings(scenario=scenario, max_area=settings["max_area"], dt=settings["dt"],
                      settle_time=settings["settle_time"], newton_tol=settings["newton_tol"],
                      end_angle_deg=settings.get("end_angle_deg", LEGACY_END_ANGLE_DEG))
    tic = time.perf_counter()
    row, _ = run_job(Job(s, point, h, tilt, start))
    row["scenario"] = scenario
    row["max_area"] = settings["max_area"]
    row["wall_s"] = time.perf_counter() - tic
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tables", type=Path, default=ROOT / "config" / "tables_1k2")
    ap.add_argument("--scenarios", nargs="+", default=["shape1", "both_sleeves"])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--points", default="tilt60,table", help="tilt60 and/or table (the table's own points)")
    ap.add_argument("--also", nargs="*", default=["shape1:2e-4:2", "T1:2e-4:1"], metavar="SCENARIO:MAX_AREA:POINT",
                    help="extra runs: a scenario (its shipped table's settings, else the sweep's defaults) at a resolution")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from clothfold_ros.trajectory import fan

    f = fan()
    jobs = []
    for sc in args.scenarios:
        d = args.tables / sc
        settings = json.loads((d / "settings.json").read_text())
        start = str(d / "start.npz") if (d / "start.npz").exists() else None
        pts: set[int] = set()
        if "tilt60" in args.points:
            pts |= set(np.flatnonzero(np.isclose(f[:, 1], 60.0)).tolist())
        if "table" in args.points:
            pts |= {json.loads(ln)["point"] for ln in (d / "runs.jsonl").read_text().splitlines() if ln.strip()}
        jobs += [(sc, settings, int(i), float(f[i, 0]), float(f[i, 1]), start) for i in sorted(pts)]
    from dataclasses import asdict

    from clothfold_ros.lookup.sweep_dir import SweepSettings

    for extra in args.also:
        sc, area, point = extra.split(":")
        d = args.tables / sc
        known = (d / "settings.json").exists()  # a shipped table's settings, else the sweep defaults
        settings = dict(json.loads((d / "settings.json").read_text()) if known else asdict(SweepSettings(sc)),
                        max_area=float(area))
        start = str(d / "start.npz") if (d / "start.npz").exists() else None
        jobs.append((sc, settings, int(point), float(f[int(point), 0]), float(f[int(point), 1]), start))
    print(f"{len(jobs)} runs on {args.workers} worker(s): " + ", ".join(args.scenarios + args.also), flush=True)
    solver_failures = physical = 0
    with ProcessPoolExecutor(args.workers) as pool:
        for row in pool.map(_run, jobs):
            reason = row["reason"]
            kind = "ok" if row["success"] else ("SOLVER FAILURE" if any(k in reason for k in SOLVER_FAILURES) else "physical failure")
            solver_failures += kind == "SOLVER FAILURE"
            physical += kind == "physical failure"
            loss = f"{row['loss_m'] * 1000:7.2f} mm" if row["success"] else "   -   "
            area = f"@{row['max_area']:g}" if row["max_area"] != 5e-4 else ""
            print(f"  {row['scenario'] + area:<13} fan {row['point']:3d} (h {row['height_ratio']:.3f}, tilt {row['tilt_deg']:4.1f}): "
                  f"{kind:<16} loss {loss}  {row['newton_iterations'] / max(row['steps'], 1):5.1f} its/step  "
                  f"{row['wall_s']:6.1f} s  {reason}", flush=True)
    print(f"solver failures: {solver_failures}; physical failures: {physical}; runs: {len(jobs)}")
    return 1 if solver_failures else 0


if __name__ == "__main__":
    sys.exit(main())
