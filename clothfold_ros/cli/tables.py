"""`clothfold tables`: where the lookup tables stand (lookup/status.py) and what each one's
landscape says (lookup/summary.py), current while sweeps run."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._options import add_tables_option, tables_arg


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("tables", help="runs, failures, best point and CPU cost of each scenario's table, "
                       "and what each landscape says")
    add_tables_option(p)
    p.add_argument("--write", type=Path, nargs="*", default=[],
                   help="also replace the table-status block (and the table-summary and table-headline "
                   "blocks, where a file has them) of these Markdown files")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..lookup import status, summary
    from ..lookup.doc_blocks import replace_block

    root = tables_arg(args)
    try:
        if not root.is_dir():
            raise FileNotFoundError(f"{root} is not a directory")
        statuses = status.tables_status(root)
        text, headline = status.markdown(statuses), status.headline(statuses)
        landscapes = summary.markdown(summary.landscape_summaries(root))
        edited = {f: status.replace_headline(replace_block(status.replace_block(f.read_text(), text), landscapes,
                                                           summary.BEGIN, summary.END, required=False), headline)
                  for f in args.write}
    except (OSError, ValueError) as err:
        print(f"clothfold tables: {err}", file=sys.stderr)
        return 2
    for f, new in edited.items():
        f.write_text(new)
    print(text)
    print()
    print(landscapes)
    return 0
