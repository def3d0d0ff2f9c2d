"""Command-line options shared by several `clothfold` commands (not a command itself)."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..sim.config import SimConfig

TABLES_ROOT = Path("config/tables")  # a package resource: below the checkout or share/clothfold_ros


def shipped_tables() -> Path:
    """The package's lookup tables: <checkout>/config/tables from source, else
    <install>/share/clothfold_ros/config/tables (ament index), never the working directory."""
    from ..nodes.resources import resource

    return resource(TABLES_ROOT)


def output_tables() -> Path:
    """Where commands write tables by default: the checkout's config/tables from source, else
    ./config/tables (an install's share/ is not for output)."""
    from ..nodes.resources import work_dir

    return work_dir() / TABLES_ROOT


def add_stepping_options(p: argparse.ArgumentParser) -> None:
    """--dt, --settle, --newton-tol: how one fold is stepped (simulate, sweep)."""
    p.add_argument("--dt", type=float, default=SimConfig.dt, help="time step (s)")
    p.add_argument("--settle", type=float, default=0.2, help="settle time after release (s)")
    p.add_argument("--newton-tol", type=float, default=SimConfig.newton_tol, help="Newton stop: RMS(|dx|)/dt (m/s)")


def add_tables_option(p: argparse.ArgumentParser, help: str = "lookup tables root") -> None:
    """--tables: the folder holding one table folder per scenario (plot, regret)."""
    p.add_argument("--tables", type=Path, default=None,
                   help=f"{help} (default: the package's {TABLES_ROOT}, from source or the install)")


def tables_arg(args: argparse.Namespace) -> Path:
    """--tables as given (relative to the working directory), else the package's tables."""
    return args.tables if args.tables is not None else shipped_tables()
