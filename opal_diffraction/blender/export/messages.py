"""The export's warnings: what the core cannot render exactly, each message once, in first-seen
order; and the tally of what was left out (hair, point clouds, volumes), reported with counts."""

from __future__ import annotations

from collections import defaultdict

__all__ = ["Warnings", "Skipped"]


class Warnings:
    """Collects warnings once each, in order; call it with a message."""

    def __init__(self):
        self.items: list[str] = []
        self._seen: set[str] = set()

    def __call__(self, message: str) -> None:
        if message not in self._seen:
            self._seen.add(message)
            self.items.append(message)


#: What is skipped, by kind: (the words for it, the words for its elements).
SKIPPED_KINDS = {
    "CURVES": ("hair curves", "strands"),
    "HAIR": ("hair particle systems", "strands"),
    "POINTCLOUD": ("point clouds", "points"),
    "VOLUME": ("volume objects", ""),
    "GREASEPENCIL": ("grease pencil objects", ""),
    "GPENCIL": ("grease pencil objects", ""),
}


class Skipped:
    """Objects and particle systems the core cannot render, counted per kind: how many, on which
    objects (the first few named) and how many strands or points they hold."""

    def __init__(self):
        self.count: dict[str, int] = defaultdict(int)
        self.elements: dict[str, int] = defaultdict(int)
        self.names: dict[str, list[str]] = defaultdict(list)

    def add(self, kind: str, name: str, elements: int = 0) -> None:
        self.count[kind] += 1
        self.elements[kind] += int(elements)
        if name not in self.names[kind]:
            self.names[kind].append(name)

    def report(self, warn) -> None:
        """One warning per kind, e.g. "hair particle systems are not rendered: 2 skipped (on 'Cube';
        100 strands)"."""
        for kind, n in self.count.items():
            what, unit = SKIPPED_KINDS.get(kind, (f"{kind.lower()} objects", ""))
            names = self.names[kind]
            where = ", ".join(f"'{x}'" for x in names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
            detail = ("on " if kind == "HAIR" else "") + where
            if unit:
                detail += f"; {self.elements[kind]} {unit}"
            warn(f"{what} are not rendered: {n} skipped ({detail})")
