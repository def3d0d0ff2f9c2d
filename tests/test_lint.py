"""Lint (ruff) and type checking (mypy) of the ROS-free core are clean.

Both tools read their settings from pyproject.toml: what they check (clothfold_ros/ minus
nodes/ and cli/ for now), the rules, and the third-party modules without type information.
The tools run from the virtual environment the suite runs in (pinned in requirements.lock).
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(tool: str, *args: str) -> subprocess.CompletedProcess:
    bindir = Path(sys.executable).parent
    exe = bindir / tool
    if not exe.exists():
        pytest.fail(f"{tool} is not installed next to {sys.executable} (requirements.txt lists it; "
                    f"./clothfold installs it)")
    env = {**os.environ, "NO_COLOR": "1"}
    return subprocess.run([str(exe), *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)


def _clean(tool: str, proc: subprocess.CompletedProcess) -> None:
    assert proc.returncode == 0, f"{tool} found problems (exit {proc.returncode}):\n{proc.stdout}{proc.stderr}"


def test_ruff_clean():
    _clean("ruff", _run("ruff", "check", "--output-format", "concise"))


def test_mypy_clean():
    _clean("mypy", _run("mypy"))  # no paths: the `files` of [tool.mypy] (cache: .mypy_cache, git-ignored)
