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

A port left that way is where a restart loses time: Fast DDS numbers a participant's listening ports from its
participant id, the first free one, and a node restarted after ``kill -9`` takes the dead one's id (its locks and
UDP sockets died with it), so it opens the dead node's port. A live peer's writers go on pushing into their old
mapping of it and hear from the new node only after their health check on it times out (about 1 s, at times
2-3 s). :func:`dead_ports_in_use` names such ports and :func:`free_participant_id` the first participant id
whose ports are neither in ``/dev/shm`` nor bound; the node then starts with that id
(:func:`cone_perception.ros_env.with_participant_id`).
"""

from __future__ import annotations

import fcntl
import os
import re
import socket
from dataclasses import dataclass, field
from pathlib import Path

SHM_DIR = Path("/dev/shm")
_LOCK = re.compile(r"^(fastrtps_(?:[0-9a-z]{16}|port\d{1,5}))_(el|sl)$")
#: The RTPS port mapping Fast DDS uses by default (PB + DG * domain + d + PG * participant id): the metatraffic
#: (discovery) and user-traffic unicast ports of a participant, the UDP ports and the shared-memory ports alike.
PORT_BASE, DOMAIN_GAIN, PARTICIPANT_GAIN, OFFSET_META_UNICAST, OFFSET_USER_UNICAST = 7400, 250, 2, 10, 11
#: Participant ids :func:`free_participant_id` tries (ROS 2's limit of 120 participants a domain).
MAX_PARTICIPANT_ID = 119


@dataclass
class CleanReport:
    removed: list = field(default_factory=list)  # file names removed
    in_use: int = 0  # segments and ports a live process holds or maps
    bytes_freed: int = 0
    dead_ports: list = field(default_factory=list)  # of those, the dead ones' ports a live process maps (numbers)

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


def dead_ports_in_use(shm_dir: Path = SHM_DIR) -> list[int]:
    """Numbers of the unicast listening ports (one owner: an ``_el`` lock file) whose owner is dead (every lock
    file free) that a live process still maps: those :func:`clean_stale` leaves, and a restarted node must not take
    (the module's doc). Shared ports (``_sl``: every participant listens there) are any node's, not a dead one's."""
    locks = _locks(shm_dir)
    used = mapped(shm_dir)
    return sorted(n for b, ls in locks.items() if (n := _dead_port_in_use(b, ls, used, shm_dir)) is not None)


def _dead_port_in_use(base: str, lock_names: list[str], used: set[str], shm_dir: Path) -> int | None:
    """``base``'s port number where it is a unicast port (an ``_el`` lock) whose owner is dead but a live process
    maps it (:func:`dead_ports_in_use`), else None."""
    if not (_port_in_use(base, used) and any(x.endswith("_el") for x in lock_names)):
        return None
    return None if any(held(shm_dir / x) for x in lock_names) else int(base[len("fastrtps_port"):])


def participant_ports(domain_id: int, participant_id: int) -> tuple[int, int]:
    """(metatraffic, user-traffic) unicast port of participant ``participant_id`` in ``domain_id`` (RTPS defaults)."""
    base = PORT_BASE + DOMAIN_GAIN * int(domain_id) + PARTICIPANT_GAIN * int(participant_id)
    return base + OFFSET_META_UNICAST, base + OFFSET_USER_UNICAST


def _udp_free(port: int) -> bool:
    """Whether ``port`` can be bound for UDP on every interface now (nobody listens there)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("", port))
        except OSError:
            return False
    return True


def free_participant_id(domain_id: int, shm_dir: Path = SHM_DIR, udp_free=_udp_free) -> int | None:
    """The first participant id of ``domain_id`` whose unicast ports (:func:`participant_ports`) have no
    shared-memory port in ``shm_dir`` (a live one's or a dead one's) and are free for UDP; None when none is."""
    try:
        names = set(os.listdir(shm_dir))
    except OSError:
        names = set()
    for pid in range(MAX_PARTICIPANT_ID + 1):
        ports = participant_ports(domain_id, pid)
        if ports[1] > 65535:
            break
        if any(f"fastrtps_port{p}" in names or f"fastrtps_port{p}_el" in names for p in ports):
            continue
        if all(udp_free(p) for p in ports):
            return pid
    return None


def clean_stale(shm_dir: Path = SHM_DIR) -> CleanReport:
    """Remove the files of every segment and port no live process holds (see the module's doc)."""
    rep = CleanReport()
    locks = _locks(shm_dir)
    used = mapped(shm_dir)
    for base, lock_names in sorted(locks.items()):
        if _port_in_use(base, used):  # a live writer still maps this port (see the module's doc)
            rep.in_use += 1
            if (n := _dead_port_in_use(base, lock_names, used, shm_dir)) is not None:
                rep.dead_ports.append(n)
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
