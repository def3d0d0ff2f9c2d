"""Decoding a bag the way a fresh user's tool would: the independent `rosbags` library with an
EMPTY type store and only the message definitions stored in the bag."""
from __future__ import annotations

from pathlib import Path

from rosbags.rosbag2.storage_mcap import McapReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore


def rosbags_messages(path: Path) -> list[tuple[str, int, object]]:
    """(topic, log time ns, decoded message) of every message of a single .mcap, in file order."""
    store = get_typestore(Stores.EMPTY)
    reader = McapReader(path)
    reader.open()
    try:
        for c in reader.connections:
            store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        return [(c.topic, t, store.deserialize_cdr(raw, c.msgtype))
                for c, t, raw in reader.messages(reader.connections)]
    finally:
        reader.close()
