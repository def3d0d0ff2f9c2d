"""`clothfold tables`: where the lookup tables stand (lookup/status.py), current while sweeps run."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._options import add_tables_option, tables_arg


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("tables", help="runs, failures, best point and CPU cost of each scenario's table")
    add_tables_option(p)
    p.add_argument("--write", type=Path, nargs="*", default=[],
                   help="also replace the table-status block of these Markdown files")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..lookup.status import markdown, replace_block, tables_status

    root = tables_arg(args)
    try:
        if not root.is_dir():
            raise FileNotFoundError(f"{root} is not a directory")
        text = markdown(tables_status(root))
        edited = {f: replace_block(f.read_text(), text) for f in args.write}
    except (OSError, ValueError) as err:
        print(f"clothfold tables: {err}", file=sys.stderr)
        return 2
    for f, new in edited.items():
        f.write_text(new)
    print(text)
    return 0
