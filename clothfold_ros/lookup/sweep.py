"""Resumable sweep of one scenario over fan points on the headless simulator.

A sweep directory holds `settings.json` (what is swept, checked on resume), `runs.jsonl`
(one line per finished trajectory, appended and fsynced as each run ends, failures
included with their reason) and `finals/pNNN.npy` (final vertices, float32, m). A killed
sweep restarted with the same settings skips the points already in `runs.jsonl`.
Runs go to a local process pool (default: one worker per core) or to Ray.
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from ..trajectory import fan
from .scenario import Scenario, features, grip_distance, scenario, spec_for

RUNS = "runs.jsonl"
SETTINGS = "settings.json"
START = "start.npz"
FINALS = "finals"


@dataclass(frozen=True)
class SweepSettings:
    """Everything that determines a sweep's results (SI units: m^2, s, m/s)."""

    scenario: str
    max_area: float = 3e-3
    dt: float = 0.04
    settle_time: float = 0.2
    newton_tol: float = 1e-3
    max_newton_iterations: int = 80

    def __post_init__(self) -> None:
        scenario(self.scenario)
        for k in ("max_area", "dt", "newton_tol"):
            if not (math.isfinite(getattr(self, k)) and getattr(self, k) > 0):
                raise ValueError(f"{k} must be > 0, got {getattr(self, k)}")
        if not self.settle_time >= 0:
            raise ValueError(f"settle_time must be >= 0 s, got {self.settle_time}")


@dataclass(frozen=True)
class Job:
    """One trajectory: fan index `point`, (height ratio, tilt deg)."""

    settings: SweepSettings
    point: int
    height_ratio: float
    tilt_deg: float
    start_file: str | None  # start.npz of a sequence stage (vertices, target_base)


def fan_points(selection: str = "all") -> np.ndarray:
    """Fan indices (into trajectory.fan()) for a selection:

    - 'all': the 134 points;
    - 'every:R:T': every R-th ring counted down from the outermost (h = 1.0 always kept)
      and, within a kept ring, every T-th tilt from 60 deg with the 0 deg end kept;
    - 'alternate' = 'every:1:2';
    - a comma list of indices.
    """
    f = fan()
    if selection == "all":
        return np.arange(len(f))
    if selection == "alternate":
        selection = "every:1:2"
    if selection.startswith("every:"):
        try:
            r_step, t_step = (int(v) for v in selection.split(":")[1:])
        except ValueError:
            raise ValueError(f"fan selection 'every:R:T' needs two integers, got {selection!r}") from None
        if r_step < 1 or t_step < 1:
            raise ValueError(f"'every:R:T' needs R, T >= 1, got {selection!r}")
        heights = np.unique(f[:, 0])
        keep: list[int] = []
        for i, h in enumerate(heights):
            if (len(heights) - 1 - i) % r_step:
                continue
            ring = np.flatnonzero(f[:, 0] == h)
            j = np.arange(len(ring))
            keep += ring[(j % t_step == 0) | (j == len(ring) - 1)].tolist()
        return np.asarray(sorted(keep))
    try:
        idx = np.asarray(sorted({int(s) for s in selection.split(",") if s.strip()}))
    except ValueError:
        raise ValueError(f"fan points must be 'all', 'alternate', 'every:R:T' or comma-separated indices, "
                         f"got {selection!r}") from None
    if len(idx) == 0 or idx.min() < 0 or idx.max() >= len(f):
        raise ValueError(f"fan indices must be in 0..{len(f) - 1}, got {selection!r}")
    return idx


def _config(s: SweepSettings):
    from ..sim.config import SimConfig

    return SimConfig(dt=s.dt, newton_tol=s.newton_tol, max_newton_iterations=s.max_newton_iterations)


def run_job(job: Job) -> tuple[dict, np.ndarray | None]:
    """Simulate one fan point (all folds of the scenario in turn with the same (h, tilt)).

    Returns (row, final vertices (N, 3) float32 or None). Never raises for a failed
    simulation: the row then has success False and the reason.
    """
    from ..garment import make_shirt
    from ..materials import material
    from ..sim.runner import flat_start, run_fold

    s = job.settings
    sc = scenario(s.scenario)
    mat = material(sc.material)
    garment = make_shirt(sc.shape, max_area=s.max_area)
    flat = flat_start(garment, mat)
    if job.start_file:
        with np.load(job.start_file) as z:
            x, base = z["vertices"].astype(float), z["target"].astype(float)
    else:
        x, base = flat, None
    kp_start = garment.keypoints(x)
    row: dict = {"point": job.point, "height_ratio": job.height_ratio, "tilt_deg": job.tilt_deg}
    wall, newton, steps, reason, loss, ok = 0.0, 0, 0, "", float("nan"), True
    final = None
    for fold in sc.folds:
        try:
            spec, _ = spec_for(fold, kp_start, garment.keypoints(flat))
            out = run_fold(garment, spec, mat, sc.friction, job.height_ratio, job.tilt_deg, sc.duration, s.dt,
                           s.settle_time, vertices=x, target_base=base, config=_config(s))
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
               newton_iterations=newton, steps=steps)
    return row, (None if final is None else np.asarray(final, dtype=np.float32))


def prepare_start(settings: SweepSettings, sweep_dir: Path, previous_dir: Path | None) -> tuple[str | None, dict]:
    """Write start.npz for a sequence stage from the best successful run of the previous
    stage's sweep; return (path or None, scenario features + spec note)."""
    from ..garment import make_shirt
    from ..materials import material
    from ..sim.runner import flat_start
    from .table import read_runs, best_row

    sc = scenario(settings.scenario)
    mat = material(sc.material)
    garment = make_shirt(sc.shape, max_area=settings.max_area)
    flat = flat_start(garment, mat)
    info: dict = {}
    path = None
    if sc.after is None:
        x = flat
    else:
        if previous_dir is None or not (previous_dir / RUNS).exists():
            raise FileNotFoundError(f"scenario {sc.name!r} starts from {sc.after!r}: no sweep of it at {previous_dir}")
        if (previous_dir / ".lock").exists() or not (previous_dir / "provenance.json").exists():
            raise ValueError(f"scenario {sc.name!r} starts from {sc.after!r}, whose sweep in {previous_dir} "
                             f"is running or unfinished (no table written yet)")
        prev = SweepSettings(**json.loads((previous_dir / SETTINGS).read_text()))
        if prev.max_area != settings.max_area:
            raise ValueError(f"{sc.after!r} was swept at max_area {prev.max_area}, this sweep uses {settings.max_area}")
        best = best_row(read_runs(previous_dir / RUNS))
        if best is None:
            raise ValueError(f"scenario {sc.after!r} has no successful run to start {sc.name!r} from")
        x = load_final(previous_dir, int(best["point"])).astype(float)
        target = _stage_target(prev, previous_dir, garment)
        path = str(sweep_dir / START)
        np.savez_compressed(path, vertices=x, target=target)
        info.update(start_from=sc.after, start_point=int(best["point"]), start_loss_m=best["loss_m"])
    kp = garment.keypoints(x)
    spec, note = spec_for(sc.folds[0], kp, garment.keypoints(flat))
    info["spec_note"] = note
    info["features"] = features(fold_name=sc.folds[0], keypoints=kp, material_name=sc.material,
                                friction=sc.friction, duration=sc.duration,
                                grip=None if sc.folds[0] == "middle" else grip_distance(spec))
    return path, info


def load_final(sweep_dir: Path, point: int) -> np.ndarray:
    """Final vertices (N, 3) float32 of fan point `point` of a sweep (per-run file or
    the packed finals.npz)."""
    p = Path(sweep_dir) / FINALS / f"p{point:03d}.npy"
    if p.exists():
        return np.load(p)
    packed = Path(sweep_dir) / "finals.npz"
    if packed.exists():
        with np.load(packed) as z:
            if f"p{point:03d}" in z:
                return z[f"p{point:03d}"]
    raise FileNotFoundError(f"no final state of point {point} in {sweep_dir}")


def _start_path(sweep_dir: Path) -> str | None:
    p = sweep_dir / START
    return str(p) if p.exists() else None


def _stage_target(prev: SweepSettings, prev_dir: Path, garment) -> np.ndarray:
    """The composed target after the previous stage's folds (recomputed from specs)."""
    from ..loss import fold_target
    from ..materials import material
    from ..sim.runner import flat_start

    sc = scenario(prev.scenario)
    mat = material(sc.material)
    flat = flat_start(garment, mat)
    start = _start_path(prev_dir)
    if start:
        with np.load(start) as z:
            x, base = z["vertices"].astype(float), z["target"].astype(float)
    else:
        x, base = flat, flat
    kp = garment.keypoints(x)
    for fold in sc.folds:
        spec, _ = spec_for(fold, kp, garment.keypoints(flat))
        base = fold_target(base, spec, mat.thickness)
    return base


def pending(sweep_dir: Path, points: Iterable[int]) -> list[int]:
    """Fan points not yet recorded in runs.jsonl."""
    from .table import read_runs

    done = {int(r["point"]) for r in read_runs(sweep_dir / RUNS)} if (sweep_dir / RUNS).exists() else set()
    return [int(p) for p in points if int(p) not in done]


def _repair_log(path: Path) -> None:
    """Drop a partial last line (a kill during the append) so new lines start clean."""
    if not path.exists() or path.stat().st_size == 0:
        return
    data = path.read_bytes()
    if not data.endswith(b"\n"):
        path.write_bytes(data[: data.rfind(b"\n") + 1])


def _append(sweep_dir: Path, row: dict, final: np.ndarray | None) -> None:
    if final is not None:
        (sweep_dir / FINALS).mkdir(exist_ok=True)
        tmp = sweep_dir / FINALS / f".p{row['point']:03d}.npy"
        np.save(tmp, final)
        os.replace(tmp, sweep_dir / FINALS / f"p{row['point']:03d}.npy")
    with open(sweep_dir / RUNS, "a") as f:
        f.write(json.dumps(row) + "\n")
        f.flush()
        os.fsync(f.fileno())


def _local(jobs: list[Job], workers: int) -> Iterator[tuple[dict, np.ndarray | None]]:
    if workers <= 1:
        for j in jobs:
            yield run_job(j)
        return
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(max_workers=workers) as pool:
        for fut in as_completed([pool.submit(run_job, j) for j in jobs]):
            yield fut.result()


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
              on_row: Callable[[dict], None] | None = None) -> list[dict]:
    """Run (or resume) the sweep of `settings.scenario` over fan indices `points` into
    `sweep_dir`; returns the rows finished in this call. ray_address: None = local pool
    with `workers` processes (default: the usable cores), 'local' = a private single-node
    Ray started here with `workers` CPUs (Ray's local mode is gone since Ray 2.4), else a
    Ray cluster address ('auto' = the running cluster). previous_dir: the sweep directory of the scenario's `after`.
    """
    d = Path(sweep_dir)
    d.mkdir(parents=True, exist_ok=True)
    with _Lock(d / ".lock"):
        return _run_locked(settings, d, points, workers, ray_address, previous_dir, progress, on_row)


class _Lock:
    """One sweep per directory: a lock file holding the owner's pid (a stale lock of a
    dead process is taken over)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __enter__(self) -> "_Lock":
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
                os.write(fd, str(os.getpid()).encode())
                os.close(fd)
                return self
            except FileExistsError:
                try:
                    pid = int(self.path.read_text() or 0)
                    os.kill(pid, 0)
                except (ValueError, ProcessLookupError, FileNotFoundError):
                    self.path.unlink(missing_ok=True)  # stale: its owner is gone
                    continue
                except PermissionError:
                    pass
                raise RuntimeError(f"another sweep (pid {pid}) is running in {self.path.parent}")
        raise RuntimeError(f"could not lock {self.path.parent}")

    def __exit__(self, *exc: object) -> None:
        self.path.unlink(missing_ok=True)


def _run_locked(settings: SweepSettings, d: Path, points: Iterable[int], workers: int | None,
                ray_address: str | None, previous_dir: str | Path | None, progress: bool,
                on_row: Callable[[dict], None] | None) -> list[dict]:
    want = asdict(settings)
    if (d / SETTINGS).exists():
        have = json.loads((d / SETTINGS).read_text())
        if have != want:
            raise ValueError(f"{d} holds a sweep with other settings {have}; use another directory "
                             f"(or delete it) to sweep {want}")
    else:
        (d / SETTINGS).write_text(json.dumps(want, indent=1))
    _repair_log(d / RUNS)
    info_path = d / "scenario.json"
    if not info_path.exists():
        start, info = prepare_start(settings, d, None if previous_dir is None else Path(previous_dir))
        info_path.write_text(json.dumps(info, indent=1))
    start = _start_path(d)
    f = fan()
    todo = pending(d, points)
    jobs = [Job(settings, p, float(f[p, 0]), float(f[p, 1]), start) for p in todo]
    bar = Progress(len(jobs), settings.scenario, progress)
    n_workers = workers or len(os.sched_getaffinity(0))
    it = _ray(jobs, ray_address, n_workers) if ray_address else _local(jobs, n_workers)
    out = []
    for row, final in it:
        _append(d, row, final)
        out.append(row)
        bar.update(bool(row["success"]))
        if on_row:
            on_row(row)
    return out
