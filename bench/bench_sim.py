"""Simulator benchmark: the default left-sleeve fold (h 0.45, tilt 51.4 deg, T 4 s).

Prints, per resolution, wall time per simulated second, Newton iterations per step and
the split of time by solver phase, plus two ratios measured in this same run:
  * fold time / machine baseline (a fixed dense LU of 1500x1500, repeated), so runs on
    different machines compare;
  * fold time / target (30 s at ~3K triangles, 180 s at ~12K on 2 cores).

    python bench/bench_sim.py [--areas 2e-4 5e-5] [--duration 4]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.materials import material
from clothfold_ros.sim.report import phase_totals
from clothfold_ros.sim.runner import flat_start, run_fold

TARGETS = {2e-4: 30.0, 5e-5: 180.0}  # s per 4-s fold on 2 cores (the goals)


def machine_baseline(repeats: int = 5) -> float:
    """Median seconds of a fixed dense LU solve (1500 x 1500), a machine-speed yardstick."""
    rng = np.random.default_rng(0)
    a = rng.standard_normal((1500, 1500)) + 1500 * np.eye(1500)
    b = rng.standard_normal(1500)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        np.linalg.solve(a, b)
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--areas", type=float, nargs="+", default=[2e-4, 5e-5], help="max triangle areas (m^2)")
    ap.add_argument("--duration", type=float, default=4.0)
    args = ap.parse_args()
    base = machine_baseline()
    print(f"machine baseline (dense LU 1500): {base * 1000:.1f} ms")
    cotton = material("cotton")
    for area in args.areas:
        g = make_shirt(1, max_area=area)
        spec = fold_spec("left_sleeve", g.keypoints(flat_start(g, cotton)))
        t0 = time.perf_counter()
        out = run_fold(g, spec, cotton, 0.5, 0.45, 51.4, args.duration)
        wall = time.perf_counter() - t0
        sim_time = args.duration + 0.2
        its = out.newton_iterations / max(out.steps, 1)
        print(f"\n== {len(g.triangles)} triangles ({len(g.vertices)} vertices), max area {area:g} m^2")
        print(f"  result: {'ok' if out.success else 'FAILED ' + out.reason}; loss {out.loss * 1000:.2f} mm")
        print(f"  wall {wall:.1f} s for {sim_time:.1f} s simulated = {wall / sim_time:.1f} s per simulated s")
        print(f"  Newton iterations per step {its:.1f} ({out.newton_iterations} in {out.steps} steps)")
        print(f"  ratio to machine baseline {wall / base:.0f}x")
        if area in TARGETS:
            print(f"  ratio to target ({TARGETS[area]:.0f} s): {wall / TARGETS[area]:.2f}")
        tot = phase_totals(out)
        s = sum(tot.values())
        print("  time by phase: " + ", ".join(f"{k} {v:.1f} s ({100 * v / s:.0f}%)" for k, v in tot.items()))


if __name__ == "__main__":
    main()
