"""ROS 2 message definitions and type hashes from the installed interface files.

A definition is what rosbag2 stores as an MCAP schema with encoding ``ros2msg``: the
type's ``.msg`` text followed, for every nested type (depth first, each once), by a line
of 80 ``=``, a line ``MSG: pkg/Type`` and that type's ``.msg`` text. Interface files are
looked up in ``$AMENT_PREFIX_PATH/*/share/<pkg>/msg/<Type>.msg``; the RIHS01 type hash
comes from the generated ``share/<pkg>/msg/<Type>.json`` type description.
"""
from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from .errors import BagError

SEPARATOR = "=" * 80
PRIMITIVES = frozenset({
    "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
    "uint64", "float32", "float64", "string", "wstring", "time", "duration",
})
_TYPE_RE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)(?:/(?:msg/)?([A-Za-z][A-Za-z0-9_]*))?")


@dataclass(frozen=True)
class MessageDefinition:
    """Full definition of one message type.

    name: ``pkg/msg/Type``; text: concatenated ros2msg definition (schema data);
    type_hash: ``RIHS01_<64 hex>`` or ``""`` when no type description is installed;
    dependencies: nested types in the order they appear in ``text`` (``pkg/msg/Type``).
    """

    name: str
    text: str
    type_hash: str
    dependencies: tuple[str, ...]


def split_type_name(name: str) -> tuple[str, str, str]:
    """``pkg/msg/Type`` or ``pkg/Type`` -> (pkg, interface kind, Type); BagError if malformed."""
    parts = name.strip().split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(parts) or parts[1] not in ("msg", "srv", "action"):
        raise BagError(f"bad ROS type name {name!r}: expected pkg/msg/Type")
    return parts[0], parts[1], parts[2]


def prefixes() -> list[Path]:
    """Install prefixes from ``$AMENT_PREFIX_PATH`` (in order, existing only)."""
    return [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p and Path(p).is_dir()]


def interface_file(pkg: str, kind: str, type_: str, suffix: str) -> Path:
    """First ``<prefix>/share/<pkg>/<kind>/<type_><suffix>``; BagError listing where it looked."""
    searched = prefixes()
    for prefix in searched:
        path = prefix / "share" / pkg / kind / f"{type_}{suffix}"
        if path.is_file():
            return path
    where = ", ".join(str(p) for p in searched) or "nothing (AMENT_PREFIX_PATH is empty)"
    raise BagError(f"no {pkg}/{kind}/{type_}{suffix} under share/ of {where}")


def _field_types(text: str, pkg: str) -> list[str]:
    """Nested (non-primitive) field types of a .msg text, as ``pkg/msg/Type``, in order."""
    out: list[str] = []
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        token = line.split()[0]
        base = re.split(r"[\[<]", token, maxsplit=1)[0]
        if base in PRIMITIVES:
            continue
        m = _TYPE_RE.match(base)
        if not m:
            raise BagError(f"cannot parse field type {token!r} in {pkg}")
        if m.group(2):
            out.append(f"{m.group(1)}/msg/{m.group(2)}")
        elif base == "Header":
            out.append("std_msgs/msg/Header")
        else:  # a bare name refers to the same package
            out.append(f"{pkg}/msg/{base}")
    return out


@lru_cache(maxsize=None)
def msg_text(name: str) -> str:
    """The raw ``.msg`` text of ``pkg/msg/Type``."""
    pkg, kind, type_ = split_type_name(name)
    if kind != "msg":
        raise BagError(f"{name}: only message types (pkg/msg/Type) can be recorded")
    return interface_file(pkg, kind, type_, ".msg").read_text(encoding="utf-8")


@lru_cache(maxsize=None)
def type_hash(name: str) -> str:
    """RIHS01 hash of ``pkg/msg/Type`` from its ``.json`` type description ("" if absent)."""
    pkg, kind, type_ = split_type_name(name)
    full = f"{pkg}/{kind}/{type_}"
    try:
        path = interface_file(pkg, kind, type_, ".json")
    except BagError:
        return ""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        for entry in data.get("type_hashes", []):
            if entry.get("type_name") == full:
                return str(entry["hash_string"])
    except (ValueError, KeyError, TypeError) as err:
        raise BagError(f"unreadable type description {path}: {err}") from None
    return ""


@lru_cache(maxsize=None)
def message_definition(name: str) -> MessageDefinition:
    """Resolve ``pkg/msg/Type`` (or ``pkg/Type``) to its full ros2msg definition and hash."""
    pkg, kind, type_ = split_type_name(name)
    full = f"{pkg}/{kind}/{type_}"
    top = msg_text(full)
    order: list[str] = []
    seen = {full}

    def visit(type_name: str, text: str) -> None:
        for dep in _field_types(text, split_type_name(type_name)[0]):
            if dep in seen:
                continue
            seen.add(dep)
            order.append(dep)
            visit(dep, msg_text(dep))

    visit(full, top)
    parts = [top.rstrip("\n")]
    for dep in order:
        dpkg, _, dtype = split_type_name(dep)
        parts += [SEPARATOR, f"MSG: {dpkg}/{dtype}", msg_text(dep).rstrip("\n")]
    return MessageDefinition(full, "\n".join(parts) + "\n", type_hash(full), tuple(order))
