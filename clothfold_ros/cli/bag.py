"""`clothfold bag info|recover`: inspect a bag, rebuild a truncated one."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bag", help="inspect (info) or repair (recover) MCAP bags")
    verbs = p.add_subparsers(dest="bag_command", metavar="VERB")
    info = verbs.add_parser("info", help="files, duration, counts, topics with type, QoS and hash")
    info.add_argument("bag", type=Path)
    info.set_defaults(func=run_info)
    rec = verbs.add_parser("recover", help="rebuild a complete bag from a truncated/killed one")
    rec.add_argument("broken", type=Path)
    rec.add_argument("-o", "--output", type=Path, required=True, help="new complete .mcap")
    rec.add_argument("--force", action="store_true", help="overwrite the output")
    rec.set_defaults(func=run_recover)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def run_info(args: argparse.Namespace) -> int:
    from ..bag import BagError, bag_info

    try:
        print(bag_info(args.bag))
    except BagError as err:
        print(f"clothfold bag info: error: {err}", file=sys.stderr)
        return 1
    return 0


def run_recover(args: argparse.Namespace) -> int:
    from ..bag import BagError, recover

    try:
        report = recover(args.broken, args.output, overwrite=args.force)
    except BagError as err:
        print(f"clothfold bag recover: error: {err}", file=sys.stderr)
        return 1
    print(report.summary())
    return 0
