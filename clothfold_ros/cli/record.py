"""`clothfold record`: record topics into one MCAP bag (runs recorder_node in this process)."""
from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="record ROS 2 topics into an MCAP bag (rosbag2 layout); Ctrl-C to stop")
    p.add_argument("topics", nargs="*", help="topics to record (default: all non-hidden topics)")
    p.add_argument("-o", "--output", type=Path, required=True, help="bag path: bags/x.mcap or a bag directory")
    p.add_argument("--exclude", default=None, help="regex: skip matching topics")
    p.add_argument("--include-hidden", action="store_true", help="also record hidden topics")
    p.add_argument("--force", action="store_true", help="overwrite an existing bag")
    p.add_argument("--no-tf", action="store_true", help="write no /tf_static and /tf frames (docs/recording.md)")
    p.add_argument("--static-tf", nargs=9, action="append", default=[],
                   metavar=("PARENT", "CHILD", "X", "Y", "Z", "QX", "QY", "QZ", "QW"),
                   help="one more fixed frame in /tf_static (m, quaternion x y z w)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import sys

    if args.output.exists() and not args.force:
        print(f"clothfold record: {args.output} exists (use --force to overwrite)", file=sys.stderr)
        return 2
    from ..nodes.recorder_node import main

    argv = ["--output", str(args.output)]
    if args.topics:
        argv += ["--topics", *args.topics]
    if args.exclude:
        argv += ["--exclude", args.exclude]
    if args.include_hidden:
        argv.append("--include-hidden")
    if args.no_tf:
        argv.append("--no-tf")
    for st in args.static_tf:
        argv += ["--static-tf", *st]
    return main(argv)
