"""Counted nouns in messages: ``plural(1, "thread")`` -> ``"1 thread"``, ``plural(2, "box", "boxes")`` -> ``"2 boxes"``."""

from __future__ import annotations


def plural(n: int | float, noun: str, many: str | None = None) -> str:
    """``n`` and the noun, singular for exactly 1, else ``many`` (default: noun + 's')."""
    return f"{n} {noun if n == 1 else (many or noun + 's')}"
