"""The sweep directory: the one module that knows its file layout.

A sweep of one scenario and the lookup table made from it share one directory
(e.g. config/tables/shape1/):

| file | written by | content |
|---|---|---|
| `settings.json` | sweep, first call | `SweepSettings` (checked on every resume) |
| `scenario.json` | sweep, first call | features and spec note of the start state (`sweep.prepare_start`) |
| `start.npz` | sweep, sequence stages only | start `vertices` and `target` (the previous stage's target), m |
| `runs.jsonl` | sweep, one line per finished run | the resume state: row of each fan point, failures included, with the commit it simulated with (`solver_commit`) |
| `finals/pNNN.npy` | sweep, before its runs.jsonl line | final vertices of fan point NNN, float32, m |
| `finals.npz` | `pack_finals` | `triangles`, `start`, `target` and every `pNNN` (replaces the packed points' finals/ files) |
| `table.csv`, `provenance.json` | `table.write_table` | the tidy table and its provenance |
| `landscape.png`, `best_worst.png` | `plot` | figures (`../landscapes.png`: `plot --overview`, all tables) |
| `.lock` | sweep, while running (and tabulating) | owner pid |

Everything else (the sweep engine, the table format, plots) reads and writes these
files through this module. No rclpy; the settings are checked with the simulator's own
checks (`SweepSettings`).
"""
from __future__ import annotations

import fcntl
import json
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..files import replacing
from ..sim.config import SimConfig
from ..folding import check_end_angle
from .scenario import scenario

SETTINGS = "settings.json"
SCENARIO_INFO = "scenario.json"
START = "start.npz"
RUNS = "runs.jsonl"
FINALS = "finals"
FINALS_NPZ = "finals.npz"
TABLE = "table.csv"
PROVENANCE = "provenance.json"
LANDSCAPE_PNG = "landscape.png"
BEST_WORST_PNG = "best_worst.png"
OVERVIEW_PNG = "landscapes.png"  # in the tables root: all scenarios side by side
LOCK = ".lock"
LOCK_GRACE_S = 10.0  # a lock file holding no pid is being written while younger than this, else stale
STUDY_END_ANGLE_DEG = 170.0  # the end angle of the study's simulations (docs/method.md)
LEGACY_END_ANGLE_DEG = 175.0  # sweeps whose settings.json predates the field were made with this


@dataclass(frozen=True)
class SweepSettings:
    """Everything that determines a sweep's results (SI units: m^2, s, m/s)."""

    scenario: str
    max_area: float = 3e-3
    dt: float = SimConfig.dt
    settle_time: float = 0.2
    newton_tol: float = SimConfig.newton_tol
    max_newton_iterations: int = SimConfig.max_newton_iterations
    end_angle_deg: float = STUDY_END_ANGLE_DEG  # fold end pose: start pose rotated this much about the line

    def __post_init__(self) -> None:
        """Checks everything before a sweep writes anything (settings.json pins a directory)."""
        from ..sim.scene import SceneSettings  # here: the simulator's import is heavy for readers of tables

        sc = scenario(self.scenario)
        check_end_angle(self.end_angle_deg)
        if not (math.isfinite(self.settle_time) and self.settle_time >= 0):
            raise ValueError(f"settle_time must be finite and >= 0 s, got {self.settle_time}")
        # the scene's and the solver's (SimConfig) own checks: max_area, dt, newton_tol, iteration cap
        SceneSettings(shape=sc.shape, max_area=self.max_area, material=sc.material, friction=sc.friction, dt=self.dt,
                      newton_tol=self.newton_tol, max_newton_iterations=self.max_newton_iterations)


def final_key(point: int) -> str:
    """Name of fan point `point`'s final state: 'pNNN' (npz key, .npy stem)."""
    return f"p{int(point):03d}"


# -- settings and scenario info ----------------------------------------------------------
def _settings_dict(text: str) -> dict:
    """settings.json as a dict, with the end angle filled in for sweeps that predate it."""
    d = json.loads(text)
    d.setdefault("end_angle_deg", LEGACY_END_ANGLE_DEG)
    return d


def read_settings(d: str | Path) -> SweepSettings:
    """The settings a sweep directory was made with."""
    return SweepSettings(**_settings_dict((Path(d) / SETTINGS).read_text()))


def claim_settings(d: str | Path, settings: SweepSettings) -> None:
    """Write `settings` into a new sweep directory, or check they equal the ones there."""
    p, want = Path(d) / SETTINGS, asdict(settings)
    if p.exists():
        have = _settings_dict(p.read_text())
        if have != want:
            raise ValueError(f"{d} holds a sweep with other settings {have}; use another directory "
                             f"(or delete it) to sweep {want}")
    else:
        p.write_text(json.dumps(want, indent=1))


def read_info(d: str | Path) -> dict | None:
    """scenario.json (features, spec note, start state), None before the sweep wrote it."""
    p = Path(d) / SCENARIO_INFO
    return json.loads(p.read_text()) if p.exists() else None


def write_info(d: str | Path, info: dict) -> None:
    """Write scenario.json whole (aside and renamed: a running sweep reads it per table)."""
    with replacing(Path(d) / SCENARIO_INFO) as tmp:
        tmp.write_text(json.dumps(info, indent=1))


def is_finished(d: str | Path) -> bool:
    """True when a table has been written and no sweep is running in `d` (a lock left by a
    killed sweep does not count)."""
    return (Path(d) / PROVENANCE).exists() and lock_owner(d) is None


def is_complete(d: str | Path) -> bool:
    """True when the table written in `d` covers every fan point its sweep was asked for."""
    try:
        return bool(json.loads((Path(d) / PROVENANCE).read_text()).get("complete", False))
    except (OSError, json.JSONDecodeError):
        return False


# -- start state of a sequence stage ------------------------------------------------------
def start_file(d: str | Path) -> str | None:
    """Path of the stage's start.npz (None: the scenario starts flat)."""
    p = Path(d) / START
    return str(p) if p.exists() else None


def read_start(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(start vertices (N, 3), previous target (N, 3)) in m from a start.npz."""
    with np.load(path) as z:
        return z["vertices"].astype(float), z["target"].astype(float)


def write_start(d: str | Path, vertices: np.ndarray, target: np.ndarray) -> str:
    """Store a stage's start state; returns the file's path."""
    p = str(Path(d) / START)
    np.savez_compressed(p, vertices=vertices, target=target)
    return p


# -- the run log ----------------------------------------------------------------------------
def read_runs(path: str | Path) -> list[dict]:
    """Rows of a runs.jsonl (a file, or a sweep directory); a partial last line (killed
    mid-write) is ignored. Later duplicates of a point (none in a healthy log) replace
    earlier ones."""
    path = Path(path)
    if path.is_dir():
        path = path / RUNS
    rows: dict[int, dict] = {}
    lines = path.read_text().split("\n")
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            r = json.loads(line)
        except json.JSONDecodeError:
            if i == len(lines) - 1:
                continue  # the partial tail of a killed append
            raise ValueError(f"{path}:{i + 1}: broken line") from None
        rows[int(r["point"])] = r
    return [rows[k] for k in sorted(rows)]


def has_runs(d: str | Path) -> bool:
    return (Path(d) / RUNS).exists()


def best_row(rows: list[dict]) -> dict | None:
    """The successful row of least loss (None if none succeeded)."""
    ok = [r for r in rows if r["success"] and math.isfinite(r["loss_m"])]
    return min(ok, key=lambda r: (r["loss_m"], r["point"])) if ok else None


def pending(d: str | Path, points) -> list[int]:
    """Fan points not yet recorded in the run log."""
    done = {int(r["point"]) for r in read_runs(Path(d) / RUNS)} if has_runs(d) else set()
    return [int(p) for p in points if int(p) not in done]


def repair_log(d: str | Path) -> None:
    """Drop a partial last line (a kill during the append) so new lines start clean; truncated
    in place, so a kill during the repair never loses the complete lines."""
    path = Path(d) / RUNS
    if not path.exists() or path.stat().st_size == 0:
        return
    data = path.read_bytes()
    if not data.endswith(b"\n"):
        os.truncate(path, data.rfind(b"\n") + 1)


def append_run(d: str | Path, row: dict, final: np.ndarray | None) -> None:
    """Record one finished run: its final vertices first, then its line (fsynced), so a
    kill never leaves a logged run without its final state."""
    d = Path(d)
    if final is not None:
        (d / FINALS).mkdir(exist_ok=True)
        name = f"{final_key(row['point'])}.npy"
        with replacing(d / FINALS / name, "." + name) as tmp:  # keeps .npy: np.save adds it otherwise
            np.save(tmp, final)
    with open(d / RUNS, "a") as f:
        f.write(json.dumps(row) + "\n")
        f.flush()
        os.fsync(f.fileno())


# -- final states -----------------------------------------------------------------------------
def load_final(d: str | Path, point: int) -> np.ndarray:
    """Final vertices (N, 3) float32 of fan point `point` (per-run file or finals.npz)."""
    p = Path(d) / FINALS / f"{final_key(point)}.npy"
    if p.exists():
        return np.load(p)
    packed = Path(d) / FINALS_NPZ
    if packed.exists():
        with np.load(packed) as z:
            if final_key(point) in z:
                return z[final_key(point)]
    raise FileNotFoundError(f"no final state of point {point} in {d}")


def pack_finals(d: str | Path, triangles: np.ndarray, start: np.ndarray, target: np.ndarray,
                points) -> Path:
    """Write finals.npz (triangles, start, target and the final state of every point of
    `points` that has one) and remove those points' per-run files (only those: a run logged
    after `points` was read keeps its own)."""
    d = Path(d)
    arrays = {"triangles": np.asarray(triangles).astype(np.int32), "start": np.asarray(start, dtype=np.float32),
              "target": np.asarray(target, dtype=np.float32)}
    for p in sorted(points):
        try:
            arrays[final_key(p)] = load_final(d, p)
        except FileNotFoundError:
            pass  # failed before any fold finished: no final state
    # aside and renamed: the old archive holds points whose per-run files are gone
    with replacing(d / FINALS_NPZ, "." + FINALS_NPZ) as tmp:  # keeps .npz: np.savez adds it otherwise
        np.savez_compressed(tmp, **arrays)
    for p in points:
        (d / FINALS / f"{final_key(p)}.npy").unlink(missing_ok=True)
    if (d / FINALS).exists() and not any((d / FINALS).iterdir()):
        (d / FINALS).rmdir()
    return d / FINALS_NPZ


def read_packed(d: str | Path, points) -> tuple[np.ndarray, np.ndarray, dict[int, np.ndarray]]:
    """(triangles, target, {point: final vertices}) from finals.npz; the final state of a run
    finished after the last pack (a sweep still under way) comes from its per-run file."""
    p = Path(d) / FINALS_NPZ
    if not p.exists():
        raise FileNotFoundError(f"no final states ({FINALS_NPZ}) in {d}")
    with np.load(p) as z:  # one open archive for every point it holds
        return z["triangles"], z["target"], {int(k): z[final_key(k)] if final_key(k) in z else load_final(d, int(k))
                                             for k in points}


# -- tables under a root ----------------------------------------------------------------------
def table_dirs(root: str | Path) -> list[Path]:
    """Sub-directories of `root` that hold a table.csv, sorted by name."""
    return [p.parent for p in sorted(Path(root).glob(f"*/{TABLE}"))]


# -- one sweep per directory --------------------------------------------------------------------
def lock_owner(d: str | Path) -> int | None:
    """The pid of the live sweep holding `d`'s lock; 0 while the lock file holds no pid yet
    (being written: younger than LOCK_GRACE_S); None when unlocked or when the lock is stale
    (its owner is gone: a sweep killed by a signal leaves its lock file behind)."""
    p = Path(d) / LOCK
    try:
        pid = int(p.read_text())
    except FileNotFoundError:
        return None
    except ValueError:  # empty or garbled
        pid = 0
    if pid <= 0:
        try:
            return 0 if time.time() - p.stat().st_mtime < LOCK_GRACE_S else None
        except FileNotFoundError:
            return None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return None
    except PermissionError:  # alive, another user's
        pass
    return pid


class Lock:
    """One sweep per directory: a lock file holding the owner's pid (a stale lock of a
    dead process is taken over). The file is created with the pid already in it (a hard
    link of a written file), takers check and take over one at a time (flock on the
    directory), and the owner removes it only while it still holds its pid."""

    def __init__(self, d: str | Path) -> None:
        self.path = Path(d) / LOCK

    def __enter__(self) -> "Lock":
        tmp = self.path.with_name(f"{LOCK}.{os.getpid()}.{id(self)}")  # this process's own
        dfd = os.open(self.path.parent, os.O_RDONLY)
        try:
            tmp.write_text(str(os.getpid()))
            fcntl.flock(dfd, fcntl.LOCK_EX)  # else two takers could both remove a stale lock, one the other's new one
            for _ in range(2):
                try:
                    os.link(tmp, self.path)  # atomic create-with-content: no reader sees it empty
                    return self
                except FileExistsError:
                    pid = lock_owner(self.path.parent)
                    if pid is None:
                        self.path.unlink(missing_ok=True)  # stale: its owner is gone
                        continue
                    raise RuntimeError(f"another sweep ({f'pid {pid}' if pid else 'pid not written yet'}) "
                                       f"is running in {self.path.parent}") from None
            raise RuntimeError(f"could not lock {self.path.parent}")
        finally:
            os.close(dfd)  # releases the flock
            tmp.unlink(missing_ok=True)

    def __exit__(self, *exc: object) -> None:
        try:
            mine = int(self.path.read_text()) == os.getpid()
        except (FileNotFoundError, ValueError):
            return
        if mine:  # else another sweep's (ours was taken over as stale): not ours to remove
            self.path.unlink(missing_ok=True)
