"""filter_bag: copy a selection of a bag's messages into a new bag (what ``ros2 bag convert``
does with an output's topics and time window), keeping each topic's type, definition, type
hash and offered QoS and each message's log and publish time and bytes.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable

from .errors import BagError
from .reader import BagMessage, BagReader
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
    unknown topic, a bad regex, an empty window or an output that exists (unless overwrite);
    a failed write leaves no output behind."""
    src, out = Path(source), Path(output)
    if src.resolve() == out.resolve():
        raise BagError(f"{out}: the output must not be the source bag")
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
        writer = BagWriter(out, overwrite=overwrite, max_chunk_age=None)
        try:
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
            writer.close()
        except BaseException:
            if not writer.closed:
                try:
                    writer.close()
                except Exception:  # noqa: BLE001 - the output is removed below either way
                    pass
            _remove(out)
            raise
    return report


def _remove(path: Path) -> None:
    if path.is_dir():
        for child in path.iterdir():
            child.unlink(missing_ok=True)
        path.rmdir()
    else:
        path.unlink(missing_ok=True)
