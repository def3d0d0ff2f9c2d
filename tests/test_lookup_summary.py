"""lookup/summary.py and `clothfold tables`' summary block: each table's landscape in one row
(best, median, worst, within 2 cm, plateau, fan middle, Spearman against shape1), from the
run logs; the committed documents carry the tables' own rows."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from clothfold_ros.cli import main
from clothfold_ros.lookup import summary, sweep_dir
from clothfold_ros.lookup.select import middle_of_fan
from clothfold_ros.trajectory import fan

ROOT = Path(__file__).resolve().parents[1]
FAN = fan()


def _write(d: Path, losses_mm: dict[int, float | None]) -> None:
    d.mkdir(parents=True, exist_ok=True)
    rows = [{"point": p, "height_ratio": float(FAN[p, 0]), "tilt_deg": float(FAN[p, 1]),
             "loss_m": (v * 1e-3 if v is not None else float("nan")), "success": v is not None,
             "reason": "" if v is not None else "grippers force the cloth into itself"} for p, v in losses_mm.items()]
    (d / sweep_dir.RUNS).write_text("".join(json.dumps(r) + "\n" for r in rows))


def _row(text: str, scenario: str) -> list[str]:
    line = next(ln for ln in text.splitlines() if ln.startswith(f"| {scenario} |"))
    return [c.strip() for c in line.strip("|").split("|")]


def test_summary_rows_from_the_run_logs(tmp_path: Path) -> None:
    mid = middle_of_fan()
    _write(tmp_path / "shape1", {0: 1.0, 1: 2.0, 2: 3.0, mid: 1.2, 5: 30.0})
    # T1 ranks the common points in reverse; one failure; its best is point 5
    _write(tmp_path / "T1", {0: 9.0, 1: 8.0, 2: 7.0, mid: 8.5, 5: 0.5, 6: None})
    text = summary.markdown(summary.landscape_summaries(tmp_path))
    s1, t1 = _row(text, "shape1"), _row(text, "T1")
    h, t = FAN[0]
    assert s1[:6] == ["shape1", "5", f"({h:.3f}, {t:.1f}) 1.00", "2.00", f"({FAN[5, 0]:.3f}, {FAN[5, 1]:.1f}) 30.00",
                      "4"]
    assert s1[6:] == ["2", "1.20", "-"]  # 1.0 and 1.2 within 0.5 mm of the best
    assert t1[1] == "6 (1 failed)" and t1[2].endswith(" 0.50") and t1[3] == "8.00" and t1[5] == "5"
    assert t1[6] == "1" and t1[7] == "8.50" and t1[8] == "-1.00"
    assert [ln.split("|")[1].strip() for ln in text.splitlines()[2:]] == ["shape1", "T1"]  # generation order


def test_tables_writes_the_summary_block_where_a_file_has_one(tmp_path: Path, capsys) -> None:
    from clothfold_ros.lookup import status

    _write(tmp_path / "tables" / "shape1", {0: 1.0, 1: 2.0, 2: 3.0})
    both, status_only = tmp_path / "both.md", tmp_path / "status.md"
    both.write_text(f"a\n{status.BEGIN}\nOLD\n{status.END}\nb\n{summary.BEGIN}\nOLD\n{summary.END}\nc\n")
    status_only.write_text(f"{status.BEGIN}\nOLD\n{status.END}\n")
    assert main(["tables", "--tables", str(tmp_path / "tables"), "--write", str(both), str(status_only)]) == 0
    text = both.read_text()
    assert "OLD" not in text and text.startswith("a\n") and text.endswith("c\n")
    best = f"| shape1 | 3 | ({FAN[0, 0]:.3f}, {FAN[0, 1]:.1f}) 1.00 | 2.00 |"
    assert best in text
    assert summary.BEGIN not in status_only.read_text() and "OLD" not in status_only.read_text()
    assert best in capsys.readouterr().out
    broken = tmp_path / "broken.md"
    broken.write_text(f"{status.BEGIN}\nx\n{status.END}\n{summary.BEGIN}\n")
    assert main(["tables", "--tables", str(tmp_path / "tables"), "--write", str(broken)]) == 2
    assert "table-summary" in capsys.readouterr().err


def test_documented_summaries_are_the_tables() -> None:
    """docs/results.md and docs/lookup.md carry the shipped tables' rows (a table being swept may have
    moved on since: its row is not compared)."""
    text = summary.markdown(summary.landscape_summaries(ROOT / "config" / "tables"))
    partial = {s.scenario for s in summary.landscape_summaries(ROOT / "config" / "tables") if len(s.rows) < len(FAN)}
    rows = [ln for ln in text.splitlines()[2:] if ln.split("|")[1].strip() not in partial]
    assert len(rows) >= 12
    for doc in ("docs/results.md", "docs/lookup.md"):
        block = (ROOT / doc).read_text().split(summary.BEGIN)[1].split(summary.END)[0]
        for row in rows:
            assert row in block, f"{doc}: stale summary row {row!r}: clothfold tables --write {doc}"
        assert re.search(r"\| shape1 \| 134 \| \(0\.238, 20\.0\) 0\.92 \|", block)
        assert np.isfinite(float(_row(block, "T8")[8]))


def test_summary_counts_the_sweeps_fan_points_as_status_does(tmp_path: Path) -> None:
    """A run at a point the sweep does not cover (its provenance lists 0-2) is left out of the
    summary's runs, best and median, as `status` leaves it out of the count."""
    from clothfold_ros.lookup import status

    d = tmp_path / "shape1"
    _write(d, {0: 4.0, 1: 5.0, 2: 6.0, 7: 0.1})  # point 7: a stray run of least loss
    (d / sweep_dir.PROVENANCE).write_text(json.dumps({"fan_points": [0, 1, 2]}))
    row = _row(summary.markdown(summary.landscape_summaries(tmp_path)), "shape1")
    assert row[1] == "3" and row[2].endswith(" 4.00") and row[3] == "5.00", row
    st = status.table_status(d)
    assert (st.runs, st.wanted, st.best["point"]) == (3, 3, 0)


def test_a_flat_landscape_has_no_rank_correlation() -> None:
    """Constant losses over the common points: NaN (printed "nan"), not scipy's warning."""
    import warnings

    row = lambda p, loss: {"point": p, "loss_m": loss, "success": True, "height_ratio": 0.1, "tilt_deg": 0.0}
    flat = summary.LandscapeSummary("T1", [row(p, 0.001) for p in range(4)])
    ranked = summary.LandscapeSummary("shape1", [row(p, 0.001 * (p + 1)) for p in range(4)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isnan(flat.spearman(ranked)) and ranked.spearman(ranked) == 1.0
