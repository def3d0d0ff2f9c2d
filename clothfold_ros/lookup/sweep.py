"""Resumable sweep of one scenario over fan points on the headless simulator.

Each finished trajectory is appended to the sweep directory's run log as it ends
(failures included with their reason), so a killed sweep restarted with the same
settings skips the points already done. The directory's files are read and written
through `sweep_dir` (the one owner of the layout); `finish` turns a sweep into a table.
Runs go to a local process pool (default: one worker per core) or to Ray.
"""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from ..folding import fold_spec
from ..garment import Garment
from ..loss import fold_target
from ..sim import runner  # runner.run_fold looked up per call (tests patch it)
from ..sim.scene import Scene, SceneSettings, build_scene
from ..trajectory import fan
from . import sweep_dir as layout
from .fan_selection import coverage_order
from .scenario import features, folds_before, grip_distance, scenario, spec_for
from .sweep_dir import SweepSettings, load_final, read_start
from .table import solver_commit, write_table

__all__ = ["Job", "Progress", "SweepSettings", "finish", "load_final", "prepare_start", "run_job",
           "run_sweep", "solver_commit", "stage_target"]


@dataclass(frozen=True)
class Job:
    """One trajectory: fan index `point`, (height ratio, tilt deg)."""

    settings: SweepSettings
    point: int
    height_ratio: float
    tilt_deg: float
    start_file: str | None  # start.npz of a sequence stage (vertices, target_base)


def _scene(s: SweepSettings) -> Scene:
    """The simulated scene of a sweep: its scenario's shirt, material and friction at the
    sweep's mesh resolution and solver settings."""
    sc = scenario(s.scenario)
    return build_scene(SceneSettings(shape=sc.shape, max_area=s.max_area, material=sc.material, friction=sc.friction,
                                     dt=s.dt, newton_tol=s.newton_tol, max_newton_iterations=s.max_newton_iterations))


def run_job(job: Job) -> tuple[dict, np.ndarray | None]:
    """Simulate one fan point (all folds of the scenario in turn with the same (h, tilt)).

    Returns (row, final vertices (N, 3) float32 or None). Never raises for a failed
    simulation: the row then has success False and the reason.
    """
    commit = solver_commit()  # before simulating: the code this process started with
    s = job.settings
    sc = scenario(s.scenario)
    scene = _scene(s)
    mat, garment, flat = scene.material, scene.garment, scene.flat
    x, base = read_start(job.start_file) if job.start_file else (flat, None)
    kp_start = garment.keypoints(x)
    row: dict = {"point": job.point, "height_ratio": job.height_ratio, "tilt_deg": job.tilt_deg}
    wall, newton, steps, reason, loss, ok = 0.0, 0, 0, "", float("nan"), True
    final = None
    cpu0 = time.process_time()  # CPU seconds: unlike wall time, not inflated while the sweep is paused
    for fold in sc.folds:
        try:
            spec, _ = spec_for(fold, kp_start, garment.keypoints(flat), s.end_angle_deg)
            out = runner.run_fold(garment, spec, mat, scene.friction, job.height_ratio, job.tilt_deg, sc.duration,
                                  s.dt, s.settle_time, vertices=x, target_base=base, config=scene.config)
        except Exception as err:  # a broken setup is recorded like a failed simulation
            ok, reason = False, f"{fold}: {type(err).__name__}: {err}"
            break
        wall += out.wall_time
        newton += out.newton_iterations
        steps += out.steps
        final = out.vertices
        if not out.success:
            ok, reason = False, f"{fold}: {out.reason}"
            break
        x, base, loss = out.vertices, out.target, out.loss
    row.update(loss_m=loss if ok else float("nan"), success=ok, reason=reason, wall_time_s=round(wall, 3),
               cpu_time_s=round(time.process_time() - cpu0, 3), newton_iterations=newton, steps=steps,
               solver_commit=commit)
    return row, (None if final is None else np.asarray(final, dtype=np.float32))


def prepare_start(settings: SweepSettings, sweep_dir: Path, previous_dir: Path | None) -> tuple[str | None, dict]:
    """Write start.npz for a sequence stage from the best successful run of the previous
    stage's sweep; return (path or None, scenario features + spec note)."""
    sc = scenario(settings.scenario)
    scene = _scene(settings)
    garment, flat = scene.garment, scene.flat
    info: dict = {}
    path = None
    if sc.after is None:
        x = flat
    else:
        if previous_dir is None or not layout.has_runs(previous_dir):
            raise FileNotFoundError(f"scenario {sc.name!r} starts from {sc.after!r}: no sweep of it at {previous_dir}")
        if not layout.is_finished(previous_dir):
            raise ValueError(f"scenario {sc.name!r} starts from {sc.after!r}, whose sweep in {previous_dir} "
                             f"is running or unfinished (no table written yet)")
        if not layout.is_complete(previous_dir):
            raise ValueError(f"scenario {sc.name!r} starts from {sc.after!r}, whose table in {previous_dir} is "
                             f"partial (its provenance lists missing points): finish that sweep first")
        prev = layout.read_settings(previous_dir)
        for key in ("max_area", "end_angle_deg"):
            if getattr(prev, key) != getattr(settings, key):
                raise ValueError(f"{sc.after!r} was swept at {key} {getattr(prev, key)}, this sweep uses "
                                 f"{getattr(settings, key)}")
        best = layout.best_row(layout.read_runs(previous_dir))
        if best is None:
            raise ValueError(f"scenario {sc.after!r} has no successful run to start {sc.name!r} from")
        x = layout.load_final(previous_dir, int(best["point"])).astype(float)
        path = layout.write_start(sweep_dir, x, stage_target(previous_dir))
        info.update(start_from=sc.after, start_point=int(best["point"]), start_loss_m=best["loss_m"])
    info["spec_note"], info["features"] = _start_info(sc.name, garment, flat, x, settings.end_angle_deg)
    return path, info


def _start_info(name: str, garment: Garment, flat: np.ndarray, x: np.ndarray,
                end_angle_deg: float) -> tuple[str, dict[str, float]]:
    """(spec note, features) of scenario `name`'s start state x (N, 3) m: how its first fold's
    spec was planned (`spec_for`) and the features of that fold (`start_features`)."""
    spec, note = spec_for(scenario(name).folds[0], garment.keypoints(x), garment.keypoints(flat), end_angle_deg)
    return note, start_features(name, garment, flat, x, spec, end_angle_deg)


def start_features(name: str, garment: Garment, flat: np.ndarray, x: np.ndarray, spec,
                   end_angle_deg: float) -> dict[str, float]:
    """Features of scenario `name`'s first fold measured as the planner measures them: on the
    keypoints seen on the start state x (N, 3) m, the visible ones after the folds made before
    it (planned on the flat shirt, as the study did), with the grip distance of its spec."""
    from ..perception.visible import visible_keypoints

    sc = scenario(name)
    flat_kp = garment.keypoints(flat)
    done = [fold_spec(f, flat_kp, end_angle_deg) for f in folds_before(name)]
    return features(fold_name=sc.folds[0], keypoints=visible_keypoints(garment, x, done), material_name=sc.material,
                    friction=sc.friction, duration=sc.duration, grip=grip_distance(spec))


def refresh_features(d: str | Path) -> dict[str, float]:
    """Recompute the features in a sequence stage's scenario.json from its start.npz (no run is
    simulated again: features only place the table for the planner); returns them."""
    d = Path(d)
    settings = layout.read_settings(d)
    start = layout.start_file(d)
    info = layout.read_info(d)
    if start is None or info is None:
        raise ValueError(f"{d} holds no sequence-stage start state (start.npz and scenario.json)")
    scene = _scene(settings)
    x, _ = read_start(start)
    _, info["features"] = _start_info(settings.scenario, scene.garment, scene.flat, x, settings.end_angle_deg)
    layout.write_info(d, info)
    return info["features"]


def stage_target(d: str | Path, scene: Scene | None = None) -> np.ndarray:
    """The composed target (N, 3) m after the folds of the stage swept in `d`
    (recomputed from its start state and the fold specs) in the sweep's scene (built from
    the settings in `d` when not given)."""
    settings = layout.read_settings(d)
    sc = scenario(settings.scenario)
    scene = _scene(settings) if scene is None else scene
    garment, mat, flat = scene.garment, scene.material, scene.flat
    start = layout.start_file(d)
    x, base = read_start(start) if start else (flat, flat)
    kp = garment.keypoints(x)
    for fold in sc.folds:
        spec, _ = spec_for(fold, kp, garment.keypoints(flat), settings.end_angle_deg)
        base = fold_target(base, spec, mat.thickness)
    return base


def table_is_current(d: str | Path) -> bool:
    """Whether <d>/table.csv and finals.npz already hold exactly the runs in runs.jsonl (then
    `finish` would only rewrite the provenance's date and commit)."""
    import csv

    d = Path(d)
    table = d / "table.csv"
    if not table.exists() or not (d / layout.FINALS_NPZ).exists():
        return False  # no table yet
    logged = sorted(int(r["point"]) for r in layout.read_runs(d))
    keys = {layout.final_key(p) for p in logged}
    if any(f.stem in keys for f in (d / layout.FINALS).glob("*.npy")):
        return False  # finals of logged runs not packed (a file without a logged run, from a run killed
        #               before its row was written, is redone and overwritten when that point runs again)
    with table.open(newline="") as fh:
        tabled = sorted(int(r["point"]) for r in csv.DictReader(fh))
    return tabled == logged


def finish(d: str | Path, command: str, points: list[int]) -> Path:
    """Write the table (table.csv, provenance.json) of the sweep in `d` and pack its final
    states into finals.npz; returns the table.csv path."""
    scene = _scene(layout.read_settings(d))
    garment, flat = scene.garment, scene.flat
    table = write_table(d, command, points)
    start = layout.start_file(d)
    x = read_start(start)[0] if start else flat
    layout.pack_finals(d, garment.triangles, x, stage_target(d, scene),
                       [int(r["point"]) for r in layout.read_runs(d)])
    return table


def _local(jobs: list[Job], workers: int) -> Iterator[tuple[dict, np.ndarray | None]]:
    if workers <= 1:
        for j in jobs:
            yield run_job(j)
        return
    from concurrent.futures import ProcessPoolExecutor, as_completed

    pool = ProcessPoolExecutor(max_workers=workers)
    futures = [pool.submit(run_job, j) for j in jobs]
    try:
        for fut in as_completed(futures):
            yield fut.result()
    except BaseException:  # Ctrl-C, an error, or the sweep left early: queued runs are dropped, not awaited
        for fut in futures:  # cancelled here: shutdown(cancel_futures=True) without waiting cancelled none
            fut.cancel()     # (Python 3.11); runs already handed to a worker still start
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()


def _ray(jobs: list[Job], address: str, workers: int) -> Iterator[tuple[dict, np.ndarray | None]]:
    import ray

    if not ray.is_initialized():
        if address == "local":  # a private single-node Ray on this machine (Ray >= 2.4 has no local_mode)
            ray.init(num_cpus=max(1, workers), include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, log_to_driver=False)
    remote = ray.remote(run_job)
    refs = [remote.remote(j) for j in jobs]
    while refs:
        ready, refs = ray.wait(refs, num_returns=1)
        yield ray.get(ready[0])


class Progress:
    """A one-line progress bar with ETA on stderr (no-op when disabled)."""

    def __init__(self, total: int, label: str, enabled: bool = True) -> None:
        self.total, self.label, self.enabled = total, label, enabled
        self.done = self.failed = 0
        self.t0 = time.perf_counter()

    def update(self, ok: bool) -> None:
        self.done += 1
        self.failed += 0 if ok else 1
        if not self.enabled:
            return
        el = time.perf_counter() - self.t0
        eta = el / self.done * (self.total - self.done)
        n = 24
        fill = int(n * self.done / max(self.total, 1))
        print(f"\r{self.label} [{'#' * fill}{'.' * (n - fill)}] {self.done}/{self.total}  failed {self.failed}  "
              f"elapsed {_hms(el)}  eta {_hms(eta)}", end="\n" if self.done == self.total else "",
              file=sys.stderr, flush=True)


def _hms(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


def run_sweep(settings: SweepSettings, sweep_dir: str | Path, points: Iterable[int], *, workers: int | None = None,
              ray_address: str | None = None, previous_dir: str | Path | None = None, progress: bool = True,
              on_row: Callable[[dict], None] | None = None, command: str | None = None) -> list[dict]:
    """Run (or resume) the sweep of `settings.scenario` over fan indices `points` into
    `sweep_dir`; returns the rows finished in this call. ray_address: None = local pool
    with `workers` processes (default: the usable cores), 'local' = a private single-node
    Ray started here with `workers` CPUs (Ray's local mode is gone since Ray 2.4), else a
    Ray cluster address ('auto' = the running cluster). previous_dir: the sweep directory of the scenario's `after`.
    command: also `finish` (table recording `command`, packed finals) before releasing the lock,
    unless this call ran nothing and the table is current.
    """
    d = Path(sweep_dir)
    d.mkdir(parents=True, exist_ok=True)
    points = [int(p) for p in points]
    solver_commit()  # read now: the provenance names the code this process started with
    with layout.Lock(d):  # the table and the pack too: a sweep started meanwhile would lose finals to the pack
        rows = _run_locked(settings, d, points, workers, ray_address, previous_dir, progress, on_row)
        if command is not None and (rows or not table_is_current(d)):
            finish(d, command, points)
        return rows


def _run_locked(settings: SweepSettings, d: Path, points: Iterable[int], workers: int | None,
                ray_address: str | None, previous_dir: str | Path | None, progress: bool,
                on_row: Callable[[dict], None] | None) -> list[dict]:
    layout.claim_settings(d, settings)
    layout.repair_log(d)
    if layout.read_info(d) is None:
        _, info = prepare_start(settings, d, None if previous_dir is None else Path(previous_dir))
        layout.write_info(d, info)
    start = layout.start_file(d)
    f = fan()
    todo = coverage_order(layout.pending(d, points))
    jobs = [Job(settings, p, float(f[p, 0]), float(f[p, 1]), start) for p in todo]
    bar = Progress(len(jobs), settings.scenario, progress)
    n_workers = workers or len(os.sched_getaffinity(0))
    it = _ray(jobs, ray_address, n_workers) if ray_address else _local(jobs, n_workers)
    out = []
    try:
        for row, final in it:
            layout.append_run(d, row, final)
            out.append(row)
            bar.update(bool(row["success"]))
            if on_row:
                on_row(row)
    finally:
        it.close()  # left early (Ctrl-C in on_row, a full disk): the pool drops its queued runs now
    return out
