"""`clothfold tables` and lookup/status.py: counts from live run logs; sweep locks of dead owners."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from clothfold_ros.cli import main
from clothfold_ros.lookup import status, sweep_dir


def _row(point: int, loss_mm: float | None, cpu: float | None = 100.0, wall: float = 120.0) -> dict:
    ok = loss_mm is not None
    r = {"point": point, "height_ratio": 0.1 * (point % 10), "tilt_deg": 6.0 * (point % 10),
         "loss_m": loss_mm * 1e-3 if ok else float("nan"), "success": ok,
         "reason": "" if ok else "Newton did not converge", "wall_time_s": wall}
    if cpu is not None:
        r["cpu_time_s"] = cpu
    return r


def _write_runs(d, rows, tail: str = "") -> None:
    d.mkdir(parents=True, exist_ok=True)
    text = "".join(json.dumps(r) + "\n" for r in rows) + tail
    (d / sweep_dir.RUNS).write_text(text)


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_status_counts_runs_failures_best_and_cost(tmp_path):
    d = tmp_path / "shape2"
    rows = [_row(0, 2.0, cpu=100.0), _row(1, None, cpu=300.0), _row(2, 1.5, cpu=None, wall=200.0)]
    _write_runs(d, rows, tail='{"point": 3, "heig')  # the partial line of a killed append
    s = status.table_status(d)
    assert (s.scenario, s.runs, s.wanted, s.failed) == ("shape2", 3, status.FAN_SIZE, 1)
    assert s.best["point"] == 2 and s.cpu_s == [100.0, 300.0, 200.0]  # wall time where cpu time is missing
    assert s.median_cpu_s == 200.0
    assert s.cpu_hours_to_go == pytest.approx((status.FAN_SIZE - 3) * 200.0 / 3600)
    assert s.state == "partial" and not s.complete


def test_status_uses_the_sweeps_fan_points_and_marks_complete(tmp_path):
    d = tmp_path / "T1"
    _write_runs(d, [_row(4, 3.0), _row(9, 1.0)])
    (d / sweep_dir.PROVENANCE).write_text(json.dumps({"fan_points": [4, 9]}))
    s = status.table_status(d)
    assert s.complete and s.state == "complete" and s.cpu_hours_to_go == 0.0


def test_status_of_a_root_lists_every_scenario_and_a_total(tmp_path):
    _write_runs(tmp_path / "shape1", [_row(0, 2.0), _row(1, None)])
    statuses = status.tables_status(tmp_path)
    names = [s.scenario for s in statuses]
    assert len(names) == 13 and names.index("both_sleeves") < names.index("both_sides") < names.index("middle")
    text = status.markdown(statuses)
    assert "| shape1 | 2 / 134 | 1 | 0 (0.000, 0.0), 2.00 | 100 |" in text
    assert "| middle | 0 / 134 | - | - | - | 0.0 | - | not started |" in text
    assert f"2 of {13 * 134} runs, 1 failed; complete: none. To go" in text
    assert "plus 1608 runs of tables not started" in text  # 12 scenarios x 134


def test_lock_of_a_dead_sweep_is_not_running(tmp_path):
    d = tmp_path / "both_sleeves"
    _write_runs(d, [_row(0, 2.0)])
    (d / sweep_dir.PROVENANCE).write_text(json.dumps({"fan_points": [0]}))
    assert sweep_dir.lock_owner(d) is None and sweep_dir.is_finished(d)
    (d / sweep_dir.LOCK).write_text(str(_dead_pid()))  # a sweep killed by SIGTERM leaves this
    assert sweep_dir.lock_owner(d) is None and sweep_dir.is_finished(d)
    assert status.table_status(d).state == "complete"
    (d / sweep_dir.LOCK).write_text(str(os.getpid()))  # a live owner
    assert sweep_dir.lock_owner(d) == os.getpid() and not sweep_dir.is_finished(d)
    assert status.table_status(d).state == "complete, sweeping"


def test_lock_takes_over_a_stale_lock_and_refuses_a_live_one(tmp_path):
    (tmp_path / sweep_dir.LOCK).write_text(str(_dead_pid()))
    with sweep_dir.Lock(tmp_path):
        assert sweep_dir.lock_owner(tmp_path) == os.getpid()
        with pytest.raises(RuntimeError, match="another sweep"):
            with sweep_dir.Lock(tmp_path):
                pass
    assert not (tmp_path / sweep_dir.LOCK).exists()


def test_cli_writes_the_block_and_reports_bad_input(tmp_path, capsys):
    _write_runs(tmp_path / "tables" / "shape1", [_row(0, 2.0)])
    doc = tmp_path / "doc.md"
    doc.write_text(f"before\n{status.BEGIN}\nSTALE-BLOCK\n{status.END}\nafter\n")
    assert main(["tables", "--tables", str(tmp_path / "tables"), "--write", str(doc)]) == 0
    text = doc.read_text()
    assert text.startswith("before\n") and text.endswith("after\n") and "STALE-BLOCK" not in text
    assert "| shape1 | 1 / 134 |" in text and "| shape1 | 1 / 134 |" in capsys.readouterr().out
    plain = tmp_path / "plain.md"
    plain.write_text("no markers\n")
    assert main(["tables", "--tables", str(tmp_path / "tables"), "--write", str(plain)]) == 2
    assert "found 0" in capsys.readouterr().err and plain.read_text() == "no markers\n"
    twice = tmp_path / "twice.md"
    two_blocks = f"{status.BEGIN}\nA\n{status.END}\nmiddle\n{status.BEGIN}\nB\n{status.END}\n"
    twice.write_text(two_blocks)
    assert main(["tables", "--tables", str(tmp_path / "tables"), "--write", str(doc), str(twice)]) == 2
    err = capsys.readouterr().err
    assert "need exactly one" in err and "found 2" in err
    assert twice.read_text() == two_blocks  # neither file is written when one is refused
    unclosed = tmp_path / "unclosed.md"
    unclosed.write_text(f"{status.BEGIN}\nA\n{status.END}\n{status.BEGIN}\n")
    assert main(["tables", "--tables", str(tmp_path / "tables"), "--write", str(unclosed)]) == 2
    assert "2 begin and 1 end markers" in capsys.readouterr().err
    assert main(["tables", "--tables", str(tmp_path / "missing")]) == 2
    assert "is not a directory" in capsys.readouterr().err


@pytest.mark.parametrize("provenance", ["{not json", '{"fan_points": "all"}', '{"fan_points": [0, 134]}', "[1, 2]"])
def test_status_refuses_a_broken_provenance_naming_the_file(tmp_path, capsys, provenance):
    d = tmp_path / "tables" / "shape1"
    _write_runs(d, [_row(0, 2.0)])
    (d / sweep_dir.PROVENANCE).write_text(provenance)
    with pytest.raises(ValueError, match="provenance"):
        status.table_status(d)
    assert main(["tables", "--tables", str(tmp_path / "tables")]) == 2
    assert f"{d / sweep_dir.PROVENANCE}" in capsys.readouterr().err


def test_status_counts_only_the_sweeps_fan_points(tmp_path):
    """Rows of points outside the provenance's fan_points (an earlier sweep of other points in
    the same directory) do not make a partial table complete."""
    d = tmp_path / "T1"
    _write_runs(d, [_row(4, 3.0), _row(5, None), _row(6, 2.0), _row(7, 1.0)])
    (d / sweep_dir.PROVENANCE).write_text(json.dumps({"fan_points": [4, 5, 9]}))
    s = status.table_status(d)
    assert (s.runs, s.wanted, s.failed) == (2, 3, 1) and not s.complete and s.state == "partial"
    assert s.best["point"] == 4  # 7 (1 mm) and 6 are not this sweep's points


def test_an_empty_lock_is_being_written_and_held_until_it_is_old(tmp_path):
    """Older code created the lock file, then wrote its pid: an empty lock is another sweep
    taking it, not a stale lock to remove (both would hold it); an old empty one is stale."""
    lock = tmp_path / sweep_dir.LOCK
    lock.write_text("")
    assert sweep_dir.lock_owner(tmp_path) == 0 and not sweep_dir.is_finished(tmp_path)
    with pytest.raises(RuntimeError, match="another sweep"):
        with sweep_dir.Lock(tmp_path):
            pass
    assert lock.exists() and lock.read_text() == ""
    old = lock.stat().st_mtime - 2 * sweep_dir.LOCK_GRACE_S
    os.utime(lock, (old, old))
    assert sweep_dir.lock_owner(tmp_path) is None
    with sweep_dir.Lock(tmp_path):
        assert lock.read_text() == str(os.getpid())
    assert not lock.exists() and os.listdir(tmp_path) == []  # no temporary file left


def test_leaving_the_lock_keeps_another_sweeps_lock(tmp_path):
    lock = tmp_path / sweep_dir.LOCK
    with sweep_dir.Lock(tmp_path):
        lock.unlink()  # taken over meanwhile (e.g. as stale) by another sweep:
        lock.write_text(str(os.getppid()))
    assert lock.read_text() == str(os.getppid())
    assert sweep_dir.lock_owner(tmp_path) == os.getppid()


def test_headline_says_how_many_are_complete_and_where_the_rest_stand(tmp_path, capsys):
    root = tmp_path / "tables"
    for name in ("shape1", "T1"):
        _write_runs(root / name, [_row(p, 1.0) for p in range(3)])
        (root / name / sweep_dir.PROVENANCE).write_text(json.dumps({"fan_points": [0, 1, 2]}))
    _write_runs(root / "middle", [_row(0, 30.0), _row(1, None)])  # partial, one failure (not counted: partial)
    line = status.headline(status.tables_status(root))
    assert line.startswith("**2 of 13 tables are complete (`shape1`, `T1`; no failure); `shape2` not started; ")
    assert "; `middle` partial (2 of 134 fan points); `T2` not started" in line  # in generation order
    assert line.count("not started") == 10 and line.endswith("`T8` not started.**")
    full = [status.TableStatus(n, 134, 134, f, None, [1.0], False) for n, f in (("shape1", 0), ("T1", 2))]
    assert status.headline(full) == "**All 2 tables are complete: 134 fan points each, 2 failed runs.**"
    # `clothfold tables --write` fills the block where a file has one
    doc = tmp_path / "doc.md"
    doc.write_text(f"{status.HEADLINE_BEGIN}\nold\n{status.HEADLINE_END}\n{status.BEGIN}\nx\n{status.END}\n")
    assert main(["tables", "--tables", str(root), "--write", str(doc)]) == 0
    assert f"{status.HEADLINE_BEGIN}\n**2 of 13 tables are complete (" in doc.read_text()
    capsys.readouterr()
