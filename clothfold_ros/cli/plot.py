"""`clothfold plot`: a scenario table's loss landscape and best / worst final states, or the
13 landscapes side by side (`--overview`) (PNG)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._options import TABLES_ROOT, add_tables_option, output_tables, tables_arg


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plot", help="PNG loss landscape (fan layout) and best/worst final cloth of lookup tables")
    p.add_argument("scenarios", nargs="*", help="scenario names (default: every table under --tables)")
    add_tables_option(p)
    p.add_argument("--out", type=Path, default=None, help="output folder (default: each table's own folder; for the "
                   f"tables of an install ./{TABLES_ROOT}/<scenario>/)")
    p.add_argument("--overview", action="store_true", help="write only the 13 landscapes side by side, one row per "
                   "study figure group, as landscapes.png in --out (default: the tables root)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..lookup.plot import plot_best_worst, plot_landscape, plot_overview
    from ..lookup.sweep_dir import BEST_WORST_PNG, FINALS_NPZ, LANDSCAPE_PNG, OVERVIEW_PNG, table_dirs

    from ..nodes.resources import SOURCE_CHECKOUT

    try:
        tables = tables_arg(args)
    except RuntimeError as err:
        print(f"clothfold plot: {err}", file=sys.stderr)
        return 2
    out_root = args.out
    if out_root is None and args.tables is None and not SOURCE_CHECKOUT:
        out_root = output_tables()  # never write into an install's share/
    if args.overview:
        try:
            print(plot_overview(tables, (out_root or tables) / OVERVIEW_PNG))
        except (FileNotFoundError, ValueError) as err:
            print(f"clothfold plot: {err}", file=sys.stderr)
            return 1
        return 0
    names = args.scenarios or [d.name for d in table_dirs(tables)]
    if not names:
        print(f"clothfold plot: no tables under {tables}", file=sys.stderr)
        return 2
    rc = 0
    for n in names:
        d = tables / n
        out = out_root / n if out_root else d
        try:
            print(plot_landscape(d, out / LANDSCAPE_PNG))
            if not (d / FINALS_NPZ).is_file():  # an install, or a sweep not finished: no final meshes here
                print(f"clothfold plot: {n}: no best/worst render: the final meshes (finals.npz) are not in {d} "
                      "(an install does not carry them; a sweep writes them when its table is complete)",
                      file=sys.stderr)
                continue
            print(plot_best_worst(d, out / BEST_WORST_PNG))
        except (FileNotFoundError, ValueError) as err:
            print(f"clothfold plot: {n}: {err}", file=sys.stderr)
            rc = 1
    return rc
