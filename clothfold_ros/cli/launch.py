"""`clothfold launch [--backend NAME]`: every pipeline node as its own process
(the pure-Python equivalent of launch/clothfold.launch.py); SIGINT (Ctrl-C, also when started in the
background of a script) or SIGTERM stops them all, exit status 130 / 143; 1 when a node exited by itself."""
from __future__ import annotations

import argparse
from pathlib import Path


def parse_overrides(items: list[str]) -> dict[str, dict[str, str]]:
    """NODE:NAME:=VALUE items -> {node: {name: value}} (ValueError on bad syntax)."""
    out: dict[str, dict[str, str]] = {}
    for item in items:
        node, sep, rest = item.partition(":")
        name, sep2, value = rest.partition(":=")
        if not (sep and sep2 and node and name):
            raise ValueError(f"bad parameter override {item!r}; use NODE:NAME:=VALUE")
        out.setdefault(node, {})[name] = value
    return out


def register(sub: argparse._SubParsersAction) -> None:
    from ..nodes.backends import BACKENDS, DEFAULT_BACKEND
    from ..nodes.resources import DEFAULT_PARAMS

    p = sub.add_parser("launch", help="start all pipeline nodes as separate processes (Ctrl-C stops them)")
    p.add_argument("--backend", choices=sorted(BACKENDS), default=DEFAULT_BACKEND,
                   help="robot backend: " + "; ".join(f"{b.name}: {b.help}" for b in BACKENDS.values())
                   + f" (default {DEFAULT_BACKEND})")
    p.add_argument("--params-file", type=Path, default=DEFAULT_PARAMS, help="ROS 2 parameters YAML")
    p.add_argument("-p", "--param", action="append", default=[], metavar="NODE:NAME:=VALUE",
                   help="override one node parameter (repeatable)")
    p.add_argument("--no-perception", dest="perception", action="store_false",
                   help="do not start keypoint_node: your own perception node publishes /keypoints")
    p.add_argument("--domain-id", type=int, default=None, help="ROS_DOMAIN_ID for all nodes")
    p.add_argument("--record", type=Path, default=None, metavar="BAG", help="also record every topic to BAG")
    p.add_argument("--force", action="store_true", help="with --record: overwrite an existing BAG")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import sys

    from .launcher import Launcher, StopSignals, node_command, pipeline_nodes, run_until_interrupted

    # The nodes run in the checkout (Launcher.start), not here: paths given relative to the
    # caller's directory are made absolute before they reach a node's command line.
    params_file = args.params_file.expanduser().absolute()
    record = args.record.expanduser().absolute() if args.record else None
    try:
        overrides = parse_overrides(args.param)
        if not params_file.is_file():
            raise ValueError(f"no parameters file {args.params_file}")
        if record is not None and record.exists() and not args.force:
            raise ValueError(f"{args.record} exists (use --force to overwrite)")
        pipeline_nodes(args.backend, params_file, overrides, perception=args.perception)  # refuses bad overrides
        launcher = Launcher(domain_id=args.domain_id)
    except ValueError as err:
        print(f"clothfold launch: {err}", file=sys.stderr)
        return 2
    # SIGINT (also when started with '&' from a script, which starts it ignored) and SIGTERM stop every
    # process: exit status 130 / 143
    signals = StopSignals().install()
    try:
        try:
            launcher.start_pipeline(args.backend, params_file, overrides, perception=args.perception)
            if record is not None:
                launcher.start("recorder_node", node_command("recorder_node", args=["--output", str(record)]))
        except BaseException as err:
            signals.ignore()
            launcher.stop_all()
            if isinstance(err, KeyboardInterrupt):
                return signals.exit_code(130)
            raise
        print(f"[launcher] started {len(launcher.procs)} processes ("
              + ", ".join(f"{p.name} pid {p.pid}" for p in launcher.procs) + "); Ctrl-C stops them", flush=True)
        return run_until_interrupted(launcher, signals)
    finally:
        signals.restore()
