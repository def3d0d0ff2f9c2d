"""Whole-file writes: a file is written aside and renamed into place, so a reader never sees half of it."""
from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def replacing(path: str | Path, tmp_name: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside `path` (named `tmp_name`, default `<name>.tmp`) to write;
    on a clean exit it is renamed onto `path` (atomic: same directory), on an error removed,
    leaving any old `path` untouched."""
    path = Path(path)
    tmp = path.with_name(tmp_name if tmp_name is not None else path.name + ".tmp")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
