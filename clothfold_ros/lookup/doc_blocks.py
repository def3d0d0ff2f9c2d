"""Generated blocks in Markdown files: the text between a begin and an end marker (HTML
comments), replaced as a whole, so a report stays where the prose around it puts it."""
from __future__ import annotations

import re


def replace_block(text: str, block: str, begin: str, end: str, *, required: bool = True) -> str:
    """`text` with the part between `begin` and `end` replaced by `block`; ValueError unless
    the file holds exactly one such block (not required: a text without either marker is
    returned as it is)."""
    if not required and begin not in text and end not in text:
        return text
    pattern = re.compile(re.escape(begin) + r".*?" + re.escape(end), re.S)
    found = len(pattern.findall(text))
    if found != 1 or text.count(begin) != 1 or text.count(end) != 1:
        raise ValueError(f"need exactly one {begin} ... {end} block, found {found} "
                         f"({text.count(begin)} begin and {text.count(end)} end markers)")
    return pattern.sub(lambda _: f"{begin}\n{block}\n{end}", text, count=1)
