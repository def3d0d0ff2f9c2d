"""keypoint_node's hypothesis chain replayed over the clouds at rest of recorded sequences, at 3K
and at 12K triangles (`tests/data/seq-3k-rest.mcap`, `seq-12k-rest.mcap`: the 32 messages of
`clothfold demo --sequence` that `bench/bench_perception.py --bag ... --bag-subset` keeps: every
/fold/active and /fold/result, and each cloud at rest with its /cloth/state), against the
simulated cloth's visible keypoints."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CELL = re.compile(r"^(\d+) / (\d+) \((\d+\.\d)\)$")  # "median / max (residual)" in mm


@pytest.mark.parametrize("bag, area, slid", [("seq-3k-rest.mcap", "2e-4", True), ("seq-12k-rest.mcap", "5e-5", False)])
def test_the_chain_tracks_a_recorded_sequence_where_a_fresh_fit_fails(bag: str, area: str, slid: bool) -> None:
    """slid: the cloth slid in a side fold (3K): the previous shape with its lines refitted is taken."""
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_perception.py"), "--random", "0", "--shapes",
                          "--repeat", "1", "--bag", str(ROOT / "tests" / "data" / bag), "--bag-area", area],
                         capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-3000:]
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in out.stdout.splitlines()
            if line.startswith("| ") and not line.startswith("| after")]
    assert [r[0] for r in rows] == ["flat"] + [f for f in ("left_sleeve", "right_sleeve", "left_side", "right_side",
                                                           "middle") for _ in range(2)], out.stdout
    for after, _, start, chain, _, fresh in rows:
        m = CELL.match(chain)
        assert m, (after, start, chain)  # the chain accepted every cloud at rest
        median, worst, residual = int(m[1]), int(m[2]), float(m[3])
        assert median <= 30 and worst <= 120 and residual <= 10.0, (after, chain)
    # after the middle fold a fresh fit lands far off (its figure depends on the CPU's numeric code
    # paths: over 100 mm median where the bags were recorded, 54-68 mm on an AMD EPYC), while the
    # chain stays within 3 cm: the fresh fit's median is over 40 mm and over twice the chain's
    worst_fresh = max(rows[-2:], key=lambda r: int(CELL.match(r[5])[1]))
    assert int(CELL.match(worst_fresh[5])[1]) > max(40, 2 * int(CELL.match(worst_fresh[3])[1])), rows[-2:]
    # where the cloth slid in a side fold, the previous shape with its lines refitted is taken
    if slid:
        assert any(r[2] == "prior shape" for r in rows if r[0] in ("left_side", "right_side")), rows


def test_bag_subset_without_a_bag_is_refused() -> None:
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_perception.py"), "--bag-subset", "x.mcap"],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 2 and "--bag-subset needs --bag" in out.stderr, out.stderr
