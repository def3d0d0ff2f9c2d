"""Fidelity benchmark: this simulator against the study's simulator on two folds at 12K.

For each reference of bench/reference/ (README there) it simulates the same fold here, in a
fresh process, and prints the loss, the mean and max per-vertex distance of the final mesh
from the reference's, how far the folded sleeve lies past its target (mean over the folded
vertices of their distance beyond the target across the fold line; the study's simulator
puts it 29 mm past on the 1-s fold) and the wall time, with the bound each must meet:

    T1 fan point 32 (1 s, end angle 170):  within 1.0 mm mean of the reference
    default fold (4 s, end angle 175):    within 0.5 mm mean of the reference

`--baseline COMMIT` also runs both folds with the simulator of an earlier commit (checked out
into a temporary git worktree, run with this venv), so before and after print in one run.
`--points I J ...` adds further fan points of the 1-s fold here only (no reference: their
losses and overshoot, e.g. to see the fix act on other points).

    python bench/bench_reference.py [--baseline 6168a7d] [--area 5e-5] [--points 5 60]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from clothfold_ros.loss import distance_past_target, mean_vertex_distance  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = Path(__file__).resolve().parent / "reference"
FOLDS = {  # name: (h, tilt deg, motion time s, end angle deg, reference file, bound m)
    "T1 point 32": (0.515385, 30.0, 1.0, 170.0, "cipc_T1_point32_12k.npy", 1.0e-3),
    "default 4 s": (0.4462, 51.43, 4.0, 175.0, "cipc_default_4s_12k.npy", 0.5e-3),
}

# One fold in a fresh process; uses only API that the earlier commits have too.
WORKER = r"""
import json, sys, numpy as np
from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.materials import material
from clothfold_ros.sim.runner import flat_start, run_fold
a = json.loads(sys.argv[1])
cot = material("cotton")
g = make_shirt(1, max_area=a["area"])
flat = flat_start(g, cot)
spec = fold_spec("left_sleeve", g.keypoints(flat), a["end"])
out = run_fold(g, spec, cot, 0.5, a["h"], a["tilt"], a["T"])
np.save(a["final"], out.vertices)
np.save(a["target"], out.target)
print("RESULT " + json.dumps(dict(ok=out.success, reason=out.reason, loss=out.loss if out.success else None,
      its=out.newton_iterations, steps=out.steps, wall=out.wall_time)))
"""


def run_fold(pythonpath: Path, area: float, h: float, tilt: float, duration: float, end: float, tmp: Path) -> dict:
    """One fold in a fresh process with the simulator under `pythonpath`; its result and final mesh."""
    tag = f"{os.getpid()}-{time.monotonic_ns()}"
    final, target = tmp / f"final-{tag}.npy", tmp / f"target-{tag}.npy"
    env = dict(os.environ, PYTHONPATH=f"{pythonpath}:{os.environ.get('PYTHONPATH', '')}")
    args = json.dumps(dict(area=area, h=h, tilt=tilt, T=duration, end=end, final=str(final), target=str(target)))
    proc = subprocess.run([sys.executable, "-c", WORKER, args], cwd=pythonpath, env=env, capture_output=True, text=True)
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")), None)
    if line is None:
        raise RuntimeError(f"worker failed ({pythonpath}):\n{proc.stderr[-2000:]}")
    res = json.loads(line[7:])
    res["final"], res["target"] = np.load(final), np.load(target)
    return res


def shirt_and_flat(area: float):
    """The default shirt at max area `area` (m^2) and its flat start (N, 3) m."""
    from clothfold_ros.garment import make_shirt
    from clothfold_ros.materials import material
    from clothfold_ros.sim.runner import flat_start

    g = make_shirt(1, max_area=area)
    return g, flat_start(g, material("cotton"))


def left_sleeve_target(garment, flat: np.ndarray, end: float) -> np.ndarray:
    """The left-sleeve fold's target (the loss's) for the flat shirt, end angle `end` deg."""
    from clothfold_ros.folding import fold_spec
    from clothfold_ros.loss import fold_target
    from clothfold_ros.materials import material

    return fold_target(flat, fold_spec("left_sleeve", garment.keypoints(flat), end), material("cotton").thickness)


def report(tag: str, r: dict, flat: np.ndarray, ref: np.ndarray | None, bound: float | None) -> None:
    if not r["ok"]:
        print(f"  {tag:<9} FAILED: {r['reason']}", flush=True)
        return
    past = distance_past_target(r["final"], flat, r["target"])
    line = (f"  {tag:<9} loss {r['loss'] * 1e3:6.2f} mm; past target {past * 1e3:6.2f} mm; "
            f"wall {r['wall']:6.1f} s; Newton {r['its'] / max(r['steps'], 1):5.1f} its/step")
    if ref is not None:
        d = np.linalg.norm(r["final"] - ref, axis=1)
        verdict = "" if bound is None else (" ok" if d.mean() <= bound else f" OVER the {bound * 1e3:.1f} mm bound")
        line += f"; from the reference {d.mean() * 1e3:.2f} mm mean, {d.max() * 1e3:.1f} mm max{verdict}"
    print(line, flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", help="also run an earlier commit's simulator (e.g. 6168a7d)")
    ap.add_argument("--area", type=float, default=5e-5, help="max triangle area (m^2); the references are 5e-5")
    ap.add_argument("--points", type=int, nargs="*", default=[], help="further T1 fan points (no reference)")
    args = ap.parse_args()
    garment, flat = shirt_and_flat(args.area)
    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        base = None
        if args.baseline:
            base = tmp / f"baseline-{args.baseline}"
            subprocess.run(["git", "worktree", "add", "--detach", str(base), args.baseline], cwd=ROOT, check=True,
                           capture_output=True)
        try:
            for name, (h, tilt, duration, end, ref_file, bound) in FOLDS.items():
                ref = np.load(REFERENCE / ref_file) if args.area == 5e-5 else None
                about = ""
                if ref is not None:
                    target = left_sleeve_target(garment, flat, end)
                    about = (f"; reference loss {mean_vertex_distance(ref, target) * 1e3:.2f} mm, "
                             f"{distance_past_target(ref, flat, target) * 1e3:.2f} mm past target")
                print(f"== {name}: (h {h}, tilt {tilt}), {duration:g} s, end angle {end:g}, max area {args.area:g}{about}",
                      flush=True)
                report("now", run_fold(ROOT, args.area, h, tilt, duration, end, tmp), flat, ref, bound)
                if base is not None:
                    report(args.baseline, run_fold(base, args.area, h, tilt, duration, end, tmp), flat, ref, None)
            if args.points:
                from clothfold_ros.trajectory import fan

                pts = fan()
                print(f"== further T1 fan points (1 s, end angle 170), max area {args.area:g}", flush=True)
                for i in args.points:
                    h, tilt = (float(v) for v in pts[i])
                    report(f"fan {i}", run_fold(ROOT, args.area, h, tilt, 1.0, 170.0, tmp), flat, None, None)
                    if base is not None:
                        report(f"  {args.baseline}", run_fold(base, args.area, h, tilt, 1.0, 170.0, tmp), flat, None, None)
        finally:
            if base is not None:
                subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, capture_output=True)


if __name__ == "__main__":
    main()
