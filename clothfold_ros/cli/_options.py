"""Command-line options shared by several `clothfold` commands (not a command itself)."""
from __future__ import annotations

import argparse
from pathlib import Path

TABLES_ROOT = Path("config/tables")


def add_stepping_options(p: argparse.ArgumentParser) -> None:
    """--dt, --settle, --newton-tol: how one fold is stepped (simulate, sweep)."""
    p.add_argument("--dt", type=float, default=0.04, help="time step (s)")
    p.add_argument("--settle", type=float, default=0.2, help="settle time after release (s)")
    p.add_argument("--newton-tol", type=float, default=1e-3, help="Newton stop: RMS(|dx|)/dt (m/s)")


def add_tables_option(p: argparse.ArgumentParser, help: str = "lookup tables root") -> None:
    """--tables: the folder holding one table folder per scenario (plot, regret)."""
    p.add_argument("--tables", type=Path, default=TABLES_ROOT, help=f"{help} (default {TABLES_ROOT})")
