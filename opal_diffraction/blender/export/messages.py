"""The export's warnings: what the core cannot render exactly, each message once, in first-seen order."""

from __future__ import annotations

__all__ = ["Warnings"]


class Warnings:
    """Collects warnings once each, in order; call it with a message."""

    def __init__(self):
        self.items: list[str] = []
        self._seen: set[str] = set()

    def __call__(self, message: str) -> None:
        if message not in self._seen:
            self._seen.add(message)
            self.items.append(message)
