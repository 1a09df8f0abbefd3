"""Names made unique: rigs' bones, BVH joints and batch jobs use one rule."""

from __future__ import annotations

from collections.abc import Callable, Iterable

__all__ = ["deduplicated"]


def deduplicated(names: Iterable[str], mark: Callable[[int], str]) -> tuple[str, ...]:
    """``names`` in order, each one already taken given ``mark(k)`` for k = 1, 2, … until
    it is free (a name that itself looks marked is never overwritten)."""
    out: list[str] = []
    taken: set[str] = set()
    for name in names:
        candidate, k = name, 0
        while candidate in taken:
            k += 1
            candidate = name + mark(k)
        out.append(candidate)
        taken.add(candidate)
    return tuple(out)
