"""Simulator benchmark: the default left-sleeve fold, against a tight reference and today's solver.

For each resolution (max triangle area) it runs, each in its own process:
  * fast:      the default settings at the exact fan point (h 0.4462, tilt 51.43 deg);
  * reference: the same fold with the Newton tolerance 100x tighter (settings printed);
  * baseline:  the solver of an earlier commit (default a11945f, checked out into a
               temporary `git worktree`, run with this venv) and the current one at the
               point that solver completes (h 0.45, tilt 51.4), for the speed ratio.
It prints wall time, Newton iterations per step, the phase split, the loss of fast and
reference and the mean / max per-vertex distance between their final meshes, and the
ratios to the baseline and to the targets (20 s at ~3K triangles, 90 s at ~12K).
`--threads N` also runs the fast fold on N threads (PARDISO, CCD, numba kernels; the
result must be bit-for-bit the one-thread result) and measures the targets on it, which
are for 2 cores; every other run uses one thread. `--fan N` also runs N fan points (spread over h and tilt) fast and tight at
`--fan-area` and prints the Spearman rank correlation of their losses. `--tols` also runs
the fold at other Newton tolerances and compares each with the reference (the stopping
rule's calibration). `--double` also runs the fast fold with every Newton system factorized
in double precision (`linear_precision = "double"`) and compares the default mixed-precision
solves with it (speed, loss, final-mesh distance).

    python bench/bench_sim.py [--areas 2e-4 5e-5] [--threads 2] [--baseline a11945f | --no-baseline]
                              [--no-reference] [--double] [--tols 3e-3 1e-2] [--fan 8 --fan-area 5e-4 [--fan-only]]
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

ROOT = Path(__file__).resolve().parents[1]
TARGETS = {2e-4: 20.0, 5e-5: 90.0}  # s per 4-s fold on 2 cores (issue goals)
FAN_POINT = (0.4462, 51.43)  # fan ring 5, the default fold of the study's figures
BASELINE_POINT = (0.45, 51.4)  # the point the earlier solver completes at 3K
TIGHTEN = 100.0

# One fold in a fresh process; works with this tree and with the earlier commit's API.
WORKER = r"""
import json, sys, time, numpy as np
from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.materials import material
from clothfold_ros.sim.config import SimConfig
from clothfold_ros.sim.report import phase_totals
from clothfold_ros.sim.runner import flat_start, run_fold
a = json.loads(sys.argv[1])
cot = material("cotton")
g = make_shirt(1, max_area=a["area"])
spec = fold_spec("left_sleeve", g.keypoints(flat_start(g, cot)))
threads = dict(solver_threads=a["threads"], ccd_threads=a["threads"]) if a["threads"] > 1 else {}
cfg = SimConfig(newton_tol=a["tol"], max_newton_iterations=a["max_it"], **threads, **a.get("config", {}))
small = make_shirt(1, max_area=1e-2)  # compile the numba kernels before the clock starts
run_fold(small, fold_spec("left_sleeve", small.keypoints(flat_start(small, cot))), cot, 0.5, a["h"], a["tilt"], 0.12, config=cfg)
t0 = time.perf_counter()
out = run_fold(g, spec, cot, 0.5, a["h"], a["tilt"], 4.0, config=cfg)
wall = time.perf_counter() - t0
np.save(a["final"], out.vertices)
print("RESULT " + json.dumps(dict(ok=out.success, reason=out.reason, loss=out.loss if out.success else None,
      steps=out.steps, its=out.newton_iterations, wall=wall, triangles=len(g.triangles),
      phases=phase_totals(out), fallbacks=sum(getattr(s, "solver_fallbacks", 0) for s in out.step_stats))))
"""


def run_worker(pythonpath: Path, area: float, h: float, tilt: float, tol: float, max_it: int, tmp: Path,
               threads: int = 1, config: dict | None = None) -> dict:
    """One fold in a fresh process; config: further SimConfig fields (this tree's)."""
    final = tmp / f"final-{os.getpid()}-{time.monotonic_ns()}.npy"
    env = dict(os.environ, PYTHONPATH=f"{pythonpath}:{os.environ.get('PYTHONPATH', '')}",
               NUMBA_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads))
    args = json.dumps(dict(area=area, h=h, tilt=tilt, tol=tol, max_it=max_it, final=str(final), threads=threads,
                           **({"config": config} if config else {})))
    proc = subprocess.run([sys.executable, "-c", WORKER, args], cwd=pythonpath, env=env, capture_output=True, text=True)
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")), None)
    if line is None:
        raise RuntimeError(f"worker failed ({pythonpath}):\n{proc.stderr[-2000:]}")
    res = json.loads(line[7:])
    res["final"] = np.load(final)
    return res


def describe(tag: str, r: dict) -> str:
    tot = sum(r["phases"].values()) or 1.0
    split = ", ".join(f"{k} {100 * v / tot:.0f}%" for k, v in r["phases"].items())
    state = f"loss {r['loss'] * 1000:.2f} mm" if r["ok"] else f"FAILED: {r['reason']}"
    fallbacks = f"; {r['fallbacks']} solved in double after single precision failed" if r.get("fallbacks") else ""
    return (f"  {tag:<10} {state}; wall {r['wall']:.1f} s ({r['wall'] / 4.2:.1f} s per simulated s); "
            f"Newton {r['its'] / max(r['steps'], 1):.1f} its/step ({r['its']} in {r['steps']} steps{fallbacks})\n"
            f"             phases: {split}")


def print_vs(label: str, r: dict, other: dict, name: str) -> None:
    """Loss difference and per-vertex final-mesh distance of run r from the run `other`."""
    if r["ok"] and other["ok"]:
        dist = np.linalg.norm(r["final"] - other["final"], axis=1)
        print(f"             {label}: loss {1000 * (r['loss'] - other['loss']):+.3f} mm; final meshes "
              f"{dist.mean() * 1000:.3f} mm mean, {dist.max() * 1000:.3f} mm max per vertex from {name}", flush=True)


def print_vs_reference(tag: str, r: dict, ref: dict) -> None:
    print_vs(f"{tag} - reference", r, ref, "the reference")


def worktree(commit: str, tmp: Path) -> Path:
    path = tmp / f"baseline-{commit}"
    subprocess.run(["git", "worktree", "add", "--detach", str(path), commit], cwd=ROOT, check=True,
                   capture_output=True)
    return path


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    from scipy.stats import spearmanr

    return float(spearmanr(a, b).statistic)


def fan_check(n: int, area: float, tol: float, max_it: int, tmp: Path) -> None:
    from clothfold_ros.trajectory import fan

    pts = fan()
    idx = np.linspace(0, len(pts) - 1, n).round().astype(int)  # spread over rings (h) and tilts
    print(f"\n== fan subset: {n} points at max area {area:g} m^2, tol {tol:g} vs {tol / TIGHTEN:g} m/s")
    fast, ref = [], []
    for i in idx:
        h, tilt = (float(v) for v in pts[i])
        f = run_worker(ROOT, area, h, tilt, tol, max_it, tmp)
        r = run_worker(ROOT, area, h, tilt, tol / TIGHTEN, 3000, tmp)
        fl = f["loss"] * 1000 if f["ok"] else float("inf")
        rl = r["loss"] * 1000 if r["ok"] else float("inf")
        print(f"  fan {i:3d} (h {h:.3f}, tilt {tilt:4.1f}): fast {fl:7.2f} mm ({f['wall']:.0f} s)"
              f"{'' if f['ok'] else ' FAILED ' + f['reason']}  reference {rl:7.2f} mm ({r['wall']:.0f} s)"
              f"{'' if r['ok'] else ' FAILED ' + r['reason']}", flush=True)
        fast.append(fl)
        ref.append(rl)
    fast_a, ref_a = np.array(fast), np.array(ref)
    ok = np.isfinite(fast_a) & np.isfinite(ref_a)
    print(f"  Spearman rank correlation fast vs reference: {spearman(fast_a[ok], ref_a[ok]):.3f} "
          f"({ok.sum()} points both completed); |loss difference| mean {np.abs(fast_a - ref_a)[ok].mean():.2f} mm")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--areas", type=float, nargs="+", default=[2e-4, 5e-5], help="max triangle areas (m^2)")
    ap.add_argument("--baseline", default="a11945f", help="earlier commit to compare against")
    ap.add_argument("--no-baseline", action="store_true")
    ap.add_argument("--threads", type=int, default=1, help="also run the fast fold on this many threads")
    ap.add_argument("--no-reference", action="store_true")
    ap.add_argument("--double", action="store_true",
                    help="also run the fast fold with double-precision factorizations (linear_precision double)")
    ap.add_argument("--baseline-only", action="store_true", help="only the comparison with the earlier solver")
    ap.add_argument("--tols", type=float, nargs="*", default=[], help="other Newton tolerances to compare (m/s)")
    ap.add_argument("--fan", type=int, default=0, help="also check this many fan points against the reference")
    ap.add_argument("--fan-area", type=float, default=5e-4)
    ap.add_argument("--fan-only", action="store_true", help="only the fan-subset check")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from clothfold_ros.sim.config import SimConfig

    cfg = SimConfig()
    tol = cfg.newton_tol
    print(f"default settings: {cfg}")
    print(f"reference: the same with newton_tol = {tol / TIGHTEN:g} m/s, max_newton_iterations = 3000")
    with tempfile.TemporaryDirectory(prefix="bench_sim_") as d:
        tmp = Path(d)
        base = None if args.no_baseline or args.fan_only else worktree(args.baseline, tmp)
        try:
            for area in ([] if args.fan_only else args.areas):
                print(f"\n== max area {area:g} m^2, left sleeve", flush=True)
                if not args.baseline_only:
                    fast = run_worker(ROOT, area, *FAN_POINT, tol, cfg.max_newton_iterations, tmp)
                    print(f"  {fast['triangles']} triangles, fan point h {FAN_POINT[0]}, tilt {FAN_POINT[1]} deg")
                    print(describe("fast", fast), flush=True)
                    timed = fast
                    if args.threads > 1:
                        timed = run_worker(ROOT, area, *FAN_POINT, tol, cfg.max_newton_iterations, tmp, args.threads)
                        print(describe(f"fast, {args.threads} threads", timed))
                        print(f"             final mesh bit-for-bit the one-thread mesh: "
                              f"{np.array_equal(timed['final'], fast['final'])}; speed-up "
                              f"{fast['wall'] / timed['wall']:.2f}x", flush=True)
                    if args.double:
                        dbl = run_worker(ROOT, area, *FAN_POINT, tol, cfg.max_newton_iterations, tmp,
                                         config={"linear_precision": "double"})
                        print(describe("double", dbl))
                        print_vs("fast - double", fast, dbl, "the all-double run")
                        print(f"             mixed precision speed-up over double: {dbl['wall'] / fast['wall']:.2f}x "
                              f"(per Newton iteration {dbl['wall'] / dbl['its'] / (fast['wall'] / fast['its']):.2f}x)",
                              flush=True)
                    if area in TARGETS:
                        print(f"             ratio to target ({TARGETS[area]:.0f} s on 2 cores), {args.threads}-thread run: "
                              f"{timed['wall'] / TARGETS[area]:.2f}")
                if not (args.no_reference or args.baseline_only):
                    ref = run_worker(ROOT, area, *FAN_POINT, tol / TIGHTEN, 3000, tmp)
                    print(describe("reference", ref), flush=True)
                    print_vs_reference("fast", fast, ref)
                    for other in args.tols:
                        r = run_worker(ROOT, area, *FAN_POINT, other, cfg.max_newton_iterations, tmp)
                        print(describe(f"tol {other:g}", r), flush=True)
                        print_vs_reference(f"tol {other:g}", r, ref)
                if base is not None:
                    now = run_worker(ROOT, area, *BASELINE_POINT, tol, cfg.max_newton_iterations, tmp)
                    old = run_worker(base, area, *BASELINE_POINT, tol, 80, tmp)
                    print(f"  at h {BASELINE_POINT[0]}, tilt {BASELINE_POINT[1]} (completed by {args.baseline}):")
                    print(describe("now", now))
                    print(describe(args.baseline, old))
                    print(f"             speed-up now vs {args.baseline}: {old['wall'] / now['wall']:.2f}x "
                          f"(per Newton iteration {old['wall'] / old['its'] / (now['wall'] / now['its']):.2f}x)", flush=True)
                    print_vs(f"now - {args.baseline}", now, old, args.baseline)
            if args.fan:
                fan_check(args.fan, args.fan_area, tol, cfg.max_newton_iterations, tmp)
        finally:
            if base is not None:
                subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, capture_output=True)


if __name__ == "__main__":
    main()
