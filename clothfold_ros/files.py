"""Whole-file writes: a file is written aside and renamed into place, so a reader never sees half of it;
and removal of an output that is a file or a directory (a bag is either)."""
from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def replacing(path: str | Path, tmp_name: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside `path` (named `tmp_name`, default `<name>.tmp`) to write;
    on a clean exit it is flushed to disk and renamed onto `path` (atomic: same directory; the
    directory is synced too, so after a power loss `path` is the old file or the whole new one),
    on an error removed, leaving any old `path` untouched."""
    path = Path(path)
    tmp = path.with_name(tmp_name if tmp_name is not None else path.name + ".tmp")
    try:
        yield tmp
        _fsync(tmp, os.O_RDONLY)
        os.replace(tmp, path)
        _fsync(path.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _fsync(path: Path, flags: int) -> None:
    fd = os.open(path, flags)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def remove_path(path: str | Path, missing_ok: bool = False) -> None:
    """Remove `path`, a directory tree or a file (FileNotFoundError when it is absent, unless
    `missing_ok`)."""
    path = Path(path)
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=missing_ok)
