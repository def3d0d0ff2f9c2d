"""clothfold_ros.files.replacing: a file appears whole or not at all."""
from __future__ import annotations

import numpy as np
import pytest

from clothfold_ros.files import replacing


def test_replacing_writes_aside_then_renames(tmp_path):
    path = tmp_path / "table.csv"
    path.write_text("old")
    with replacing(path) as tmp:
        assert tmp == tmp_path / "table.csv.tmp"
        tmp.write_text("new, whole")
        assert path.read_text() == "old"  # not in place until the block ends
    assert path.read_text() == "new, whole"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.csv"]


def test_replacing_named_temp_in_same_directory(tmp_path):
    path = tmp_path / "p007.npy"
    with replacing(path, ".p007.npy") as tmp:
        assert tmp == tmp_path / ".p007.npy"
        np.save(tmp, np.arange(3, dtype=np.float32))
    np.testing.assert_array_equal(np.load(path), [0, 1, 2])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p007.npy"]


@pytest.mark.parametrize("existing", [True, False])
def test_failure_while_writing_keeps_old_file_and_leaves_no_temp(tmp_path, existing):
    path = tmp_path / "metadata.yaml"
    if existing:
        path.write_text("old")
    with pytest.raises(RuntimeError, match="killed"):
        with replacing(path) as tmp:
            tmp.write_text("half")
            raise RuntimeError("killed mid-write")
    if existing:
        assert path.read_text() == "old"
    else:
        assert not path.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == (["metadata.yaml"] if existing else [])


def test_remove_path_takes_a_tree_a_file_or_a_link_itself(tmp_path):
    from clothfold_ros.files import remove_path

    tree = tmp_path / "bag"
    (tree / "sub").mkdir(parents=True)
    (tree / "sub" / "a.mcap").write_bytes(b"x")
    keep = tmp_path / "keep"
    keep.mkdir()
    (keep / "k").write_text("k")
    link = tmp_path / "link"
    link.symlink_to(keep, target_is_directory=True)
    remove_path(tree)
    remove_path(link)  # the link, not the directory it points to
    f = tmp_path / "one.mcap"
    f.write_bytes(b"x")
    remove_path(f)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep"] and (keep / "k").exists()
    with pytest.raises(FileNotFoundError):
        remove_path(f)
    remove_path(f, missing_ok=True)
