"""QoS profiles as rosbag2 stores them (``offered_qos_profiles`` YAML, metadata version 9).

Pure data: the ROS adapters convert to and from ``rclpy.qos.QoSProfile``. Durations are
integer nanoseconds; infinite is ``INFINITE_NS`` (2**63 - 1), written as
``{sec: 9223372036, nsec: 854775807}`` like rosbag2 (RMW_DURATION_INFINITE).
"""
from __future__ import annotations

from dataclasses import dataclass

import yaml

from .errors import BagError

INFINITE_NS = 2**63 - 1
HISTORY = ("system_default", "keep_last", "keep_all", "unknown")
RELIABILITY = ("system_default", "reliable", "best_effort", "unknown", "best_available")
DURABILITY = ("system_default", "transient_local", "volatile", "unknown", "best_available")
LIVELINESS = ("system_default", "automatic", "manual_by_node", "manual_by_topic", "unknown", "best_available")
KEYS = ("history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
        "liveliness_lease_duration", "avoid_ros_namespace_conventions")


@dataclass(frozen=True)
class Qos:
    """One offered QoS profile; policy names are rosbag2's lower-case enum names.

    Durations (deadline_ns, lifespan_ns, liveliness_lease_ns) are in nanoseconds; 0 means
    "default" and INFINITE_NS infinite. The enum order matches rmw's numeric values.
    """

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline_ns: int = INFINITE_NS
    lifespan_ns: int = INFINITE_NS
    liveliness: str = "automatic"
    liveliness_lease_ns: int = INFINITE_NS
    avoid_ros_namespace_conventions: bool = False

    def __post_init__(self) -> None:
        for value, allowed, key in ((self.history, HISTORY, "history"), (self.reliability, RELIABILITY, "reliability"),
                                    (self.durability, DURABILITY, "durability"),
                                    (self.liveliness, LIVELINESS, "liveliness")):
            if value not in allowed:
                raise BagError(f"bad QoS {key} {value!r}: expected one of {', '.join(allowed)}")
        if self.depth < 0:
            raise BagError(f"bad QoS depth {self.depth}")

    def to_dict(self) -> dict:
        """The rosbag2 YAML map (all nine keys)."""
        return {"history": self.history, "depth": int(self.depth), "reliability": self.reliability,
                "durability": self.durability, "deadline": _dur(self.deadline_ns), "lifespan": _dur(self.lifespan_ns),
                "liveliness": self.liveliness, "liveliness_lease_duration": _dur(self.liveliness_lease_ns),
                "avoid_ros_namespace_conventions": bool(self.avoid_ros_namespace_conventions)}

    @classmethod
    def from_dict(cls, d: dict) -> Qos:
        """Inverse of ``to_dict``; also accepts rosbag2 v8 integer enums."""
        missing = [k for k in KEYS if k not in d]
        if missing:
            raise BagError(f"QoS profile lacks {', '.join(missing)}")
        return cls(history=_enum(d["history"], HISTORY), depth=int(d["depth"]),
                   reliability=_enum(d["reliability"], RELIABILITY), durability=_enum(d["durability"], DURABILITY),
                   deadline_ns=_ns(d["deadline"]), lifespan_ns=_ns(d["lifespan"]),
                   liveliness=_enum(d["liveliness"], LIVELINESS), liveliness_lease_ns=_ns(d["liveliness_lease_duration"]),
                   avoid_ros_namespace_conventions=bool(d["avoid_ros_namespace_conventions"]))


def _dur(ns: int) -> dict[str, int]:
    ns = min(int(ns), INFINITE_NS)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _ns(d: dict) -> int:
    try:
        return min(int(d["sec"]) * 1_000_000_000 + int(d["nsec"]), INFINITE_NS)
    except (KeyError, TypeError, ValueError):
        raise BagError(f"bad QoS duration {d!r}: expected {{sec, nsec}}") from None


def _enum(value: object, names: tuple[str, ...]) -> str:
    if isinstance(value, int) and 0 <= value < len(names):
        return names[value]
    if isinstance(value, str) and value.lower() in names:
        return value.lower()
    raise BagError(f"bad QoS value {value!r}: expected one of {', '.join(names)}")


def dump_qos(profiles: list[Qos]) -> str:
    """``offered_qos_profiles`` YAML string (a list, one map per publisher; "[]" when none)."""
    if not profiles:
        return "[]"
    return yaml.safe_dump([p.to_dict() for p in profiles], default_flow_style=False, sort_keys=False).rstrip("\n")


def parse_qos(text: str) -> list[Qos]:
    """Parse an ``offered_qos_profiles`` YAML string; BagError on malformed input."""
    if not text or not text.strip():
        return []
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise BagError(f"offered_qos_profiles is not YAML: {err}") from None
    if data is None:
        return []
    if not isinstance(data, list) or not all(isinstance(d, dict) for d in data):
        raise BagError("offered_qos_profiles must be a YAML list of maps")
    return [Qos.from_dict(d) for d in data]


def playback_qos(offers: list[Qos], default_depth: int = 100) -> Qos:
    """QoS to republish with, adapted from the recorded offers (rosbag2's rule).

    Reliable only if every offer was reliable, transient_local only if every offer was;
    keep_last with the largest recorded depth (``default_depth`` when unknown; 1 for
    latched topics with unknown depth).
    """
    if not offers:
        return Qos(depth=default_depth)
    reliable = all(o.reliability == "reliable" for o in offers)
    latched = all(o.durability == "transient_local" for o in offers)
    depth = max((o.depth for o in offers if o.history == "keep_last"), default=0)
    if depth <= 0:
        depth = 1 if latched else default_depth
    return Qos(history="keep_last", depth=depth, reliability="reliable" if reliable else "best_effort",
               durability="transient_local" if latched else "volatile")


def from_profile(profile: object) -> Qos:
    """Qos from an ``rclpy.qos.QoSProfile``-like object (duck-typed; this module never imports rclpy).

    Enum members are read by ``.name`` (e.g. KEEP_LAST), durations by ``.nanoseconds``.
    """
    def name(attr: str) -> str:
        return str(getattr(getattr(profile, attr), "name", getattr(profile, attr))).lower()

    def ns(attr: str) -> int:
        return int(getattr(getattr(profile, attr), "nanoseconds", 0))

    return Qos(history=name("history"), depth=int(getattr(profile, "depth", 0) or 0), reliability=name("reliability"),
               durability=name("durability"), deadline_ns=ns("deadline"), lifespan_ns=ns("lifespan"),
               liveliness=name("liveliness"), liveliness_lease_ns=ns("liveliness_lease_duration"),
               avoid_ros_namespace_conventions=bool(getattr(profile, "avoid_ros_namespace_conventions", False)))
