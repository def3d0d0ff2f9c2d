"""Constants and the rosbag2 metadata map shared by the writer, reader and recovery.

One bag is one MCAP file in the rosbag2 layout: profile ``ros2``, schemas ``pkg/msg/Type``
(encoding ``ros2msg``), channels with encoding ``cdr`` and metadata
``offered_qos_profiles`` + ``topic_type_hash``, and a ``rosbag2`` metadata record holding
``serialized_metadata`` (the metadata.yaml map, version 9, without its top key). Times are integer ns.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import yaml

from .qos import Qos

PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
METADATA_NAME = "rosbag2"
METADATA_KEY = "serialized_metadata"
METADATA_VERSION = 9
STORAGE_ID = "mcap"
ROS_DISTRO = "jazzy"


@dataclass
class TopicInfo:
    """One recorded topic: name, type ``pkg/msg/Type``, definition text, RIHS01 hash, offers, count."""

    name: str
    type: str
    definition: str = ""
    type_hash: str = ""
    offered_qos: list[Qos] = field(default_factory=list)
    message_count: int = 0
    serialization_format: str = MESSAGE_ENCODING


def bag_metadata(topics: list[TopicInfo], files: list[tuple[str, int, int, int]], start_ns: int, end_ns: int,
                 custom_data: dict[str, str] | None = None) -> dict:
    """The ``rosbag2_bagfile_information`` map (metadata.yaml version 9).

    files: (relative path, start ns, duration ns, message count) per MCAP file. In version 9
    ``offered_qos_profiles`` is a list of maps here (a YAML string only in channel metadata).
    """
    count = sum(t.message_count for t in topics)
    return {
        "version": METADATA_VERSION,
        "storage_identifier": STORAGE_ID,
        "duration": {"nanoseconds": max(0, end_ns - start_ns)},
        "starting_time": {"nanoseconds_since_epoch": start_ns},
        "message_count": count,
        "topics_with_message_count": [
            {"topic_metadata": {"name": t.name, "type": t.type, "serialization_format": t.serialization_format,
                                "offered_qos_profiles": [q.to_dict() for q in t.offered_qos],
                                "type_description_hash": t.type_hash},
             "message_count": t.message_count} for t in topics],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [f[0] for f in files],
        "files": [{"path": p, "starting_time": {"nanoseconds_since_epoch": s}, "duration": {"nanoseconds": d},
                   "message_count": n} for p, s, d, n in files],
        "custom_data": custom_data or {},
        "ros_distro": ROS_DISTRO,
    }


def dump_metadata(info: dict) -> str:
    """YAML text of metadata.yaml: the map under its ``rosbag2_bagfile_information`` key."""
    return yaml.safe_dump({"rosbag2_bagfile_information": info}, default_flow_style=False, sort_keys=False)


def dump_metadata_record(info: dict) -> str:
    """YAML text of the MCAP ``rosbag2`` record's ``serialized_metadata``: the bare map, as
    rosbag2's MCAP plugin writes it (``convert<BagMetadata>::encode``) and reads it back (a
    ``version`` key at the top; under the file's top key `ros2 bag info` would find none)."""
    return yaml.safe_dump(info, default_flow_style=False, sort_keys=False)
