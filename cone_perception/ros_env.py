"""DDS settings every entry point applies before rclpy starts.

Images of 4 MB between processes need Fast DDS's shared-memory transport with a
large segment, and discovery must stay on this machine. :func:`apply` sets:

* ``FASTRTPS_DEFAULT_PROFILES_FILE`` -> the shipped profile
  (``cone_perception/config/fastdds_localhost_shm.xml``), unless already set;
* ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (Jazzy and newer), or
  ``ROS_LOCALHOST_ONLY=1`` on Humble (``ROS_DISTRO=humble``), unless set.

A team whose car spreads nodes over several computers sets
``CONE_PERCEPTION_DDS=system`` to keep its own DDS settings untouched.
This module does not import rclpy.
"""

from __future__ import annotations

import os
from typing import MutableMapping

from .resources import dds_profile_path

OPT_OUT_VAR = "CONE_PERCEPTION_DDS"


def apply(env: MutableMapping[str, str] | None = None) -> dict[str, str]:
    """Set the DDS variables in ``env`` (default ``os.environ``) unless opted out.

    Returns the variables this call set (empty when opted out or all were set).
    Must run before ``rclpy.init()`` (Fast DDS reads them when it starts).
    """
    env = os.environ if env is None else env
    if env.get(OPT_OUT_VAR, "").lower() in ("system", "off", "0", "false"):
        return {}
    wanted = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(dds_profile_path())}
    if env.get("ROS_DISTRO", "").lower() == "humble":
        wanted["ROS_LOCALHOST_ONLY"] = "1"
    else:
        wanted["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    done = {}
    for key, value in wanted.items():
        if not env.get(key):
            env[key] = value
            done[key] = value
    return done
