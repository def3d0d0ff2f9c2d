"""Benchmark of the point-cloud keypoint estimator (issue 13).

Keypoint error = horizontal distance (mm) between estimated and true keypoints (table
frame), true = the visible (folded-state) keypoints of the mesh the camera saw. Shirts:
shapes 1-3 and --random shirts drawn within docs/method.md's parameter ranges; each lies
rotated by up to --max-rot deg and shifted by up to --max-offset m; the camera
(perception.camera.DepthCamera) adds --noise m depth noise and --dropout.

- flat: one cloud per shirt, estimated from scratch;
- folded (--folded): the study's sequence folded ideally (loss.fold_target composed stage
  by stage, every stage planned from the previous stage's visible keypoints), one cloud
  per stage, each estimated with the folds done and the previous stage's estimate as prior
  (as keypoint_node does);
- time per estimate (process CPU time, one thread) for a cloud of about --points points;
- --simulated: the sequence folded by the IPC simulator (as far as it gets), each
  simulated state's estimate against its visible keypoints;
- --off-plan: capture range of the fold lines: shape 1 folded ideally, every stage as
  planned except one whose line lies -50..50 mm along its normal (toward the grippers) from
  the planned one; that stage's estimate (prior: the previous one) against its visible
  keypoints, and the fitted line's offset from the true one;
- --bag BAG: the clouds of a recorded run (`clothfold demo --sequence` records /cloth/points,
  /cloth/state, /fold/active and /fold/result) taken as keypoint_node takes them (clouds at
  rest, the folds done from the results), each estimated by its chain
  (perception.tracking.estimate_state) and, beside it, by the prior's lines alone and by a
  fresh fit alone; error against the visible keypoints of the simulated cloth (shirt
  --bag-shape at --bag-area, as the run's sim);
- --pipeline: `clothfold demo`'s fold (sim backend) with keypoints from the point cloud and
  from the cloth state (ground truth), loss of each.

    python bench/bench_perception.py --folded
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from clothfold_ros.folding import FOLD_SEQUENCE, fold_spec  # noqa: E402
from clothfold_ros.garment import KEYPOINT_NAMES, SHAPES, ShirtShape, make_shirt  # noqa: E402
from clothfold_ros.loss import fold_target  # noqa: E402
from clothfold_ros.perception.camera import DepthCamera  # noqa: E402
from clothfold_ros.perception.estimator import PerceptionError, estimate_keypoints, flat_area  # noqa: E402
from clothfold_ros.perception.tracking import estimate_state  # noqa: E402
from clothfold_ros.perception.visible import visible_keypoints  # noqa: E402

RANGES = {  # docs/method.md section 1: plausible ranges (shoulder_height: around the presets')
    "bottom_width": (0.6, 0.75), "neck_width": (0.2, 0.4), "neck_depth": (0.0, 0.2), "shoulder_width": (0.4, 0.8),
    "shoulder_height": (0.88, 0.96), "sleeve_width_start": (0.22, 0.34), "sleeve_width_end": (0.14, 0.22),
    "sleeve_length": (0.05, 1.0), "sleeve_angle_deg": (-10.0, 60.0),
}
THICKNESS = 3.18e-4  # m, cotton
OFF_PLAN_SHIFTS_MM = (-50, -40, -30, -20, -10, 0, 10, 20, 30, 40, 50)


def random_shirts(n: int, rng: np.random.Generator) -> list[ShirtShape]:
    out = []
    while len(out) < n:
        try:
            out.append(ShirtShape(**{k: rng.uniform(*r) for k, r in RANGES.items()}))
        except ValueError:
            continue  # not a valid outline (e.g. neck wider than shoulders)
    return out


def placed(vertices: np.ndarray, rng: np.random.Generator, max_rot: float, max_offset: float) -> np.ndarray:
    """Vertices rotated about z by up to max_rot deg and shifted by up to max_offset m."""
    a = math.radians(rng.uniform(-max_rot, max_rot))
    r = max_offset * math.sqrt(rng.random())
    phi = rng.uniform(0, 2 * math.pi)
    c, s = math.cos(a), math.sin(a)
    out = vertices @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]).T
    out[:, :2] += r * np.array([math.cos(phi), math.sin(phi)])
    return out


def errors_mm(kp: dict, truth: dict) -> np.ndarray:
    return np.array([np.linalg.norm((kp[n] - truth[n])[:2]) for n in KEYPOINT_NAMES]) * 1e3


def report(title: str, errs: list[np.ndarray], failures: list[str], n: int) -> None:
    print(f"\n## {title}: {len(errs)} of {n} clouds estimated" + (f", {len(failures)} failed" if failures else ""))
    for f in failures:
        print(f"   failed: {f}")
    if not errs:
        return
    e = np.array(errs)  # (clouds, 13)
    print(f"{'keypoint':<22}{'median':>9}{'p95':>9}{'max':>9}  (mm)")
    for i, name in enumerate(KEYPOINT_NAMES):
        print(f"{name:<22}{np.median(e[:, i]):9.1f}{np.percentile(e[:, i], 95):9.1f}{e[:, i].max():9.1f}")
    print(f"{'overall':<22}{np.median(e):9.1f}{np.percentile(e, 95):9.1f}{e.max():9.1f}")


def shirts(args, rng) -> list[tuple[str, ShirtShape]]:
    out = [(f"shape {k}", SHAPES[k]) for k in args.shapes]
    out += [(f"random {i}", s) for i, s in enumerate(random_shirts(args.random, rng))]
    return out


def bench_flat(args, cam, rng) -> None:
    errs, fails, times = [], [], []
    all_shirts = shirts(args, rng)
    for label, shape in all_shirts:
        g = make_shirt(shape, max_area=args.max_area)
        v = placed(g.vertices, rng, args.max_rot, args.max_offset)
        try:
            est = estimate_keypoints(cam.cloud(v, g.triangles, rng))
        except PerceptionError as err:
            fails.append(f"{label}: {type(err).__name__}: {err}")
            continue
        errs.append(errors_mm(est.keypoints, g.keypoints(v)))
        times.append(est.seconds)
        if args.verbose:
            print(f"{label}: median {np.median(errs[-1]):.1f} mm, max {errs[-1].max():.1f} mm "
                  f"({KEYPOINT_NAMES[int(np.argmax(errs[-1]))]}), residual {est.residual * 1e3:.1f} mm, "
                  f"{est.seconds * 1e3:.0f} ms")
    report("flat", errs, fails, len(all_shirts))
    if times:
        print(f"CPU time per estimate: median {np.median(times) * 1e3:.0f} ms, max {max(times) * 1e3:.0f} ms")


def bench_folded(args, cam, rng) -> None:
    per_stage = {n: [] for n in FOLD_SEQUENCE}
    fails = {n: [] for n in FOLD_SEQUENCE}
    times = {n: [] for n in FOLD_SEQUENCE}
    all_shirts = shirts(args, rng)
    for label, shape in all_shirts:
        g = make_shirt(shape, max_area=args.max_area)
        g.vertices = placed(g.vertices, rng, args.max_rot, args.max_offset)  # the shirt lies there, flat
        v, specs = g.vertices.copy(), []
        try:
            prior = estimate_keypoints(cam.cloud(v, g.triangles, rng))
        except PerceptionError as err:
            fails[FOLD_SEQUENCE[0]].append(f"{label}: flat estimate: {err}")
            continue
        first = flat_area(prior.shape)
        for name in FOLD_SEQUENCE:
            try:
                spec = fold_spec(name, visible_keypoints(g, v, specs), folds_done=[s.name for s in specs])
            except ValueError as err:
                fails[name].append(f"{label}: cannot plan: {err}")
                break
            specs.append(spec)
            v = fold_target(v, spec, THICKNESS)
            try:
                est = estimate_state(cam.cloud(v, g.triangles, rng), [s.name for s in specs], prior=prior,
                                     flat_shirt_area=first).estimate
            except PerceptionError as err:
                fails[name].append(f"{label}: {type(err).__name__}: {err}")
                break
            prior = est
            per_stage[name].append(errors_mm(est.keypoints, visible_keypoints(g, v, specs)))
            times[name].append(est.seconds)
    for name in FOLD_SEQUENCE:
        report(f"after {name}", per_stage[name], fails[name], len(all_shirts))
        if times[name]:
            print(f"CPU time per estimate: median {np.median(times[name]) * 1e3:.0f} ms")
    all_e = [e for n in FOLD_SEQUENCE for e in per_stage[n]]
    if all_e:
        e = np.array(all_e)
        print(f"\nfolded, all stages: median {np.median(e):.1f} mm, p95 {np.percentile(e, 95):.1f} mm")


def bench_off_plan(args, cam) -> None:
    import dataclasses

    print("\n## folds off their plan (shape 1): keypoint error median / max (mm), fitted line - true line (mm)")
    print(f"{'fold':13s}" + "".join(f"{d:>12.0f}" for d in OFF_PLAN_SHIFTS_MM))
    for stage in FOLD_SEQUENCE:
        cells = []
        for shift_mm in OFF_PLAN_SHIFTS_MM:
            rng = np.random.default_rng(args.seed)
            g = make_shirt(1, max_area=args.max_area)
            v, specs = g.vertices.copy(), []
            prior = estimate_keypoints(cam.cloud(v, g.triangles, rng))
            first, cell = flat_area(prior.shape), "-"
            for name in FOLD_SEQUENCE[:FOLD_SEQUENCE.index(stage) + 1]:
                spec = fold_spec(name, visible_keypoints(g, v, specs), folds_done=[s.name for s in specs])
                if name == stage:
                    spec = dataclasses.replace(spec, line_point=spec.line_point + shift_mm * 1e-3 * spec.normal)
                specs.append(spec)
                v = fold_target(v, spec, THICKNESS)
                try:
                    prior = estimate_state(cam.cloud(v, g.triangles, rng), [s.name for s in specs], prior=prior,
                                           flat_shirt_area=first).estimate
                except PerceptionError as err:
                    cell = type(err).__name__
                    break
            else:
                e = errors_mm(prior.keypoints, visible_keypoints(g, v, specs))
                off = np.dot(prior.folds[-1].point - specs[-1].line_point[:2], specs[-1].normal[:2]) * 1e3
                cell = f"{np.median(e):.0f}/{e.max():.0f} {off:+.0f}"
            cells.append(cell)
        print(f"{stage:13s}" + "".join(f"{c:>12s}" for c in cells), flush=True)


def bench_simulated(args, rng) -> None:
    """The sequence on the IPC simulator (shape 1, cotton, mu 0.5, (h, tilt) = (0.723, 30),
    args.sim_area), each stage planned from the simulated state's visible keypoints, until a
    fold fails; the estimate of each folded state against its visible keypoints."""
    from clothfold_ros.materials import material
    from clothfold_ros.sim.runner import flat_start, run_fold

    cotton = material("cotton")
    g = make_shirt(1, max_area=args.sim_area)
    cam = DepthCamera(noise=args.noise, dropout=args.dropout)
    v = flat_start(g, cotton)
    base, specs = v.copy(), []
    prior = estimate_keypoints(cam.cloud(v, g.triangles, rng))
    first = flat_area(prior.shape)
    print(f"\n## simulated sequence (shape 1, {len(g.triangles)} triangles, (0.723, 30))")
    for name in FOLD_SEQUENCE:
        spec = fold_spec(name, visible_keypoints(g, v, specs), folds_done=[s.name for s in specs])
        tic = time.monotonic()
        out = run_fold(g, spec, cotton, 0.5, 0.723, 30.0, vertices=v, target_base=base)
        if not out.success:
            print(f"{name}: the simulated fold failed ({out.reason}); stopping after {time.monotonic() - tic:.0f} s")
            return
        specs.append(spec)
        v, base = out.vertices, out.target
        truth = visible_keypoints(g, v, specs)
        try:
            est = estimate_state(cam.cloud(v, g.triangles, rng), [s.name for s in specs], prior=prior,
                                 flat_shirt_area=first).estimate
        except PerceptionError as err:
            print(f"{name}: fold loss {out.loss * 1e3:.1f} mm; estimate failed: {type(err).__name__}: {err}")
            return
        prior = est
        e = errors_mm(est.keypoints, truth)
        worst = KEYPOINT_NAMES[int(np.argmax(e))]
        print(f"{name}: fold loss {out.loss * 1e3:.1f} mm; keypoint error median {np.median(e):.1f} mm, "
              f"max {e.max():.1f} mm ({worst}); residual {est.residual * 1e3:.1f} mm")


def bench_bag(args) -> None:
    from clothfold_msgs.msg import ClothState, FoldResult, FoldSpec as FoldSpecMsg
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import PointCloud2

    from clothfold_ros.bag import BagReader
    from clothfold_ros.nodes import conversions as rc
    from clothfold_ros.nodes.keypoint_node import cloud_from_msg

    g = make_shirt(args.bag_shape, max_area=args.bag_area)
    kinds = {"/cloth/points": PointCloud2, "/cloth/state": ClothState, "/fold/active": FoldSpecMsg,
             "/fold/result": FoldResult}
    events, states = [], {}
    logged: dict[tuple[str, int], int] = {}  # (topic, header stamp) -> log time of a cloud or state (ns)
    for m in BagReader(args.bag).messages(list(kinds)):
        msg = deserialize_message(m.data, kinds[m.topic])
        stamp = rc.stamp_ns(msg.header, m.topic)
        if m.topic in ("/cloth/state", "/cloth/points"):
            logged[(m.topic, stamp)] = m.log_time_ns
        if m.topic == "/cloth/state":
            states[stamp] = rc.cloth_state_from_msg(msg).vertices
        elif m.topic == "/cloth/points":
            events.append((stamp, 1, cloud_from_msg(msg)))
        else:
            events.append((stamp, 0, rc.fold_spec_from_msg(msg) if m.topic == "/fold/active" else msg))
    events.sort(key=lambda e: e[:2])
    print(f"\n## recorded run {args.bag} (shape {args.bag_shape}, {len(g.triangles)} triangles): keypoint error "
          "median / max (mm) against the simulated cloth's visible keypoints, residual (mm)")
    print("| after | cloud at (s) | chain: start | chain | prior's lines kept | fresh fit |")
    print("|---|---|---|---|---|---|")
    specs, failed, active, held = [], None, None, None
    prior = first = None
    used: set[int] = set()  # log times (ns) of the clouds estimated and their states
    queue = list(events)
    while queue:
        stamp, _, item = queue.pop(0)
        if isinstance(item, FoldResult):
            specs += [active.spec] if item.success else []
            failed, active = (None if item.success else active.spec.name), None
            if held is not None:
                queue.insert(0, held)
                held = None
            continue
        if not isinstance(item, np.ndarray):
            active = item
            continue
        if active is not None:
            held = (stamp, 1, item)  # a fold is moving the cloth: the last cloud is taken after its result
            continue
        names, truth = [s.name for s in specs], visible_keypoints(g, states[stamp], specs)
        used.update({logged[("/cloth/points", stamp)], logged[("/cloth/state", stamp)]})

        def cell(fit) -> str:
            try:
                est = fit()
            except PerceptionError as err:
                residual = getattr(getattr(err, "estimate", None), "residual", None)
                return type(err).__name__ + (f" ({residual * 1e3:.1f})" if residual is not None else "")
            e = errors_mm(est.keypoints, truth)
            return f"{np.median(e):.0f} / {e.max():.0f} ({est.residual * 1e3:.1f})"

        try:
            state = estimate_state(item, names, prior=prior, failed=failed, flat_shirt_area=first)
        except PerceptionError as err:
            chain = f"rejected: {type(err).__name__}"
        else:
            chain = f"{state.start}"
            kept = cell(lambda: state.estimate)
        alone = cell(lambda: estimate_keypoints(item, folds=names, prior=prior)) if prior is not None else "-"
        fresh = cell(lambda: estimate_keypoints(item, folds=names))
        print(f"| {(names or ['flat'])[-1]} | {stamp * 1e-9:.2f} | {chain} | {kept if chain[0] != 'r' else '-'} "
              f"| {alone} | {fresh} |", flush=True)
        if not chain.startswith("rejected"):  # the folds done stay the bag's results (the truth's folds)
            prior, failed = state.estimate, None
            if not state.folds and first is None:
                first = flat_area(state.estimate.shape)
    if args.bag_subset:  # what this replay used: every fold message, the clouds at rest and their states
        from clothfold_ros.bag import filter_bag

        report = filter_bag(args.bag, args.bag_subset, topics=list(kinds), overwrite=True,
                            keep=lambda m: m.topic.startswith("/fold/") or m.log_time_ns in used)
        print(f"\nsubset written: {report.summary()}")


def bench_time(args, rng) -> None:
    g = make_shirt(1, max_area=args.max_area)
    area = g.to_trimesh().area
    cam = DepthCamera(pitch=math.sqrt(area / args.points), noise=args.noise, dropout=0.0)
    pts = cam.cloud(g.vertices, g.triangles, rng)
    estimate_keypoints(pts)  # warm-up (imports)
    t = []
    for _ in range(args.repeat):
        tic = time.process_time()
        estimate_keypoints(pts)
        t.append(time.process_time() - tic)
    print(f"\n## time per estimate, {len(pts)}-point cloud (shape 1, flat), one thread, {args.repeat} runs: "
          f"median {np.median(t) * 1e3:.0f} ms, min {min(t) * 1e3:.0f} ms, max {max(t) * 1e3:.0f} ms (CPU)")


def bench_pipeline(args) -> None:
    """The demo's fold with keypoints from the cloud vs from the cloth state (ground truth)."""
    from clothfold_ros.cli.launcher import Launcher
    from clothfold_ros.nodes.pipeline_client import PipelineClient

    for source in ("points", "cloth_state"):
        domain = 160 + os.getpid() % 10
        os.environ["ROS_DOMAIN_ID"] = str(domain)
        overrides = {"keypoint_node": {"source": source}}
        with Launcher(domain_id=domain, echo=False) as launcher:
            launcher.start_pipeline("sim", overrides=overrides)
            with PipelineClient("bench_perception") as client:
                client.wait_keypoints(180)
                r = client.plan("left_sleeve", execute=True, timeout=180, retry_refused=30)
                if not r.success:
                    print(f"{source}: planner refused: {r.message}")
                    continue
                res = client.wait_result("left_sleeve", 900)
                print(f"\n## pipeline, keypoints from {source}: left_sleeve loss {res.loss * 1e3:.2f} mm "
                      f"({'success' if res.success else 'FAILED ' + res.reason}); {r.message}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--shapes", type=int, nargs="*", default=[1, 2, 3])
    p.add_argument("--random", type=int, default=20, help="random shirts (default 20)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--noise", type=float, default=0.002, help="depth noise std (m)")
    p.add_argument("--dropout", type=float, default=0.1)
    p.add_argument("--max-rot", type=float, default=20.0, help="deg")
    p.add_argument("--max-offset", type=float, default=0.05, help="m")
    p.add_argument("--max-area", type=float, default=1e-4, help="mesh max triangle area (m^2) of the shirts")
    p.add_argument("--folded", action="store_true", help="also the folded states of the sequence")
    p.add_argument("--points", type=int, default=20000, help="cloud size for the timing")
    p.add_argument("--repeat", type=int, default=10)
    p.add_argument("--off-plan", action="store_true", help="also folds whose line lies off the planned one")
    p.add_argument("--pipeline", action="store_true", help="also the demo fold with perceived vs true keypoints")
    p.add_argument("--simulated", action="store_true", help="also the sequence folded by the IPC simulator")
    p.add_argument("--sim-area", type=float, default=5e-4, help="mesh max triangle area (m^2) for --simulated")
    p.add_argument("--bag", help="also the clouds of a recorded run (MCAP), see above")
    p.add_argument("--bag-subset", help="with --bag: also write the messages the replay used (a small bag) here")
    p.add_argument("--bag-shape", type=int, default=1, help="the recorded run's shirt shape")
    p.add_argument("--bag-area", type=float, default=2e-4, help="the recorded run's mesh max triangle area (m^2)")
    p.add_argument("--verbose", action="store_true")
    args = p.parse_args(argv)
    if args.bag_subset and not args.bag:
        p.error("--bag-subset needs --bag (it keeps the messages the replay of that bag used)")
    rng = np.random.default_rng(args.seed)
    cam = DepthCamera(noise=args.noise, dropout=args.dropout)
    print(f"# perception benchmark: shapes {args.shapes} + {args.random} random, noise {args.noise * 1e3:g} mm, "
          f"dropout {args.dropout:.0%}, rotations <= {args.max_rot:g} deg, offsets <= {args.max_offset * 1e2:g} cm, "
          f"camera pitch {cam.pitch * 1e3:g} mm, mesh {args.max_area:g} m^2")
    bench_flat(args, cam, rng)
    if args.folded:
        bench_folded(args, cam, rng)
    bench_time(args, rng)
    if args.off_plan:
        bench_off_plan(args, cam)
    if args.simulated:
        bench_simulated(args, rng)
    if args.bag:
        bench_bag(args)
    if args.pipeline:
        bench_pipeline(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
