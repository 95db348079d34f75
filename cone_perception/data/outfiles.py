"""Output files of the commands: never overwritten silently (ROS-free).

Every command that writes files checks all of them before it starts (:func:`refuse_existing`: an
existing one is an error naming it, unless ``--force``) and prints each file it wrote.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Iterable

from ..errors import ConfigError


def refuse_existing(paths: Iterable[str | Path], force: bool, command: str) -> None:
    """:class:`ConfigError` naming the first of ``paths`` that exists, unless ``force``."""
    if force:
        return
    for p in paths:
        if Path(p).exists():
            raise ConfigError(str(p), None, f"{command} would overwrite this existing file; "
                                            "remove it, choose another output or add --force")


def print_written(paths: Iterable[str | Path], command: str) -> None:
    """One line per file written: ``<command>: wrote <path>``."""
    for p in paths:
        print(f"{command}: wrote {p}")


def remove_bag(path: Path) -> None:
    """Remove a rosbag2 directory for ``--force``; anything else is left alone and refused."""
    if not (path.is_dir() and (path / "metadata.yaml").is_file()):
        raise ConfigError(str(path), None, "--force replaces only a rosbag2 directory (with metadata.yaml); "
                                           "this is something else: remove it yourself")
    shutil.rmtree(path)
