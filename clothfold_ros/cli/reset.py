"""`clothfold reset [NODE ...]`: start over with a new shirt (each node's ~/reset service, in order)."""
from __future__ import annotations

import argparse
import sys


def register(sub: argparse._SubParsersAction) -> None:
    from ..nodes.reset import RESET_ORDER

    p = sub.add_parser("reset", help="reset the running pipeline for a new shirt (cloth, keypoints, planner)",
                       description="Call ~/reset (std_srvs/Trigger) of each node in turn. Without NODE: "
                                   f"{', '.join(RESET_ORDER)}, skipping (and naming) those without the service, e.g. "
                                   "cloth_sim_node beside a real robot or keypoint_node with source model, which "
                                   "tracks no folds; a NODE named must answer.")
    p.add_argument("nodes", nargs="*", metavar="NODE",
                   help="node names (their /<node>/reset) or full service names starting with '/'")
    p.add_argument("--timeout", type=float, default=5.0, help="seconds per node for discovery and reply (default 5)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..nodes.reset import RESET_ORDER, exit_code, reset_nodes

    nodes = list(args.nodes) or list(RESET_ORDER)
    try:
        outcomes = reset_nodes(nodes, args.timeout)
    except ValueError as err:
        print(f"clothfold reset: {err}", file=sys.stderr)
        return 2
    for o in outcomes:
        if not o.reached and not args.nodes:
            print(f"{o.node}: skipped ({o.message}: not running, or without one)", file=sys.stderr)
        elif not o.reached or not o.success:
            print(f"{o.node}: FAILED: {o.message}", file=sys.stderr)
        else:
            print(f"{o.node}: {o.message}")
    code = exit_code(outcomes, required=args.nodes)
    if code and not any(o.reached for o in outcomes):
        print("clothfold reset: no node answered (is the pipeline running on this ROS_DOMAIN_ID?)", file=sys.stderr)
    return code
