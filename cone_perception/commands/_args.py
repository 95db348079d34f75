"""Argument types and options shared by several commands (argparse only: no command imports another)."""

from __future__ import annotations

import argparse

from ..errors import ConfigError


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


def size_arg(text: str) -> tuple[int, int]:
    """argparse type of a model input ``WxH`` (``--imgsz``); a single number means a square."""
    try:
        return parse_size(text, "--imgsz", "WxH (e.g. 960x288)", square=True)
    except ConfigError as e:
        raise argparse.ArgumentTypeError(e.message) from None


def parse_crop(text: str) -> tuple[int, ...]:
    try:
        vals = tuple(int(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"crop must be V0,V1 or V0,V1,U0,U1 (integers), got {text!r}") from None
    if len(vals) not in (2, 4):
        raise argparse.ArgumentTypeError(f"crop must be V0,V1 or V0,V1,U0,U1, got {text!r}")
    return vals
