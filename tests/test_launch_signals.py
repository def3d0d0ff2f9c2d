"""SIGINT and SIGTERM stop every command that starts or waits on processes, also when a script
started it in the background: a non-interactive shell starts `cmd &` with SIGINT ignored, and
`clothfold launch ... &` then ran on after `kill -INT` (19 minutes in the issue) until a SIGTERM.
Exit status 130 after SIGINT, 143 after SIGTERM (what a shell reports for a process those signals
killed; the demo said 130 for both). Each command runs as a user runs it, under `bash -c 'cmd & wait'`."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

DOMAIN = 159
ROOT = Path(__file__).resolve().parents[1]
CLOTHFOLD = f"{sys.executable} -c 'import sys; from clothfold_ros.cli import main; sys.exit(main())'"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie is gone for this purpose
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


class Background:
    """`bash -c '<clothfold args> & wait'`: the command as a script's background job; its output in a file."""

    def __init__(self, tmp_path: Path, args: str) -> None:
        self.out, self.pidfile = tmp_path / "out.txt", tmp_path / "pid"
        env = {**os.environ, "ROS_DOMAIN_ID": str(DOMAIN), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
        script = f"{CLOTHFOLD} {args} > {self.out} 2>&1 & echo $! > {self.pidfile}; wait $!; echo \"rc=$?\" >> {self.out}"
        self.shell = subprocess.Popen(["bash", "-c", script], env=env, cwd=ROOT, start_new_session=True)
        deadline = time.monotonic() + 30
        while not (self.pidfile.exists() and self.pidfile.read_text().strip()):
            assert time.monotonic() < deadline, "no pid"
            time.sleep(0.05)
        self.pid = int(self.pidfile.read_text())

    def descendants(self) -> list[int]:
        """Every live process below the shell (the nodes run in sessions of their own)."""
        parent = {}
        for entry in os.listdir("/proc"):
            if entry.isdigit():
                try:
                    parent[int(entry)] = int(Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()[1])
                except (OSError, IndexError, ValueError):
                    pass
        found, todo = [], [self.shell.pid]
        while todo:
            pid = todo.pop()
            kids = [c for c, pp in parent.items() if pp == pid]
            found += kids
            todo += kids
        return found

    def kill_all(self) -> None:
        """Whatever the test saw: nothing it started stays behind."""
        for pid in self.descendants():
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        try:
            os.killpg(self.shell.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.shell.wait(10)

    def __enter__(self) -> "Background":
        return self

    def __exit__(self, *exc) -> None:
        self.kill_all()

    def text(self) -> str:
        return self.out.read_text(errors="replace") if self.out.exists() else ""

    def wait_line(self, pattern: str, timeout: float = 90.0) -> re.Match:
        deadline = time.monotonic() + timeout
        while True:
            m = re.search(pattern, self.text())
            if m:
                return m
            assert time.monotonic() < deadline and self.shell.poll() is None, \
                f"no line {pattern!r}:\n{self.text()[-3000:]}"
            time.sleep(0.1)

    def sigint_ignored(self) -> bool:
        for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
            if line.startswith("SigIgn:"):
                return bool(int(line.split()[1], 16) & (1 << (signal.SIGINT - 1)))
        raise AssertionError("no SigIgn line")

    def finish(self, timeout: float = 60.0) -> int:
        try:
            self.shell.wait(timeout)
        finally:
            if self.shell.poll() is None:
                os.killpg(self.shell.pid, signal.SIGKILL)
        m = re.search(r"rc=(\d+)", self.text())
        assert m, self.text()[-3000:]
        return int(m.group(1))


def test_a_background_shell_job_starts_with_sigint_ignored(tmp_path):
    """The premise: what `cmd &` in a script gets (this is why the commands must restore SIGINT)."""
    job = subprocess.run(["bash", "-c", "sleep 0.1 & grep SigIgn /proc/$!/status; wait"], capture_output=True,
                         text=True, timeout=10)
    assert int(job.stdout.split()[1], 16) & (1 << (signal.SIGINT - 1)), job.stdout


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_launch_in_the_background_stops_every_node_on_a_signal(tmp_path, sig):
    with Background(tmp_path, "launch --backend none --no-perception") as job:
        job.wait_line(r"\[launcher\] started \d+ processes")
        time.sleep(1.0)  # the nodes up (rclpy's handlers installed)
        nodes = job.descendants()
        assert len(nodes) >= 3, nodes  # the launcher and its two nodes
        assert not job.sigint_ignored(), "SIGINT is still ignored"
        os.kill(job.pid, sig)
        code = job.finish()
        assert code == 128 + int(sig), job.text()[-3000:]
        assert f"[launcher] {sig.name}: stopping every process" in job.text()
        deadline = time.monotonic() + 10
        while any(_alive(p) for p in nodes) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not [p for p in nodes if _alive(p)], job.text()[-3000:]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_fold_in_the_background_ends_on_a_signal(tmp_path, sig):
    """No pipeline: `clothfold fold` waits for keypoints (60 s) when the signal comes."""
    with Background(tmp_path, "fold left_sleeve --keypoints-timeout 60") as job:
        time.sleep(4.0)  # past the imports: waiting for keypoints
        assert not job.sigint_ignored(), "SIGINT is still ignored"
        os.kill(job.pid, sig)
        assert job.finish(30) == 128 + int(sig), job.text()
        assert f"clothfold fold: interrupted ({sig.name}" in job.text(), job.text()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_run_in_the_background_ends_on_a_signal(tmp_path, sig):
    with Background(tmp_path, "run trajectory_node") as job:
        job.wait_line(r"ready: /execute_fold")
        assert not job.sigint_ignored(), "SIGINT is still ignored"
        os.kill(job.pid, sig)
        assert job.finish(30) == 128 + int(sig), job.text()
