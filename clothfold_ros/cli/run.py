"""`clothfold run <node> [args] [--ros-args ...]`: start one pipeline node in this process
(what `ros2 run clothfold_ros <node>` does on a ROS install)."""
from __future__ import annotations

import argparse
import importlib

from ..nodes.backends import NODES


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run one node (e.g. clothfold run cloth_sim_node --ros-args -p max_area:=2e-3)")
    p.add_argument("node", choices=NODES, help="node to run")
    p.add_argument("args", nargs=argparse.REMAINDER, help="node arguments, then --ros-args ...")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The node's exit code; 130 / 143 when SIGINT / SIGTERM stopped it (SIGINT also when started in
    the background of a script, which starts it ignored)."""
    from .launcher import StopSignals

    signals = StopSignals().install()  # rclpy.init installs its own on top and calls these after its shutdown
    try:
        module = importlib.import_module(f"clothfold_ros.nodes.{args.node}")
        code = int(module.main(list(args.args)) or 0)
    except KeyboardInterrupt:  # before or after the node's spin
        code = 0
    finally:
        signals.restore()
    return signals.exit_code(code)
