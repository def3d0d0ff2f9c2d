"""PNG plots of a scenario table: the loss landscape in the fan layout and the best /
worst final cloth states seen from above next to the target."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..trajectory import fan
from . import sweep_dir as layout
from .select import smoothed_loss
from .table import load_table


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


def plot_landscape(table_dir: str | Path, out: str | Path) -> Path:
    """Loss landscape: radius = height ratio, angle = tilt, colour = loss (mm); failed
    runs as red crosses, not-simulated fan points as small grey dots, the chosen
    (smoothed-best) point circled."""
    plt = _plt()
    t = load_table(table_dir)
    f = fan()
    fig, ax = plt.subplots(figsize=(6.2, 5.2), subplot_kw={"projection": "polar"})
    ax.scatter(np.radians(f[:, 1]), f[:, 0], s=6, c="0.8", label="fan point (not simulated)")
    ok = t.success & np.isfinite(t.loss)
    sc = ax.scatter(np.radians(t.tilt_deg[ok]), t.height_ratio[ok], c=t.loss[ok] * 1e3, s=70, cmap="viridis_r",
                    edgecolors="k", linewidths=0.4, label="simulated")
    if (~ok).any():
        ax.scatter(np.radians(t.tilt_deg[~ok]), t.height_ratio[~ok], marker="x", c="red", s=60, label="failed")
    if ok.any():
        fig.colorbar(sc, ax=ax, pad=0.1, label="loss (mm)")
        k = int(np.argmin(smoothed_loss(t)))
        ax.scatter([np.radians(t.tilt_deg[k])], [t.height_ratio[k]], s=260, facecolors="none", edgecolors="m",
                   linewidths=1.6, label="robust choice")
    ax.set_thetamin(0)
    ax.set_thetamax(60)
    ax.set_rlim(0, 1.05)
    ax.set_xlabel("height ratio (radius), tilt deg (angle)")
    res = t.provenance.get("resolution", {}).get("max_area_m2")
    ax.set_title(f"{t.name}: loss landscape (max_area {res} m$^2$)", fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.05), fontsize=7, ncol=2)
    return _save(fig, out, 110)


def plot_best_worst(table_dir: str | Path, out: str | Path) -> Path:
    """Top-down views of the best and worst successful final states over the target."""
    plt = _plt()
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
    for ax, (lab, v, k) in zip(axes, panels):
        ax.triplot(target[:, 0], target[:, 1], tri, color="0.75", lw=0.5)
        tc = ax.tripcolor(v[:, 0], v[:, 1], tri, facecolors=v[tri, 2].mean(axis=1) * 1e3, cmap="magma",
                          vmin=0.0, vmax=vmax, edgecolors="k", linewidth=0.2, alpha=0.85)
        if k is not None:
            ax.set_title(f"{lab}: h={t.height_ratio[k]:.2f} tilt={t.tilt_deg[k]:.1f} "
                         f"loss {t.loss[k] * 1e3:.1f} mm", fontsize=9)
        else:
            ax.set_title(f"{t.name}: target (grey mesh in every panel)", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("y (m)")
    fig.colorbar(tc, ax=axes, label="mean triangle height (mm)", shrink=0.8)
    return _save(fig, out, 100)
