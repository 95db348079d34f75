"""Words in messages and options: counted nouns (``plural(1, "thread")`` -> ``"1 thread"``, ``plural(2, "box",
"boxes")`` -> ``"2 boxes"``) and sizes (``parse_size("960x288")`` -> ``(960, 288)``)."""

from __future__ import annotations

from .errors import ConfigError


def plural(n: int | float, noun: str, many: str | None = None) -> str:
    """``n`` and the noun, singular for exactly 1, else ``many`` (default: noun + 's')."""
    return f"{n} {noun if n == 1 else (many or noun + 's')}"


def parse_size(text: str, option: str = "--size", example: str = "WxH (e.g. 960x288)", square: bool = False) -> tuple[int, int]:
    """``"960x288"`` -> ``(960, 288)`` (``*`` works as ``x``; with ``square`` one number means a square).
    :class:`ConfigError` naming ``option`` otherwise (``example``: what the option looks like)."""
    parts = str(text).lower().replace("*", "x").split("x")
    if square and len(parts) == 1:
        parts *= 2
    try:
        a, b = (int(p) for p in parts)
    except ValueError:
        raise ConfigError(option, None, f"must look like {example}, got {text!r}") from None
    if a <= 0 or b <= 0:
        raise ConfigError(option, None, f"both numbers must be > 0, got {text!r}")
    return a, b
