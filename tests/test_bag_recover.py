"""Truncated and corrupt bags: clear BagErrors, recovery up to the last complete chunk."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rclpy.serialization import serialize_message
from std_msgs.msg import Int32

from clothfold_ros.bag import BagError, BagReader, BagWriter, Qos, recover

T0 = 1_700_000_000_000_000_000
N = 400
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    """A bag of N Int32 (value i at T0 + i ms) with small chunks, plus its chunk index."""
    path = tmp_path_factory.mktemp("rec") / "full.mcap"
    with BagWriter(path, chunk_size=600, max_chunk_age=None) as w:
        w.add_topic("/count", "std_msgs/msg/Int32", [Qos(depth=7, durability="transient_local")])
        w.add_topic("/other", "std_msgs/msg/Int32")
        for i in range(N):
            w.write("/count" if i % 4 else "/other", serialize_message(Int32(data=i)), T0 + i * 1_000_000)
    return path


def _chunks(path: Path):
    """[(start offset, end offset, message count)] of the chunk records, in file order."""
    with open(path, "rb") as f:
        s = make_reader(f).get_summary()
    out = []
    for ci in sorted(s.chunk_indexes, key=lambda c: c.chunk_start_offset):
        with open(path, "rb") as f:
            n = sum(1 for _ in make_reader(f).iter_messages(starting_at=ci.message_start_time,
                                                             ending_at=ci.message_end_time))
        out.append((ci.chunk_start_offset, ci.chunk_start_offset + ci.chunk_length, n))
    return out


def _cut(src: Path, dst: Path, size: int) -> Path:
    dst.write_bytes(src.read_bytes()[:size])
    return dst


def _values(path: Path) -> list[int]:
    with BagReader(path) as b:
        return [int.from_bytes(m.data[4:8], "little", signed=True) for m in b.messages()]


@pytest.mark.parametrize("which,where", [(3, 0.5), (10, 0.1), (10, 0.99), (0, 0.5), (7, 1.0)])
def test_recover_keeps_exactly_the_complete_chunks(bag, tmp_path, which, where):
    chunks = _chunks(bag)
    assert len(chunks) > 12 and sum(c[2] for c in chunks) == N  # message time ranges do not overlap
    start, end, _ = chunks[which]
    cut = _cut(bag, tmp_path / "cut.mcap", int(start + where * (end - start)))
    complete = [c for c in chunks if c[1] <= cut.stat().st_size]
    expected = sum(c[2] for c in complete)
    with pytest.raises(BagError, match="truncated"):
        BagReader(cut)
    if expected == 0:
        with pytest.raises(BagError, match="nothing recoverable"):
            recover(cut, tmp_path / "fixed.mcap")
        return
    report = recover(cut, tmp_path / "fixed.mcap")
    assert "truncated" in report.reason
    assert report.messages == expected and report.chunks == len(complete)
    # the kept part ends after the last complete chunk (and its message index records)
    assert not report.complete and report.bytes_read >= complete[-1][1]
    assert 0 <= report.bytes_lost <= cut.stat().st_size - complete[-1][1]
    assert report.bytes_read + report.bytes_lost == cut.stat().st_size
    assert report.topics == {"/count": sum(1 for i in range(expected) if i % 4),
                             "/other": sum(1 for i in range(expected) if not i % 4)}
    assert _values(tmp_path / "fixed.mcap") == list(range(expected))
    with BagReader(tmp_path / "fixed.mcap") as b:
        assert b.topics["/count"].offered_qos == [Qos(depth=7, durability="transient_local")]
        assert b.metadata["message_count"] == expected
        assert b.metadata["custom_data"]["recovered_from"] == str(cut)


def test_recover_complete_bag_loses_nothing(bag, tmp_path):
    report = recover(bag, tmp_path / "same.mcap")
    assert report.complete and report.messages == N and report.bytes_lost == 0
    assert _values(tmp_path / "same.mcap") == list(range(N))


def test_corrupt_chunk_gives_bag_error_and_recovery_stops_before_it(bag, tmp_path):
    chunks = _chunks(bag)
    data = bytearray(bag.read_bytes())
    start, end, _ = chunks[5]
    mid = (start + end) // 2
    data[mid:mid + 16] = b"\xff" * 16  # damage the compressed payload of chunk 5
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with pytest.raises(BagError, match="damaged"):
        with BagReader(bad) as b:
            list(b.messages())
    report = recover(bad, tmp_path / "fixed.mcap")
    assert report.messages == sum(c[2] for c in chunks[:5])
    assert "damaged record" in report.reason


@pytest.mark.parametrize("content", [b"", b"not a bag at all", b"\x89MCAP0\r\n" + b"\x00" * 3])
def test_garbage_files_raise_bag_error(tmp_path, content):
    p = tmp_path / "g.mcap"
    p.write_bytes(content)
    with pytest.raises(BagError):
        BagReader(p)
    with pytest.raises(BagError):
        recover(p, tmp_path / "o.mcap")


def test_missing_bag_is_a_bag_error(tmp_path):
    with pytest.raises(BagError, match="no such bag"):
        BagReader(tmp_path / "nope.mcap")


def test_cli_info_and_recover_without_traceback(bag, tmp_path):
    cut = _cut(bag, tmp_path / "cut.mcap", bag.stat().st_size // 2)
    cmd = [sys.executable, "-c", "import sys; from clothfold_ros.cli import main; sys.exit(main())"]
    info = subprocess.run(cmd + ["bag", "info", str(cut)], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert info.returncode == 1 and "Traceback" not in info.stderr
    assert "truncated" in info.stderr and "clothfold bag recover" in info.stderr
    fixed = tmp_path / "fixed.mcap"
    rec = subprocess.run(cmd + ["bag", "recover", str(cut), "-o", str(fixed)], capture_output=True, text=True,
                         cwd=ROOT, timeout=60)
    assert rec.returncode == 0, rec.stderr
    n = len(_values(fixed))
    assert 0 < n < N and f"recovered {n} messages" in rec.stdout
    info2 = subprocess.run(cmd + ["bag", "info", str(fixed)], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert info2.returncode == 0 and f"Messages:          {n}" in info2.stdout


def test_damaged_summary_or_footer_is_a_bag_error_never_wrong_counts(bag, tmp_path):
    """mcap's reader does not check the summary CRC: one flipped byte in the summary once gave a
    /count of 0 or messages out of order without an error. Every flip in the summary section and
    the footer's fields is a BagError now (or, where it changes nothing the reader uses, the bag reads
    exactly as before)."""
    import struct

    data = bag.read_bytes()
    footer = len(data) - 8 - 29
    _, _, summary_start, _, crc = struct.unpack("<BQQQI", data[footer:footer + 29])
    assert crc != 0 and 0 < summary_start < footer  # the recorder writes the CRC
    expected = _values(bag)
    step = max(1, (footer + 25 - summary_start) // 40)
    offsets = list(range(summary_start, footer + 25, step)) + [footer + 9, footer + 17]
    for off in offsets:
        damaged = bytearray(data)
        damaged[off] ^= 0x5A
        path = tmp_path / "damaged.mcap"
        path.write_bytes(bytes(damaged))
        with pytest.raises(BagError, match="damaged|truncated"):
            _values(path)
    assert _values(bag) == expected


def test_broken_bag_directories_and_tiny_files_are_bag_errors(bag, tmp_path):
    """From a review of broken files: metadata.yaml naming a file twice (counted twice before),
    a file outside the bag, a string instead of a list (read character by character), bytes
    that are not UTF-8 (a raw UnicodeDecodeError); a file of the magic twice (a raw OSError)."""
    import shutil

    d = tmp_path / "dirbag"
    d.mkdir()
    shutil.copy(bag, d / "dirbag_0.mcap")
    good = "rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n  relative_file_paths: [dirbag_0.mcap]\n"
    (d / "metadata.yaml").write_text(good)
    assert len(_values(d)) == N
    for listing, words in [("[dirbag_0.mcap, dirbag_0.mcap]", "twice"), (f"[{bag}]", "inside the bag directory"),
                           ("[../x.mcap]", "inside the bag directory"), ("dirbag_0.mcap", "list of file names")]:
        (d / "metadata.yaml").write_text(good.replace("[dirbag_0.mcap]", listing))
        with pytest.raises(BagError, match=words):
            BagReader(d)
    (d / "metadata.yaml").write_bytes(b"rosbag2_bagfile_information: \xff\xfe\n")
    with pytest.raises(BagError, match="not a rosbag2 metadata file"):
        BagReader(d)
    tiny = tmp_path / "tiny.mcap"
    tiny.write_bytes(b"\x89MCAP0\r\n" * 2)
    with pytest.raises(BagError, match="truncated"):
        BagReader(tiny)


def test_recover_drops_foreign_encodings_and_keeps_topics_with_unreadable_qos(tmp_path):
    """A channel that is not ROS 2 encoded (a JSON schema) is not relabelled as CDR: its messages
    are dropped and counted; a channel whose QoS metadata cannot be parsed is recovered without
    QoS (its bad QoS failed the whole recovery and left an empty bag behind)."""
    from mcap.writer import Writer

    src = tmp_path / "mixed.mcap"
    with open(src, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        ros = w.register_schema("std_msgs/msg/Int32", "ros2msg", b"int32 data")
        js = w.register_schema("thing", "jsonschema", b"{}")
        good = w.register_channel("/count", "cdr", ros, {"offered_qos_profiles": "- not: a qos profile"})
        foreign = w.register_channel("/json", "json", js)
        for i in range(5):
            w.add_message(good, T0 + i, serialize_message(Int32(data=i)), T0 + i)
            w.add_message(foreign, T0 + i, b"{}", T0 + i)
        w.finish()
    report = recover(src, tmp_path / "out.mcap")
    assert report.messages == 5 and report.foreign == {"/json": 5} and report.qos_lost == ["/count"]
    assert "not ROS 2 encoded" in report.summary() and "QoS metadata unreadable" in report.summary()
    assert _values(tmp_path / "out.mcap") == list(range(5))


def test_recover_takes_a_killed_bag_directory(bag, tmp_path):
    """A directory bag killed mid-recording has its MCAP file and no metadata.yaml yet: recover
    takes the directory (it said 'no such file'), and refuses one with several files."""
    d = tmp_path / "killed"
    d.mkdir()
    _cut(bag, d / "killed_0.mcap", bag.stat().st_size // 2)
    report = recover(d, tmp_path / "fixed.mcap")
    assert report.messages > 0 and _values(tmp_path / "fixed.mcap") == list(range(report.messages))
    _cut(bag, d / "killed_1.mcap", 100)
    with pytest.raises(BagError, match="exactly one"):
        recover(d, tmp_path / "again.mcap")
