"""Which mesh resolution ranks trajectories like the study's (max area 5e-5, 12K triangles)?

The fan-point sweeps themselves are ordinary resumable sweeps, one directory per
resolution (docs/lookup.md, "Resolution"):

    clothfold sweep shape1 --points every:3:3 --max-area A --workers 1 --out docs/resolution/area_A

This script adds the run-to-run spread and the comparison:

    python scripts/resolution_study.py spread --area 5e-04 [--dh 1e-3] [--points every:3:3]
        reruns each point with h + dh (resumable; docs/resolution/area_A/spread.jsonl)
    python scripts/resolution_study.py report [--reference 5e-05]
        Spearman rho of the losses against the reference resolution (points both completed),
        agreement on "failed or loss > 2 cm", the spread |loss(h + dh) - loss(h)|, and
        docs/resolution/resolution.png (candidate vs reference loss, one panel each).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
STUDY = ROOT / "docs" / "resolution"
SCENARIO = "shape1"
BAD_LOSS = 0.02  # m: a run that fails or ends above this is "bad"


def area_dir(area: str) -> Path:
    return STUDY / f"area_{area}" / SCENARIO


def read_rows(path: Path) -> dict[int, dict]:
    """A runs.jsonl-like file's rows by fan point ({} when absent; sweep_dir.read_runs)."""
    from clothfold_ros.lookup.sweep_dir import read_runs
    return {int(r["point"]): r for r in read_runs(path)} if path.exists() else {}


def spread(args: argparse.Namespace) -> int:
    from clothfold_ros.lookup.fan_selection import fan_points
    from clothfold_ros.lookup.sweep import Job, run_job
    from clothfold_ros.lookup.sweep_dir import read_settings
    from clothfold_ros.trajectory import fan

    d = area_dir(args.area)
    settings = read_settings(d)  # the sweep's own settings: same mesh, stepping, Newton
    out = d / "spread.jsonl"
    done = read_rows(out)
    f = fan()
    for p in fan_points(args.points):
        if int(p) in done:
            continue
        h, tilt = float(f[p, 0]) + args.dh, float(f[p, 1])
        if h > 1.0:
            h = float(f[p, 0]) - args.dh
        row, _ = run_job(Job(settings, int(p), h, tilt, None))
        row["dh"] = h - float(f[p, 0])
        with out.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        print(f"point {p}: h {h:.4f} tilt {tilt:.1f}: {'%.2f mm' % (row['loss_m'] * 1e3) if row['success'] else row['reason']}",
              flush=True)
    return 0


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    from scipy.stats import spearmanr

    return float(spearmanr(a, b).statistic) if len(a) >= 3 else float("nan")


def bad(r: dict) -> bool:
    return not r["success"] or r["loss_m"] > BAD_LOSS


def report(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ref = read_rows(area_dir(args.reference) / "runs.jsonl")
    areas = sorted((p.name.removeprefix("area_") for p in STUDY.glob("area_*")), key=float, reverse=True)
    cands = [a for a in areas if a != args.reference]
    ref_wall = np.median([r["wall_time_s"] for r in ref.values()]) if ref else float("nan")
    lines = [f"reference: max area {args.reference} m^2, {len(ref)} runs ({sum(r['success'] for r in ref.values())} "
             f"completed), median {ref_wall:.0f} s per run", "",
             "| max area (m^2) | triangles | runs | common | rho (both completed) | bad agree | spread median / max (mm) "
             "| s per run (median) |",
             "|---|---|---|---|---|---|---|---|"]
    fig, axes = plt.subplots(1, max(1, len(cands)), figsize=(4.2 * max(1, len(cands)), 4.2), squeeze=False)
    from clothfold_ros.garment import make_shirt

    for ax, a in zip(axes[0], cands):
        rows = read_rows(area_dir(a) / "runs.jsonl")
        common = sorted(set(rows) & set(ref))
        both = [p for p in common if rows[p]["success"] and ref[p]["success"]]
        x = np.array([ref[p]["loss_m"] for p in both]) * 1e3
        y = np.array([rows[p]["loss_m"] for p in both]) * 1e3
        rho = spearman(x, y)
        agree = np.mean([bad(rows[p]) == bad(ref[p]) for p in common]) if common else float("nan")
        sp = read_rows(area_dir(a) / "spread.jsonl")
        diffs = [abs(sp[p]["loss_m"] - rows[p]["loss_m"]) * 1e3 for p in sp
                 if p in rows and sp[p]["success"] and rows[p]["success"]]
        spread_txt = f"{np.median(diffs):.2f} / {np.max(diffs):.2f} (n={len(diffs)})" if diffs else "-"
        wall = np.median([r["wall_time_s"] for r in rows.values()]) if rows else float("nan")
        tris = len(make_shirt(1, max_area=float(a)).triangles)
        lines.append(f"| {a} | {tris} | {len(rows)} | {len(common)} | {rho:.3f} (n={len(both)}) | {agree:.2f} "
                     f"| {spread_txt} | {wall:.0f} |")
        ax.scatter(x, y, s=18)
        for p in common:
            if not rows[p]["success"] or not ref[p]["success"]:
                ax.annotate("x", (ref[p]["loss_m"] * 1e3 if ref[p]["success"] else 0,
                                  rows[p]["loss_m"] * 1e3 if rows[p]["success"] else 0), color="red")
        lim = max([1.0, *x, *y]) * 1.05
        ax.plot([0, lim], [0, lim], "k:", lw=0.8)
        ax.set(xlim=(0, lim), ylim=(0, lim), xlabel=f"loss at {args.reference} m^2 (mm)",
               ylabel=f"loss at {a} m^2 (mm)", title=f"{tris} triangles: rho {rho:.2f}, n={len(both)}")
    fig.suptitle("shape1, fan points every:3:3: loss against the study's resolution (red x: a failure)")
    fig.tight_layout()
    png = STUDY / "resolution.png"
    fig.savefig(png, dpi=110)
    spr = read_rows(area_dir(args.reference) / "spread.jsonl")
    dref = [abs(spr[p]["loss_m"] - ref[p]["loss_m"]) * 1e3 for p in spr if p in ref and spr[p]["success"] and ref[p]["success"]]
    if dref:
        lines.append(f"reference spread median / max: {np.median(dref):.2f} / {np.max(dref):.2f} mm (n={len(dref)})")
    text = "\n".join(lines)
    print(text)
    (STUDY / "resolution.md").write_text(text + f"\n\n![resolution]({png.name})\n")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("spread")
    s.add_argument("--area", required=True)
    s.add_argument("--dh", type=float, default=1e-3)
    s.add_argument("--points", default="every:3:3")
    s.set_defaults(func=spread)
    r = sub.add_parser("report")
    r.add_argument("--reference", default="5e-05")
    r.set_defaults(func=report)
    args = p.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
