"""MCAP bags in the rosbag2 layout: definitions, QoS, writing, reading, recovery, filtering, info.

Pure Python (never imports rclpy). Times are integer nanoseconds since the epoch; message
data is serialized CDR exactly as a ``raw=True`` subscription delivers it.
"""
from .definitions import MessageDefinition, message_definition, type_hash
from .errors import BagError
from .filter import FilterReport, filter_bag
from .info import bag_info
from .layout import TopicInfo
from .qos import Qos, dump_qos, from_profile, parse_qos, playback_qos
from .reader import BagMessage, BagReader
from .recover import RecoveryReport, recover
from .writer import BagWriter

__all__ = ["BagError", "BagMessage", "FilterReport", "BagReader", "BagWriter", "MessageDefinition", "Qos", "RecoveryReport",
           "TopicInfo", "bag_info", "dump_qos", "filter_bag", "from_profile", "message_definition", "parse_qos", "playback_qos", "recover",
           "type_hash"]
