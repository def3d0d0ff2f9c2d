"""`clothfold` error paths: piped into a reader that stops early (`clothfold regret | head -1`) it ends quietly
with 141 (128 + SIGPIPE), as shell tools do, and still writes its --out file first; bad arguments and
unwritable paths are one line and exit code 2."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_closed_stdout_ends_quietly_and_keeps_the_report(tmp_path: Path) -> None:
    out = tmp_path / "regret.md"
    code = ("import sys; from clothfold_ros.cli import main; "
            f"sys.exit(main(['regret', '--tables', {str(ROOT / 'config' / 'tables')!r}, '--out', {str(out)!r}]))")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    proc.stdout.close()  # the reader is gone before the command prints anything
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141, err
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    assert out.read_text().startswith("12 tables:") or out.read_text().startswith("13 tables:")


def test_bad_arguments_and_unwritable_paths_are_one_line_and_exit_2(tmp_path, capsys):
    """From a review: these ended in tracebacks (or, for --timeout nan, a demo that never times
    out). Now every command prints one line naming the problem and exits 2."""
    from clothfold_ros.cli import main

    afile = tmp_path / "afile"
    afile.write_text("x")
    for argv, words in [(["shirt", "--max-area", "-1"], "max_area must be a triangle area"),
                        (["shirt", "--out", str(tmp_path / "nodir" / "s.png")], "No such file or directory"),
                        (["sweep", "shape1", "--points", "0", "--out", str(afile)], "Not a directory"),
                        (["plot", "--overview", "--tables", str(Path(__file__).resolve().parents[1] / "config" / "tables"),
                          "--out", str(afile)], "afile"),
                        (["demo", "--timeout", "nan"], "--timeout must be a positive number"),
                        (["demo", "--domain-id", "999"], "--domain-id must be in 0..232")]:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, (argv, err)
