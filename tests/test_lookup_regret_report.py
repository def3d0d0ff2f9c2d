"""`clothfold regret`: the committed reports and the documented figures are the data's, and the
command's --out / --partial / refusal paths."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from test_lookup_select import _bowl, _table, _write_table_dir

from clothfold_ros.cli import main

ROOT = Path(__file__).resolve().parents[1]
PARTIAL = re.compile(r"; partial tables left out: [^\n]*")  # partial tables enter no figure


def _regret(capsys, *args: str) -> tuple[int, str, str]:
    code = main(["regret", *args])
    out = capsys.readouterr()
    return code, out.out, out.err


def _summary_rows(text: str) -> list[str]:
    """The summary table's rows, each with its rule's label: '| raw argmin ... | 6 of 6 | 0.2 | 0.4 | 6 of 6 (100 %) |'
    (with the label: figures quoted under another rule's name are caught)."""
    block = text.split("\n\n")[1]
    return block.splitlines()[2:]


@pytest.mark.parametrize("root", ["config/tables", "config/tables_1k2"])
def test_committed_regret_report_is_the_tables(root: str, capsys) -> None:
    code, out, err = _regret(capsys, "--tables", str(ROOT / root))
    assert code == 0, err
    committed = (ROOT / root / "regret.md").read_text()
    assert PARTIAL.sub("", committed).strip() == PARTIAL.sub("", out).strip(), \
        f"{root}/regret.md is stale: clothfold regret --tables {root} --out {root}/regret.md"


def test_documented_regret_figures_are_the_tables(capsys) -> None:
    results, lookup = (ROOT / "docs" / "results.md").read_text(), (ROOT / "docs" / "lookup.md").read_text()
    for root, docs in (("config/tables", {"docs/results.md": results, "docs/lookup.md": lookup}),
                       ("config/tables_1k2", {"docs/lookup.md": lookup})):
        code, out, err = _regret(capsys, "--tables", str(ROOT / root))
        assert code == 0, err
        rows = _summary_rows(out)
        assert len(rows) == 4, out
        for name, text in docs.items():
            for row in rows:
                assert row in text, f"{name} lacks the regret row {row!r} of {root}"


def test_regret_writes_its_report_and_names_partial_tables(tmp_path: Path, capsys) -> None:
    pts = np.arange(0, 134, 2)
    _write_table_dir(tmp_path / "shape1", _table("shape1", _bowl(32)[pts], points=pts))
    _write_table_dir(tmp_path / "T1", _table("T1", _bowl(40)[pts] + 0.001, points=pts))
    _write_table_dir(tmp_path / "mu0.8", _table("mu0.8", _bowl(50)[pts[:10]], points=pts[:10]))
    prov = tmp_path / "mu0.8" / "provenance.json"
    prov.write_text(json.dumps({**json.loads(prov.read_text()), "complete": False}))

    out_md = tmp_path / "reports" / "regret.md"
    code, out, err = _regret(capsys, "--tables", str(tmp_path), "--out", str(out_md))
    assert code == 0, err
    assert out_md.read_text() == out  # the file is what was printed
    assert out.startswith("2 tables: T1, shape1; partial tables left out: mu0.8 (10 points)")
    assert all(r.split("|")[2].strip() == "2 of 2" for r in _summary_rows(out)[:3])

    code, out, err = _regret(capsys, "--tables", str(tmp_path), "--partial")
    assert code == 0, err
    assert out.startswith("3 tables: T1, mu0.8, shape1; partial tables included: mu0.8 (10 points)")
    assert "held out" in out and "| mu0.8 |" in out

    (tmp_path / "T1" / "provenance.json").write_text(json.dumps({"complete": False}))
    code, out, err = _regret(capsys, "--tables", str(tmp_path))
    assert code == 2 and "at least two" in err


def test_regret_writes_its_summary_block_where_a_file_has_one(tmp_path: Path, capsys) -> None:
    from clothfold_ros.cli.regret import BEGIN, END

    pts = np.arange(0, 134, 2)
    _write_table_dir(tmp_path / "t" / "shape1", _table("shape1", _bowl(32)[pts], points=pts))
    _write_table_dir(tmp_path / "t" / "T1", _table("T1", _bowl(40)[pts] + 0.001, points=pts))
    doc, plain = tmp_path / "doc.md", tmp_path / "plain.md"
    doc.write_text(f"intro\n{BEGIN}\nOLD ROWS\n{END}\nafter\n")
    plain.write_text("no block here\n")
    code, out, err = _regret(capsys, "--tables", str(tmp_path / "t"), "--write", str(doc), str(plain))
    assert code == 0, err
    text = doc.read_text()
    assert "OLD ROWS" not in text and text.startswith("intro\n") and text.endswith("after\n")
    assert text.split(BEGIN)[1].split(END)[0].strip() == "\n\n".join(out.split("\n\n")[:2]).strip()
    assert all(row in text for row in _summary_rows(out))
    assert plain.read_text() == "no block here\n"
    broken = tmp_path / "broken.md"
    broken.write_text(f"{BEGIN}\nA\n{END}\n{BEGIN}\n")
    code, out, err = _regret(capsys, "--tables", str(tmp_path / "t"), "--write", str(doc), str(broken))
    assert code == 2 and "need exactly one" in err


def test_tie_margin_report_spans_argmin_to_fan_middle(tmp_path: Path, capsys) -> None:
    """A tie margin of 0 picks the smoothed minimum (the other table's bowl centre, far from the
    middle); one wider than the whole landscape picks the fan middle for every held-out table."""
    from clothfold_ros.lookup.regret import evaluate, tie_margin_report
    from clothfold_ros.lookup.select import middle_of_fan

    tables = {"shape1": _table("shape1", _bowl(5)), "T1": _table("T1", _bowl(120) + 0.001)}
    assert [r.point for r in evaluate(tables, "robust", tie_margin=10.0)] == [middle_of_fan()] * 2
    assert {r.point for r in evaluate(tables, "robust", tie_margin=0.0)} != {middle_of_fan()}
    default = evaluate(tables, "robust")
    text = tie_margin_report(tables, [0.0, 5e-4, 10.0])
    rows = [line for line in text.splitlines() if line.startswith("| ") and line[2].isdigit()]
    assert [r.split(" | ")[0] for r in rows] == ["| 0", "| 0.5", "| 10000"]
    assert f"| {sum(r.regret for r in default) / 2 * 1e3:.3f} |" in rows[1]  # 0.5 mm is the rule's default
    with pytest.raises(ValueError, match="robust rule only"):
        evaluate(tables, "static", tie_margin=0.0)

    for name, t in tables.items():
        _write_table_dir(tmp_path / name, t)
    code, out, err = _regret(capsys, "--tables", str(tmp_path), "--tie-margins", "0,0.5")
    assert code == 0 and "robust rule by tie margin" in out, err
    code, out, err = _regret(capsys, "--tables", str(tmp_path), "--tie-margins", "-1")
    assert code == 2 and "--tie-margins" in err
