"""`clothfold demo --backend kinematic` as a user runs it (a subprocess): SIGTERM or SIGINT in the
middle of the fold stops every process it started and closes the bag; a backend killed mid-fold
ends the demo at once with a failure (not after its 900 s timeout), showing the nodes' last lines."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time

import pytest

from clothfold_ros.bag import BagReader

DOMAIN = 160


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except FileNotFoundError:
        return False


class Demo:
    """The demo as a subprocess; its output lines collected by a thread."""

    def __init__(self, tmp_path, name: str, *extra: str) -> None:
        self.bag = tmp_path / f"{name}.mcap"
        cmd = [sys.executable, "-c", "import sys; from clothfold_ros.cli import main; sys.exit(main())", "demo",
               "--backend", "kinematic", "--domain-id", str(DOMAIN), "--bags", str(tmp_path), "--name", name, *extra]
        self.p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                  start_new_session=True)
        self.lines: list[str] = []
        self.cond = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.p.stdout:
            with self.cond:
                self.lines.append(line.rstrip("\n"))
                self.cond.notify_all()
        with self.cond:
            self.cond.notify_all()

    def wait_line(self, pattern: str, timeout: float = 120.0) -> re.Match:
        rx, deadline, seen = re.compile(pattern), time.monotonic() + timeout, 0
        with self.cond:
            while True:
                for ln in self.lines[seen:]:
                    if m := rx.search(ln):
                        return m
                seen = len(self.lines)
                left = deadline - time.monotonic()
                assert left > 0 and self.p.poll() is None or seen < len(self.lines), \
                    f"no line {pattern!r}; output:\n" + "\n".join(self.lines[-40:])
                self.cond.wait(min(max(left, 0.01), 0.2))

    def pids(self) -> dict[str, int]:
        return {m.group(1): int(m.group(2)) for ln in list(self.lines)
                if (m := re.search(r"\[demo\] started (\w+) \(pid (\d+)\)", ln))}

    def finish(self, timeout: float = 120.0) -> int:
        try:
            return self.p.wait(timeout)
        finally:
            if self.p.poll() is None:
                os.killpg(self.p.pid, signal.SIGKILL)
            for pid in self.pids().values():  # never leave a node behind, even when the test fails
                if _alive(pid):
                    os.killpg(pid, signal.SIGKILL)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_every_process_and_closes_the_bag(tmp_path, sig):
    demo = Demo(tmp_path, f"sig{int(sig)}")
    demo.wait_line(r"\[demo\] stage 0: executing")
    pids = demo.pids()
    assert {"recorder_node", "kinematic_robot_node", "trajectory_node"} <= set(pids), pids
    demo.p.send_signal(sig)
    code = demo.finish()
    out = "\n".join(demo.lines)
    assert code == 128 + int(sig), out[-3000:]  # 130 after SIGINT, 143 after SIGTERM
    left = [n for n, pid in pids.items() if _alive(pid)]
    assert not left, f"still running after {sig.name}: {left}\n{out[-3000:]}"
    assert "bag closed" in out, out[-3000:]
    with BagReader(str(demo.bag)) as bag:  # complete: summary and statistics written
        assert bag.message_count > 0


def test_killed_backend_ends_the_demo_promptly(tmp_path):
    """--quiet hides the nodes' output; on an error the demo then shows each node's last lines."""
    demo = Demo(tmp_path, "killed", "--quiet")
    demo.wait_line(r"\[demo\] stage 0: executing")
    pids = demo.pids()
    os.killpg(pids["kinematic_robot_node"], signal.SIGKILL)
    code = demo.finish(timeout=120)  # the demo's own timeout is 900 s
    out = "\n".join(demo.lines)
    assert code == 1, out[-3000:]
    assert "kinematic_robot_node" in out and "process exited" in out, out[-3000:]
    assert re.search(r"^\[demo\]   trajectory_node: .*\S", out, re.M), out[-3000:]
    assert not [n for n, pid in pids.items() if _alive(pid)], out[-3000:]


def test_a_backend_without_cloth_reports_no_loss_in_words(tmp_path):
    """The kinematic backend reports NaN for the loss (it has no cloth): the demo says so instead
    of printing 'loss nan m'."""
    demo = Demo(tmp_path, "no-cloth", "--quiet")
    try:
        demo.wait_line(r"\[demo\] left_sleeve: success, no loss \(the backend simulates no cloth\)", 120)
        demo.wait_line(r"\[demo\] left_sleeve: no loss \(the backend simulates no cloth\) ok", 60)
        assert demo.finish() == 0
    finally:
        demo.finish(5)
    assert not any("nan" in ln for ln in demo.lines if ln.startswith("[demo] left_sleeve")), demo.lines
