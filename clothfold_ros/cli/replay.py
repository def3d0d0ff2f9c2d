"""`clothfold replay`: republish a bag with its original timing and QoS."""
from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="replay an MCAP bag (original timing and QoS)")
    p.add_argument("bag", help="bag: x.mcap or a rosbag2 bag directory")
    p.add_argument("--rate", "-r", type=float, default=1.0, help="rate factor (2 = twice as fast)")
    p.add_argument("--topics", nargs="*", default=None, help="only these topics")
    p.add_argument("--loop", "-l", action="store_true", help="repeat until Ctrl-C")
    p.add_argument("--start-offset", type=float, default=0.0, help="skip the first S seconds")
    p.add_argument("--clock", type=float, nargs="?", const=40.0, default=None, metavar="HZ",
                   help="publish /clock from the bag (default 40 Hz)")
    p.add_argument("--delay", type=float, default=1.0, help="seconds to wait for discovery before playing")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..nodes.player_node import main

    argv = [args.bag, "--rate", str(args.rate), "--start-offset", str(args.start_offset), "--delay", str(args.delay)]
    if args.topics:
        argv += ["--topics", *args.topics]
    if args.loop:
        argv.append("--loop")
    if args.clock is not None:
        argv += ["--clock", str(args.clock)]
    return main(argv)
