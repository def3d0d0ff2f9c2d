"""`clothfold fold` against a running kinematic pipeline (a subprocess, as a user runs it beside a
real driver): two folds in turn, each result awaited, the second planned after the first's
result; a fold done already is refused by the planner and the command says so; bad arguments
are one line and exit 2."""
from __future__ import annotations

import re
import subprocess
import sys

import pytest

from pipeline_helpers import FAST_KINEMATIC, running_pipeline

from clothfold_ros.nodes import conversions as rc

DOMAIN = 161


def clothfold(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-c", "import sys; from clothfold_ros.cli import main; sys.exit(main())", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


def test_fold_runs_folds_in_turn_on_the_running_pipeline(monkeypatch):
    # the tables choose the path: at the method's 4 s it keeps the speed limit (FAST_KINEMATIC's 2 s may not)
    overrides = {**FAST_KINEMATIC, "fold_planner_node": {"selection": "table", "duration": 4.0}}
    with running_pipeline(monkeypatch, DOMAIN, "kinematic", overrides, "test_cli_fold") as (launcher, client):
        client.wait_keypoints(60)
        before = client.result_count()
        out = clothfold("fold", "left_sleeve", "right_sleeve", "--timeout", "60")
        assert out.returncode == 0, out.stdout + out.stderr
        lines = out.stdout.splitlines()
        assert lines[0].startswith("stage 0: executing left_sleeve (h="), out.stdout + out.stderr
        # the reply names the table and fan point the planner chose (h, tilt) from
        assert re.search(r"; table \w+, fan point \d+\); result on /fold/result", lines[0]), lines[0]
        assert any(ln.startswith("stage 1: ") and "right_sleeve" in ln for ln in lines), out.stdout + out.stderr
        assert lines[-2:] == ["left_sleeve: no loss (the backend simulates no cloth) ok",
                              "right_sleeve: no loss (the backend simulates no cloth) ok"], out.stdout + out.stderr
        # the results as this client saw them (it may get them after the command has exited)
        first = client.wait_result("left_sleeve", 30, after=before)
        second = client.wait_result("right_sleeve", 30, after=before)
        assert first.success and second.success
        assert rc.time_to_ns(second.header.stamp) > rc.time_to_ns(first.header.stamp)

        again = clothfold("fold", "left_sleeve", "--timeout", "30")
        assert again.returncode == 1, again.stdout + again.stderr
        assert "left_sleeve: planner refused: " in again.stdout and "done already" in again.stdout, \
            again.stdout + again.stderr
        assert again.stdout.splitlines()[-1].startswith("left_sleeve: no loss FAILED planner refused")


@pytest.mark.parametrize("args,words", [
    ((), "no fold given"), (("sideways",), "unknown fold(s) sideways"),
    (("left_sleeve", "--sequence"), "not both"), (("left_sleeve", "--timeout", "nan"), "--timeout must be"),
])
def test_bad_arguments_are_one_line_and_exit_2(args, words, capsys):
    from clothfold_ros.cli import main

    assert main(["fold", *args]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("clothfold fold: ") and words in err, err


def test_fold_in_turn_keeps_the_finished_stages_when_a_later_one_raises():
    """No ROS: PipelineClient.fold_in_turn over a stand-in client whose keypoints never come
    after the first fold. The first stage's outcome is in the caller's list when it raises."""
    import math
    from types import SimpleNamespace

    from clothfold_msgs.msg import FoldResult

    from clothfold_ros.nodes.pipeline_client import PipelineClient, loss_text

    def no_keypoints(*_a, **_k):
        raise TimeoutError("no keypoints")

    result = FoldResult(fold_name="left_sleeve", success=True, loss=0.004)
    fake = SimpleNamespace(result_count=lambda: 0, wait_keypoints=no_keypoints,
                           plan=lambda fold, **_k: SimpleNamespace(success=True, message=f"executing {fold}", spec=None),
                           _wait_result_alive=lambda fold, timeout, after, alive: result)
    said, outcomes = [], []
    with pytest.raises(RuntimeError, match="no keypoints of the cloth after left_sleeve within 5 s"):
        PipelineClient.fold_in_turn(fake, ["left_sleeve", "right_sleeve"], 10.0, say=said.append,
                                    keypoints_wait=5.0, outcomes=outcomes)
    assert [(o.fold, o.success, o.loss) for o in outcomes] == [("left_sleeve", True, pytest.approx(0.004))]
    assert said == ["stage 0: executing left_sleeve", "left_sleeve: success, loss 0.004000 m, 0 steps"]
    assert loss_text(math.nan) == "no loss (the backend simulates no cloth)"
    assert loss_text(math.nan, success=False) == "no loss"
