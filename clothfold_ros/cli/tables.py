"""`clothfold tables`: where the lookup tables stand (lookup/status.py), what each one's
landscape says (lookup/summary.py) and what the planner chooses from them for the default
shirt (lookup/choices.py), current while sweeps run."""
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
                   help="also replace the table-status block (and the table-summary, table-headline and "
                   "table-choices blocks, where a file has them) of these Markdown files "
                   "(the shipped ones: docs/results.md docs/lookup.md config/tables/README.md)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..lookup import choices, status, summary
    from ..lookup.doc_blocks import replace_block

    root = tables_arg(args)
    try:
        if not root.is_dir():
            raise FileNotFoundError(f"{root} is not a directory")
        statuses = status.tables_status(root)
        text, headline = status.markdown(statuses), status.headline(statuses)
        landscapes = summary.markdown(summary.landscape_summaries(root))
        chosen = _choices_or_reason(choices, root)
        edited = {}
        for f in args.write:
            new = status.replace_headline(status.replace_block(f.read_text(), text), headline)
            new = replace_block(new, landscapes, summary.BEGIN, summary.END, required=False)
            edited[f] = replace_block(new, chosen, choices.BEGIN, choices.END, required=False)
    except (OSError, ValueError) as err:
        print(f"clothfold tables: {err}", file=sys.stderr)
        return 2
    for f, new in edited.items():
        f.write_text(new)
    print(text)
    print()
    print(landscapes)
    print()
    print("What the planner chooses for the default shirt (shape 1, cotton, mu 0.5, 4 s):")
    print(chosen)
    return 0


def _choices_or_reason(choices, root: Path) -> str:
    """The planner's choices on the default shirt, or why there are none (no usable table yet)."""
    try:
        return choices.markdown(choices.planner_choices(root))
    except (FileNotFoundError, ValueError) as err:
        return f"No choice: {err}"
