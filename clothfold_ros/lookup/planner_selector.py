"""The lookup the fold planner node plugs in: observed scenario -> (height ratio, tilt)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from .scenario import FOLD_TYPE_NAME, STAGE_OF_FOLD, features
from .fan_selection import COVERAGE_LEVELS, fan_points
from .select import choose
from .sweep_dir import LEGACY_END_ANGLE_DEG
from .table import load_layered_tables, table_roots


@dataclass(frozen=True)
class Selection:
    """The chosen trajectory parameters; expected_loss in m (neighbourhood-smoothed)."""

    height_ratio: float
    tilt_deg: float
    scenario: str
    expected_loss: float
    note: str
    end_angle_deg: float  # the end angle the table's folds were simulated with (use it to execute)
    point: int = -1  # the fan point chosen (index into trajectory.fan())
    raw_loss: float = float("nan")  # m, simulated at the point in the nearest table (NaN: failed there)
    blended: tuple[tuple[str, float], ...] = ()  # (scenario, scaled distance) of the tables used, nearest first


class TableSelector:
    """Loads every scenario table under `table_dir` once and picks robustly from the nearest
    scenario(s) (docs/lookup.md). table_dir: one directory, or several in order of precedence
    (a list or "a:b"; e.g. "my_tables:config/tables": a scenario's table from my_tables where it
    has a complete one, else from config/tables; `table.load_layered_tables`)."""

    def __init__(self, table_dir: str | Path | list) -> None:
        self.table_roots = table_roots(table_dir)
        self.table_dir = ":".join(str(r) for r in self.table_roots)
        try:
            self.tables, self.origin = load_layered_tables(self.table_roots)
        except FileNotFoundError as err:
            raise FileNotFoundError(f"TableSelector: {err}; generate them with "
                                    f"scripts/generate_lookup_tables.sh") from err
        except ValueError as err:
            raise ValueError(f"TableSelector: {err}") from err
        #: tables that cannot be chosen from (no successful run), named in every note
        self.unusable = sorted(n for n, t in self.tables.items() if not t.success.any())
        if len(self.unusable) == len(self.tables):
            raise ValueError(f"TableSelector: no table in {self.table_dir} has a successful run")
        #: partial tables (a sweep still under way) that do not yet hold the coarse subsample of the
        #: fan a sweep runs first (fan_selection.COVERAGE_LEVELS[0], the first coarse tables' points, config/tables_1k2),
        #: left out while a complete table exists: they rank only part of the fan and would
        #: confine the choice to it (tables swept ring by ring from the lowest height before
        #: 2026-12-06 hold the low corner)
        coarse = set(fan_points(COVERAGE_LEVELS[0]).tolist())
        self.partial = sorted(n for n, t in self.tables.items()
                              if not t.complete and n not in self.unusable
                              and not coarse <= set(t.point.tolist()))
        complete = {n: t for n, t in self.tables.items() if n not in self.partial}
        if not any(t.success.any() for t in complete.values()):
            complete, self.partial = dict(self.tables), []
        self.choosable = complete

    def select(self, *, fold_name: str, keypoints: Mapping[str, np.ndarray], material: str, friction: float,
               duration: float, stage: int) -> Selection:
        """Choose for fold `fold_name` of the shirt seen with `keypoints` (name -> (3,) m).

        stage: index of the fold in FOLD_SEQUENCE (0 left sleeve ... 4 middle); it is
        mapped to the table stage group (STAGE_OF_FOLD). Raises ValueError for unknown
        folds/materials or keypoints that define no fold.
        """
        from ..folding import FOLD_SEQUENCE, fold_type

        if not (isinstance(stage, (int, np.integer)) and 0 <= stage < len(FOLD_SEQUENCE)):
            raise ValueError(f"stage must be a FOLD_SEQUENCE index 0..{len(FOLD_SEQUENCE) - 1}, got {stage!r}")
        group = STAGE_OF_FOLD[FOLD_SEQUENCE[int(stage)]]
        feats = features(fold_name=fold_name, keypoints=keypoints, material_name=material, friction=friction,
                         duration=duration, stage=group)
        c = choose(self.choosable, feats)
        t = self.tables[c.scenarios[0]]
        raw = "failed there" if math.isnan(c.raw_loss) else f"{c.raw_loss * 1e3:.1f} mm"
        note = (f"fan point {c.point} from {', '.join(f'{n} (d={d:.2f})' for n, d in zip(c.scenarios, c.distances))}; "
                f"smoothed loss {c.expected_loss * 1e3:.1f} mm, simulated {raw}; "
                f"table {t.directory or self.origin[t.name] / t.name}, max_area {t.provenance.get('resolution', {}).get('max_area_m2')} "
                f"m^2, {len(t.point)} fan points{'' if t.complete else ' (incomplete)'}")
        if t.fold_type != feats["fold_type"]:  # nearest neighbour across fold types: say so
            kind = fold_type(fold_name)
            own = any(u.fold_type == feats["fold_type"] and u.success.any() for u in self.choosable.values())
            note += (f"; a {FOLD_TYPE_NAME.get(t.fold_type, t.fold_type)} table for a {kind} fold: "
                     + (f"the {kind} tables are farther" if own else f"no complete {kind} table yet"))
        note += self._left_out()
        end_angle = float(t.provenance.get("settings", {}).get("end_angle_deg", LEGACY_END_ANGLE_DEG))
        return Selection(c.height_ratio, c.tilt_deg, c.scenarios[0], c.expected_loss, note, end_angle, int(c.point),
                         float(c.raw_loss), tuple(zip(c.scenarios, map(float, c.distances))))

    def _left_out(self) -> str:
        """The note's tail naming the tables not chosen from (no success; partial)."""
        out = f"; skipped (no successful run): {', '.join(self.unusable)}" if self.unusable else ""
        if self.partial:
            out += "; left out (partial): " + ", ".join(f"{n} ({len(self.tables[n].point)} fan points)"
                                                        for n in self.partial)
        return out
