"""README.md is the user's first page: short, with the two commands, and every page of the
documentation reachable from it by links; the figures and the generated result blocks live in
docs/results.md, the dated rounds of measurement in docs/history/."""
from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote

from clothfold_ros.cli import regret
from clothfold_ros.lookup import choices, status, summary

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
RESULTS = ROOT / "docs" / "results.md"
MAX_README_CHARS = 12_000
#: the generated blocks (`clothfold tables --write`, `clothfold regret --write`,
#: scripts/report_lookup_tables.sh): each once in docs/results.md, none in README.md
BLOCKS = [(status.HEADLINE_BEGIN, status.HEADLINE_END), (status.BEGIN, status.END),
          (summary.BEGIN, summary.END), (choices.BEGIN, choices.END), (regret.BEGIN, regret.END)]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def _links(md: Path) -> list[tuple[Path, str]]:
    """(target path, fragment) of every relative Markdown link in `md`."""
    out = []
    for target in LINK.findall(md.read_text()):
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            continue
        path, _, frag = target.partition("#")
        out.append(((md.parent / unquote(path)).resolve() if path else md.resolve(), frag))
    return out


def _anchors(md: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens."""
    anchors = set()
    for line in md.read_text().splitlines():
        m = re.match(r"#+ (.*)", line)
        if m:
            slug = re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-")
            anchors.add(slug)
    return anchors


def test_readme_is_short() -> None:
    n = len(README.read_text())
    assert n < MAX_README_CHARS, (f"README.md has {n} characters (limit {MAX_README_CHARS}): "
                                  "put figures in docs/results.md, dated measurements in docs/history/")


def test_readme_has_the_two_commands() -> None:
    block = re.search(r"## The two commands\n\n```bash\n(.*?)```", README.read_text(), re.S).group(1)
    assert [ln.split()[:2] for ln in block.splitlines()] == [["./clothfold", "demo"], ["./clothfold", "test"]]
    assert "exec ./clothfold test" in (ROOT / ".ci" / "run").read_text()


def test_generated_blocks_live_in_results_not_readme() -> None:
    readme, results = README.read_text(), RESULTS.read_text()
    for begin, end in BLOCKS:
        assert begin not in readme and end not in readme, f"{begin}: README.md holds no generated block"
        assert results.count(begin) == 1 and results.count(end) == 1, f"docs/results.md needs one {begin} block"
    assert "<!--" not in readme


def test_generators_are_pointed_at_results() -> None:
    """The documented --write targets are docs/results.md, not README.md."""
    for f in ("scripts/report_lookup_tables.sh", "docs/lookup.md", "docs/results.md", "config/tables/README.md"):
        text = (ROOT / f).read_text()
        assert not re.search(r"--write[^`\n]*\bREADME\.md", text.replace("config/tables/README.md", "")), f
        assert "report_lookup_tables.sh config/tables README.md" not in text, f
    assert "report_lookup_tables.sh config/tables docs/results.md" in (ROOT / "scripts/report_lookup_tables.sh").read_text()


def test_links_resolve_inside_the_repository() -> None:
    pages = [README, RESULTS, *sorted((ROOT / "docs" / "history").glob("*.md"))]
    for md in pages:
        for path, frag in _links(md):
            assert path.is_relative_to(ROOT), f"{md.relative_to(ROOT)}: link outside the repository: {path}"
            assert path.exists(), f"{md.relative_to(ROOT)}: broken link to {path.relative_to(ROOT)}"
            if frag and path.suffix == ".md":
                assert frag in _anchors(path), f"{md.relative_to(ROOT)}: no heading #{frag} in {path.relative_to(ROOT)}"


def test_every_doc_page_is_reachable_from_readme() -> None:
    seen, todo = {README.resolve()}, [README.resolve()]
    while todo:
        md = todo.pop()
        for path, _ in _links(md):
            if path.suffix == ".md" and path.is_file() and path not in seen:
                seen.add(path)
                todo.append(path)
    pages = {p.resolve() for p in [*(ROOT / "docs").glob("*.md"), *(ROOT / "docs" / "history").glob("*.md"),
                                   ROOT / "config" / "tables" / "README.md"]}
    missing = sorted(str(p.relative_to(ROOT)) for p in pages - seen)
    assert not missing, f"not reachable by links from README.md: {missing}"
