"""DDS settings every entry point applies before rclpy starts.

``CONE_PERCEPTION_DDS`` chooses (read by :func:`apply`):

* ``shm`` (default, what ``ros2 run`` / ``ros2 launch`` get): ``FASTRTPS_DEFAULT_PROFILES_FILE``
  -> ``cone_perception/config/fastdds_shm.xml`` unless the user set one (theirs always wins).
  That profile only enlarges Fast DDS's shared-memory segment (64 MiB, for 1-4 MB images between
  local processes) and keeps the standard UDPv4 transport; the discovery range is the system's
  (``ROS_AUTOMATIC_DISCOVERY_RANGE`` untouched), so rviz2 or Foxglove on a laptop see the topics
  as they see any ROS 2 node.
* ``localhost``: nothing leaves this computer: the profile
  ``cone_perception/config/fastdds_localhost_shm.xml`` (shared memory + UDPv4 on 127.0.0.1 only,
  builtin transports off) and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (``ROS_LOCALHOST_ONLY=1``
  on Humble), both set even over the user's own. The tests, ``replay --live`` and ``demo`` force
  this mode (:func:`use_localhost`), also for the node processes they start.
* ``system``: touch nothing (the car's own DDS set-up).

A node restarted after ``kill -9`` may start with a fixed participant id (:func:`with_participant_id`), so it does
not take the dead node's shared-memory port that a live peer still maps (:mod:`cone_perception.nodes._shm`).

This module does not import rclpy.
"""

from __future__ import annotations

import os
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import MutableMapping

from .errors import ConfigError
from .resources import DDS_PROFILES, dds_profile_path, user_cache_dir

MODE_VAR = "CONE_PERCEPTION_DDS"
MODES = ("shm", "localhost", "system")
DEFAULT_MODE = "shm"


def mode_of(env: MutableMapping[str, str] | None = None) -> str:
    """The DDS mode ``CONE_PERCEPTION_DDS`` asks for (default ``shm``); an unknown value is a
    :class:`~cone_perception.errors.ConfigError` naming the allowed ones."""
    env = os.environ if env is None else env
    value = env.get(MODE_VAR, "").strip().lower() or DEFAULT_MODE
    if value not in MODES:
        raise ConfigError(
            MODE_VAR, None, f"unknown value {env.get(MODE_VAR)!r}; allowed: {', '.join(MODES)} (default {DEFAULT_MODE})"
        )
    return value


def apply(env: MutableMapping[str, str] | None = None) -> dict[str, str]:
    """Set the DDS variables in ``env`` (default ``os.environ``) for the mode of :func:`mode_of`.

    Returns the variables this call set. Must run before ``rclpy.init()`` (Fast DDS reads them
    when it starts).
    """
    env = os.environ if env is None else env
    mode = mode_of(env)
    if mode == "system":
        return {}
    if mode == "shm":
        wanted = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(dds_profile_path("shm"))}
        force = False
    else:
        wanted = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(dds_profile_path("localhost"))}
        if env.get("ROS_DISTRO", "").lower() == "humble":
            wanted["ROS_LOCALHOST_ONLY"] = "1"
        else:
            wanted["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        force = True
    done = {}
    for key, value in wanted.items():
        if force or not env.get(key):
            if env.get(key) != value:
                done[key] = value
            env[key] = value
    return done


def use_localhost(env: MutableMapping[str, str] | None = None) -> dict[str, str]:
    """Force the ``localhost`` mode in ``env`` (and so in every process started from it), then apply it."""
    env = os.environ if env is None else env
    env[MODE_VAR] = "localhost"
    return apply(env)


#: The namespace of Fast DDS's XML profiles.
PROFILES_NS = "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"


def with_participant_id(participant_id: int, env: MutableMapping[str, str] | None = None,
                        folder: Path | None = None) -> Path | None:
    """Start this process's participant with id ``participant_id``: where ``FASTRTPS_DEFAULT_PROFILES_FILE`` is one
    of the package's own profiles (modes ``shm`` and ``localhost``; a user's own is never touched), write a copy of
    it with ``<participantID>`` in its default participant's ``<rtps>`` to ``folder`` (default: the user's cache,
    ``dds/``), point the variable at it and return its path; None (nothing changed) otherwise, or when the copy
    cannot be written. Must run before ``rclpy.init()``."""
    env = os.environ if env is None else env
    current = env.get("FASTRTPS_DEFAULT_PROFILES_FILE", "")
    kinds = [k for k in DDS_PROFILES if current == str(dds_profile_path(k))]
    if not kinds:
        return None
    ET.register_namespace("", PROFILES_NS)
    tree = ET.parse(current)
    rtps = tree.getroot().find(f"{{{PROFILES_NS}}}participant[@is_default_profile='true']/{{{PROFILES_NS}}}rtps")
    if rtps is None:
        return None
    for old in rtps.findall(f"{{{PROFILES_NS}}}participantID"):
        rtps.remove(old)
    node = ET.Element(f"{{{PROFILES_NS}}}participantID")
    node.text = str(int(participant_id))
    node.tail = rtps.text
    rtps.insert(0, node)
    folder = user_cache_dir() / "dds" if folder is None else Path(folder)
    out = folder / f"{Path(current).stem}.participant{int(participant_id)}.xml"
    data = ET.tostring(tree.getroot(), encoding="unicode", xml_declaration=True)
    try:
        if not out.is_file() or out.read_text(encoding="utf-8") != data:
            folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=folder, prefix=out.name, suffix=".tmp")
            try:
                with os.fdopen(fd, "w", encoding="utf-8") as f:
                    f.write(data)
                os.replace(tmp, out)
            except OSError:
                os.unlink(tmp)
                raise
    except OSError:
        return None
    env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(out)
    return out
