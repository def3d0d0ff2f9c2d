"""`clothfold replay`: republish a bag with its original timing and QoS."""
from __future__ import annotations

import argparse

from ..bag.playback import add_playback_arguments


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="replay an MCAP bag (original timing and QoS)")
    add_playback_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..nodes.player_node import play

    return play(args)
