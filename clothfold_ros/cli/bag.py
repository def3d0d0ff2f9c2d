"""`clothfold bag info|recover|filter`: inspect a bag, rebuild a truncated one, copy a selection."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bag", help="inspect (info), repair (recover) or cut (filter) MCAP bags")
    verbs = p.add_subparsers(dest="bag_command", metavar="VERB")
    info = verbs.add_parser("info", help="files, duration, counts, topics with type, QoS and hash")
    info.add_argument("bag", type=Path)
    info.set_defaults(func=run_info)
    rec = verbs.add_parser("recover", help="rebuild a complete bag from a truncated/killed one")
    rec.add_argument("broken", type=Path)
    rec.add_argument("-o", "--output", type=Path, required=True, help="new complete .mcap")
    rec.add_argument("--force", action="store_true", help="overwrite the output")
    rec.set_defaults(func=run_recover)
    flt = verbs.add_parser("filter", help="copy some topics and a time window into a new bag (like ros2 bag convert)")
    flt.add_argument("bag", type=Path)
    flt.add_argument("-o", "--output", type=Path, required=True, help="new bag: x.mcap or a bag directory")
    flt.add_argument("--topics", nargs="+", default=None, help="topics to keep (default: all)")
    flt.add_argument("--exclude", default=None, help="regex: drop matching topics")
    flt.add_argument("--start", type=float, default=None, help="s after the bag's first message: keep from here")
    flt.add_argument("--end", type=float, default=None, help="s after the bag's first message: keep before here")
    flt.add_argument("--force", action="store_true", help="overwrite the output")
    flt.set_defaults(func=run_filter)
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


def run_filter(args: argparse.Namespace) -> int:
    import math

    from ..bag import BagError, BagReader
    from ..bag.filter import filter_bag

    try:
        for name in ("start", "end"):
            value = getattr(args, name)
            if value is not None and not (math.isfinite(value) and value >= 0):
                raise BagError(f"--{name} must be a finite number of seconds >= 0, got {value}")
        with BagReader(args.bag) as bag:
            t0 = bag.start_ns
        window = [None if v is None else t0 + round(v * 1e9) for v in (args.start, args.end)]
        report = filter_bag(args.bag, args.output, topics=args.topics, exclude=args.exclude, start_ns=window[0],
                            end_ns=window[1], overwrite=args.force)
    except BagError as err:
        print(f"clothfold bag filter: error: {err}", file=sys.stderr)
        return 1
    print(report.summary())
    return 0
