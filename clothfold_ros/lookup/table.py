"""Tidy lookup tables: one CSV row per simulated fan point, with provenance.

`write_table` turns a sweep directory (one per scenario, e.g. config/tables/shape1/;
its files are listed in `sweep_dir`) into
- `table.csv`: scenario, fold(s), features (scenario.FEATURE_NAMES), point, height_ratio,
  tilt_deg, loss_m (NaN for failures), success, reason, wall_time_s, newton_iterations,
  steps, max_area_m2, vertices;
- `provenance.json`: git commit, command, resolution, fan points, date, coverage.
`load_table` / `load_tables` read them back.
"""
from __future__ import annotations

import csv
import datetime as _dt
import functools
import json
import subprocess
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..files import replacing
from ..garment import make_shirt
from . import sweep_dir as layout
from .scenario import FEATURE_NAMES, scenario
from .sweep_dir import PROVENANCE, TABLE

COLUMNS = ("scenario", "folds", "shape", "material", *FEATURE_NAMES, "point", "height_ratio", "tilt_deg", "loss_m",
           "success", "reason", "wall_time_s", "newton_iterations", "steps", "max_area_m2", "vertices")


@dataclass
class Table:
    """A loaded scenario table: metadata and column arrays (points sorted)."""

    name: str
    features: dict[str, float]
    point: np.ndarray  # (K,) fan indices
    height_ratio: np.ndarray  # (K,)
    tilt_deg: np.ndarray  # (K,) deg
    loss: np.ndarray  # (K,) m, NaN where failed
    success: np.ndarray  # (K,) bool
    reason: list[str]
    provenance: dict
    directory: Path | None = None  # where it was loaded from (None: built in memory)

    @property
    def complete(self) -> bool:
        """Every fan point its sweep asked for simulated (provenance "complete"; a provenance
        without the field counts as partial, so it is never taken as finished)."""
        return bool(self.provenance.get("complete", False))

    @property
    def fold_type(self) -> float:
        return self.features["fold_type"]

    def loss_at(self, point: int) -> tuple[float, bool]:
        """(loss m, success) of fan point `point`; KeyError if not simulated here."""
        k = np.flatnonzero(self.point == point)
        if len(k) == 0:
            raise KeyError(f"fan point {point} is not in table {self.name!r}")
        return float(self.loss[k[0]]), bool(self.success[k[0]])


def git_commit(repo: str | Path = ".") -> str:
    """`git describe`-like commit id of the working tree (+ '-dirty'), or 'unknown'."""
    try:
        c = subprocess.run(["git", "rev-parse", "HEAD"], cwd=repo, capture_output=True, text=True, check=True).stdout
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "clothfold_ros"], cwd=repo,
                               capture_output=True, text=True, check=True).stdout
        return c.strip() + ("-dirty" if dirty.strip() else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


@functools.lru_cache(maxsize=1)
def solver_commit() -> str:
    """Commit of the code this process simulates with, from the package's own checkout (read
    once: a sweep that runs for hours keeps the code it started with, whatever the checkout
    or the working directory does meanwhile); 'unknown' outside git."""
    return git_commit(Path(__file__).resolve().parents[2])


def write_table(sweep_dir: str | Path, command: str, points: list[int]) -> Path:
    """Build table.csv + provenance.json from a sweep directory; returns the CSV path."""
    d = Path(sweep_dir)
    settings = asdict(layout.read_settings(d))
    info = layout.read_info(d)
    if info is None:
        raise FileNotFoundError(f"{d} holds no sweep ({layout.SCENARIO_INFO} missing)")
    sc = scenario(settings["scenario"])
    garment = make_shirt(sc.shape, max_area=settings["max_area"])
    rows = layout.read_runs(d)
    done = {int(r["point"]) for r in rows}
    missing = sorted(set(points) - done)
    best = layout.best_row(rows)
    prov = {
        "scenario": sc.as_dict(), "settings": settings, "features": info["features"],
        "spec_note": info.get("spec_note", ""), "start_from": info.get("start_from"),
        "start_point": info.get("start_point"), "start_loss_m": info.get("start_loss_m"),
        "git_commit": solver_commit(), "command": command,  # the code this process runs
        # the code each run simulated with (rows written before runs recorded it: "unrecorded")
        "run_commits": dict(Counter(r.get("solver_commit", "unrecorded") for r in rows)),
        "resolution": {"max_area_m2": settings["max_area"], "vertices": len(garment.vertices),
                       "triangles": len(garment.triangles)},
        "fan_points": sorted(points), "simulated": len(rows), "missing_points": missing,
        "failures": sum(not r["success"] for r in rows), "complete": not missing,
        "best": None if best is None else {k: best[k] for k in ("point", "height_ratio", "tilt_deg", "loss_m")},
        "cpu_seconds": round(sum(r.get("cpu_time_s", r["wall_time_s"]) for r in rows), 1),  # wall where not recorded
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
    # both written aside and renamed (the table first, as the inner one): a reader never sees half a table
    with replacing(d / PROVENANCE) as prov_tmp, replacing(d / TABLE) as tmp:
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=COLUMNS)
            w.writeheader()
            for r in rows:
                w.writerow({"scenario": sc.name, "folds": "+".join(sc.folds), "shape": sc.shape,
                            "material": sc.material, **{k: f"{info['features'][k]:.6g}" for k in FEATURE_NAMES},
                            "point": r["point"], "height_ratio": f"{r['height_ratio']:.6g}",
                            "tilt_deg": f"{r['tilt_deg']:.6g}", "loss_m": f"{r['loss_m']:.6g}",
                            "success": int(bool(r["success"])), "reason": r["reason"], "wall_time_s": r["wall_time_s"],
                            "newton_iterations": r["newton_iterations"], "steps": r["steps"],
                            "max_area_m2": settings["max_area"], "vertices": len(garment.vertices)})
        prov_tmp.write_text(json.dumps(prov, indent=1))
    return d / TABLE


def load_table(table_dir: str | Path) -> Table:
    """Load one scenario table directory (clear errors for missing or broken files: one
    scenario per table, one set of finite features, fan points of `trajectory.fan` with their own (h,
    tilt), each once, success 0 or 1, a finite loss >= 0 for every successful run)."""
    from ..trajectory import fan

    d = Path(table_dir)
    if not (d / TABLE).is_file():
        raise FileNotFoundError(f"no lookup table at {d / TABLE}")
    try:
        prov = json.loads((d / PROVENANCE).read_text())
        if not isinstance(prov, dict):
            raise ValueError(f"{PROVENANCE} is not a JSON object")
        with open(d / TABLE, newline="") as f:
            rows = list(csv.DictReader(f))
        if not rows:
            raise ValueError("no rows")
        names = sorted({r["scenario"] for r in rows})
        if len(names) != 1:
            raise ValueError(f"rows of several scenarios: {', '.join(names)}")
        differ = [k for k in FEATURE_NAMES if len({r[k] for r in rows}) > 1]
        if differ:
            raise ValueError(f"feature(s) {', '.join(differ)} differ between rows")
        feats = {k: float(rows[0][k]) for k in FEATURE_NAMES}
        bad = [k for k, v in feats.items() if not np.isfinite(v)]
        if bad:
            raise ValueError(f"feature(s) {', '.join(bad)} not finite")
        point = np.array([int(r["point"]) for r in rows])
        h = np.array([float(r["height_ratio"]) for r in rows])
        tilt = np.array([float(r["tilt_deg"]) for r in rows])
        f = fan()
        if point.min() < 0 or point.max() >= len(f):
            raise ValueError(f"fan point outside 0..{len(f) - 1}: {sorted(set(point[(point < 0) | (point >= len(f))]))}")
        dup = sorted(p for p, n in Counter(point.tolist()).items() if n > 1)
        if dup:
            raise ValueError(f"fan point(s) listed twice: {dup}")
        off = ~(np.isclose(h, f[point, 0], atol=1e-4) & np.isclose(tilt, f[point, 1], atol=1e-3))
        if off.any():
            k = int(np.flatnonzero(off)[0])
            raise ValueError(f"fan point {point[k]} has (h, tilt) ({h[k]:g}, {tilt[k]:g}); the fan's is "
                             f"({f[point[k], 0]:g}, {f[point[k], 1]:g})")
        flags = [r["success"] for r in rows]
        if set(flags) - {"0", "1"}:
            raise ValueError(f"success must be 0 or 1, not {sorted(set(flags) - {'0', '1'})}")
        success = np.array([x == "1" for x in flags])
        loss = np.array([float(r["loss_m"]) for r in rows])
        wrong = success & ~(np.isfinite(loss) & (loss >= 0))
        if wrong.any():
            raise ValueError(f"successful run(s) without a finite loss >= 0 at fan point(s) {point[wrong].tolist()}")
        return Table(name=names[0], features=feats, point=point, height_ratio=h, tilt_deg=tilt, loss=loss,
                     success=success, reason=[r["reason"] for r in rows], provenance=prov, directory=d)
    except (OSError, KeyError, ValueError, json.JSONDecodeError) as err:
        raise ValueError(f"broken lookup table in {d}: {type(err).__name__}: {err}") from err


def load_tables(root: str | Path) -> dict[str, Table]:
    """All scenario tables under `root` (each sub-directory with a table.csv)."""
    return load_layered_tables([Path(root)])[0]


def table_roots(spec: str | Path | list) -> list[Path]:
    """Table directories in order of precedence: a list, or one string with several joined by
    ':' (e.g. "my_tables:config/tables")."""
    if isinstance(spec, (list, tuple)):
        return [Path(p) for p in spec]
    return [Path(p) for p in str(spec).split(":") if p]


def load_layered_tables(roots: list[Path]) -> tuple[dict[str, Table], dict[str, Path]]:
    """Scenario tables from several roots in order of precedence, with the root each came from.

    A scenario's table comes from the first root whose table for it is complete (every fan
    point the sweep asked for simulated: provenance "complete"); where no root has a complete
    one, from the first root that has it at all. So a finer table being computed replaces a
    coarse one only once it is finished. Roots that do not exist are skipped; none existing,
    or no table in any, is a FileNotFoundError; a broken table is a ValueError.
    """
    existing = [r for r in roots if Path(r).is_dir()]
    if not existing:
        raise FileNotFoundError(f"lookup table directory {' or '.join(str(r) for r in roots)} does not exist")
    chosen: dict[str, Table] = {}
    origin: dict[str, Path] = {}
    for root in existing:
        here: dict[str, Path] = {}
        for d in layout.table_dirs(root):
            t = load_table(d)
            if t.name in here:
                raise ValueError(f"two tables of scenario {t.name!r} in {root}: {here[t.name]} and {d}")
            here[t.name] = Path(d)
            held = chosen.get(t.name)
            if held is None or (not held.complete and t.complete):
                chosen[t.name], origin[t.name] = t, Path(root)
    if not chosen:
        raise FileNotFoundError(f"no lookup tables (*/{TABLE}) under {', '.join(str(r) for r in existing)}")
    return chosen, origin
