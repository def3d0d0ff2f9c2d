"""Rebuild a complete bag from a truncated or damaged one (e.g. a killed recorder).

The damaged file is read record by record from the start; every complete chunk whose
data decompresses (and matches its CRC) is kept, reading stops at the first incomplete
or damaged record. The kept messages are written to a new bag with the original
schemas, channel metadata (QoS, type hash) and times, plus a fresh summary and rosbag2
metadata. Nothing is dropped silently: the report counts what was kept and lost (channels
not ROS 2 encoded are dropped and counted; topics with unreadable QoS are kept without it).
A recovery that fails leaves no output.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from ..files import remove_path
from .errors import BagError
from .qos import parse_qos
from .reader import _DAMAGE
from .writer import BagWriter


@dataclass
class RecoveryReport:
    """What recovery kept and lost.

    messages: recovered; chunks: complete chunks kept; bytes_read / bytes_lost: bytes of the
    source before / after the last good record; complete: the source already had its
    summary (nothing was lost); reason: why reading stopped ("" if it reached the end);
    topics: recovered messages per topic; orphans: messages dropped because their channel
    or schema record was lost; foreign: messages dropped per topic whose encoding is not ROS 2's
    (schema ``ros2msg``, messages ``cdr``: copied, they would be read as CDR); qos_lost: topics
    whose QoS metadata could not be parsed (recovered with none).
    """

    source: Path
    output: Path
    messages: int = 0
    chunks: int = 0
    bytes_read: int = 0
    bytes_lost: int = 0
    complete: bool = False
    reason: str = ""
    topics: dict[str, int] = field(default_factory=dict)
    orphans: int = 0
    foreign: dict[str, int] = field(default_factory=dict)
    qos_lost: list[str] = field(default_factory=list)

    def summary(self) -> str:
        """Human-readable multi-line report."""
        lines = [f"recovered {self.messages} messages in {self.chunks} complete chunks from {self.source} "
                 f"-> {self.output}"]
        if self.complete:
            lines.append("source was complete (summary present): nothing lost")
        else:
            lines.append(f"lost: {self.bytes_lost} trailing bytes after offset {self.bytes_read} "
                         f"(the unfinished chunk and the summary); stopped because: {self.reason or 'end of file'}")
        if self.orphans:
            lines.append(f"dropped {self.orphans} messages whose channel/schema record was lost")
        for topic, n in sorted(self.foreign.items()):
            lines.append(f"dropped {n} messages of {topic}: not ROS 2 encoded (schema ros2msg, messages cdr)")
        if self.qos_lost:
            lines.append(f"QoS metadata unreadable, recovered without it: {', '.join(sorted(self.qos_lost))}")
        for topic, n in sorted(self.topics.items()):
            lines.append(f"  {topic}: {n}")
        return "\n".join(lines)


def recover(source: str | os.PathLike, output: str | os.PathLike, overwrite: bool = False) -> RecoveryReport:
    """Copy every message of ``source`` (an MCAP file, or a bag directory holding one) up to its
    last complete chunk into a complete bag ``output``."""
    src, dst = Path(source), Path(output)
    if src.is_dir():  # a bag directory killed mid-recording: its one MCAP file (metadata.yaml is written last)
        files = sorted(src.glob("*.mcap"))
        if len(files) != 1:
            raise BagError(f"{src}: a bag directory to recover must hold exactly one *.mcap file, it holds "
                           f"{len(files)}{': ' + ', '.join(f.name for f in files) if files else ''}; name the file")
        src = files[0]
    if not src.is_file():
        raise BagError(f"{src}: no such file")
    if src.resolve() == dst.resolve():
        raise BagError("recover writes a new file: output must differ from the source")
    report = RecoveryReport(src, dst)
    size = src.stat().st_size
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    kept: list[Message] = []
    with open(src, "rb") as f:
        reader = StreamReader(f, emit_chunks=True, record_size_limit=size)
        records = reader.records
        good = 0
        while True:
            try:
                record = next(records)
                if isinstance(record, Chunk):
                    inner = breakup_chunk(record, validate_crc=True)
                else:
                    inner = [record]
            except StopIteration:
                break
            except _DAMAGE as err:
                report.reason = _reason(err, size, good)
                break
            good = reader._stream.count  # offset after this complete record
            if isinstance(record, Chunk):
                report.chunks += 1
            for r in inner:
                if isinstance(r, Schema):
                    schemas[r.id] = r
                elif isinstance(r, Channel):
                    channels[r.id] = r
                elif isinstance(r, Message):
                    kept.append(r)
            if isinstance(record, (DataEnd, Footer)):
                report.complete = True
                break
        if not kept and not report.complete:
            raise BagError(f"{src}: nothing recoverable, no complete chunk "
                           f"({report.reason or 'empty file'})")
    report.bytes_read = good
    report.bytes_lost = 0 if report.complete else size - good
    _write(dst, schemas, channels, kept, report, overwrite)
    return report


def _reason(err: BaseException, size: int, offset: int) -> str:
    if type(err).__name__ in ("EndOfFile", "RecordLengthLimitExceeded") or isinstance(err, EOFError):
        if offset >= size:
            return f"file ends at byte {size} without a summary (truncated)"
        return f"file ends inside a record at byte {offset}..{size} (truncated)"
    return f"damaged record after byte {offset}: {type(err).__name__}: {err}".rstrip(": ")


def _write(dst: Path, schemas: dict[int, Schema], channels: dict[int, Channel], kept: list[Message],
           report: RecoveryReport, overwrite: bool) -> None:
    """Write the recovered bag; on any error nothing is left at ``dst`` (no empty, valid-looking bag)."""
    writer = BagWriter(dst, overwrite=overwrite, max_chunk_age=None)
    try:
        for ch in channels.values():
            schema = schemas.get(ch.schema_id)
            if schema is None:
                continue
            if schema.encoding != "ros2msg" or ch.message_encoding != "cdr":
                report.foreign[ch.topic] = 0
                continue
            try:
                qos = parse_qos(ch.metadata.get("offered_qos_profiles", ""))
            except BagError:
                qos = []
                report.qos_lost.append(ch.topic)
            writer.add_topic(ch.topic, schema.name, qos, definition=schema.data.decode("utf-8", "replace"),
                             type_hash=ch.metadata.get("topic_type_hash", ""))
        for msg in sorted(kept, key=lambda m: m.log_time):
            ch = channels.get(msg.channel_id)
            if ch is not None and ch.topic in report.foreign:
                report.foreign[ch.topic] += 1
                continue
            if ch is None or ch.topic not in writer.topics:
                report.orphans += 1
                continue
            writer.write(ch.topic, msg.data, msg.log_time, msg.publish_time)
            report.topics[ch.topic] = report.topics.get(ch.topic, 0) + 1
            report.messages += 1
        writer.custom_data["recovered_from"] = str(report.source)
    except BaseException:
        try:
            writer.close()
        finally:
            remove_path(dst, missing_ok=True)
        raise
    writer.close()


__all__ = ["RecoveryReport", "recover"]
