"""The `clothfold` command: one sub-command per module in this package.

Each module `clothfold_ros/cli/<name>.py` defines `register(subparsers)` which adds its
sub-parser and sets `func` (called with the parsed args; returns an exit code).
Modules are discovered, so adding a command never touches this file.
"""
from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="clothfold",
        description="Shirt folding with ROS 2: geometry, simulation, pipeline, bags, lookup tables.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(module, "register"):
            module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:  # stdout closed early (`clothfold ... | head`): stop quietly, like a shell tool
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # Python's final flush must not raise again
        return 141  # 128 + SIGPIPE, what a shell reports for a tool ended by a closed pipe
    except (ValueError, OSError) as err:  # bad input or a path that cannot be written: one line, exit 2
        if os.environ.get("CLOTHFOLD_DEBUG"):
            raise
        print(f"clothfold {args.command}: {type(err).__name__}: {err} (CLOTHFOLD_DEBUG=1 shows the traceback)",
              file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
