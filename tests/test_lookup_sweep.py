"""Sweep engine: resume after a real kill, failure recording, local pool == Ray local mode."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from clothfold_ros.lookup.fan_selection import COVERAGE_LEVELS, coverage_order, fan_points
from clothfold_ros.lookup.sweep import SweepSettings, load_final, run_sweep, table_is_current
from clothfold_ros.lookup.sweep_dir import read_runs
from clothfold_ros.lookup.table import load_table, write_table

TINY = dict(max_area=1e-2)  # ~60 vertices: about 1 s per 1 s fold on one core
POINTS = [70, 96, 133, 110, 84, 120]  # successful fan points of the tiny T1 sweep


def _sweep_cmd(out: Path, points: list[int]) -> list[str]:
    code = ("import sys; from clothfold_ros.cli import main; sys.exit(main(sys.argv[1:]))")
    return [sys.executable, "-c", code, "sweep", "T1", "--out", str(out), "--max-area", str(TINY["max_area"]),
            "--points", ",".join(map(str, points)), "--workers", "1", "--quiet"]


def test_resume_after_kill(tmp_path: Path) -> None:
    runs = tmp_path / "T1" / "runs.jsonl"
    proc = subprocess.Popen(_sweep_cmd(tmp_path, POINTS), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.time() + 90
    while time.time() < deadline and (not runs.exists() or runs.read_text().count("\n") < 2):
        time.sleep(0.05)
        assert proc.poll() is None, proc.stderr.read().decode()
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = read_runs(runs)
    assert 2 <= len(before) < len(POINTS), "the kill must land mid-sweep"
    # the killed sweep left the table of its finished runs (written after each; the kill may
    # land between a run's row and its table, or between the table's rename and the
    # provenance's), marked incomplete; a whole file, never half of one
    partial = load_table(tmp_path / "T1")
    assert set(partial.point.tolist()) <= {r["point"] for r in before} and len(partial.point) >= len(before) - 1
    prov = json.loads((tmp_path / "T1" / "provenance.json").read_text())
    assert not prov["complete"] and prov["simulated"] in (len(partial.point), len(partial.point) - 1)
    # a kill during an append leaves a partial line: simulate the worst case too
    with open(runs, "a") as f:
        f.write('{"point": 1')
    done = subprocess.run(_sweep_cmd(tmp_path, POINTS), capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = [json.loads(x) for x in runs.read_text().splitlines()]
    pts = [r["point"] for r in lines]
    assert sorted(pts) == sorted(POINTS) and len(pts) == len(set(pts))  # none lost, none twice
    for r in before:  # finished rows were kept as written
        assert lines[pts.index(r["point"])] == r
    t = load_table(tmp_path / "T1")
    assert sorted(t.point.tolist()) == sorted(POINTS)
    assert not list((tmp_path / "T1").glob("*.tmp"))  # a write the kill cut short was replaced
    prov = json.loads((tmp_path / "T1" / "provenance.json").read_text())
    assert prov["complete"] and prov["resolution"]["max_area_m2"] == TINY["max_area"]
    assert "clothfold sweep T1" in prov["command"]
    assert re.fullmatch(r"[0-9a-f]{40}(-dirty)?", prov["git_commit"]), prov["git_commit"]
    # every run records the code it ran with; the provenance counts them
    assert all(re.fullmatch(r"[0-9a-f]{40}(-dirty)?", r["solver_commit"]) for r in lines)
    assert sum(prov["run_commits"].values()) == len(POINTS) and "unrecorded" not in prov["run_commits"]
    # a call with nothing left to run keeps the table and its provenance (date, commit) as they are
    d = tmp_path / "T1"
    assert table_is_current(d)
    kept = {f: (d / f).read_bytes() for f in ("provenance.json", "table.csv", "finals.npz")}
    again = subprocess.run(_sweep_cmd(tmp_path, POINTS), capture_output=True, text=True, timeout=120)
    assert again.returncode == 0 and "up to date" in again.stdout, again.stderr
    assert {f: (d / f).read_bytes() for f in kept} == kept
    # a final state whose run was never logged (killed between the file and its row) does not make
    # the table stale for good (it is overwritten when that point runs again); one of a logged run does
    (d / "finals").mkdir(exist_ok=True)
    np.save(d / "finals" / "p099.npy", np.zeros((3, 3), dtype=np.float32))
    assert table_is_current(d)
    np.save(d / "finals" / f"p{POINTS[0]:03d}.npy", np.zeros((3, 3), dtype=np.float32))
    assert not table_is_current(d)
    (d / "finals" / f"p{POINTS[0]:03d}.npy").unlink()
    # a row the table does not hold yet (a sweep killed before tabulating) makes it stale
    with open(runs, "a") as f:
        f.write(json.dumps({**lines[0], "point": 5}) + "\n")
    assert not table_is_current(d)


def test_failures_are_recorded_not_dropped(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import clothfold_ros.sim.runner as runner

    real = runner.run_fold

    def flaky(garment, spec, material, friction, height_ratio, tilt_deg, *a, **k):
        if height_ratio < 0.5:
            raise FloatingPointError("synthetic blow-up")
        return real(garment, spec, material, friction, height_ratio, tilt_deg, *a, **k)

    monkeypatch.setattr(runner, "run_fold", flaky)
    pts = [6, 133]  # h = 0.308 (fails) and h = 1.0
    rows = run_sweep(SweepSettings("T1", **TINY), tmp_path / "T1", pts, workers=1, progress=False)
    by = {r["point"]: r for r in rows}
    assert set(by) == set(pts)
    assert not by[6]["success"] and "synthetic blow-up" in by[6]["reason"] and np.isnan(by[6]["loss_m"])
    assert by[133]["success"] and by[133]["loss_m"] > 0
    write_table(tmp_path / "T1", "test", pts)
    t = load_table(tmp_path / "T1")
    assert t.success.tolist() == [False, True] and "synthetic" in t.reason[0]


def test_local_pool_and_ray_local_mode_agree(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    pts = [96, 133]
    s = SweepSettings("T1", **TINY)
    local = sorted(run_sweep(s, tmp_path / "pool" / "T1", pts, workers=2, progress=False), key=lambda r: r["point"])
    ray_rows = sorted(run_sweep(s, tmp_path / "ray" / "T1", pts, ray_address="local", progress=False),
                      key=lambda r: r["point"])
    import ray

    ray.shutdown()
    strip = lambda r: {k: v for k, v in r.items() if k not in ("wall_time_s", "cpu_time_s")}  # noqa: E731
    assert [strip(r) for r in local] == [strip(r) for r in ray_rows]
    assert all(r["success"] for r in local)
    for p in pts:
        np.testing.assert_array_equal(load_final(tmp_path / "pool" / "T1", p), load_final(tmp_path / "ray" / "T1", p))


def test_settings_mismatch_and_fan_selection(tmp_path: Path) -> None:
    run_sweep(SweepSettings("T1", **TINY), tmp_path / "T1", [], workers=1, progress=False)
    with pytest.raises(ValueError, match="other settings"):
        run_sweep(SweepSettings("T1", max_area=2e-2), tmp_path / "T1", [0], workers=1, progress=False)
    assert len(fan_points("all")) == 134
    alt = fan_points("alternate")
    assert 60 < len(alt) < 134 and {0, 1, 133}.issubset(set(alt.tolist()))
    with pytest.raises(ValueError):
        fan_points("7,999")


def test_a_sweep_covers_the_fan_coarse_to_fine(tmp_path: Path, monkeypatch) -> None:
    """Points run level by level of COVERAGE_LEVELS (the coarse tables' 12 points first), so a
    table left partial spans the fan instead of its lowest rings."""
    order = coverage_order(range(134))
    assert sorted(order) == list(range(134))
    coarse = fan_points(COVERAGE_LEVELS[0]).tolist()
    assert order[:12] == coarse and 133 in coarse and 0 not in coarse
    seen: set[int] = set()
    for level in COVERAGE_LEVELS:  # each level's points come before any point only a finer level holds
        pts = [p for p in fan_points(level).tolist() if p not in seen]
        assert order[len(seen):len(seen) + len(pts)] == pts
        seen.update(pts)
    assert coverage_order([5, 133, 0]) == [133, 0, 5]

    from clothfold_ros.lookup import sweep

    ran: list[int] = []

    def fake(job):
        ran.append(job.point)
        return {"point": job.point, "height_ratio": job.height_ratio, "tilt_deg": job.tilt_deg, "loss_m": 0.01,
                "success": True, "reason": "", "wall_time_s": 0.0, "cpu_time_s": 0.0, "newton_iterations": 1,
                "steps": 1, "solver_commit": "test"}, None

    monkeypatch.setattr(sweep, "_local", lambda jobs, n: (fake(j) for j in jobs))
    run_sweep(SweepSettings("T1", **TINY), tmp_path / "T1", [0, 1, 2, 4, 133], workers=1, progress=False)
    assert ran == [2, 4, 133, 0, 1]


def test_end_angle_is_a_sweep_setting_and_legacy_sweeps_were_175(tmp_path: Path) -> None:
    from dataclasses import asdict

    from clothfold_ros.lookup.scenario import spec_for
    from clothfold_ros.lookup.sweep_dir import SETTINGS, read_settings

    assert SweepSettings("T1").end_angle_deg == 170.0  # the study's simulations
    legacy = {k: v for k, v in asdict(SweepSettings("T1", **TINY)).items() if k != "end_angle_deg"}
    d = tmp_path / "T1"
    d.mkdir()
    (d / SETTINGS).write_text(json.dumps(legacy))
    assert read_settings(d).end_angle_deg == 175.0
    run_sweep(SweepSettings("T1", end_angle_deg=175.0, **TINY), d, [], workers=1, progress=False)  # resumes
    with pytest.raises(ValueError, match="other settings"):
        run_sweep(SweepSettings("T1", **TINY), d, [], workers=1, progress=False)
    with pytest.raises(ValueError, match="end_angle_deg"):
        SweepSettings("T1", end_angle_deg=190.0)
    from clothfold_ros.garment import make_shirt

    kp = make_shirt(1, max_area=1e-2).keypoints()
    a, _ = spec_for("left_sleeve", kp, end_angle_deg=170.0)
    b, _ = spec_for("left_sleeve", kp, end_angle_deg=175.0)
    assert not np.allclose(a.end_poses[0].position, b.end_poses[0].position)


def test_table_only_writes_a_partial_table_and_stages_refuse_to_start_from_it(tmp_path: Path, capsys) -> None:
    from clothfold_ros.cli import main
    from clothfold_ros.lookup.sweep_dir import is_complete

    area = str(TINY["max_area"])
    run_sweep(SweepSettings("T1", **TINY), tmp_path / "T1", [96], workers=1, progress=False)
    assert main(["sweep", "T1", "--out", str(tmp_path), "--max-area", area, "--points", "96,133",
                 "--table-only"]) == 0
    prov = json.loads((tmp_path / "T1" / "provenance.json").read_text())
    assert prov["simulated"] == 1 and prov["missing_points"] == [133] and not prov["complete"]
    assert len(read_runs(tmp_path / "T1" / "runs.jsonl")) == 1  # nothing was simulated
    assert not is_complete(tmp_path / "T1")
    # other settings than the sweep's are refused, and an empty directory has nothing to tabulate
    capsys.readouterr()
    assert main(["sweep", "T1", "--out", str(tmp_path), "--max-area", "2e-2", "--points", "96", "--table-only"]) == 2
    assert "settings" in capsys.readouterr().err
    assert main(["sweep", "T2", "--out", str(tmp_path), "--max-area", area, "--table-only"]) == 2
    assert "holds no runs" in capsys.readouterr().err
    # a sequence stage does not start from a partial table of the stage before it
    run_sweep(SweepSettings("shape1", **TINY), tmp_path / "shape1", [], workers=1, progress=False)
    assert main(["sweep", "shape1", "--out", str(tmp_path), "--max-area", area, "--points", "96",
                 "--table-only"]) == 2  # no runs yet
    assert "holds no runs" in capsys.readouterr().err
    (tmp_path / "shape1" / "runs.jsonl").write_text(
        (tmp_path / "T1" / "runs.jsonl").read_text())  # one row stands in for a run
    assert main(["sweep", "shape1", "--out", str(tmp_path), "--max-area", area, "--points", "96,133",
                 "--table-only"]) == 0
    with pytest.raises(ValueError, match="partial"):
        run_sweep(SweepSettings("both_sleeves", **TINY), tmp_path / "both_sleeves", [96], workers=1, progress=False,
                  previous_dir=tmp_path / "shape1")


def test_read_packed_takes_runs_finished_after_the_last_pack(tmp_path: Path) -> None:
    """A sweep resumed after its pack keeps new finals as per-run files until it packs again:
    the best/worst picture of that partial table reads both."""
    from clothfold_ros.lookup.sweep_dir import FINALS, final_key, pack_finals, read_packed

    tri, start = np.array([[0, 1, 2]]), np.zeros((3, 3))
    (tmp_path / FINALS).mkdir()
    np.save(tmp_path / FINALS / f"{final_key(1)}.npy", np.full((3, 3), 1.0, dtype=np.float32))
    pack_finals(tmp_path, tri, start, start, [1])
    (tmp_path / FINALS).mkdir()
    np.save(tmp_path / FINALS / f"{final_key(2)}.npy", np.full((3, 3), 2.0, dtype=np.float32))
    _, _, finals = read_packed(tmp_path, [1, 2])
    assert finals[1][0, 0] == 1.0 and finals[2][0, 0] == 2.0
    with pytest.raises(FileNotFoundError, match="point 3"):
        read_packed(tmp_path, [3])


def test_a_pack_that_fails_keeps_the_old_archive_and_the_per_run_files(tmp_path: Path, monkeypatch) -> None:
    """finals.npz holds points whose per-run files the last pack removed: a pack that dies
    while writing (disk full, killed) must leave it whole, and keep the new per-run files."""
    from clothfold_ros.lookup import sweep_dir
    from clothfold_ros.lookup.sweep_dir import FINALS, FINALS_NPZ, final_key, pack_finals, read_packed

    tri, start = np.array([[0, 1, 2]]), np.zeros((3, 3))
    (tmp_path / FINALS).mkdir()
    np.save(tmp_path / FINALS / f"{final_key(1)}.npy", np.full((3, 3), 1.0, dtype=np.float32))
    pack_finals(tmp_path, tri, start, start, [1])
    before = (tmp_path / FINALS_NPZ).read_bytes()
    (tmp_path / FINALS).mkdir()
    np.save(tmp_path / FINALS / f"{final_key(2)}.npy", np.full((3, 3), 2.0, dtype=np.float32))

    def dies_half_way(file, **arrays):
        Path(file).write_bytes(b"PK\x03\x04 half an archive")
        raise OSError("No space left on device")

    monkeypatch.setattr(sweep_dir.np, "savez_compressed", dies_half_way)
    with pytest.raises(OSError, match="No space"):
        pack_finals(tmp_path, tri, start, start, [1, 2])
    monkeypatch.undo()
    assert (tmp_path / FINALS_NPZ).read_bytes() == before
    assert not list(tmp_path.glob(".*")), "temporary archive left behind"
    _, _, finals = read_packed(tmp_path, [1, 2])
    assert finals[1][0, 0] == 1.0 and finals[2][0, 0] == 2.0


def _fake_row(point: int) -> dict:
    return {"point": point, "height_ratio": 1.0, "tilt_deg": 0.0, "loss_m": 0.01, "success": True, "reason": "",
            "wall_time_s": 0.0, "cpu_time_s": 0.0, "newton_iterations": 1, "steps": 1, "solver_commit": "test"}


def test_a_pack_keeps_the_per_run_files_of_points_it_did_not_pack(tmp_path: Path) -> None:
    """finish reads the logged points, then packs: a run another sweep logged in between keeps
    its final state."""
    from clothfold_ros.lookup.sweep_dir import FINALS, append_run, pack_finals, read_packed

    append_run(tmp_path, _fake_row(1), np.full((3, 3), 1.0, dtype=np.float32))
    packed = [r["point"] for r in read_runs(tmp_path)]
    append_run(tmp_path, _fake_row(2), np.full((3, 3), 2.0, dtype=np.float32))  # logged after the read
    pack_finals(tmp_path, np.array([[0, 1, 2]]), np.zeros((3, 3)), np.zeros((3, 3)), packed)
    assert [f.name for f in (tmp_path / FINALS).iterdir()] == ["p002.npy"]
    _, _, finals = read_packed(tmp_path, [1, 2])
    assert finals[1][0, 0] == 1.0 and finals[2][0, 0] == 2.0
    pack_finals(tmp_path, np.array([[0, 1, 2]]), np.zeros((3, 3)), np.zeros((3, 3)), [1, 2])
    assert not (tmp_path / FINALS).exists()  # all packed: the directory goes too


def test_the_sweep_command_tabulates_and_packs_under_its_lock(tmp_path: Path, monkeypatch) -> None:
    from clothfold_ros.cli import main
    from clothfold_ros.lookup import sweep
    from clothfold_ros.lookup.sweep_dir import lock_owner

    owners: list[int | None] = []
    real = sweep.finish

    def finish(d, command, points):
        owners.append(lock_owner(d))
        return real(d, command, points)

    monkeypatch.setattr(sweep, "_local", lambda jobs, n: ((_fake_row(j.point), None) for j in jobs))
    monkeypatch.setattr(sweep, "finish", finish)
    assert main(["sweep", "T1", "--out", str(tmp_path), "--max-area", str(TINY["max_area"]), "--points", "96,133",
                 "--workers", "1", "--quiet"]) == 0
    assert owners == [os.getpid()] and lock_owner(tmp_path / "T1") is None
    assert json.loads((tmp_path / "T1" / "provenance.json").read_text())["complete"]


@pytest.mark.parametrize("bad", [dict(settle_time=float("inf")), dict(max_newton_iterations=0),
                                 dict(max_newton_iterations=2.5), dict(dt=float("nan")), dict(newton_tol=-1.0)])
def test_bad_settings_are_refused_before_a_directory_is_claimed(tmp_path: Path, bad: dict) -> None:
    """settings.json pins a directory to its settings: settings the simulator refuses must not
    get there (the sweep would fail, and a rerun with good settings be refused)."""
    with pytest.raises(ValueError, match=next(iter(bad))):
        SweepSettings("T1", **TINY, **bad)


def test_provenance_names_the_code_the_process_runs_from_any_directory(tmp_path: Path, monkeypatch) -> None:
    from clothfold_ros.lookup.sweep_dir import append_run
    from clothfold_ros.lookup.sweep import solver_commit

    d = tmp_path / "T1"
    run_sweep(SweepSettings("T1", **TINY), d, [], workers=1, progress=False)
    append_run(d, _fake_row(96), None)
    monkeypatch.chdir(tmp_path)  # no git checkout here
    write_table(d, "test", [96])
    commit = json.loads((d / "provenance.json").read_text())["git_commit"]
    assert commit == solver_commit() and re.fullmatch(r"[0-9a-f]{40}(-dirty)?", commit), commit


def test_repair_truncates_the_partial_line_in_place(tmp_path: Path, monkeypatch) -> None:
    from clothfold_ros.lookup.sweep_dir import RUNS, repair_log

    lines = "".join(json.dumps(_fake_row(p)) + "\n" for p in (1, 2))
    (tmp_path / RUNS).write_text(lines + '{"point": 3, "hei')

    def killed_mid_write(self, data):  # what a rewrite killed between truncating and writing leaves
        open(self, "wb").close()
        raise OSError("killed")

    monkeypatch.setattr(Path, "write_bytes", killed_mid_write)
    repair_log(tmp_path)
    assert (tmp_path / RUNS).read_text() == lines
    repair_log(tmp_path)  # a complete log is left as it is
    assert (tmp_path / RUNS).read_text() == lines


def _slow_job(job) -> tuple[dict, None]:
    """A fake run that leaves a marker file when it starts (directory: $CLOTHFOLD_TEST_MARKERS)."""
    (Path(os.environ["CLOTHFOLD_TEST_MARKERS"]) / f"p{job}").touch()
    time.sleep(1.0)
    return _fake_row(job), None


def test_a_pool_left_early_drops_its_queued_runs(monkeypatch, tmp_path: Path) -> None:
    """Ctrl-C (or any error) in a multi-worker sweep: the queued runs are cancelled, not run and
    discarded (a `with ProcessPoolExecutor` waited for all of them). Of 10 runs on 2 workers, those
    running or handed to a worker when the sweep stops may still start; the rest never do."""
    from clothfold_ros.lookup import sweep

    monkeypatch.setenv("CLOTHFOLD_TEST_MARKERS", str(tmp_path))
    monkeypatch.setattr(sweep, "run_job", _slow_job)
    it = sweep._local(list(range(10)), 2)
    next(it)
    it.close()
    time.sleep(5.5)  # what 10 runs of 1 s take on 2 workers, with margin: all would have started
    started = len(list(tmp_path.iterdir()))
    assert 1 <= started <= 7, started  # the first 2, 2 running and at most 3 in the executor's call queue


def test_stage_features_are_measured_as_the_planner_measures_them() -> None:
    """A sequence stage's table features come from the keypoints the planner is sent for its start
    state (keypoint_node: the visible keypoints after the folds made), not from the material
    keypoints: after the sleeve folds those sit on the folded sleeves and gave both_sides a sleeve
    length of 0.481 m where the planner measures 0.539 m."""
    from clothfold_ros.folding import fold_spec
    from clothfold_ros.lookup.scenario import features, folds_before, grip_distance, scenario
    from clothfold_ros.lookup.sweep import start_features
    from clothfold_ros.materials import material
    from clothfold_ros.perception.visible import apply_folds, visible_keypoints
    from clothfold_ros.garment import make_shirt
    from clothfold_ros.sim.runner import flat_start

    assert folds_before("middle") == ("left_sleeve", "right_sleeve", "left_side", "right_side")
    assert folds_before("shape1") == ()
    g = make_shirt(1, max_area=5e-3)
    flat = flat_start(g, material("cotton"))
    flat_kp = g.keypoints(flat)
    sleeves = [fold_spec(f, flat_kp, 170.0) for f in folds_before("both_sides")]
    x = flat.copy()
    x[:, :2] = apply_folds(flat[:, :2], sleeves)  # the sleeves ideally folded
    spec = fold_spec("left_side", g.keypoints(x), 170.0)
    mine = start_features("both_sides", g, flat, x, spec, 170.0)
    # what the pipeline's planner gets: keypoint_node's visible keypoints after the folds it saw announced
    sc = scenario("both_sides")
    seen = visible_keypoints(g, x, sleeves)
    planner = features(fold_name="left_side", keypoints=seen, material_name=sc.material, friction=sc.friction,
                       duration=sc.duration, grip=grip_distance(spec))
    assert mine == planner
    material_kp = features(fold_name="left_side", keypoints=g.keypoints(x), material_name=sc.material,
                           friction=sc.friction, duration=sc.duration, grip=grip_distance(spec))
    assert abs(material_kp["sleeve_length"] - mine["sleeve_length"]) > 0.01  # what the tables recorded before


def test_refresh_features_rewrites_a_stage_directorys_features_only(tmp_path: Path) -> None:
    """refresh_features recomputes scenario.json's features from start.npz (nothing simulated)
    and keeps its other entries; a directory without a stage start state is refused."""
    from clothfold_ros.folding import fold_spec
    from clothfold_ros.lookup import sweep_dir as layout
    from clothfold_ros.lookup.sweep import _scene, refresh_features, start_features
    from clothfold_ros.perception.visible import apply_folds

    d = tmp_path / "both_sides"
    d.mkdir()
    settings = SweepSettings("both_sides", max_area=TINY["max_area"], end_angle_deg=170.0)
    layout.claim_settings(d, settings)
    scene = _scene(settings)
    flat = scene.flat
    sleeves = [fold_spec(f, scene.garment.keypoints(flat), 170.0) for f in ("left_sleeve", "right_sleeve")]
    x = flat.copy()
    x[:, :2] = apply_folds(flat[:, :2], sleeves)
    layout.write_start(d, x, flat)
    layout.write_info(d, {"features": {"sleeve_length": 0.0}, "spec_note": "kept", "start_point": 7})
    got = refresh_features(d)
    spec = fold_spec("left_side", scene.garment.keypoints(x), 170.0)
    assert got == start_features("both_sides", scene.garment, flat, x, spec, 170.0)
    info = layout.read_info(d)
    assert info["features"] == got and info["spec_note"] == "kept" and info["start_point"] == 7
    with pytest.raises(ValueError, match="no sequence-stage start state"):
        (tmp_path / "shape1").mkdir()
        layout.claim_settings(tmp_path / "shape1", SweepSettings("shape1", max_area=TINY["max_area"]))
        refresh_features(tmp_path / "shape1")


def test_a_sweep_runs_nicer_than_the_nodes_and_tests(tmp_path) -> None:
    """`clothfold sweep --nice` raises the process's niceness (its workers inherit it), never
    lowers it, and refuses values outside 0..19 (checked in a child: os.nice is per process)."""
    import os
    import subprocess
    import sys

    n0 = os.nice(0)  # the test's own niceness (a CI may run it niced)
    if n0 > 17:
        pytest.skip(f"the tests run at niceness {n0}: nothing to raise")
    code = (f"import os; from clothfold_ros.cli.sweep import raise_niceness as r; r({n0 + 2}); a = os.nice(0); "
            f"r({n0}); b = os.nice(0)\ntry:\n    r(25)\nexcept ValueError as e:\n    print(a, b, e)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == f"{n0 + 2} {n0 + 2} --nice must be 0..19, got 25"
    from clothfold_ros.cli import main

    with pytest.raises(SystemExit) as exit_:  # refused when parsed, whatever the mode
        main(["sweep", "T1", "--nice", "25", "--table-only", "--out", str(tmp_path)])  # never the shipped tables
    assert exit_.value.code == 2
