"""PNG plots of a scenario table: the loss landscape in the fan layout and the best /
worst final cloth states seen from above next to the target."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..trajectory import fan
from . import sweep_dir as layout
from .scenario import SCENARIO_GROUPS
from .select import choose
from .table import Table, load_table


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out: str | Path, dpi: int) -> Path:
    """Write `fig` to the PNG `out` (folders created) and close it."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi, bbox_inches="tight")
    _plt().close(fig)
    return out


def _draw_fan(ax, t: Table | None, norm, legend: bool = False):
    """One table's landscape on the polar axes `ax`: every fan point as a grey dot,
    successful runs coloured by loss (mm) under `norm`, failed runs as red crosses, the
    robust choice (select.choose on this table alone) circled. t None: the fan alone (no table). Returns the
    scatter of the coloured points (None when there is none)."""
    f = fan()
    ax.scatter(np.radians(f[:, 1]), f[:, 0], s=4 if not legend else 6, c="0.8", label="fan point (not simulated)")
    sc = None
    if t is not None:
        ok = t.success & np.isfinite(t.loss)
        if ok.any():
            sc = ax.scatter(np.radians(t.tilt_deg[ok]), t.height_ratio[ok], c=t.loss[ok] * 1e3, s=70 if legend else 14,
                            cmap="viridis_r", norm=norm, edgecolors="k", linewidths=0.4 if legend else 0.2,
                            label="simulated")
            k = int(np.flatnonzero(t.point == choose({t.name: t}, t.features).point)[0])  # the table alone
            ax.scatter([np.radians(t.tilt_deg[k])], [t.height_ratio[k]], s=260 if legend else 70, facecolors="none",
                       edgecolors="m", linewidths=1.6 if legend else 1.0, label="robust choice")
        if (~ok).any():
            ax.scatter(np.radians(t.tilt_deg[~ok]), t.height_ratio[~ok], marker="x", c="red", s=60 if legend else 18,
                       linewidths=1.0, label="failed")
    ax.set_thetamin(0)
    ax.set_thetamax(60)
    ax.set_rlim(0, 1.05)
    if not legend:
        ax.set_xticks(np.radians([0, 20, 40, 60]))
        ax.set_yticks([0.5, 1.0])
        ax.tick_params(labelsize=6, pad=1)
    return sc


def plot_landscape(table_dir: str | Path, out: str | Path) -> Path:
    """Loss landscape: radius = height ratio, angle = tilt, colour = loss (mm); failed
    runs as red crosses, not-simulated fan points as small grey dots, the robust
    choice (select.choose on this table alone) circled."""
    plt = _plt()
    t = load_table(table_dir)
    fig, ax = plt.subplots(figsize=(6.2, 5.2), subplot_kw={"projection": "polar"})
    sc = _draw_fan(ax, t, None, legend=True)
    if sc is not None:
        fig.colorbar(sc, ax=ax, pad=0.1, label="loss (mm)")
    ax.set_xlabel("height ratio (radius), tilt deg (angle)")
    res = t.provenance.get("resolution", {}).get("max_area_m2")
    ax.set_title(f"{t.name}: loss landscape (max_area {res} m$^2$)", fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.05), fontsize=7, ncol=2)
    return _save(fig, out, 110)


def _group_norm(tables: list[Table]):
    """Colour scale shared by a group: min to the 95th percentile of its successful losses (mm)."""
    from matplotlib.colors import Normalize

    losses = np.concatenate([t.loss[t.success & np.isfinite(t.loss)] for t in tables] or [np.zeros(0)]) * 1e3
    if not len(losses):
        return Normalize(0.0, 1.0)
    lo, hi = float(losses.min()), float(np.percentile(losses, 95))
    return Normalize(lo, hi if hi > lo else lo + 1e-3)


def plot_overview(tables_root: str | Path, out: str | Path) -> Path:
    """The 13 scenario landscapes side by side, one row per figure group of the study
    (`scenario.SCENARIO_GROUPS`: each row varies one factor against the default, shape1),
    with one colour scale per row (its losses' minimum to 95th percentile; higher losses
    take the darkest colour). Each panel is titled with its scenario and how many of the
    134 fan points it holds; a scenario without a table shows the bare fan."""
    plt = _plt()
    root = Path(tables_root)
    if not root.is_dir():
        raise FileNotFoundError(f"lookup table directory {root} does not exist")
    available = {p.name: load_table(p) for p in layout.table_dirs(root)}
    rows = list(SCENARIO_GROUPS.items())
    ncols = max(len(names) for _, names in rows)
    fig, axes = plt.subplots(len(rows), ncols, figsize=(3.0 * ncols + 1.2, 2.7 * len(rows)),
                             subplot_kw={"projection": "polar"}, squeeze=False,
                             gridspec_kw={"top": 0.94, "hspace": 0.45})
    n_fan = len(fan())
    res = sorted({str(t.provenance.get("resolution", {}).get("max_area_m2")) for t in available.values()})
    for r, (group, names) in enumerate(rows):
        tables = [available[n] for n in names if n in available]
        norm = _group_norm(tables)
        sc = None
        for c in range(ncols):
            ax = axes[r, c]
            if c >= len(names):
                ax.set_visible(False)
                continue
            t = available.get(names[c])
            sc = _draw_fan(ax, t, norm) or sc
            label = f"{names[c]} (default)" if names[c] == "shape1" else names[c]
            held = f"{len(t.point)}/{n_fan} points" if t is not None else "no table"
            ax.set_title(f"{label}\n{held}", fontsize=8, pad=16)
        if sc is None:
            from matplotlib.cm import ScalarMappable
            sc = ScalarMappable(norm=norm, cmap="viridis_r")
        cb = fig.colorbar(sc, ax=list(axes[r, :len(names)]), pad=0.02, shrink=0.85, extend="max")
        cb.set_label(f"{group}: loss (mm)", fontsize=8)
        cb.ax.tick_params(labelsize=7)
    fig.suptitle(f"Loss landscapes (radius: height ratio, angle: tilt deg; red x: failed; circle: robust choice; "
                 f"max area {', '.join(res) or '-'} m$^2$)", fontsize=10, y=0.995)
    return _save(fig, out, 90)


def _outline(ax, v: np.ndarray, tri: np.ndarray, **style) -> None:
    """Outline (top-down silhouette) of the triangles `tri` of the mesh `v` (N, 3), m."""
    import shapely

    if len(tri) == 0:
        return
    shape = shapely.unary_union(shapely.polygons(v[tri][:, :, :2])).buffer(0)
    for poly in getattr(shape, "geoms", [shape]):
        if poly.is_empty:
            continue
        x, y = poly.exterior.xy
        ax.plot(x, y, **style)


def _flipped(v: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Triangles facing down (normal z < 0; the rest shirt's triangles face up): folded-over cloth."""
    a, b, c = v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]]
    return np.cross(b - a, c - a)[:, 2] < 0.0


def plot_best_worst(table_dir: str | Path, out: str | Path) -> Path:
    """Top-down views of the target and the best and worst successful final states: cloth
    facing up in light grey, folded-over (face-down) cloth coloured by its height, higher
    triangles drawn over lower ones; the target's silhouette and folded flap as dashed lines."""
    plt = _plt()
    from matplotlib.colors import ListedColormap

    t = load_table(table_dir)
    ok = np.flatnonzero(t.success & np.isfinite(t.loss))
    if len(ok) == 0:
        raise ValueError(f"table {t.name!r} has no successful run to draw")
    picks = [("best", ok[np.argmin(t.loss[ok])]), ("worst", ok[np.argmax(t.loss[ok])])]
    tri, target, by_point = layout.read_packed(table_dir, [int(t.point[k]) for _, k in picks])
    finals = {lab: by_point[int(t.point[k])] for lab, k in picks}
    fig, axes = plt.subplots(1, 3, figsize=(12, 4.2), sharex=True, sharey=True)
    panels = [("target", target, None)] + [(lab, finals[lab], k) for lab, k in picks]
    vmax = max(float(v[:, 2].max()) for _, v, _ in panels) * 1e3
    target_flap = tri[_flipped(target, tri)]
    face_up = ListedColormap(["0.82"])
    for ax, (lab, v, k) in zip(axes, panels):
        height = v[tri, 2].mean(axis=1) * 1e3
        order = np.argsort(height, kind="stable")  # top layers last: seen from above
        flipped = _flipped(v, tri)[order]
        srt, h = tri[order], height[order]
        ax.tripcolor(v[:, 0], v[:, 1], srt, facecolors=np.where(flipped, np.nan, 0.0), cmap=face_up,
                     vmin=0.0, vmax=1.0, linewidth=0.0)
        tc = ax.tripcolor(v[:, 0], v[:, 1], srt, facecolors=np.where(flipped, h, np.nan), cmap="plasma",
                          vmin=0.0, vmax=vmax, linewidth=0.0)
        _outline(ax, target, tri, color="k", lw=0.8, ls="--")
        _outline(ax, target, target_flap, color="tab:green", lw=1.0, ls="--")
        if k is not None:
            ax.set_title(f"{lab}: h={t.height_ratio[k]:.2f} tilt={t.tilt_deg[k]:.1f} "
                         f"loss {t.loss[k] * 1e3:.1f} mm", fontsize=9)
        else:
            ax.set_title(f"{t.name}: target", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("y (m)")
    fig.colorbar(tc, ax=axes, label="folded-over cloth: mean triangle height (mm)", shrink=0.8)
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    axes[1].legend(handles=[Patch(color="0.82", label="cloth facing up"),
                            Line2D([], [], color="k", lw=0.8, ls="--", label="target outline"),
                            Line2D([], [], color="tab:green", lw=1.0, ls="--", label="target's folded-over flap")],
                   loc="upper center", bbox_to_anchor=(0.5, 0.0), borderaxespad=4.0, ncol=3, fontsize=8,
                   frameon=False)  # below the x labels, whatever the panels' aspect
    return _save(fig, out, 110)
