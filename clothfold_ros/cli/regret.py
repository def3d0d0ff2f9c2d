"""`clothfold regret`: leave-one-scenario-out regret of the selection rules (lookup/regret.py)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._options import add_tables_option, tables_arg

BEGIN = "<!-- regret-summary (clothfold regret) -->"
END = "<!-- /regret-summary -->"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("regret", help="leave-one-scenario-out regret of the lookup selection")
    add_tables_option(p)
    p.add_argument("--out", type=Path, default=None, help="also write the Markdown report here")
    p.add_argument("--partial", action="store_true",
                   help="also hold out and choose from partial tables (default: complete tables only)")
    p.add_argument("--write", type=Path, nargs="*", default=[],
                   help="also replace the regret-summary block (the rules' summary table) of these Markdown files; "
                   "a file without one is left as it is (the shipped ones: docs/results.md docs/lookup.md)")
    p.add_argument("--tie-margins", default=None, metavar="MM,MM,...",
                   help="also report the robust rule's regret for each of these tie margins (mm; default rule: 0.5)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..lookup.doc_blocks import replace_block
    from ..lookup.regret import RULES, evaluate, report, summary, tie_margin_report
    from ..lookup.table import load_tables

    try:
        tables = load_tables(tables_arg(args))
        partial = sorted(n for n, t in tables.items() if not t.complete)
        if not args.partial:
            tables = {n: t for n, t in tables.items() if n not in partial}
        rows = {name: evaluate(tables, name) for name in RULES}
        head = f"{len(tables)} tables: {', '.join(sorted(tables))}"
        if partial:
            head += ("; partial tables included: " if args.partial else "; partial tables left out: ") + \
                ", ".join(f"{n} ({len(t.point)} points)" for n, t in sorted(load_tables(tables_arg(args)).items())
                          if n in partial)
        table = summary(rows)
        text = "\n\n".join([head, table] + [report(r, RULES[name][1]) for name, r in rows.items()])
        if args.tie_margins:
            text += "\n\n" + tie_margin_report(tables, _margins_m(args.tie_margins))
        edited = {f: replace_block(f.read_text(), f"{head}\n\n{table}", BEGIN, END, required=False)
                  for f in args.write}
    except (FileNotFoundError, ValueError, RuntimeError, OSError) as err:
        print(f"clothfold regret: {err}", file=sys.stderr)
        return 2
    if args.out:  # before printing: a closed stdout (| head) must not lose the file
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")
    for f, new in edited.items():
        f.write_text(new)
    print(text)
    return 0


def _margins_m(text: str) -> list[float]:
    """'0,0.5,1' (mm) -> metres; a clear ValueError for anything else."""
    try:
        mm = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"--tie-margins takes millimetres separated by commas, not {text!r}") from None
    if not mm or any(not (m >= 0 and m < float("inf")) for m in mm):
        raise ValueError(f"--tie-margins takes finite millimetres >= 0, not {text!r}")
    return [m * 1e-3 for m in mm]
