"""Stale Fast DDS shared-memory files of dead processes: find them and remove them safely (ROS-free).

Fast DDS's shared-memory transport keeps, in ``/dev/shm``, per participant a data segment
``fastrtps_<16 hex>`` and per listening port a segment ``fastrtps_port<N>`` with its named mutex
``sem.fastrtps_port<N>_mutex``. Each has a lock file (``..._el`` exclusive, ``..._sl`` shared) that
its owner holds with ``flock`` while it lives: the kernel releases the lock when the process dies,
however it dies. A process killed with ``kill -9`` cannot remove its files, so they stay (70 MB
per node with the package's 64 MiB segment) and a restarted node may open the dead one's port.

:func:`clean_stale` removes the files of a segment or port only when it can take the exclusive lock
on each of its lock files itself, that is when no live process holds one, and it removes them while
it holds the locks, so no process can take the port in between. A *port* is also left while a live
process maps it (``/proc/<pid>/maps``): a live writer still sending to a dead reader's port would go
on writing into the unlinked segment, and a restarted node that takes the same port number would
never hear from it; Fast DDS reuses or renews such a port itself, and a later start removes it once
nobody maps it. A dead process's *data segment* is removed at once (the 64 MiB): live readers have it
mapped already and keep their mapping. Files without a lock file are left alone (a process creating
its segment has not locked it yet). ``fastdds shm clean`` checks the locks only, between the check and
the removal unlocked. (Fast DDS itself may recreate a live process's port under it when a restarted
peer finds it slow to answer its health check, with or without this clean-up: docs/robustness.md.)
"""

from __future__ import annotations

import fcntl
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

SHM_DIR = Path("/dev/shm")
_LOCK = re.compile(r"^(fastrtps_(?:[0-9a-z]{16}|port\d{1,5}))_(el|sl)$")


@dataclass
class CleanReport:
    removed: list = field(default_factory=list)  # file names removed
    in_use: int = 0  # segments and ports a live process holds or maps
    bytes_freed: int = 0

    def line(self) -> str:
        n = len({_base(f) for f in self.removed if _LOCK.match(f)})
        return (f"removed {n} stale Fast DDS shared-memory segment(s)/port(s) of dead processes "
                f"({self.bytes_freed / 2**20:.0f} MiB); {self.in_use} in use left alone")


def _base(lock_name: str) -> str:
    return lock_name[:-3]


def _files_of(base: str) -> list[str]:
    """The files of a segment or port besides its lock files."""
    files = [base]
    if base.startswith("fastrtps_port"):
        files.append(f"sem.{base}_mutex")
    return files


def _port_in_use(base: str, used: set[str]) -> bool:
    return base.startswith("fastrtps_port") and any(f in used for f in _files_of(base))


def held(lock_file: Path) -> bool:
    """True when a live process holds ``lock_file``'s flock (or it cannot be checked)."""
    try:
        fd = os.open(lock_file, os.O_RDONLY)
    except OSError:
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)  # releases the lock if taken
    return False


def mapped(shm_dir: Path = SHM_DIR) -> set[str]:
    """Names of the files in ``shm_dir`` that a live process (whose maps this user may read) has mapped."""
    prefix = str(shm_dir).rstrip("/") + "/"
    out = set()
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/maps", encoding="utf-8", errors="replace") as f:
                for line in f:
                    i = line.find(prefix)
                    if i >= 0 and not line.rstrip().endswith("(deleted)"):
                        out.add(line[i + len(prefix):].rstrip("\n"))
        except OSError:  # gone, or another user's
            continue
    return out


def _locks(shm_dir: Path) -> dict[str, list[str]]:
    """``segment or port -> its lock file names`` in ``shm_dir`` (empty where it cannot be listed)."""
    try:
        names = os.listdir(shm_dir)
    except OSError:
        return {}
    locks: dict[str, list[str]] = {}
    for n in names:
        m = _LOCK.match(n)
        if m:
            locks.setdefault(m.group(1), []).append(n)
    return locks


def stale(shm_dir: Path = SHM_DIR) -> list[str]:
    """Names of the segments and ports (``fastrtps_...``) whose every lock file is free: their owners are dead."""
    locks = _locks(shm_dir)
    used = mapped(shm_dir)
    return sorted(b for b, ls in locks.items() if not any(held(shm_dir / x) for x in ls) and not _port_in_use(b, used))


def clean_stale(shm_dir: Path = SHM_DIR) -> CleanReport:
    """Remove the files of every segment and port no live process holds (see the module's doc)."""
    rep = CleanReport()
    locks = _locks(shm_dir)
    used = mapped(shm_dir)
    for base, lock_names in sorted(locks.items()):
        if _port_in_use(base, used):  # a live writer still maps this port (see the module's doc)
            rep.in_use += 1
            continue
        fds = []
        try:
            for ln in lock_names:  # take every lock file of it; any held: in use
                fd = os.open(shm_dir / ln, os.O_RDONLY)
                fds.append(fd)
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            rep.in_use += 1
        else:
            for f in _files_of(base) + lock_names:  # removed while the locks are held
                p = shm_dir / f
                try:
                    size = p.stat().st_size
                    p.unlink()
                except OSError:
                    continue
                rep.removed.append(f)
                rep.bytes_freed += size
        finally:
            for fd in fds:
                os.close(fd)
    return rep
