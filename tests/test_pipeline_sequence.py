"""The five-fold sequence end to end through the ROS pipeline, as a user runs it:
`clothfold demo --sequence` on a coarse IPC mesh (2e-3 m^2, the folds are crude: the test is
about every stage completing from the cloth as it is, not about the losses). The planner
re-plans each stage from /keypoints (here the visible keypoints of the simulated cloth,
`--keypoints cloth_state`, so no shape fit can reject a crude fold; from the coarse tables,
`--tables config/tables_1k2`: the 12K table's sleeve choice, a low path, drags a mesh this coarse,
which cannot buckle, across the table: 0.41 m), the trajectory node
streams both grippers of the side and middle folds, and the bag holds each stage's spec
and result."""
from __future__ import annotations

import math
import re
import subprocess
import sys

import numpy as np
from rclpy.serialization import deserialize_message

from clothfold_msgs.msg import FoldResult, FoldSpec
from clothfold_ros.bag import BagReader
from clothfold_ros.folding import FOLD_SEQUENCE, fold_spec
from clothfold_ros.garment import make_shirt

DOMAIN = 165
AREA = 2e-3


def test_demo_sequence_folds_all_five_through_the_nodes(tmp_path):
    cmd = [sys.executable, "-c", "import sys; from clothfold_ros.cli import main; sys.exit(main())", "demo",
           "--sequence", "--max-area", str(AREA), "--keypoints", "cloth_state", "--tables", "config/tables_1k2", "--quiet",
           "--domain-id", str(DOMAIN), "--bags", str(tmp_path), "--name", "seq", "--timeout", "600"]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=1500)
    out = run.stdout + run.stderr
    assert run.returncode == 0, out[-3000:]
    printed = {m[1]: float(m[2]) for m in re.finditer(r"\[demo\] (\w+): loss ([0-9.]+) m ok", out)}
    assert list(printed) == list(FOLD_SEQUENCE), out[-3000:]

    bag = BagReader(tmp_path / "seq.mcap")
    results = [deserialize_message(m.data, FoldResult) for m in bag.messages(["/fold/result"])]
    specs = [deserialize_message(m.data, FoldSpec) for m in bag.messages(["/fold/spec"])]
    assert [r.fold_name for r in results] == list(FOLD_SEQUENCE)
    assert all(r.success and math.isfinite(r.loss) for r in results), [(r.fold_name, r.reason) for r in results]
    assert [round(r.loss, 6) for r in results] == [round(v, 6) for v in printed.values()]
    assert [s.fold_name for s in specs] == list(FOLD_SEQUENCE)
    assert [len(s.start_poses) for s in specs] == [1, 1, 2, 2, 2]  # both grippers for sides and middle
    # the middle fold is planned from the folded cloth, not from the flat shirt: its grips are
    # not the flat hem's quarter points (where they land depends on how this crude mesh folded)
    g = make_shirt(1, max_area=AREA)
    flat_grips = np.array([p.position[0] for p in fold_spec("middle", g.keypoints(g.vertices)).start_poses])
    grips = np.array([p.position.x for p in specs[-1].start_poses])
    assert np.abs(grips - flat_grips).max() > 0.01, (grips, flat_grips)
    for k, fold in enumerate(FOLD_SEQUENCE):
        assert (tmp_path / f"seq-stage{k}-{fold}.png").stat().st_size > 10_000
