"""`clothfold sweep`: simulate a scenario over the trajectory fan into a resumable table."""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from ..lookup.sweep_dir import STUDY_END_ANGLE_DEG
from ..sim.config import SimConfig
from ._options import TABLES_ROOT, add_stepping_options, output_tables, shipped_tables


def register(sub: argparse._SubParsersAction) -> None:
    from ..lookup.scenario import SCENARIOS

    p = sub.add_parser("sweep", help="run a scenario over the 134-point fan (resumable) into a lookup table")
    p.add_argument("scenario", help=f"one of: {', '.join(SCENARIOS)}")
    p.add_argument("--out", type=Path, default=None,
                   help=f"tables root; the sweep writes <out>/<scenario>/ (default: the checkout's {TABLES_ROOT} "
                   f"from source, ./{TABLES_ROOT} on an install). A stage scenario starts from its previous "
                   "stage's best final mesh: its table in <out>, else the package's shipped one (from source; an "
                   "install carries no final meshes)")
    p.add_argument("--points", default="all", help="'all' (134), 'alternate', 'every:R:T' or comma list of fan indices")
    p.add_argument("--max-area", type=float, default=5e-5,
                   help="max triangle area (m^2); default 5e-5 (12K triangles: the study's resolution, the shipped "
                   "tables'); 5e-4 = 1.2K triangles, the first coarse tables (config/tables_1k2)")
    add_stepping_options(p)
    p.add_argument("--max-newton", type=int, default=SimConfig.max_newton_iterations,
                   help="Newton iterations per step before failing (default: the simulator's)")
    p.add_argument("--end-angle", type=float, default=STUDY_END_ANGLE_DEG,
                   help=f"fold end pose rotation about the fold line (deg; default {STUDY_END_ANGLE_DEG:g}, the "
                   "study's simulations; the resolution study and the 1.2K tables were made at 175)")
    p.add_argument("--workers", type=int, default=None, help="local processes (default: number of cores)")
    p.add_argument("--ray", default=None, metavar="ADDRESS",
                   help="run on Ray: a cluster address, 'auto', or 'local' (a private single-node Ray here)")
    p.add_argument("--nice", type=_niceness, default=10,
                   help="run the local workers at least this nice (default 10: hours of background CPU yield to "
                   "the nodes, tests and a user's commands on the same cores; 0 = as started)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--table-only", action="store_true",
                   help="simulate nothing: write the (partial) table of the runs done so far; its provenance "
                   "lists the missing points")
    p.set_defaults(func=run)


def _niceness(text: str) -> int:
    """argparse type of --nice: an integer 0..19."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 0 <= value <= 19:
        raise argparse.ArgumentTypeError(f"must be 0..19, got {value}")
    return value


def raise_niceness(nice: int) -> None:
    """Make this process (and the workers it starts, which inherit it) at least `nice` nice;
    a niceness can only be raised. ValueError outside 0..19."""
    if not 0 <= nice <= 19:
        raise ValueError(f"--nice must be 0..19, got {nice}")
    current = os.nice(0)
    if nice > current:
        os.nice(nice - current)


def run(args: argparse.Namespace) -> int:
    from ..lookup.scenario import scenario
    from ..lookup.fan_selection import fan_points
    from ..lookup.sweep import SweepSettings, finish, run_sweep

    try:
        sc = scenario(args.scenario)
        points = fan_points(args.points).tolist()
        settings = SweepSettings(sc.name, args.max_area, args.dt, args.settle, args.newton_tol, args.max_newton,
                                 args.end_angle)
    except ValueError as err:
        print(f"clothfold sweep: {err}", file=sys.stderr)
        return 2
    out = args.out if args.out is not None else output_tables()
    d = out / sc.name
    try:
        prev = None if sc.after is None else previous_stage(out, sc.after)
    except FileNotFoundError as err:
        print(f"clothfold sweep: {err}", file=sys.stderr)
        return 2
    command = (f"clothfold sweep {sc.name} --points {args.points} --max-area {args.max_area} --dt {args.dt} "
               f"--settle {args.settle} --newton-tol {args.newton_tol} --max-newton {args.max_newton} "
               f"--end-angle {args.end_angle:g} --out {out}")
    if args.table_only:
        from ..lookup.sweep_dir import Lock, claim_settings, has_runs

        if not has_runs(d):
            print(f"clothfold sweep: {d} holds no runs to tabulate", file=sys.stderr)
            return 2
        try:
            with Lock(d):  # not while a sweep runs here
                claim_settings(d, settings)
                table = finish(d, command, points)
        except (ValueError, RuntimeError) as err:
            print(f"clothfold sweep: {err}", file=sys.stderr)
            return 2
        print(f"{sc.name}: table of the runs so far -> {table}")
        return 0
    from ..lookup.table import write_table

    def tabulate(_row: dict) -> None:  # after every run: a sweep ended mid-way leaves the table of its runs
        write_table(d, command, points)

    try:
        raise_niceness(args.nice)
    except ValueError as err:
        print(f"clothfold sweep: {err}", file=sys.stderr)
        return 2
    try:  # finished (table, packed finals) under the sweep's lock; kept as it is when nothing is new
        rows = run_sweep(settings, d, points, workers=args.workers, ray_address=args.ray, previous_dir=prev,
                         progress=not args.quiet, on_row=tabulate, command=command)
    except (ValueError, FileNotFoundError, RuntimeError) as err:
        print(f"clothfold sweep: {err}", file=sys.stderr)
        return 2
    if not rows:
        print(f"{sc.name}: no run left to do; {d / 'table.csv'} is up to date")
        return 0
    failed = sum(not r["success"] for r in rows)
    print(f"{sc.name}: {len(rows)} runs this call ({failed} failed) -> {d / 'table.csv'}")
    return 0


def previous_stage(out: Path, name: str) -> Path:
    """The table a stage scenario starts from: <out>/<name> when swept there, else the package's
    shipped table (from source), else <out>/<name> (reported as missing). FileNotFoundError when
    only an installed table exists: an install carries the tables, not the final meshes a stage
    starts from."""
    from ..lookup.sweep_dir import FINALS, FINALS_NPZ, TABLE, has_runs

    here = out / name
    if has_runs(here):
        return here
    try:
        shipped = shipped_tables() / name
    except RuntimeError:
        return here
    if has_runs(shipped) and ((shipped / FINALS_NPZ).is_file() or (shipped / FINALS).is_dir()):
        return shipped
    if (shipped / TABLE).is_file():
        raise FileNotFoundError(f"the next stage starts from {name!r}'s best final mesh, and its table at {shipped} "
                                "has none (an install carries the tables' CSV and JSON files, not the sweeps' runs "
                                f"and meshes): sweep {name} into {out} first, or run from a source checkout")
    return here
