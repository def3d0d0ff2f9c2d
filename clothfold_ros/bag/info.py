"""``clothfold bag info``: a summary of a bag like ``ros2 bag info``."""
from __future__ import annotations

import datetime as _dt
import os

from .reader import BagReader


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{n} B"
        n /= 1024
    return f"{n} B"


def _stamp(ns: int) -> str:
    t = _dt.datetime.fromtimestamp(ns / 1e9, tz=_dt.timezone.utc)
    return f"{t:%Y-%m-%d %H:%M:%S.%f} UTC ({ns / 1e9:.9f})"


def _qos_text(info) -> str:
    if not info.offered_qos:
        return "none stored"
    return ", ".join(f"{q.reliability}/{q.durability}/{q.history}" + (f"({q.depth})" if q.depth else "")
                     for q in info.offered_qos)


def bag_info(path: str | os.PathLike) -> str:
    """Multi-line description: files, size, duration (s), times, counts, topics with type/QoS/hash."""
    with BagReader(path) as bag:
        meta = bag.metadata
        lines = [
            f"Files:             {', '.join(str(f) for f in bag.files)}",
            f"Bag size:          {_size(bag.size_bytes)}",
            f"Storage id:        mcap (profile ros2, written by {bag.library or '?'})",
            f"ROS distro:        {meta.get('ros_distro', '?')} "
            f"(rosbag2 metadata {'version ' + str(meta.get('version')) if meta else 'record missing'})",
            f"Duration:          {bag.duration_ns / 1e9:.3f} s",
            f"Start:             {_stamp(bag.start_ns)}",
            f"End:               {_stamp(bag.end_ns)}",
            f"Messages:          {bag.message_count}",
            f"Chunks:            {bag.chunk_count}",
            f"Topics:            {len(bag.topics)}",
        ]
        width = max((len(t) for t in bag.topics), default=0)
        for name in sorted(bag.topics):
            t = bag.topics[name]
            lines.append(f"  {name:<{width}}  {t.type}  count {t.message_count}  qos {_qos_text(t)}  "
                         f"hash {t.type_hash[:20] + '...' if t.type_hash else 'none'}")
        custom = meta.get("custom_data") or {}
        if not isinstance(custom, dict):
            custom = {"(not a map)": custom}
        for key, value in sorted(custom.items()):
            lines.append(f"custom_data {key}: {value}")
    return "\n".join(lines)
