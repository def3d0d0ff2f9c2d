"""`clothfold demo`: the whole pipeline as separate processes, one recorded fold (or the sequence).

Starts the recorder and every node (cloth_sim_node or kinematic_robot_node, keypoint_node,
fold_planner_node, trajectory_node) as their own processes on a private ROS domain with
localhost-only discovery, plans and executes the default shirt's left sleeve (or, with
--sequence, left sleeve, right sleeve, left side, right side, middle, re-planning each
stage from the keypoints of the cloth as it is then), prints each loss and the bag path,
and stops every process (the recorder with SIGINT, so the bag is complete). SIGINT (Ctrl-C, also
when started in the background of a script) or SIGTERM to the demo stop every process it started
and close the bag the same way (exit status 130 / 143); a
node that exits during a fold (e.g. a killed backend) ends the demo at once with a failure.
Relative --bags paths are below the checkout when run from source, else the current directory.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

from ..folding import FOLD_NAMES, FOLD_SEQUENCE
from ..nodes.backends import BACKENDS, DEFAULT_BACKEND


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="fold the default shirt's left sleeve through the ROS pipeline; record a bag")
    demo_backends = [b for b in BACKENDS.values() if b.demo]
    p.add_argument("--backend", choices=[b.name for b in demo_backends], default=DEFAULT_BACKEND,
                   help="robot backend: " + "; ".join(f"{b.name}: {b.help}" for b in demo_backends)
                   + f" (default {DEFAULT_BACKEND})")
    p.add_argument("--fold", choices=FOLD_NAMES, default="left_sleeve", help="the fold (default left_sleeve)")
    p.add_argument("--sequence", action="store_true", help="fold the whole sequence: " + ", ".join(FOLD_SEQUENCE))
    p.add_argument("--sequence-max-loss", type=float, default=0.15,
                   help="with --sequence: largest loss (m) against the composed target a stage may end with (default 0.15)")
    p.add_argument("--max-area", type=float, default=None,
                   help="sim mesh max triangle area (m^2; default 5e-4, about 1.2K triangles; with --sequence 2e-4, about 3K)")
    p.add_argument("--keypoints", choices=("points", "cloth_state"), default=None,
                   help="keypoint_node source: points: fitted to the sim's camera-like cloud (perception); "
                   "cloth_state: what a camera would see of the simulated mesh, no fitting (default: config file)")
    p.add_argument("--selection", choices=("table", "parameter"), default=None,
                   help="(height ratio, tilt) from the lookup table or the parameters (default: config file)")
    p.add_argument("--tables", default=None, metavar="DIR[:DIR...]",
                   help="the planner's table directories in order of precedence (default: config file, "
                   "config/tables, the 12K tables); e.g. config/tables_1k2 for the first coarse tables' choices")
    p.add_argument("--bags", type=Path, default=Path("bags"),
                   help="bag directory (default bags/: in the checkout from source, else in the current directory)")
    p.add_argument("--name", default=None, help="run name (default demo-<date>-<time>)")
    p.add_argument("--domain-id", type=int, default=None, help="ROS_DOMAIN_ID (default: from the process id)")
    p.add_argument("--timeout", type=float, default=900.0, help="seconds allowed per fold")
    p.add_argument("--quiet", action="store_true", help="do not echo the nodes' output")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..nodes.resources import DEFAULT_PARAMS, work_dir
    from .launcher import Launcher, StopSignals, node_command

    # checked before anything is started or created: one line, exit code 2
    if not (math.isfinite(args.timeout) and args.timeout > 0):
        print(f"clothfold demo: --timeout must be a positive number of seconds, got {args.timeout}", file=sys.stderr)
        return 2
    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        print(f"clothfold demo: --domain-id must be in 0..232, got {args.domain_id}", file=sys.stderr)
        return 2
    tic = time.monotonic()
    # SIGTERM: the same clean stop as Ctrl-C; SIGINT also when started with '&' from a script (inherited
    # ignored); exit status 130 / 143
    signals = StopSignals().install()
    folds = list(FOLD_SEQUENCE) if args.sequence else [args.fold]
    name = args.name or time.strftime("demo-%Y%m%d-%H%M%S")
    bags = args.bags if args.bags.is_absolute() else work_dir() / args.bags
    bags.mkdir(parents=True, exist_ok=True)
    bag = bags / f"{name}.mcap"
    domain = args.domain_id if args.domain_id is not None else 100 + os.getpid() % 50
    os.environ["ROS_DOMAIN_ID"] = str(domain)  # the in-process client joins the same domain
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    if args.max_area is None:
        args.max_area = 2e-4 if args.sequence else 5e-4
    overrides: dict[str, dict] = {"cloth_sim_node": {"max_area": args.max_area}}
    if args.selection:
        overrides["fold_planner_node"] = {"selection": args.selection}
    if args.tables:
        overrides.setdefault("fold_planner_node", {})["table_dir"] = args.tables
    if args.keypoints:
        overrides["keypoint_node"] = {"source": args.keypoints, "max_area": args.max_area}
    if args.sequence:
        # Tables exist for the sleeve stages only (docs/lookup.md): the side and middle folds
        # take the nearest table's choice, or the planner's parameters (h 0.45, tilt 0) if no
        # table can be used; a stage fails only when its loss against the composed target
        # exceeds sequence_max_loss (errors of earlier stages are part of that loss).
        overrides.setdefault("fold_planner_node", {}).update(fallback_to_parameters=True, height_ratio=0.45,
                                                              tilt_deg=0.0)
        overrides["cloth_sim_node"]["max_loss"] = args.sequence_max_loss
    print(f"[demo] {args.backend} backend, folds: {', '.join(folds)}, ROS_DOMAIN_ID={domain}, bag {bag}", flush=True)
    print(f"[demo] parameters {DEFAULT_PARAMS}", flush=True)
    outcomes: list = []  # StageOutcome of each fold that ended
    code = 1
    launcher = Launcher(domain_id=domain, echo=not args.quiet)
    recorder = None
    try:
        if not DEFAULT_PARAMS.is_file():
            raise RuntimeError(f"no parameters file {DEFAULT_PARAMS}")
        recorder = launcher.start("recorder_node", node_command("recorder_node", args=["--output", str(bag)]))
        launcher.wait_for(recorder, r"recording to", 120)
        launcher.start_pipeline(args.backend, overrides=overrides)
        for p in launcher.procs:
            print(f"[demo] started {p.name} (pid {p.pid})", flush=True)
        from ..nodes.pipeline_client import PipelineClient, loss_text

        with PipelineClient("clothfold_demo") as client:
            client.wait_keypoints(120)
            pictures = StagePictures(client, bag.with_suffix("")) if args.backend == "sim" else None
            for topic in ("/gripper_0/target_pose", "/fold/result"):  # record the fold from its start
                launcher.wait_for(recorder, f"matched {topic} ", 60)

            def finished(stage: int, fold: str, res) -> None:
                png = pictures.finished(stage, fold, res) if pictures is not None else None
                if png:
                    print(f"[demo] {fold}: picture {png}", flush=True)

            try:
                client.fold_in_turn(folds, args.timeout, alive=launcher.check_alive,
                                    planned=pictures.planned if pictures is not None else None,
                                    finished=finished, say=lambda line: print(f"[demo] {line}", flush=True),
                                    outcomes=outcomes)  # the finished stages stay when a later one raises
            except RuntimeError as err:
                if "no keypoints of the cloth" in str(err):
                    raise RuntimeError(f"{err}; --keypoints cloth_state skips the fit") from None
                raise
        code = 0 if len(outcomes) == len(folds) and all(o.success for o in outcomes) else 1
    except (RuntimeError, TimeoutError) as err:
        print(f"[demo] error: {err}", file=sys.stderr, flush=True)
        if args.quiet:  # the nodes' output was not shown: their last lines say what each was doing
            for p in launcher.procs:
                for line in p.lines[-4:]:
                    print(f"[demo]   {p.name}: {line}", file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        print(f"[demo] interrupted ({signals.name}): stopping every process", file=sys.stderr, flush=True)
        code = signals.exit_code(130)
    finally:
        # a second Ctrl-C / SIGTERM must not cut the clean-up short (every stop below is bounded)
        signals.ignore()
        closed = None
        try:
            if recorder is not None:
                if recorder.alive() and not signals.received:
                    time.sleep(1.0)  # let the recorder write what is in flight (the last result)
                launcher.stop(recorder, timeout=30)
                closed = next((ln for ln in recorder.lines if "bag closed" in ln), None)
            launcher.stop_all()
        finally:
            signals.restore()
    print("[demo] ---", flush=True)
    for o in outcomes:
        print(f"[demo] {o.fold}: {loss_text(o.loss, o.success)} {'ok' if o.success else 'FAILED ' + o.reason}",
              flush=True)
    print(f"[demo] bag: {bag} ({closed or 'recorder did not report closing the bag'})", flush=True)
    print(f"[demo] wall time {time.monotonic() - tic:.1f} s; all processes stopped", flush=True)
    return code


class StagePictures:
    """One top-down PNG per executed stage: the cloth as /cloth/state reports it after the
    fold, beside the composed target (the flat shirt with the folds the plan assumed made, as
    cloth_sim_node composes it, and the fold)."""

    def __init__(self, client, stem: Path) -> None:
        from ..nodes.conversions import cloth_state_from_msg

        self.client = client
        self.stem = stem
        state = cloth_state_from_msg(client.wait_state(60))
        self.triangles = state.triangles
        self.thickness = state.thickness
        self.flat = state.vertices.copy()
        self.target = self.flat  # the base of the first fold
        self.spec, self.done, self.specs = None, None, {}

    def planned(self, spec_msg) -> None:
        from ..nodes.conversions import fold_spec_from_msg

        plan = fold_spec_from_msg(spec_msg)
        self.spec, self.done = plan.spec, plan.folds_done

    def finished(self, stage: int, fold: str, res) -> Path | None:
        from ..loss import composed_target, fold_target
        from ..nodes.conversions import cloth_state_from_msg, time_to_ns
        from ..sim.report import plot_top_down

        if self.spec is None:
            return None
        base = self.target
        if self.done is not None and all(n in self.specs for n in self.done):
            base = composed_target(self.flat, [self.specs[n] for n in self.done], self.thickness)
        self.target = fold_target(base, self.spec, self.thickness)
        self.specs[self.spec.name] = self.spec
        try:
            state = cloth_state_from_msg(self.client.wait_state(30, newer_than_ns=time_to_ns(res.header.stamp) - 1))
        except TimeoutError:
            return None
        path = Path(f"{self.stem}-stage{stage}-{fold}.png")
        verdict = f"loss {res.loss * 1000:.1f} mm" if res.success else f"FAILED: {res.reason}"
        plot_top_down(state.vertices, self.target, self.triangles, path,
                      f"stage {stage}: {fold.replace('_', ' ')} (h {res.height_ratio:.2f}, tilt {res.tilt_deg:.0f} deg)"
                      f" - {verdict}")
        return path
