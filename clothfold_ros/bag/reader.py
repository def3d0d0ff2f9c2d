"""BagReader: topics, metadata and time-ordered messages of a bag written in the rosbag2 layout.

Accepts a single ``.mcap`` file or a rosbag2 bag directory (``metadata.yaml`` + files).
Every failure inside the mcap library (truncation, bad CRC, garbage) becomes a BagError
that names the file and suggests ``clothfold bag recover`` where it can help.
"""
from __future__ import annotations

import heapq
import os
import struct
import zlib
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Iterable, Iterator

import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.stream_reader import CRCValidationError

from . import layout
from .errors import BagError
from .layout import TopicInfo
from .qos import parse_qos

# what the mcap library (and zstd/lz4 below it) raises on damaged input
_DAMAGE = (McapError, CRCValidationError, EOFError, struct.error, ValueError, KeyError, IndexError, zlib.error,
           UnicodeDecodeError, MemoryError, OSError, OverflowError)
try:  # zstandard.ZstdError is not a ValueError
    import zstandard

    _DAMAGE = _DAMAGE + (zstandard.ZstdError,)
except ImportError:  # pragma: no cover
    pass

MAGIC = b"\x89MCAP0\r\n"
FOOTER_OPCODE = 0x02
FOOTER_LEN = 1 + 8 + 8 + 8 + 4  # the footer record: opcode, length, summary start, summary offset start, CRC
RECOVER_HINT = "run `clothfold bag recover BAG -o FIXED.mcap` to salvage its complete chunks"


@dataclass(frozen=True)
class BagMessage:
    """One stored message: topic, log (receive) and publish time in ns, serialized CDR, sequence."""

    topic: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    sequence: int


@contextmanager
def _damage_as_bag_error(path: Path, what: str) -> Iterator[None]:
    try:
        yield
    except BagError:
        raise
    except _DAMAGE as err:
        detail = str(err) or type(err).__name__
        raise BagError(f"{path}: {what} failed, the file is damaged or truncated ({detail}); {RECOVER_HINT}") from None


def bag_files(path: str | os.PathLike) -> list[Path]:
    """The MCAP files of a bag path (a file, or a directory with metadata.yaml / *.mcap)."""
    p = Path(path)
    if p.is_file():
        return [p]
    if not p.is_dir():
        raise BagError(f"{p}: no such bag (file or directory)")
    meta = p / "metadata.yaml"
    if meta.is_file():
        try:
            info = (yaml.safe_load(meta.read_text(encoding="utf-8")) or {})["rosbag2_bagfile_information"]
            names = info["relative_file_paths"]
        except (yaml.YAMLError, KeyError, TypeError, UnicodeDecodeError, OSError) as err:
            raise BagError(f"{meta}: not a rosbag2 metadata file ({type(err).__name__}: {err})") from None
        if not (isinstance(names, list) and names and all(isinstance(f, str) for f in names)):
            raise BagError(f"{meta}: relative_file_paths must be a list of file names, got {names!r}")
        if len(set(names)) != len(names):
            raise BagError(f"{meta}: relative_file_paths lists a file twice: {names}")
        files = [p / f for f in names]
        outside = [f for f in names if Path(f).is_absolute() or p.resolve() not in (p / f).resolve().parents]
        if outside:
            raise BagError(f"{meta}: relative_file_paths must name files inside the bag directory, not {outside}")
        if info.get("storage_identifier", "mcap") != "mcap":
            raise BagError(f"{p}: storage {info.get('storage_identifier')!r} is not supported, only mcap")
    else:
        files = sorted(p.glob("*.mcap"))
    missing = [str(f) for f in files if not f.is_file()]
    if missing or not files:
        raise BagError(f"{p}: missing bag files {', '.join(missing) or '(no *.mcap)'}")
    return files


class _File:
    """One open MCAP file with its summary."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self.stream: IO[bytes] = open(path, "rb")
        except OSError as err:
            raise BagError(f"cannot open {path}: {err.strerror}") from None
        self.size = path.stat().st_size
        head = self.stream.read(8)
        if head != MAGIC:
            self.stream.close()
            raise BagError(f"{path}: not an MCAP file (bad magic {head[:8]!r})")
        self.stream.seek(max(0, self.size - 8))
        if self.size < 16 + FOOTER_LEN or self.stream.read(8) != MAGIC:  # magic, footer record, magic
            self.stream.close()
            raise BagError(f"{path}: truncated, it has no footer (the recorder was killed or is still running); "
                           f"{RECOVER_HINT}")
        self._check_summary_crc()
        self.stream.seek(0)
        with _damage_as_bag_error(path, "reading the header"):
            self.reader = make_reader(self.stream, validate_crcs=True)
            header = self.reader.get_header()
        if header.profile != layout.PROFILE:
            raise BagError(f"{path}: MCAP profile {header.profile!r} is not a ROS 2 bag (expected 'ros2')")
        self.library = header.library
        with _damage_as_bag_error(path, "reading the summary"):
            summary = self.reader.get_summary()
        if summary is None or summary.statistics is None:
            raise BagError(f"{path}: no summary, the recording was not closed (killed or still running); "
                           f"{RECOVER_HINT}")
        self.summary = summary
        with _damage_as_bag_error(path, "reading the metadata"):
            self.metadata = {m.name: dict(m.metadata) for m in self.reader.iter_metadata()}


    def _check_summary_crc(self) -> None:
        """Compare the footer's summary CRC (0: not written) with the summary section and the
        footer fields before it: mcap's reader does not, and a damaged summary otherwise gives
        wrong counts or message order without an error."""
        footer = self.size - 8 - FOOTER_LEN  # opcode, record length, summary start, offset start, crc
        self.stream.seek(footer)
        raw = self.stream.read(FOOTER_LEN)
        opcode, length, summary_start, _, crc = struct.unpack("<BQQQI", raw)
        if opcode != FOOTER_OPCODE or length != FOOTER_LEN - 9:
            self.stream.close()
            raise BagError(f"{self.path}: damaged footer record; {RECOVER_HINT}")
        if crc == 0 or summary_start == 0:
            return  # no CRC written / no summary (reported below)
        if not 8 <= summary_start <= footer:
            self.stream.close()
            raise BagError(f"{self.path}: damaged footer (summary start {summary_start} outside the file); "
                           f"{RECOVER_HINT}")
        self.stream.seek(summary_start)
        covered = self.stream.read(footer + FOOTER_LEN - 4 - summary_start)  # through the footer's offset start
        if zlib.crc32(covered) != crc:
            self.stream.close()
            raise BagError(f"{self.path}: the summary section is damaged (CRC mismatch); {RECOVER_HINT}")


class BagReader:
    """Read a bag: ``topics`` (name -> TopicInfo), times (ns), ``metadata`` and ``messages()``."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._files = [_File(f) for f in bag_files(path)]
        self.topics: dict[str, TopicInfo] = {}
        self.chunk_count = 0
        starts, ends = [], []
        for f in self._files:
            stats = f.summary.statistics
            assert stats is not None
            self.chunk_count += stats.chunk_count
            if stats.message_count:
                starts.append(stats.message_start_time)
                ends.append(stats.message_end_time)
            for cid, ch in f.summary.channels.items():
                schema = f.summary.schemas.get(ch.schema_id)
                if schema is None:
                    raise BagError(f"{f.path}: channel {ch.topic} has no schema; not a rosbag2 bag")
                if schema.encoding != layout.SCHEMA_ENCODING or ch.message_encoding != layout.MESSAGE_ENCODING:
                    raise BagError(f"{f.path}: {ch.topic} is {schema.encoding}/{ch.message_encoding}, "
                                   f"expected {layout.SCHEMA_ENCODING}/{layout.MESSAGE_ENCODING}")
                info = self.topics.get(ch.topic)
                if info is None:
                    with _damage_as_bag_error(f.path, f"reading the QoS of {ch.topic}"):
                        qos = parse_qos(ch.metadata.get("offered_qos_profiles", ""))
                    info = self.topics[ch.topic] = TopicInfo(
                        ch.topic, schema.name, schema.data.decode("utf-8", "replace"),
                        ch.metadata.get("topic_type_hash", ""), qos)
                elif info.type != schema.name:
                    raise BagError(f"{self.path}: topic {ch.topic} has two types, {info.type} and {schema.name}")
                info.message_count += stats.channel_message_counts.get(cid, 0)
        self.start_ns = min(starts, default=0)
        self.end_ns = max(ends, default=0)

    @property
    def files(self) -> list[Path]:
        """The MCAP files of this bag."""
        return [f.path for f in self._files]

    @property
    def size_bytes(self) -> int:
        """Total size of the bag files (bytes)."""
        return sum(f.size for f in self._files)

    @property
    def message_count(self) -> int:
        return sum(t.message_count for t in self.topics.values())

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns)

    @property
    def library(self) -> str:
        """Writer library of the first file."""
        return self._files[0].library

    @property
    def metadata(self) -> dict:
        """The ``rosbag2_bagfile_information`` map from the ``rosbag2`` record ({} if absent)."""
        raw = self._files[0].metadata.get(layout.METADATA_NAME, {}).get(layout.METADATA_KEY)
        if not raw:
            return {}
        try:
            data = yaml.safe_load(raw) or {}
        except yaml.YAMLError as err:
            raise BagError(f"{self.path}: rosbag2 metadata record is not YAML ({err})") from None
        inner = data.get("rosbag2_bagfile_information", data) if isinstance(data, dict) else None
        if not isinstance(inner, dict):  # the bare map (rosbag2's) or under its file key (ours before 2026-12-06)
            raise BagError(f"{self.path}: rosbag2 metadata record holds no metadata map ({type(inner).__name__})")
        return inner

    def messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[BagMessage]:
        """Messages in log-time order; optional topic filter and [start_ns, end_ns) window."""
        wanted = None if topics is None else sorted(set(topics))
        if wanted is not None:
            unknown = [t for t in wanted if t not in self.topics]
            if unknown:
                raise BagError(f"{self.path}: no topic {', '.join(unknown)} in the bag "
                               f"(has {', '.join(sorted(self.topics)) or 'none'})")
        streams = [self._iter_file(f, wanted, start_ns, end_ns) for f in self._files]
        if len(streams) == 1:
            yield from streams[0]
        else:
            yield from heapq.merge(*streams, key=lambda m: m.log_time_ns)

    def _iter_file(self, f: _File, topics: list[str] | None, start_ns: int | None,
                   end_ns: int | None) -> Iterator[BagMessage]:
        with _damage_as_bag_error(f.path, "reading messages"):
            for _, channel, msg in f.reader.iter_messages(topics=topics, starting_at=start_ns, ending_before=end_ns,
                                                          log_time_order=True):
                yield BagMessage(channel.topic, msg.log_time, msg.publish_time, msg.data, msg.sequence)

    def close(self) -> None:
        for f in self._files:
            f.stream.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
