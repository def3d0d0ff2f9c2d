"""`clothfold simulate` with a bad argument: one clear line on stderr and exit code 2 (like the
other commands), before anything is simulated or written; no traceback."""
from __future__ import annotations

import pytest

from clothfold_ros.cli import main

COARSE = ["--max-area", "1e-2", "--quiet"]  # the checks run before the (short) scene build is used


@pytest.mark.parametrize("extra,words", [
    (["--height-ratio", "5"], "height ratio must be in (0, 1.5], got 5.0"),
    (["--height-ratio", "nan"], "height ratio must be in"),
    (["--tilt", "100"], "tilt must be in [0, 90.0] deg, got 100.0"),
    (["--duration", "-1"], "duration must be > 0 s, got -1.0"),
    (["--settle", "inf"], "settle_time must be >= 0 s, got inf"),
    (["--material", "silk"], "unknown material 'silk'"),
    (["--dt", "0"], "dt must be > 0"),
    (["--duration", "0.01"], "duration 0.01 s is shorter than one time step (dt 0.04 s)"),
])
def test_bad_arguments_are_one_line_and_exit_2(tmp_path, capsys, extra, words):
    out = tmp_path / "out"
    code = main(["simulate", *COARSE, "--out", str(out), *extra])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("clothfold simulate: ") and words in lines[0], err
    assert not out.exists()  # nothing simulated, nothing written


def test_out_that_is_a_file_is_refused_before_simulating(tmp_path, capsys):
    out = tmp_path / "taken"
    out.write_text("x")
    assert main(["simulate", *COARSE, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.strip() == f"clothfold simulate: --out {out} is not a directory"
    assert out.read_text() == "x"
