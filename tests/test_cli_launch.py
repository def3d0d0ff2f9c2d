"""`clothfold launch`: paths given relative to the caller's directory reach the nodes as the
caller's files (the nodes run in the checkout, Launcher.start), and bad arguments are one line
with exit code 2. No node is started: Launcher.start is replaced by a recorder of commands."""
from __future__ import annotations

from pathlib import Path

import pytest

from clothfold_ros.cli import launcher as launcher_mod
from clothfold_ros.cli import main
from clothfold_ros.nodes.resources import DEFAULT_PARAMS, work_dir


@pytest.fixture
def started(monkeypatch):
    """(name, command, the directory the process would run in) of every start; nothing runs."""
    calls: list[tuple[str, list[str], Path]] = []

    def start(self, name, cmd, cwd=None):
        calls.append((name, list(cmd), Path(cwd or work_dir())))

    monkeypatch.setattr(launcher_mod.Launcher, "start", start)
    monkeypatch.setattr(launcher_mod, "run_until_interrupted", lambda launcher, signals=None: 0)
    return calls


def _arg(cmd: list[str], option: str) -> str:
    return cmd[cmd.index(option) + 1]


def test_relative_params_file_and_bag_are_the_callers(tmp_path, monkeypatch, started):
    caller = tmp_path / "caller"
    (caller / "cfg").mkdir(parents=True)
    mine = caller / "cfg" / "mine.yaml"
    mine.write_text(DEFAULT_PARAMS.read_text())
    monkeypatch.chdir(caller)
    assert work_dir() != caller  # the nodes do not run where the caller is
    code = main(["launch", "--backend", "kinematic", "--params-file", "cfg/mine.yaml", "--record", "bags/run.mcap"])
    assert code == 0
    nodes = {name: (cmd, cwd) for name, cmd, cwd in started}
    assert {"keypoint_node", "fold_planner_node", "trajectory_node", "recorder_node"} <= set(nodes)
    for name, (cmd, cwd) in nodes.items():
        if name != "recorder_node":  # what the node opens, from where it runs
            assert (cwd / _arg(cmd, "--params-file")).resolve() == mine.resolve(), name
    cmd, cwd = nodes["recorder_node"]
    assert (cwd / _arg(cmd, "--output")).resolve() == (caller / "bags" / "run.mcap").resolve()


@pytest.mark.parametrize("extra,words", [
    (["--params-file", "missing.yaml"], "no parameters file missing.yaml"),
    (["--domain-id", "999"], "ROS_DOMAIN_ID must be in 0..232, got 999"),
    (["-p", "trajectory_node:rate=5"], "bad parameter override"),
    (["--record", "old.mcap"], "old.mcap exists (use --force to overwrite)"),
    (["-p", "keypoint_nod:source:=points"], "unknown node(s) keypoint_nod"),
    (["--no-perception", "-p", "keypoint_node:source:=points"], "keypoint_node, which is not started"),
])
def test_bad_arguments_are_one_line_and_exit_2(tmp_path, monkeypatch, capsys, started, extra, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "old.mcap").write_bytes(b"a recording to keep")
    assert main(["launch", *extra]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("clothfold launch: ") and words in err, err
    assert not started


def test_record_force_starts_the_recorder_on_an_existing_bag(tmp_path, monkeypatch, started):
    """Without --force the launch is refused (above); with it the recorder is started on that
    path (the recorder opens its bag with overwrite: tests/test_bag_core.py)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "old.mcap").write_bytes(b"a recording to replace")
    assert main(["launch", "--backend", "kinematic", "--record", "old.mcap", "--force"]) == 0
    cmd, cwd = {name: (cmd, cwd) for name, cmd, cwd in started}["recorder_node"]
    assert (cwd / _arg(cmd, "--output")).resolve() == (tmp_path / "old.mcap").resolve()


def test_no_perception_leaves_keypoint_node_out(tmp_path, monkeypatch, started):
    monkeypatch.chdir(tmp_path)
    assert main(["launch", "--backend", "none", "--no-perception"]) == 0
    assert {name for name, _, _ in started} == {"fold_planner_node", "trajectory_node"}
