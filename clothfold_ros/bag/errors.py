"""Errors raised by the bag core."""
from __future__ import annotations


class BagError(Exception):
    """A bag cannot be read, written or recovered; the message says why and what to do."""
