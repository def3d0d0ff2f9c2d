"""The repository is self-contained: no file refers to documents outside it.

The method's reference is docs/method.md. Checked: every file git tracks, plus the
untracked files git does not ignore (so a new file is checked before it is committed);
binary files (a NUL byte) are skipped.
"""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
THIS = Path(__file__).resolve()

#: references to files that only exist next to the checkout, never in it
OUTSIDE = re.compile(r"\.\./shared|shared/SPEC|SPEC\.md|ipc-notes\.md|ros2-notes\.md|/work/(?:shared|main)"
                     r"|(?<![\w.])/tmp/")  # a scratch path of one machine: a command with it cannot be rerun
#: "SPEC section 5" and the like: the old name of docs/method.md (FOLD_SPEC is not matched)
OLD_NAME = re.compile(r"(?<![A-Za-z0-9_])SPEC(?![A-Za-z0-9_])")

#: Files with an OLD_NAME reference that their owners are still to change (issue 14):
#: path -> number of lines. An entry that is no longer true fails the test (remove it).
PENDING: dict[str, int] = {}


def repo_files() -> list[Path]:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                         capture_output=True, check=True).stdout
    files = []
    for name in sorted(set(out.decode().split("\0")) - {""}):
        p = ROOT / name
        if p.is_file() and p.resolve() != THIS:
            files.append(p)
    return files


def hits(pattern: re.Pattern[str]) -> dict[str, list[str]]:
    found: dict[str, list[str]] = {}
    for p in repo_files():
        data = p.read_bytes()
        if b"\0" in data:
            continue
        for i, line in enumerate(data.decode("utf-8", "replace").splitlines(), 1):
            if pattern.search(line):
                found.setdefault(str(p.relative_to(ROOT)), []).append(f"{i}: {line.strip()}")
    return found


def test_checks_see_the_repository():
    files = {str(p.relative_to(ROOT)) for p in repo_files()}
    assert {"README.md", "docs/method.md", "docs/results.md", "clothfold_ros/garment.py",
            "msg_defs/msg/Keypoints.msg"} <= files
    assert OUTSIDE.search("see ../shared/SPEC.md") and OLD_NAME.search("(SPEC section 5)")
    assert not OLD_NAME.search("FOLD_SPEC = '/fold/spec'")


def test_no_reference_outside_the_repository():
    found = hits(OUTSIDE)
    assert not found, "references outside the repository (use docs/method.md):\n" + "\n".join(
        f"{f}:{line}" for f, lines in found.items() for line in lines)


def test_no_reference_to_the_old_spec_name():
    found = hits(OLD_NAME)
    unexpected = {f: lines for f, lines in found.items() if f not in PENDING}
    assert not unexpected, "'SPEC' references (point to docs/method.md section N):\n" + "\n".join(
        f"{f}:{line}" for f, lines in unexpected.items() for line in lines)
    stale = {f: n for f, n in PENDING.items() if len(found.get(f, [])) != n}
    assert not stale, f"PENDING is out of date (update or remove these entries): " \
                      f"{ {f: len(found.get(f, [])) for f in stale} }"


def test_method_doc_has_the_sections_referred_to():
    text = (ROOT / "docs/method.md").read_text()
    numbers = {int(m) for m in re.findall(r"^## (\d+) ", text, flags=re.M)}
    assert numbers == set(range(1, 12)), sorted(numbers)
    refs = set()
    for p in repo_files():
        data = p.read_bytes()
        if b"\0" in data:
            continue
        for m in re.finditer(r"method\.md sections? (\d+)(?:\s*(?:-|and|,)\s*(\d+))?", data.decode("utf-8", "replace")):
            refs.update(int(g) for g in m.groups() if g)
    assert refs and refs <= numbers, sorted(refs - numbers)
