"""`clothfold fold FOLD ... | --sequence`: fold with the pipeline already running (any backend, a
real robot driver included), as `ros2 service call /plan_fold ...` would, stage by stage.

Joins the current ROS_DOMAIN_ID, waits for keypoints, then plans and executes each fold through
/plan_fold (execute: true) and waits for its /fold/result; the next fold is planned from keypoints
stamped after that result (the cloth as it lies now). Stops at the first refused or failed fold.
Every fold that ended is listed at the end, also when a later one times out or the command is
interrupted. Exit code 0 when every fold succeeded, 1 otherwise, 2 on bad arguments, 130 on
SIGINT (Ctrl-C; also when started in the background of a script), 143 on SIGTERM. Starts nothing: start the nodes first (`clothfold launch`, `ros2 launch clothfold_ros
clothfold.launch.py`).
"""
from __future__ import annotations

import argparse
import math
import sys

from ..folding import FOLD_NAMES, FOLD_SEQUENCE


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fold", help="fold with the running pipeline (any backend or a real robot): each fold "
                                    "planned from the keypoints of the cloth as it lies, its result awaited",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("folds", nargs="*", metavar="FOLD", help=f"folds in order ({', '.join(FOLD_NAMES)})")
    p.add_argument("--sequence", action="store_true", help="the whole sequence: " + ", ".join(FOLD_SEQUENCE))
    p.add_argument("--timeout", type=float, default=600.0,
                   help="wall seconds to wait for each fold's result (default 600)")
    p.add_argument("--keypoints-timeout", type=float, default=60.0,
                   help="wall seconds to wait for keypoints, at the start and after each fold (default 60)")
    p.set_defaults(func=run)


def _check(args: argparse.Namespace) -> list[str]:
    """The folds to run; ValueError with the reason the arguments are refused."""
    if args.sequence and args.folds:
        raise ValueError("give FOLD names or --sequence, not both")
    folds = list(FOLD_SEQUENCE) if args.sequence else list(args.folds)
    if not folds:
        raise ValueError("no fold given (FOLD names or --sequence)")
    unknown = [f for f in folds if f not in FOLD_NAMES]
    if unknown:
        raise ValueError(f"unknown fold(s) {', '.join(unknown)}; folds: {', '.join(FOLD_NAMES)}")
    for name in ("timeout", "keypoints_timeout"):
        v = getattr(args, name)
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"--{name.replace('_', '-')} must be a positive number of seconds, got {v}")
    return folds


def run(args: argparse.Namespace) -> int:
    try:
        folds = _check(args)
    except ValueError as err:
        print(f"clothfold fold: {err}", file=sys.stderr)
        return 2
    from ..nodes.pipeline_client import PipelineClient, loss_text
    from .launcher import StopSignals

    outcomes: list = []  # StageOutcome of each fold that ended, kept when a later stage raises
    interrupted = False
    signals = StopSignals().install()  # SIGINT also when started with '&' from a script; SIGTERM the same
    try:
        with PipelineClient("clothfold_fold") as client:
            try:
                client.wait_keypoints(args.keypoints_timeout)
            except TimeoutError as err:
                raise TimeoutError(f"{err} (is the pipeline running on this ROS_DOMAIN_ID?)") from None
            client.fold_in_turn(folds, args.timeout, keypoints_wait=args.keypoints_timeout,
                                say=lambda line: print(line, flush=True), outcomes=outcomes)
    except (RuntimeError, TimeoutError) as err:
        print(f"clothfold fold: {err}", file=sys.stderr)
    except KeyboardInterrupt:
        interrupted = True
        print(f"clothfold fold: interrupted ({signals.name}; the fold under way, if any, goes on; its result is "
              "not awaited)", file=sys.stderr)
    finally:
        signals.restore()
    for o in outcomes:
        print(f"{o.fold}: {loss_text(o.loss, o.success)} {'ok' if o.success else 'FAILED ' + o.reason}", flush=True)
    if interrupted:
        return signals.exit_code(130)
    return 0 if len(outcomes) == len(folds) and all(o.success for o in outcomes) else 1
