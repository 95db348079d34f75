"""Exceptions of the package.

Two families, handled differently by every entry point:

* :class:`ConfigError`: a start-up problem (calibration file, model file,
  parameters). The process stops with the message, which names the file and
  the field.
* :class:`FrameError`: one bad input message (image, boxes). The node drops
  that one frame, counts it under :attr:`FrameError.reason` and keeps running.
"""

from __future__ import annotations


class ConePerceptionError(Exception):
    """Base class of all errors raised on purpose by this package."""


class ConfigError(ConePerceptionError):
    """A configuration problem found at start-up.

    The message reads ``<source>: <field>: <what is wrong>`` so a user knows
    which file and which field to fix.
    """

    def __init__(self, source: str, field: str | None, message: str):
        self.source = str(source)
        self.field = field
        self.message = message
        where = f"{self.source}: {field}" if field else self.source
        super().__init__(f"{where}: {message}")


class FrameError(ConePerceptionError):
    """One input message that cannot be processed.

    ``reason`` is a short stable key (e.g. ``"odd_width"``) used to count
    dropped frames per cause; the message says what exactly was wrong.
    """

    def __init__(self, reason: str, message: str):
        self.reason = reason
        super().__init__(message)
