"""scripts/compare_runs.py: point-by-point loss differences between two sweeps."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import compare_runs  # noqa: E402


def _sweep(d: Path, rows: list[tuple[int, float | None]]) -> Path:
    d.mkdir()
    with open(d / "runs.jsonl", "w") as f:
        for p, loss in rows:
            f.write(json.dumps({"point": p, "loss_m": loss if loss is not None else float("nan"),
                                "success": loss is not None}) + "\n")
    return d


def test_reports_differences_and_the_points_beyond_the_spread(tmp_path, capsys):
    new = _sweep(tmp_path / "new", [(0, 0.010), (3, 0.002), (6, None), (9, 0.004)])
    old = _sweep(tmp_path / "old", [(0, 0.002), (3, 0.0025), (6, 0.003), (12, 0.001)])
    assert compare_runs.main([str(new), str(old)]) == 0
    out = capsys.readouterr().out
    assert "fan   0: new   10.00 mm  old    2.00 mm    +8.00 mm" in out
    assert "3 points" in out and "max 8.00 mm" in out and "1 moved by more than 3.0 mm (0)" in out
    assert "failed in one of them: [6]" in out


def test_refuses_sweeps_without_runs_or_common_points(tmp_path, capsys):
    a = _sweep(tmp_path / "a", [(0, 0.001)])
    b = _sweep(tmp_path / "b", [(1, 0.001)])
    assert compare_runs.main([str(a), str(b)]) == 2
    assert "share no fan point" in capsys.readouterr().err
    assert compare_runs.main([str(a), str(tmp_path / "missing")]) == 2
    assert "holds no runs.jsonl" in capsys.readouterr().err
