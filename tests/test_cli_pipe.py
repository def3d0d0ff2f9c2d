"""`clothfold` piped into a reader that stops early (`clothfold regret | head -1`) ends quietly
with 141 (128 + SIGPIPE), as shell tools do, and still writes its --out file first."""
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
    assert out.read_text().startswith("2 tables:")
