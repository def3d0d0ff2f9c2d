"""tf2_msgs/msg/TFMessage written into a bag without the tf2_msgs package.

The PyPI ROS wheels have no tf2_msgs, so no node can publish /tf or /tf_static here; the
recorder writes them into the bag itself (docs/recording.md, "Frames"). What it writes is
what rosbag2 writes for a real tf2_msgs publisher on ROS 2 Jazzy:

- schema ``tf2_msgs/msg/TFMessage``, encoding ``ros2msg``: the Jazzy ``TFMessage.msg``
  (``geometry_msgs/TransformStamped[] transforms``) followed by its dependencies from the
  installed geometry_msgs/std_msgs/builtin_interfaces files (or the installed tf2_msgs
  definition where one exists: a real ROS install has it, and it is never shadowed);
- channel metadata ``topic_type_hash`` = the Jazzy RIHS01 hash of TFMessage (the value
  rosidl computes from that definition; tests/test_bag_tf.py recomputes it);
- message data: plain little-endian CDR (XCDR1), byte for byte what a TFMessage publisher
  sends.

Pure Python, no rclpy.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

from .definitions import SEPARATOR, message_definition
from .errors import BagError
from .qos import Qos

TF_TYPE = "tf2_msgs/msg/TFMessage"
TF_MSG_TEXT = "geometry_msgs/TransformStamped[] transforms\n"  # tf2_msgs/msg/TFMessage.msg of ROS 2 Jazzy
TF_TYPE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"
# what tf2_ros offers: TransformBroadcaster keep_last 100 volatile, StaticTransformBroadcaster keep_last 1 latched
TF_QOS = Qos(depth=100)
TF_STATIC_QOS = Qos(depth=1, durability="transient_local")
_CDR_LE = b"\x00\x01\x00\x00"  # encapsulation: plain CDR, little endian


@dataclass(frozen=True)
class Transform:
    """One geometry_msgs/TransformStamped: the pose of `child` in `parent` at stamp_ns
    (translation m, rotation quaternion x, y, z, w)."""

    parent: str
    child: str
    stamp_ns: int
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        if not self.parent or not self.child or self.parent == self.child:
            raise BagError(f"transform needs two different frame names, got {self.parent!r} -> {self.child!r}")
        values = (*self.translation, *self.rotation)
        if len(self.translation) != 3 or len(self.rotation) != 4 or not all(math.isfinite(v) for v in values):
            raise BagError(f"transform {self.parent} -> {self.child}: bad translation/rotation {values}")
        if self.stamp_ns < 0:
            raise BagError(f"transform {self.parent} -> {self.child}: negative stamp {self.stamp_ns}")


@lru_cache(maxsize=1)
def tf_definition() -> tuple[str, str]:
    """(schema text, type hash) of tf2_msgs/msg/TFMessage: the installed one where tf2_msgs is
    installed, else built from the Jazzy TFMessage.msg and the installed geometry_msgs."""
    try:
        installed = message_definition(TF_TYPE)
        return installed.text, installed.type_hash or TF_TYPE_HASH
    except BagError:
        pass
    stamped = message_definition("geometry_msgs/msg/TransformStamped")
    text = TF_MSG_TEXT + SEPARATOR + "\nMSG: geometry_msgs/TransformStamped\n" + stamped.text
    return text, TF_TYPE_HASH


class _Cdr:
    def __init__(self) -> None:
        self.buf = bytearray()

    def align(self, n: int) -> None:
        self.buf += b"\x00" * (-len(self.buf) % n)

    def put(self, fmt: str, *values) -> None:
        self.align(struct.calcsize(fmt[-1]))
        self.buf += struct.pack("<" + fmt, *values)

    def string(self, s: str) -> None:
        data = s.encode("utf-8")
        self.put("I", len(data) + 1)
        self.buf += data + b"\x00"


def encode_tf_message(transforms: Sequence[Transform]) -> bytes:
    """Serialized CDR of a tf2_msgs/msg/TFMessage holding the transforms."""
    c = _Cdr()
    c.put("I", len(transforms))
    for t in transforms:
        sec, nsec = divmod(int(t.stamp_ns), 1_000_000_000)
        c.put("i", sec)
        c.put("I", nsec)
        c.string(t.parent)
        c.string(t.child)
        c.put("3d", *(float(v) for v in t.translation))
        c.put("4d", *(float(v) for v in t.rotation))
    return _CDR_LE + bytes(c.buf)
