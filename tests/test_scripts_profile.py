"""The solver diagnostics in scripts/ run against today's simulator (a tiny mesh, a few steps)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from clothfold_ros.lookup.sweep import SweepSettings, run_sweep

ROOT = Path(__file__).resolve().parents[1]


def _script(name: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "scripts" / name), *args], capture_output=True, text=True,
                          timeout=300, cwd=ROOT)


def test_newton_profile_runs_a_material_and_reports_iterations() -> None:
    out = _script("newton_profile.py", "--area", "1e-2", "--steps", "1", "3", "--material", "thin_cotton",
                  "--history")
    assert out.returncode == 0, out.stderr
    assert "thin_cotton" in out.stdout and "total Newton iterations, steps 1..3:" in out.stdout
    assert out.stdout.count("contacts") == 3  # one line per profiled step


def test_profile_table_run_profiles_a_sweep_point(tmp_path: Path) -> None:
    run_sweep(SweepSettings("T1", max_area=1e-2), tmp_path / "T1", [], workers=1, progress=False)  # settings only
    out = _script("profile_table_run.py", "T1", "96", "--tables", str(tmp_path), "--top", "5")
    assert out.returncode == 0, out.stderr
    assert '"point": 96' in out.stdout and '"success": true' in out.stdout
    assert "Newton directions" in out.stdout and "function calls" in out.stdout
    assert "state digest " in out.stdout and "state digest none" not in out.stdout
    assert not (tmp_path / "T1" / "runs.jsonl").exists() or not (tmp_path / "T1" / "runs.jsonl").read_text()
    bad = _script("profile_table_run.py", "T2", "96", "--tables", str(tmp_path))
    assert bad.returncode == 2 and "no sweep settings" in bad.stderr


def test_profile_table_run_stops_after_k_steps_with_a_repeatable_digest(tmp_path: Path) -> None:
    """--steps K cuts the run after K simulator steps (not recorded as a failure); the same
    job gives the same digest, a different one (another fan point) another."""
    run_sweep(SweepSettings("T1", max_area=1e-2), tmp_path / "T1", [], workers=1, progress=False)

    def digest(point: str) -> str:
        out = _script("profile_table_run.py", "T1", point, "--tables", str(tmp_path), "--steps", "3", "--top", "1")
        assert out.returncode == 0, out.stderr
        assert "stopped early" in out.stdout and '"success"' not in out.stdout and "steps 3, CPU" in out.stdout
        return out.stdout.split("state digest ")[1].split()[0]

    first = digest("96")
    assert len(first) == 40 and digest("96") == first != digest("10")


def test_loss_breakdown_splits_the_folded_part_from_the_part_that_stays() -> None:
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        from loss_breakdown import breakdown
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    import numpy as np

    base = np.zeros((4, 3))
    target = base.copy()
    target[:2, 0] = 0.3  # two vertices folded 30 cm over
    final = target.copy()
    final[0, 2] += 0.04  # one of them still 4 cm up
    final[2:, 1] += 0.01  # the part that stays dragged 1 cm along y
    b = breakdown(final, target, base)
    assert b["moved_fraction"] == 0.5
    assert np.isclose(b["moved_loss"], 20.0) and np.isclose(b["moved_dz"], 20.0) and np.isclose(b["moved_dxy"], 0.0)
    assert np.isclose(b["stayed_loss"], 10.0) and np.isclose(b["stayed_offset_y"], 10.0)
    assert np.isclose(b["loss"], 15.0) and np.isclose(b["moved_z_max"], 40.0)


def test_loss_breakdown_reads_a_committed_table() -> None:
    out = _script("loss_breakdown.py", "shape1", "7", "32")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == "shape1: the loss had the cloth not moved (its start state against the target): 90.2 mm"
    assert lines[1].startswith("point 7 (h 0.238, tilt 20.0 deg): loss 0.9 mm")
    assert lines[2].startswith("point 32 (h 0.515, tilt 30.0 deg)")
    bad = _script("loss_breakdown.py", "shape1", "999")
    assert bad.returncode == 2 and "no run" in bad.stderr


def test_table_spread_reruns_a_point_once_and_refuses_bad_points(tmp_path: Path) -> None:
    run_sweep(SweepSettings("T1", max_area=1e-2), tmp_path / "T1", [96], workers=1, progress=False)
    args = ("T1", "--tables", str(tmp_path), "--out", str(tmp_path / "spread"))
    out = _script("table_spread.py", *args, "--points", "96")
    assert out.returncode == 0, out.stderr
    assert "T1 point 96 (h " in out.stdout and "; h +1e-03: " in out.stdout
    rows = (tmp_path / "spread" / "spread_T1.jsonl").read_text().splitlines()
    assert len(rows) == 1 and abs(json.loads(rows[0])["dh"] - 1e-3) < 1e-12
    again = _script("table_spread.py", *args, "--points", "96")  # resumable: the point is not rerun
    assert again.returncode == 0 and again.stdout == out.stdout
    assert len((tmp_path / "spread" / "spread_T1.jsonl").read_text().splitlines()) == 1
    for bad, says in (("200", "outside the fan"), ("7", "is not in"), ("a", "comma-separated integers")):
        r = _script("table_spread.py", *args, "--points", bad)
        assert r.returncode == 2 and says in r.stderr, r.stderr
    r = _script("table_spread.py", "nosuch", "--tables", str(tmp_path), "--points", "96")
    assert r.returncode == 2 and "holds no sweep" in r.stderr
