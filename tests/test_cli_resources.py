"""`clothfold sweep`, `plot` and `regret` find the package's lookup tables through the package
resources (clothfold_ros/nodes/resources.py), not the working directory: from a source checkout
run in another directory, and from an install (share/clothfold_ros found through the ament
index). On an install their default output goes to the working directory, never into share/."""
from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest

from clothfold_ros.cli import main
from clothfold_ros.nodes import resources

CHECKOUT_TABLES = Path(__file__).resolve().parent.parent / "config" / "tables"
# a sweep of the second sleeve at another resolution than its shipped first stage: refused at once,
# with a message that proves the shipped first-stage table was found (no simulation runs)
SWEEP = ["sweep", "both_sleeves", "--points", "0", "--max-area", "1e-3", "--workers", "1", "--quiet"]
FOUND_SHIPPED = "'shape1' was swept at max_area 5e-05"
PARTIAL = re.compile(r"; partial tables left out: [^\n]*")  # a partial table's point count grows while it is swept


@pytest.fixture
def elsewhere(tmp_path, monkeypatch):
    """Run from a directory that has no config/."""
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    return work


@pytest.fixture
def installed(tmp_path, monkeypatch, elsewhere):
    """The package as an install sees it: not a source checkout, resources in
    <prefix>/share/clothfold_ros registered in the ament index."""
    prefix = tmp_path / "install"
    marker = prefix / "share" / "ament_index" / "resource_index" / "packages" / resources.PACKAGE
    marker.parent.mkdir(parents=True)
    marker.write_text("")
    share_tables = prefix / "share" / resources.PACKAGE / "config" / "tables"
    checkout = CHECKOUT_TABLES.parents[1]
    for dest, files in resources.table_data_files(checkout):  # what setup.py installs, from the same function
        (prefix / dest).mkdir(parents=True)
        for f in files:
            shutil.copy(checkout / f, prefix / dest)
    monkeypatch.setattr(resources, "SOURCE_CHECKOUT", False)
    monkeypatch.setenv("AMENT_PREFIX_PATH", os.pathsep.join([str(prefix), os.environ.get("AMENT_PREFIX_PATH", "")]))
    return share_tables


def _files(d: Path) -> set[str]:
    return {str(p.relative_to(d)) for p in d.rglob("*")}


def _shipped_report() -> str:
    """The committed regret report without its count of a partial table's points (a sweep may be adding to it)."""
    return PARTIAL.sub("", (CHECKOUT_TABLES / "regret.md").read_text()).strip()


def test_regret_from_another_directory(elsewhere, capsys):
    assert main(["regret"]) == 0, capsys.readouterr().err
    # the package's shipped tables, so the shipped report
    assert PARTIAL.sub("", capsys.readouterr().out).strip() == _shipped_report()


def test_regret_on_an_install(installed, capsys):
    assert main(["regret"]) == 0, capsys.readouterr().err
    assert PARTIAL.sub("", capsys.readouterr().out).strip() == _shipped_report()


def test_plot_from_another_directory(elsewhere, capsys):
    assert main(["plot", "shape1", "--out", str(elsewhere / "plots")]) == 0, capsys.readouterr().err
    assert (elsewhere / "plots" / "shape1" / "landscape.png").is_file()


def test_plot_on_an_install_writes_to_the_working_directory(installed, elsewhere, capsys):
    before = _files(installed)
    # the landscape from table.csv; the best/worst renders need the sweep's final meshes, which
    # an install does not carry (about 9 MB a table): said
    assert main(["plot", "shape1"]) == 0
    err = capsys.readouterr().err
    assert "shape1: no best/worst render: the final meshes (finals.npz) are not in" in err, err
    assert (elsewhere / "config" / "tables" / "shape1" / "landscape.png").is_file()
    assert not (elsewhere / "config" / "tables" / "shape1" / "best_worst.png").exists()
    assert _files(installed) == before  # nothing written into share/


def test_sweep_stage_starts_from_the_shipped_table_from_another_directory(elsewhere, capsys):
    out = elsewhere / "tables"
    assert main([*SWEEP, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert FOUND_SHIPPED in err, err


def test_sweep_on_an_install(installed, elsewhere, capsys):
    """A stage starts from its previous stage's best final mesh, which an install does not carry:
    said, nothing written (into share/ or here)."""
    before = _files(installed)
    assert main(SWEEP) == 2
    err = capsys.readouterr().err
    assert "its table at" in err and "has none (an install carries the tables' CSV and JSON files" in err, err
    assert str(installed / "shape1") in err and str(elsewhere / "config" / "tables") in err, err
    assert not (elsewhere / "config").exists()
    assert _files(installed) == before
