"""BagWriter: serialized CDR messages -> one MCAP file in the rosbag2 layout.

Chunked (zstd): a chunk is written to disk when it exceeds ``chunk_size`` bytes or is
older than ``max_chunk_age`` seconds (checked on each write and by ``flush_if_due``), and
the file is unbuffered, so a killed writer loses at most the chunk being built.
``close()`` writes the ``rosbag2`` metadata record, the summary (schemas, channels,
statistics, chunk indexes) and, for a bag directory, ``metadata.yaml``.

Output path: ``x.mcap`` -> that single file (``ros2 bag play x.mcap -s mcap`` reads it);
any other path -> a rosbag2 bag directory ``<path>/<name>_0.mcap`` + ``metadata.yaml``.
"""
from __future__ import annotations

import numbers
import os
import time
from pathlib import Path

from mcap.writer import CompressionType, Writer

from ..files import replacing
from . import layout
from .definitions import message_definition
from .errors import BagError
from .layout import TopicInfo
from .qos import Qos, dump_qos

LIBRARY = "clothfold_ros.bag"


class _DirectFile:
    """Unbuffered file for the mcap Writer: every record it writes goes straight to the OS.

    (A raw ``FileIO`` would be wrapped in a BufferedWriter by mcap, holding back up to 8 KiB.)
    """

    def __init__(self, path: Path) -> None:
        self._f = open(path, "wb", buffering=0)

    def write(self, data: bytes | bytearray | memoryview) -> int:
        view = memoryview(data)
        while view.nbytes:
            view = view[self._f.write(view):]
        return len(data)

    def tell(self) -> int:
        return self._f.tell()

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self._f.close()


def _time_ns(value: object, which: str, topic: str) -> int:
    """A message time as an int in [0, 2**63) ns since the epoch (MCAP stores uint64, rosbag2's
    metadata and ROS 2 time stamps signed 64-bit ns); BagError otherwise."""
    if not isinstance(value, numbers.Integral) or isinstance(value, bool):
        raise BagError(f"{which} time on {topic} must be an integer number of ns, got {value!r}")
    value = int(value)
    if not 0 <= value < 2**63:
        raise BagError(f"{which} time {value} ns on {topic} is outside [0, 2**63) (ROS 2 time, signed 64-bit ns)")
    return value


class BagWriter:
    """Write one bag; use as a context manager or call ``close()``.

    path: ``.mcap`` file or bag directory; chunk_size: bytes (uncompressed) per chunk;
    max_chunk_age: s before a non-empty chunk is flushed (None: size only);
    overwrite: replace an existing file/directory instead of raising BagError.
    """

    def __init__(self, path: str | os.PathLike, *, chunk_size: int = 256 * 1024, max_chunk_age: float | None = 1.0,
                 compression: str = "zstd", overwrite: bool = False,
                 custom_data: dict[str, str] | None = None) -> None:
        self.path = Path(path)
        if self.path.suffix == ".mcap":
            self.file_path = self.path
            self.metadata_path: Path | None = None
        else:
            self.file_path = self.path / f"{self.path.name}_0.mcap"
            self.metadata_path = self.path / "metadata.yaml"
        if self.path.exists() and not overwrite:
            raise BagError(f"{self.path} exists; choose another output or allow overwriting")
        if compression not in ("zstd", "lz4", "none"):
            raise BagError(f"unknown compression {compression!r}: zstd, lz4 or none")
        try:
            self.file_path.parent.mkdir(parents=True, exist_ok=True)
            if self.metadata_path is not None and self.metadata_path.exists():
                self.metadata_path.unlink()
            self._stream = _DirectFile(self.file_path)
        except OSError as err:
            raise BagError(f"cannot create {self.file_path}: {err.strerror}") from None
        comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[compression]
        self._mcap = Writer(self._stream, chunk_size=chunk_size, compression=comp)
        self._mcap.start(profile=layout.PROFILE, library=LIBRARY)
        self.custom_data = dict(custom_data or {})
        self.max_chunk_age = max_chunk_age
        self.topics: dict[str, TopicInfo] = {}
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._chunk_started: float | None = None  # monotonic s of the first message in the open chunk
        self._start_ns: int | None = None
        self._end_ns = 0
        self.closed = False

    # -- topics -------------------------------------------------------------------------
    def add_topic(self, topic: str, msgtype: str, offered_qos: list[Qos] | tuple[Qos, ...] = (),
                  definition: str | None = None, type_hash: str | None = None) -> TopicInfo:
        """Register a topic (once). Definition and hash default to the installed interface files."""
        self._check_open()
        if not topic.startswith("/"):
            raise BagError(f"topic {topic!r} must be absolute (start with '/')")
        if topic in self.topics:
            known = self.topics[topic]
            if known.type != msgtype:
                raise BagError(f"topic {topic} already recorded as {known.type}, not {msgtype}")
            return known
        if definition is None or type_hash is None:
            resolved = message_definition(msgtype)
            msgtype = resolved.name
            definition = resolved.text if definition is None else definition
            type_hash = resolved.type_hash if type_hash is None else type_hash
        info = TopicInfo(topic, msgtype, definition, type_hash, list(offered_qos))
        if msgtype not in self._schemas:
            self._schemas[msgtype] = self._mcap.register_schema(msgtype, layout.SCHEMA_ENCODING,
                                                                definition.encode("utf-8"))
        meta = {"offered_qos_profiles": dump_qos(info.offered_qos), "topic_type_hash": type_hash}
        self._channels[topic] = self._mcap.register_channel(topic, layout.MESSAGE_ENCODING, self._schemas[msgtype],
                                                            meta)
        self._sequence[topic] = 0
        self.topics[topic] = info
        return info

    # -- messages -----------------------------------------------------------------------
    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Append one serialized CDR message; times in ns since the epoch (publish defaults to log)."""
        self._check_open()
        channel = self._channels.get(topic)
        if channel is None:
            raise BagError(f"topic {topic} was not added to the bag")
        # Checked before anything reaches mcap: a time it cannot pack (uint64) fails there half-way
        # through a record and leaves the open chunk, and with it the whole file, unreadable.
        log_time_ns = _time_ns(log_time_ns, "log", topic)
        publish_time_ns = log_time_ns if publish_time_ns is None else _time_ns(publish_time_ns, "publish", topic)
        payload = bytes(data)
        self._sequence[topic] += 1
        self._mcap.add_message(channel, log_time=log_time_ns, data=payload, publish_time=publish_time_ns,
                               sequence=self._sequence[topic] & 0xFFFFFFFF)
        self.topics[topic].message_count += 1
        self._start_ns = log_time_ns if self._start_ns is None else min(self._start_ns, log_time_ns)
        self._end_ns = max(self._end_ns, log_time_ns)
        if self._chunk_started is None:
            self._chunk_started = time.monotonic()
        self.flush_if_due()

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return sum(t.message_count for t in self.topics.values())

    def flush_if_due(self) -> bool:
        """Write the open chunk if it is older than ``max_chunk_age``; True if flushed."""
        if (self.max_chunk_age is not None and self._chunk_started is not None
                and time.monotonic() - self._chunk_started >= self.max_chunk_age):
            self.flush()
            return True
        return False

    def flush(self) -> None:
        """Write the open chunk to disk now (no-op when empty)."""
        self._check_open()
        self._mcap.flush()  # finishes the open chunk (with its message indexes) and writes it
        self._chunk_started = None

    # -- closing ------------------------------------------------------------------------
    def metadata(self) -> dict:
        """The rosbag2 ``rosbag2_bagfile_information`` map for what was written."""
        start = self._start_ns or 0
        end = self._end_ns if self._start_ns is not None else 0
        rel = self.file_path.name
        return layout.bag_metadata(list(self.topics.values()), [(rel, start, end - start, self.message_count)],
                                   start, end, self.custom_data)

    def close(self) -> None:
        """Finish the file: rosbag2 metadata record, summary, footer; metadata.yaml for a directory."""
        if self.closed:
            return
        info = self.metadata()
        text = layout.dump_metadata(info)
        try:
            self.flush()
            self.closed = True
            self._mcap.add_metadata(layout.METADATA_NAME, {layout.METADATA_KEY: layout.dump_metadata_record(info)})
            self._mcap.finish()
        finally:
            self._stream.close()
        if self.metadata_path is not None:
            with replacing(self.metadata_path) as tmp:  # metadata.yaml.tmp
                tmp.write_text(text, encoding="utf-8")

    def _check_open(self) -> None:
        if self.closed:
            raise BagError(f"{self.path} is closed")

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
