"""`clothfold simulate`: one fold on the IPC simulator without ROS."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..folding import FOLD_NAMES
from ..materials import DEFAULT_FRICTION, MATERIALS
from ._options import add_stepping_options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate one fold headless (no ROS) and write loss, mesh, stats, PNG")
    p.add_argument("--shape", type=int, default=1, choices=(1, 2, 3), help="shirt shape preset (docs/method.md section 1)")
    p.add_argument("--material", default="cotton", help=", ".join(MATERIALS))
    p.add_argument("--friction", type=float, default=DEFAULT_FRICTION, help="Coulomb coefficient for every contact")
    p.add_argument("--fold", default="left_sleeve", choices=FOLD_NAMES, help="the fold (default left_sleeve)")
    p.add_argument("--height-ratio", type=float, default=0.45)
    p.add_argument("--tilt", type=float, default=51.4, help="tilt angle (deg)")
    p.add_argument("--duration", type=float, default=4.0, help="motion time T (s)")
    p.add_argument("--max-area", type=float, default=1 / 20000, help="max triangle area (m^2); 1/20000 = full")
    add_stepping_options(p)
    p.add_argument("--out", type=Path, default=Path("out/simulate"), help="output directory")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..folding import fold_spec
    from ..plan import FoldPlan
    from ..sim.report import write_outcome
    from ..sim.runner import run_plan
    from ..sim.scene import SceneSettings, build_scene

    # every argument is checked here, before the simulation: a bad one is one line and exit code 2
    try:
        scene = build_scene(SceneSettings(shape=args.shape, max_area=args.max_area, material=args.material,
                                          friction=args.friction, dt=args.dt, newton_tol=args.newton_tol))
        garment, mat, cfg = scene.garment, scene.material, scene.config
        spec = fold_spec(args.fold, garment.keypoints(scene.flat))
        # (h, tilt, T, settle) checked by the plan itself (its trajectory is built here)
        plan = FoldPlan(spec, args.height_ratio, args.tilt, args.duration, args.settle)
        if args.duration < args.dt:
            raise ValueError(f"duration {args.duration:g} s is shorter than one time step (dt {args.dt:g} s): "
                             "no motion step")
        if args.out.exists() and not args.out.is_dir():
            raise ValueError(f"--out {args.out} is not a directory")
    except ValueError as err:
        print(f"clothfold simulate: {err}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()

    def progress(k: int, n: int, stats) -> None:
        if args.quiet:
            return
        el = time.perf_counter() - t0
        eta = el / k * (n - k)
        print(f"\r  step {k}/{n}  t={stats.time:.2f}s  newton {stats.newton_iterations:2d}  "
              f"contacts {stats.contacts:5d}  elapsed {el:6.1f}s  eta {eta:6.1f}s", end="", file=sys.stderr, flush=True)

    print(f"simulating {args.fold} of shape {args.shape} ({len(garment.vertices)} vertices, "
          f"{len(garment.triangles)} triangles), {args.material}, mu={args.friction}, "
          f"h={args.height_ratio}, tilt={args.tilt} deg, T={args.duration} s", file=sys.stderr)
    outcome = run_plan(garment, plan, mat, scene.friction, config=cfg, progress=progress)
    if not args.quiet:
        print(file=sys.stderr)
    meta = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items() if k != "func"}
    meta.update(vertices=len(garment.vertices), triangles=len(garment.triangles))
    summary = write_outcome(outcome, garment.triangles, args.out, meta,
                            title=f"{args.fold} h={args.height_ratio} tilt={args.tilt}")
    if outcome.success:
        print(f"loss {outcome.loss * 1000:.2f} mm  ({outcome.steps} steps, {outcome.newton_iterations} Newton "
              f"iterations, {outcome.wall_time:.1f} s)  -> {args.out}")
    else:
        print(f"FAILED: {outcome.reason}  -> {args.out}")
    return 0 if summary["success"] else 1
