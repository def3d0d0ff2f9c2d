"""Package resources and the output directory, from a source checkout or a ROS install.

From source the checkout holds config/, launch/ and package.xml; on an install they are in
share/clothfold_ros, found through the ament index (AMENT_PREFIX_PATH). Used by the nodes
(fold_planner_node's table_dir) and the commands (parameters file, bags/). Standard library
only: setup.py loads it for `table_data_files`, what an install carries of the lookup tables.
"""
from __future__ import annotations

import os
from pathlib import Path

PACKAGE = "clothfold_ros"
ROOT = Path(__file__).resolve().parents[2]  # the checkout when run from source, else site-packages
SOURCE_CHECKOUT = (ROOT / "package.xml").is_file() and (ROOT / "config").is_dir()
TABLES = "config/tables"
# what an install carries of each table: the table, provenance, settings and run logs (the planner,
# `clothfold tables`, `regret`, `plot`'s landscapes); not the sweeps' final meshes (about 9 MB a table)
TABLE_FILE_PATTERNS = ("*.csv", "*.json", "*.jsonl")


def table_data_files(checkout: str | Path = ".") -> list[tuple[str, list[str]]]:
    """setup.py's data_files for the lookup tables: (share/clothfold_ros/config/tables/<scenario>,
    its files as paths relative to `checkout`), one entry per scenario directory, sorted."""
    base = Path(checkout)
    out = []
    for d in sorted(p for p in (base / TABLES).glob("*") if p.is_dir()):
        files = sorted(str(f.relative_to(base)) for pattern in TABLE_FILE_PATTERNS for f in d.glob(pattern))
        out.append((f"share/{PACKAGE}/{TABLES}/{d.name}", files))
    return out


def share_dir() -> Path:
    """Directory of the package resources (config/, launch/, package.xml): the checkout when
    run from source, else share/clothfold_ros of the install, found through the ament index
    (AMENT_PREFIX_PATH). RuntimeError when neither exists."""
    if SOURCE_CHECKOUT:
        return ROOT
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError as err:
        raise RuntimeError(f"not a source checkout and ament_index_python is missing ({err})") from err
    try:
        return Path(get_package_share_directory(PACKAGE))
    except PackageNotFoundError as err:
        raise RuntimeError(f"package {PACKAGE} not in the ament index (AMENT_PREFIX_PATH="
                           f"{os.environ.get('AMENT_PREFIX_PATH', '')!r}); source the install's setup.bash") from err


def resource(path: str | Path) -> Path:
    """A package resource: absolute paths as given, relative ones below share_dir()
    (e.g. "config/tables" -> <share>/config/tables)."""
    p = Path(path)
    return p if p.is_absolute() else share_dir() / p


def work_dir() -> Path:
    """Where relative output paths (bags/) go: the checkout from source, else the current directory
    (an install's share/ and site-packages are not for output)."""
    return ROOT if SOURCE_CHECKOUT else Path.cwd()


def _default_params() -> Path:
    try:
        return resource("config/clothfold.yaml")
    except RuntimeError:
        return Path("config/clothfold.yaml")  # reported as missing where it is used


DEFAULT_PARAMS = _default_params()
