"""Selection, regret, TableSelector and plots on synthetic tables (no simulation)."""
from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from clothfold_ros.lookup.fan_selection import COVERAGE_LEVELS, fan_points
from clothfold_ros.lookup.planner_selector import Selection, TableSelector
from clothfold_ros.lookup.plot import plot_best_worst, plot_landscape, plot_overview
from clothfold_ros.lookup.regret import evaluate, mean_regret, middle_of_fan, report, success_rate, summary, worst_regret
from clothfold_ros.lookup.scenario import (SCENARIO_GROUPS, SCENARIOS, definition_features, features, flat_keypoints,
                                           generation_order, normalized_distance)
from clothfold_ros.lookup.select import choose, smoothed_loss
from clothfold_ros.lookup.table import COLUMNS, FEATURE_NAMES, Table
from clothfold_ros.trajectory import fan

FAN = fan()


def _table(name: str, loss: np.ndarray, feats: dict | None = None, points: np.ndarray | None = None) -> Table:
    p = np.arange(len(FAN)) if points is None else points
    loss = np.asarray(loss, dtype=float)
    return Table(name, feats or definition_features(SCENARIOS["shape1"]), p, FAN[p, 0], FAN[p, 1], loss,
                 np.isfinite(loss), ["" if np.isfinite(x) else "failed" for x in loss], {})


def _bowl(centre: int, base: float = 0.02, slope: float = 0.05) -> np.ndarray:
    """Loss growing with fan-layout distance from fan point `centre`."""
    xy = np.column_stack([FAN[:, 0] * np.cos(np.radians(FAN[:, 1])), FAN[:, 0] * np.sin(np.radians(FAN[:, 1]))])
    return base + slope * np.linalg.norm(xy - xy[centre], axis=1)


def test_robust_plateau_beats_isolated_optimum() -> None:
    loss = np.full(len(FAN), 0.040)
    plateau = np.flatnonzero((FAN[:, 0] > 0.8) & (FAN[:, 1] < 20))  # a broad good region
    loss[plateau] = 0.006
    spike = int(np.flatnonzero((np.isclose(FAN[:, 0], 0.3076923)) & (FAN[:, 1] == 30.0))[0])
    loss[spike] = 0.002  # the sharp optimum ...
    nb = np.flatnonzero(np.abs(FAN[:, 0] - FAN[spike, 0]) < 0.08)
    loss[nb[nb != spike]] = np.nan  # ... surrounded by failures
    t = _table("shape1", loss)
    raw = choose({"shape1": t}, t.features, robust=False)
    rob = choose({"shape1": t}, t.features)
    assert raw.point == spike
    assert rob.point in set(plateau.tolist())
    assert rob.expected_loss == pytest.approx(smoothed_loss(t)[rob.point])
    assert rob.raw_loss == pytest.approx(0.006)


def test_failures_count_as_bad() -> None:
    loss = _bowl(100)
    loss[100] = np.nan  # the centre itself failed: its neighbours are pulled up
    t = _table("shape1", loss)
    assert choose({"shape1": t}, t.features).point != 100
    assert np.all(np.isfinite(smoothed_loss(t)))


def test_nearest_scenario_is_used() -> None:
    a = _table("shape1", _bowl(20), definition_features(SCENARIOS["shape1"]))
    b = _table("shape3", _bowl(120), definition_features(SCENARIOS["shape3"]))
    c = _table("T8", _bowl(60), definition_features(SCENARIOS["T8"]))
    tables = {t.name: t for t in (a, b, c)}
    for t, centre in ((a, 20), (b, 120), (c, 60)):
        ch = choose(tables, t.features, blend_margin=0.0)
        assert ch.scenarios == (t.name,) and ch.point == centre
    # a short-sleeved shirt of unseen length is nearest to shape 3
    kp = flat_keypoints(3, "cotton")
    f = features(fold_name="left_sleeve", keypoints=kp, material_name="cotton", friction=0.45, duration=4.0)
    assert choose(tables, f, blend_margin=0.0).scenarios[0] == "shape3"
    assert normalized_distance(f, b.features) < normalized_distance(f, a.features)


def test_regret_arithmetic() -> None:
    f1, f2 = definition_features(SCENARIOS["shape1"]), definition_features(SCENARIOS["mu0.2"])
    l1, l2 = _bowl(50), _bowl(80)
    rows = {r.scenario: r for r in evaluate({"shape1": _table("shape1", l1, f1), "mu0.2": _table("mu0.2", l2, f2)},
                                            "argmin")}
    # each held-out scenario gets the other's optimum, evaluated in its own table
    assert rows["shape1"].point == 80 and rows["mu0.2"].point == 50
    assert rows["shape1"].regret == pytest.approx(l1[80] - l1.min())
    assert rows["mu0.2"].regret == pytest.approx(l2[50] - l2.min())
    assert mean_regret(list(rows.values())) == pytest.approx(((l1[80] - l1.min()) + (l2[50] - l2.min())) / 2)
    l2f = l2.copy()
    l2f[50] = np.nan  # the chosen point failed in the held-out table: counted as its worst loss, flagged
    rows = {r.scenario: r for r in evaluate({"shape1": _table("shape1", l1, f1), "mu0.2": _table("mu0.2", l2f, f2)},
                                            "argmin")}
    assert rows["mu0.2"].flag == "failed in held-out"
    assert rows["mu0.2"].regret == pytest.approx(np.nanmax(l2f) - np.nanmin(l2f))
    # a held-out table that never simulated the chosen point, or has no success at all: no regret, flagged
    pts = np.setdiff1d(np.arange(len(FAN)), [50])
    rows = {r.scenario: r for r in evaluate({"shape1": _table("shape1", l1, f1),
                                             "mu0.2": _table("mu0.2", l2[pts], f2, points=pts)}, "argmin")}
    assert rows["mu0.2"].flag == "not simulated in held-out" and math.isnan(rows["mu0.2"].regret)
    rows = evaluate({"shape1": _table("shape1", l1, f1), "mu0.2": _table("mu0.2", np.full(len(FAN), np.nan), f2)},
                    "argmin")
    held = next(r for r in rows if r.scenario == "mu0.2")
    assert held.flag == "no success in held-out" and math.isnan(held.regret)
    lone = next(r for r in rows if r.scenario == "shape1")  # nothing left to choose from: a row, not a crash
    assert lone.flag.startswith("n/a: no lookup table to choose from") and math.isnan(lone.regret)
    text = report(rows, "argmin")
    assert "| mu0.2 |" in text and "no success in held-out" in text and "over 0 of 2 scenarios" in text


def test_static_and_default_rules_and_summary() -> None:
    mid = middle_of_fan()
    assert 0.45 < FAN[mid, 0] < 0.65 and FAN[mid, 1] == pytest.approx(30.0)
    f1, f2, f3 = (definition_features(SCENARIOS[n]) for n in ("shape1", "mu0.2", "T8"))
    l1, l2, l3 = _bowl(50, 0.003, 0.02), _bowl(80, 0.004, 0.02), _bowl(mid, 0.005, 0.2)
    l3[50] = np.nan  # the default's best failed in T8
    tables = {"shape1": _table("shape1", l1, f1), "mu0.2": _table("mu0.2", l2, f2), "T8": _table("T8", l3, f3)}
    static = {r.scenario: r for r in evaluate(tables, "static")}
    assert {r.point for r in static.values()} == {mid} and static["T8"].regret == pytest.approx(0.0)
    assert static["shape1"].regret == pytest.approx(l1[mid] - l1.min())
    default = {r.scenario: r for r in evaluate(tables, "default_best")}
    assert default["shape1"].flag.startswith("n/a") and math.isnan(default["shape1"].regret)
    assert default["mu0.2"].point == 50 and default["mu0.2"].regret == pytest.approx(l2[50] - l2.min())
    assert default["T8"].flag == "failed in held-out" and default["T8"].regret == pytest.approx(np.nanmax(l3) - l3[mid])
    assert worst_regret(list(default.values())) == pytest.approx(np.nanmax(l3) - l3[mid])
    # successes: completed and within 2 cm (T8's penalty loss is far beyond it)
    assert success_rate(list(default.values())) == (1, 2)
    good, n = success_rate(list(static.values()))
    assert n == 3 and good == sum(t.loss[mid] <= 0.02 for t in tables.values())
    text = summary({"static": list(static.values()), "default_best": list(default.values())})
    assert "middle of the fan" in text and "1 of 2 (50 %)" in text and text.count("\n") == 3
    with pytest.raises(ValueError):
        evaluate(tables, "oracle")


def _write_table_dir(d: Path, t: Table, with_finals: bool = False) -> None:
    d.mkdir(parents=True)
    with open(d / "table.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        for i in range(len(t.point)):
            w.writerow({"scenario": t.name, "folds": "left_sleeve", "shape": 1, "material": "cotton",
                        **{k: t.features[k] for k in FEATURE_NAMES}, "point": t.point[i],
                        "height_ratio": t.height_ratio[i], "tilt_deg": t.tilt_deg[i], "loss_m": t.loss[i],
                        "success": int(t.success[i]), "reason": t.reason[i], "wall_time_s": 1.0,
                        "newton_iterations": 10, "steps": 5, "max_area_m2": 4e-3, "vertices": 3})
    settings = {} if t.name == "shape1" else {"settings": {"end_angle_deg": 170.0}}  # shape1: legacy (175)
    (d / "provenance.json").write_text(json.dumps({"resolution": {"max_area_m2": 4e-3}, "complete": True, **settings}))
    if with_finals:
        tri = np.array([[0, 1, 2]])
        target = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
        finals = {f"p{p:03d}": target + 0.01 * p for p in t.point}
        np.savez(d / "finals.npz", triangles=tri, target=target, start=target, **finals)


def test_table_selector_layers_directories(tmp_path: Path) -> None:
    """A scenario's table comes from the first directory holding a complete one; an incomplete
    finer table waits; the note names the directory the choice came from."""
    pts = np.arange(0, 134, 3)
    _write_table_dir(tmp_path / "coarse" / "shape1", _table("shape1", _bowl(66)[pts], points=pts))
    _write_table_dir(tmp_path / "fine" / "shape1", _table("shape1", _bowl(99)[pts], points=pts))
    kp = flat_keypoints(1, "cotton")
    args = dict(fold_name="left_sleeve", keypoints=kp, material="cotton", friction=0.5, duration=4.0, stage=0)
    prov = tmp_path / "fine" / "shape1" / "provenance.json"
    for complete, winner, best in ((True, "fine", 99), (False, "coarse", 66)):
        prov.write_text(json.dumps({"resolution": {"max_area_m2": 5e-5}, "complete": complete}))
        sel = TableSelector(f"{tmp_path / 'fine'}:{tmp_path / 'missing'}:{tmp_path / 'coarse'}")
        s = sel.select(**args)
        assert (s.height_ratio, s.tilt_deg) == (FAN[best, 0], FAN[best, 1]) and s.point == best, (complete, s)
        assert f"table {tmp_path / winner / 'shape1'}" in s.note, s.note
    (tmp_path / "coarse" / "shape1" / "table.csv").unlink()  # only the incomplete fine one left: it is used
    sel = TableSelector([tmp_path / "fine", tmp_path / "coarse"])
    assert (sel.select(**args).height_ratio, sel.origin["shape1"]) == (FAN[99, 0], tmp_path / "fine")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        TableSelector(f"{tmp_path / 'a'}:{tmp_path / 'b'}")


def test_table_selector(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="does not exist"):
        TableSelector(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="no lookup tables"):
        TableSelector(tmp_path / "empty")
    (tmp_path / "broken" / "x").mkdir(parents=True)
    (tmp_path / "broken" / "x" / "table.csv").write_text("scenario,point\nx,1\n")
    with pytest.raises(ValueError, match="broken lookup table"):
        TableSelector(tmp_path / "broken")
    pts = np.arange(0, 134, 3)
    _write_table_dir(tmp_path / "ok" / "shape1", _table("shape1", _bowl(66)[pts], points=pts))
    mid = _table("middle", _bowl(99)[pts], points=pts,
                 feats={**definition_features(SCENARIOS["shape1"]), "stage": 3.0, "fold_type": 2.0})
    _write_table_dir(tmp_path / "ok" / "middle", mid)
    dead = _table("both_sides", np.full(len(pts), np.nan), points=pts,
                  feats={**definition_features(SCENARIOS["shape1"]), "stage": 2.0, "fold_type": 1.0})
    _write_table_dir(tmp_path / "ok" / "both_sides", dead)
    sel = TableSelector(tmp_path / "ok")
    assert sel.unusable == ["both_sides"]
    s = sel.select(fold_name="left_side", keypoints=flat_keypoints(1, "cotton"), material="cotton", friction=0.5,
                   duration=4.0, stage=2)
    assert s.scenario != "both_sides" and "skipped (no successful run): both_sides" in s.note
    kp = flat_keypoints(1, "cotton")
    s = sel.select(fold_name="right_sleeve", keypoints=kp, material="cotton", friction=0.5, duration=4.0, stage=0)
    assert isinstance(s, Selection) and s.scenario == "shape1"
    assert (s.height_ratio, s.tilt_deg) == (FAN[66, 0], FAN[66, 1]) and s.expected_loss > 0 and "66" in s.note
    assert s.point == 66
    assert s.end_angle_deg == 175.0  # a table whose settings predate the end angle was made at 175 deg
    s = sel.select(fold_name="middle", keypoints=kp, material="cotton", friction=0.5, duration=4.0, stage=4)
    assert s.scenario == "middle" and (s.height_ratio, s.tilt_deg) == (FAN[99, 0], FAN[99, 1])
    assert s.end_angle_deg == 170.0  # the execution uses the table's own end angle
    with pytest.raises(ValueError):
        sel.select(fold_name="collar", keypoints=kp, material="cotton", friction=0.5, duration=4.0, stage=0)
    with pytest.raises(ValueError):
        sel.select(fold_name="left_sleeve", keypoints=kp, material="silk", friction=0.5, duration=4.0, stage=0)


def test_plots_write_png(tmp_path: Path) -> None:
    loss = _bowl(40)[::4]
    loss[2] = np.nan
    _write_table_dir(tmp_path / "shape1", _table("shape1", loss, points=np.arange(0, 134, 4)), with_finals=True)
    for fn, name in ((plot_landscape, "landscape.png"), (plot_best_worst, "best_worst.png")):
        out = fn(tmp_path / "shape1", tmp_path / "plots" / name)
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 5000



def test_best_worst_shows_the_tables_best_and_worst_runs(tmp_path: Path, monkeypatch) -> None:
    from clothfold_ros.lookup import plot

    pts = np.arange(0, 134, 4)
    loss = _bowl(40)[pts]
    loss[5] = np.nan  # a failed run is neither best nor worst
    _write_table_dir(tmp_path / "shape1", _table("shape1", loss, points=pts), with_finals=True)
    figures = []
    monkeypatch.setattr(plot, "_save", lambda fig, out, dpi: figures.append(fig) or Path(out))
    plot.plot_best_worst(tmp_path / "shape1", tmp_path / "bw.png")
    titles = [ax.get_title() for ax in figures[0].axes[:3]]
    best, worst = int(np.nanargmin(loss)), int(np.nanargmax(loss))
    assert titles[0] == "shape1: target"
    assert titles[1] == f"best: h={FAN[pts[best], 0]:.2f} tilt={FAN[pts[best], 1]:.1f} loss {loss[best] * 1e3:.1f} mm"
    assert titles[2] == f"worst: h={FAN[pts[worst], 0]:.2f} tilt={FAN[pts[worst], 1]:.1f} loss {loss[worst] * 1e3:.1f} mm"
    _write_table_dir(tmp_path / "none", _table("T1", np.full(3, np.nan), points=np.arange(3)), with_finals=True)
    with pytest.raises(ValueError, match="no successful run"):
        plot.plot_best_worst(tmp_path / "none", tmp_path / "none.png")


def test_overview_draws_every_group_with_partial_and_missing_tables(tmp_path: Path, monkeypatch) -> None:
    assert sorted({n for names in SCENARIO_GROUPS.values() for n in names}) == sorted(SCENARIOS)
    assert all("shape1" in names for names in SCENARIO_GROUPS.values())
    loss = _bowl(40)[::4]
    loss[3] = np.nan  # a failed run
    _write_table_dir(tmp_path / "shape1", _table("shape1", loss, points=np.arange(0, 134, 4)))
    _write_table_dir(tmp_path / "mu0.8", _table("mu0.8", 2 * loss[:10], points=np.arange(0, 40, 4)))
    out = plot_overview(tmp_path, tmp_path / "landscapes.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20000
    with pytest.raises(FileNotFoundError):
        plot_overview(tmp_path / "absent", tmp_path / "x.png")
    # what the figure says: the two tables with their point counts, every other scenario without a table
    from clothfold_ros.lookup import plot

    figures = []
    monkeypatch.setattr(plot, "_save", lambda fig, out, dpi: figures.append(fig) or Path(out))
    plot_overview(tmp_path, tmp_path / "again.png")
    titles = [ax.get_title() for ax in figures[0].axes if ax.name == "polar" and ax.get_visible()]
    assert len(titles) == sum(len(names) for names in SCENARIO_GROUPS.values())
    assert titles.count("shape1 (default)\n34/134 points") == len(SCENARIO_GROUPS)
    assert "mu0.8\n10/134 points" in titles
    others = [t for t in titles if not t.startswith(("shape1", "mu0.8"))]
    assert others and all(t.endswith("no table") for t in others), others


def test_plot_command_overview_and_refusals(tmp_path: Path, capsys) -> None:
    from clothfold_ros.cli import main

    _write_table_dir(tmp_path / "t" / "shape1", _table("shape1", _bowl(40)[::4], points=np.arange(0, 134, 4)),
                     with_finals=True)
    assert main(["plot", "--overview", "--tables", str(tmp_path / "t")]) == 0
    assert (tmp_path / "t" / "landscapes.png").read_bytes()[:4] == b"\x89PNG"
    assert main(["plot", "shape1", "--tables", str(tmp_path / "t"), "--out", str(tmp_path / "o")]) == 0
    assert (tmp_path / "o" / "shape1" / "best_worst.png").is_file()
    capsys.readouterr()
    assert main(["plot", "nosuch", "--tables", str(tmp_path / "t")]) == 1
    assert "nosuch" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["plot", "--tables", str(tmp_path / "empty")]) == 2
    assert "no tables under" in capsys.readouterr().err


def test_scenarios_and_features() -> None:
    assert len(SCENARIOS) == 13
    order = generation_order()
    assert sorted(order) == sorted(SCENARIOS)
    assert order.index("shape1") < order.index("both_sleeves") < order.index("both_sides") < order.index("middle")
    f1, f2, f3 = (definition_features(SCENARIOS[f"shape{i}"]) for i in (1, 2, 3))
    assert f1["sleeve_angle"] == pytest.approx(-3.0) and f2["sleeve_angle"] == pytest.approx(30.0)
    assert f3["sleeve_length"] < f1["sleeve_length"] == pytest.approx(f2["sleeve_length"])
    assert f1["sleeve_length"] == pytest.approx(0.76 * 0.635)
    thin, thick = (definition_features(SCENARIOS[n]) for n in ("thin_cotton", "thick_cotton"))
    assert normalized_distance(thin, f1) == pytest.approx(1.0) and normalized_distance(thick, f1) == pytest.approx(1.0)
    assert math.isfinite(f1["grip_distance"]) and f1["grip_distance"] > 0.1


def test_losses_within_the_tie_margin_go_to_the_middle_of_the_fan() -> None:
    """A plateau whose losses differ by less than the tie margin (0.5 mm) ranks nothing: the
    robust rule takes the point nearest the fan's middle; a middle worse by more than the
    margin is not taken, and the raw argmin ignores the margin."""
    rng = np.random.default_rng(3)
    mid = middle_of_fan()
    loss = 0.001 + 2e-4 * rng.random(len(FAN))  # a 0.2 mm spread over the whole fan
    loss[mid] = 0.0012
    t = _table("shape1", loss)
    assert choose({"shape1": t}, t.features).point == mid
    assert choose({"shape1": t}, t.features, robust=False).point == int(np.argmin(loss))
    assert choose({"shape1": t}, t.features, tie_margin=0.0).point != mid
    far = loss.copy()
    far[mid] = 0.010  # 9 mm worse: its smoothed loss (a mean with its neighbours) leaves the margin
    t = _table("shape1", far)
    assert choose({"shape1": t}, t.features).point != mid


def test_a_partial_table_is_left_out_of_a_blend_not_intersected() -> None:
    """A table within the blend margin that lacks some of the nearest table's points (a
    partial sweep) is not blended in: it would restrict the choice to its few points."""
    full = _table("shape1", _bowl(50))
    partial = _table("zz_partial", np.array([0.001, 0.001, 0.001]), points=np.array([0, 1, 2]))
    ch = choose({"shape1": full, "zz_partial": partial}, full.features)
    assert ch.point == 50 and ch.scenarios == ("shape1",)
    whole = _table("zz_whole", _bowl(52))  # a complete neighbour is blended in
    assert choose({"shape1": full, "zz_whole": whole}, full.features).scenarios == ("shape1", "zz_whole")


def test_best_worst_marks_folded_over_cloth_by_its_facing() -> None:
    from clothfold_ros.garment import make_shirt
    from clothfold_ros.lookup.plot import _flipped
    from clothfold_ros.materials import material
    from clothfold_ros.sim.runner import flat_start

    g = make_shirt(1, max_area=5e-3)
    flat = flat_start(g, material("cotton"))
    assert not _flipped(flat, g.triangles).any()  # the rest shirt faces up
    folded = flat.copy()
    left = folded[:, 0] < 0.0  # the left half folded over x = 0 onto the right half
    folded[left, 0] *= -1.0
    folded[left, 2] += 1e-3
    flips = _flipped(folded, g.triangles)
    all_left = left[g.triangles].all(axis=1)
    all_right = (~left)[g.triangles].all(axis=1)
    assert flips[all_left].all() and not flips[all_right].any()


def test_table_selector_leaves_partial_tables_out_and_names_them(tmp_path: Path) -> None:
    """A partial table (sweep under way) that lacks the fan's coarse subsample ranks only part of
    the fan: the planner leaves it out while complete tables exist and says so in every note; a
    side fold then takes the nearest complete table, of another fold type, and the note says
    that too. One that holds the coarse subsample is used."""
    kp = flat_keypoints(1, "cotton")
    _write_table_dir(tmp_path / "shape1", _table("shape1", _bowl(66)))
    low = np.arange(16)  # the first rings of the fan, as a sweep leaves them
    side = _table("both_sides", np.full(16, 0.001), {**definition_features(SCENARIOS["shape1"]), "stage": 2.0,
                                                     "fold_type": 1.0}, points=low)
    _write_table_dir(tmp_path / "both_sides", side)
    prov = tmp_path / "both_sides" / "provenance.json"
    prov.write_text(json.dumps({"resolution": {"max_area_m2": 5e-5}, "complete": False}))
    sel = TableSelector(tmp_path)
    assert sel.partial == ["both_sides"] and set(sel.choosable) == {"shape1"}
    args = dict(keypoints=kp, material="cotton", friction=0.5, duration=4.0)
    s = sel.select(fold_name="left_side", stage=2, **args)
    assert s.scenario == "shape1" and (s.height_ratio, s.tilt_deg) == (FAN[66, 0], FAN[66, 1])
    assert "a sleeve table for a side fold: no complete side table yet" in s.note
    assert "left out (partial): both_sides (16 fan points)" in s.note
    s = sel.select(fold_name="left_sleeve", stage=0, **args)
    assert s.scenario == "shape1" and "left out (partial): both_sides" in s.note and "fold:" not in s.note
    prov.write_text(json.dumps({"resolution": {"max_area_m2": 5e-5}, "complete": True}))  # finished: it counts
    s = TableSelector(tmp_path).select(fold_name="left_side", stage=2, **args)
    assert s.scenario == "both_sides" and s.height_ratio in FAN[low, 0] and "partial" not in s.note
    assert "fold:" not in s.note
    # a partial table that holds the coarse subsample a sweep runs first spans the fan: it is used
    spread = np.array(sorted(set(fan_points(COVERAGE_LEVELS[0]).tolist()) | {0, 1}))
    side_spread = _table("both_sides", _bowl(58)[spread], side.features, points=spread)
    shutil.rmtree(tmp_path / "both_sides")
    _write_table_dir(tmp_path / "both_sides", side_spread)
    prov.write_text(json.dumps({"resolution": {"max_area_m2": 5e-5}, "complete": False}))
    sel = TableSelector(tmp_path)
    assert sel.partial == [] and "both_sides" in sel.choosable
    s = sel.select(fold_name="left_side", stage=2, **args)
    assert s.scenario == "both_sides" and "(incomplete)" in s.note and s.height_ratio in FAN[spread, 0]
    shutil.rmtree(tmp_path / "both_sides")
    _write_table_dir(tmp_path / "both_sides", side)
    prov.write_text(json.dumps({"resolution": {"max_area_m2": 5e-5}, "complete": False}))
    (tmp_path / "shape1" / "table.csv").unlink()  # only partial tables: they are used
    s = TableSelector(tmp_path).select(fold_name="left_side", stage=2, **args)
    assert s.scenario == "both_sides" and "(incomplete)" in s.note


def test_a_non_finite_keypoint_a_feature_is_measured_from_is_named() -> None:
    """A side fold measures both sleeves: a NaN shoulder of either side makes sleeve features NaN,
    which would make every table distance NaN (IndexError in choose); a sleeve fold does not use
    the other sleeve's keypoints, so a NaN there is harmless."""
    kp = flat_keypoints(1, "cotton")
    kp["shoulder_right"] = np.array([np.nan, 0.1, 0.0])
    args = dict(keypoints=kp, material_name="cotton", friction=0.5, duration=4.0)
    with pytest.raises(ValueError, match=r"feature sleeve_length is nan: non-finite keypoint\(s\) shoulder_right"):
        features(fold_name="left_side", **args)
    assert all(math.isfinite(v) for v in features(fold_name="left_sleeve", **args).values())


@pytest.mark.parametrize("column, value, message", [
    ("fold_type", "nan", "fold_type differ between rows"),
    ("point", "134", "fan point outside 0..133"),
    ("tilt_deg", "12.5", "has \\(h, tilt\\)"),
    ("success", "yes", "success must be 0 or 1"),
    ("loss_m", "nan", "without a finite loss"),
    ("loss_m", "-0.001", "without a finite loss"),
    ("scenario", "shape2", "rows of several scenarios"),
])
def test_a_broken_table_row_is_refused_naming_the_problem(tmp_path: Path, column: str, value: str,
                                                         message: str) -> None:
    """A table read from disk is checked: a NaN feature, a point off the fan or not at its own
    (h, tilt), a success flag other than 0/1, a successful run without a finite loss >= 0,
    rows of two scenarios: each a ValueError naming the table and the fault (they crashed
    the selection deep inside or vanished from the regret before)."""
    from clothfold_ros.lookup.table import load_table

    pts = np.arange(0, 134, 7)
    _write_table_dir(tmp_path / "shape1", _table("shape1", _bowl(66)[pts], points=pts))
    assert len(load_table(tmp_path / "shape1").point) == len(pts)  # the table as written loads
    path = tmp_path / "shape1" / "table.csv"
    rows = list(csv.DictReader(open(path, newline="")))
    rows[-1][column] = value
    if column == "fold_type":  # every row: no longer a row that differs, a table whose feature is NaN
        rows_all = [{**r, column: value} for r in rows]
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=COLUMNS)
            w.writeheader()
            w.writerows(rows_all)
        with pytest.raises(ValueError, match="fold_type not finite"):
            load_table(tmp_path / "shape1")
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)
    with pytest.raises(ValueError, match=f"broken lookup table in .*shape1: ValueError: .*{message}"):
        load_table(tmp_path / "shape1")


def test_two_tables_of_one_scenario_in_one_root_are_refused(tmp_path: Path) -> None:
    pts = np.arange(0, 134, 7)
    _write_table_dir(tmp_path / "shape1", _table("shape1", _bowl(66)[pts], points=pts))
    _write_table_dir(tmp_path / "shape1_old", _table("shape1", _bowl(20)[pts], points=pts))
    with pytest.raises(ValueError, match="two tables of scenario 'shape1'"):
        TableSelector(tmp_path)


def test_coverage_order_refuses_points_off_the_fan() -> None:
    from clothfold_ros.lookup.fan_selection import coverage_order

    assert sorted(coverage_order([5, 4])) == [4, 5]
    with pytest.raises(ValueError, match="must be in 0..133, got \\[134\\]"):
        coverage_order([3, 134])
