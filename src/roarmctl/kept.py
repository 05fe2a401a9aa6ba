"""``Kept``: results kept by their exact key, bounded in number (the one such store of the package)."""

from __future__ import annotations

from typing import TypeVar

V = TypeVar("V")


class Kept(dict[tuple, V]):
    """Results kept by their exact key (what the result is a function of, as bytes or plain values), at most
    ``limit``: when full, all are forgotten, so work that never repeats itself does not grow the store."""

    def __init__(self, limit: int) -> None:
        super().__init__()
        self.limit = limit

    def keep(self, key: tuple, value: V) -> V:
        """Keep ``value`` under ``key``; returns ``value``."""
        if len(self) >= self.limit:
            self.clear()
        self[key] = value
        return value
