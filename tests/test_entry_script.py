"""The ./clothfold entry script: `./clothfold test PATH` runs that path only (issue 38)."""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _collect(*args: str) -> str:
    env = dict(os.environ)
    env.pop("PYTEST_ADDOPTS", None)
    out = subprocess.run([str(ROOT / "clothfold"), "test", *args, "--collect-only", "-q"], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def test_a_named_file_is_all_that_runs():
    lines = [ln for ln in _collect("tests/test_entry_script.py").splitlines() if "::" in ln]
    assert lines and all(ln.startswith("tests/test_entry_script.py::") for ln in lines), lines


def test_a_named_test_is_all_that_runs():
    lines = [ln for ln in _collect("tests/test_entry_script.py::test_a_named_test_is_all_that_runs").splitlines()
             if "::" in ln]
    assert lines == ["tests/test_entry_script.py::test_a_named_test_is_all_that_runs"], lines


def test_options_alone_still_run_the_whole_suite():
    import re

    out = _collect("-k", "named_file")
    files = {ln.split("::")[0] for ln in out.splitlines() if "::" in ln}
    deselected = re.search(r"\((\d+) deselected\)", out)
    assert files == {"tests/test_entry_script.py"}
    assert deselected and int(deselected.group(1)) > 300, out[-300:]  # -k filtered the whole suite
