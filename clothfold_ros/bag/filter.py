"""filter_bag: copy a selection of a bag's messages into a new bag (what ``ros2 bag convert``
does with an output's topics and time window), keeping each topic's type, definition, type
hash and offered QoS and each message's log and publish time and bytes.
"""
from __future__ import annotations

import os
import re
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable

from ..files import remove_path
from .errors import BagError
from .reader import BagMessage, BagReader, bag_files
from .writer import BagWriter


@dataclass
class FilterReport:
    """Messages kept per topic and how many were read."""

    output: Path
    kept: dict[str, int] = field(default_factory=dict)
    read: int = 0

    def summary(self) -> str:
        n = sum(self.kept.values())
        per_topic = ", ".join(f"{t} {c}" for t, c in sorted(self.kept.items())) or "none"
        return f"{self.output}: {n} of {self.read} messages ({per_topic})"


def filter_bag(source: str | os.PathLike, output: str | os.PathLike, *, topics: Iterable[str] | None = None,
               exclude: str | None = None, start_ns: int | None = None, end_ns: int | None = None,
               keep: Callable[[BagMessage], bool] | None = None, overwrite: bool = False) -> FilterReport:
    """Write the messages of `source` on `topics` (default: all) whose topic does not match the
    regex `exclude`, logged in [start_ns, end_ns) (ns since the epoch) and for which `keep`
    returns True, into the new bag `output` (.mcap file or bag directory). BagError for an
    unknown topic, a bad regex, an empty window, a selection of no message, an output that
    exists (unless overwrite) or that is, holds or lies inside the source. The bag is written
    beside `output` and moved there when complete: a failed cut leaves `output` as it was."""
    src, out = Path(source), Path(output)
    _check_apart(src, out)
    if out.exists() and not overwrite:
        raise BagError(f"{out} exists; choose another output or allow overwriting")
    try:
        pattern = re.compile(exclude) if exclude else None
    except re.error as err:
        raise BagError(f"bad exclude regex {exclude!r}: {err}") from None
    if start_ns is not None and end_ns is not None and not start_ns < end_ns:
        raise BagError(f"empty time window: start {start_ns} ns is not before end {end_ns} ns")
    report = FilterReport(out)
    with BagReader(src) as reader:
        wanted = list(reader.topics) if topics is None else list(dict.fromkeys(topics))
        unknown = [t for t in wanted if t not in reader.topics]
        if unknown:
            raise BagError(f"{src}: no topic {', '.join(unknown)} in the bag (has {', '.join(sorted(reader.topics))})")
        wanted = [t for t in wanted if not (pattern and pattern.search(t))]
        if not wanted:
            raise BagError(f"{src}: every topic selected is excluded by {exclude!r}")
        out.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".filter-", dir=out.parent))  # beside it: a rename moves it there
        try:
            with BagWriter(staging / out.name, max_chunk_age=None) as writer:
                for msg in reader.messages(wanted, start_ns, end_ns):
                    report.read += 1
                    if keep is not None and not keep(msg):
                        continue
                    if msg.topic not in writer.topics:
                        info = reader.topics[msg.topic]
                        writer.add_topic(msg.topic, info.type, info.offered_qos, definition=info.definition,
                                         type_hash=info.type_hash)
                    writer.write(msg.topic, msg.data, msg.log_time_ns, msg.publish_time_ns)
                    report.kept[msg.topic] = report.kept.get(msg.topic, 0) + 1
            if not report.kept:
                raise BagError(f"{src}: no message selected ({report.read} read on {', '.join(wanted)}"
                               f"{' in the time window' if start_ns is not None or end_ns is not None else ''})")
            if out.exists():
                remove_path(out)
            os.replace(staging / out.name, out)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    return report


def _check_apart(src: Path, out: Path) -> None:
    """BagError when the output is the source, one of its files, or holds or lies inside it."""
    s, o = src.resolve(), out.resolve()
    files = [f.resolve() for f in bag_files(src)] if src.exists() else []
    if s == o or o in files or s in o.parents or o in s.parents or any(o in f.parents for f in files):
        raise BagError(f"{out}: the output must lie apart from the source bag {src} (not the bag, one of its "
                       "files, or a directory holding or inside it)")
