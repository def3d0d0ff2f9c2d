"""lookup/choices.py: the planner's choice for each fold of the default shirt, on the flat
keypoints and in sequence (after the ideal earlier folds), as `clothfold tables` reports it."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from test_lookup_select import _bowl, _table, _write_table_dir

from clothfold_ros.folding import FOLD_SEQUENCE
from clothfold_ros.lookup import choices
from clothfold_ros.lookup.fan_selection import COVERAGE_LEVELS, fan_points
from clothfold_ros.lookup.scenario import SCENARIOS, definition_features, flat_keypoints
from clothfold_ros.trajectory import fan

ROOT = Path(__file__).resolve().parents[1]
FAN = fan()


def test_sequence_keypoints_follow_the_ideal_folds():
    seen = choices.sequence_keypoints()
    flat = flat_keypoints(1, "cotton")
    assert len(seen) == len(FOLD_SEQUENCE)
    assert all(np.allclose(seen[0][n], flat[n]) for n in flat)  # the first fold sees the flat shirt
    # after the left sleeve its keypoints moved onto the body, the right sleeve's did not
    assert abs(seen[1]["sleeve_top_left"][0]) < abs(flat["sleeve_top_left"][0])
    assert np.allclose(seen[1]["sleeve_top_right"], flat["sleeve_top_right"])
    # after both side folds the hem corners are the folded outline's, inside the flat hem
    assert abs(seen[4]["bottom_left"][0]) < abs(flat["bottom_left"][0])


def test_choices_name_the_table_fan_point_and_losses(tmp_path):
    pts = np.arange(0, 134, 2)
    _write_table_dir(tmp_path / "shape1", _table("shape1", _bowl(66)[pts], points=pts))
    some = np.array(sorted(set(fan_points(COVERAGE_LEVELS[0]).tolist()) | {1, 3, 5}))  # the coarse points and 3
    middle = _table("middle", _bowl(99)[some], points=some,
                    feats={**definition_features(SCENARIOS["shape1"]), "stage": 3.0, "fold_type": 2.0})
    _write_table_dir(tmp_path / "middle", middle)
    prov = tmp_path / "middle" / "provenance.json"
    prov.write_text(json.dumps({**json.loads(prov.read_text()), "complete": False}))
    got = choices.planner_choices(tmp_path)
    assert [(c.fold, c.keypoints) for c in got] == [("left_sleeve", "flat")] + [
        (f, k) for f in FOLD_SEQUENCE[1:] for k in ("flat", "in sequence")]
    first = got[0].selection
    assert first.scenario == "shape1" and first.point == 66 and first.raw_loss == _bowl(66)[66]
    text = choices.markdown(got)
    assert f"| left_sleeve | flat | 66 ({FAN[66, 0]:.3f}, {FAN[66, 1]:.1f}) | shape1 (" in text
    assert re.search(rf"\| middle \| flat \| \d+ \(.*\) \| middle \([\d.]+; partial, {len(some)} points\)", text), text


def test_clothfold_tables_prints_and_writes_the_choices(tmp_path, capsys):
    from clothfold_ros.cli import main
    from clothfold_ros.lookup import status

    pts = np.arange(0, 134, 2)
    _write_table_dir(tmp_path / "shape1", _table("shape1", _bowl(66)[pts], points=pts))
    doc = tmp_path / "doc.md"
    doc.write_text(f"{status.BEGIN}\nx\n{status.END}\n{choices.BEGIN}\nSTALE-CHOICES\n{choices.END}\n")
    assert main(["tables", "--tables", str(tmp_path), "--write", str(doc)]) == 0
    out = capsys.readouterr().out
    assert "What the planner chooses for the default shirt" in out and "| left_sleeve | flat | 66 (" in out
    assert "| left_sleeve | flat | 66 (" in doc.read_text() and "STALE-CHOICES" not in doc.read_text()
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["tables", "--tables", str(empty)]) == 0
    assert "No choice: " in capsys.readouterr().out


def test_documented_choices_are_the_tables_where_their_tables_are_complete():
    """docs/results.md's block holds the planner's choices on the shipped tables (rows that use a
    partial table are left out of the comparison: a sweep may be adding to it)."""
    text = (ROOT / "docs" / "results.md").read_text()
    block = text.split(choices.BEGIN, 1)[1].split(choices.END, 1)[0].strip()
    now = choices.markdown(choices.planner_choices(ROOT / "config" / "tables"))
    settled = [ln for ln in now.splitlines() if "partial" not in ln]
    assert [ln for ln in block.splitlines() if "partial" not in ln] == settled
