"""DDS modes (``CONE_PERCEPTION_DDS``): what each sets, the user's own profile, bad values. No rclpy."""

from __future__ import annotations

import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

from cone_perception import ros_env
from cone_perception.errors import ConfigError
from cone_perception.resources import dds_profile_path

NS = {"p": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}


def test_default_mode_enlarges_shm_and_keeps_the_system_discovery_range():
    env = {"ROS_DISTRO": "jazzy"}
    done = ros_env.apply(env)
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(dds_profile_path("shm"))
    assert "ROS_AUTOMATIC_DISCOVERY_RANGE" not in env and "ROS_LOCALHOST_ONLY" not in env
    assert done == {"FASTRTPS_DEFAULT_PROFILES_FILE": str(dds_profile_path("shm"))}


def test_a_users_own_profile_always_wins_in_the_default_mode():
    env = {"FASTRTPS_DEFAULT_PROFILES_FILE": "/home/team/dds.xml", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    assert ros_env.apply(env) == {}
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == "/home/team/dds.xml"
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"


@pytest.mark.parametrize("distro, var", [("jazzy", "ROS_AUTOMATIC_DISCOVERY_RANGE"), ("humble", "ROS_LOCALHOST_ONLY")])
def test_localhost_mode_keeps_everything_on_this_computer(distro, var):
    env = {"ROS_DISTRO": distro, "CONE_PERCEPTION_DDS": "localhost",
           "FASTRTPS_DEFAULT_PROFILES_FILE": "/home/team/dds.xml", var: "0"}
    ros_env.apply(env)
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(dds_profile_path("localhost"))  # forced, even over the user's
    assert env[var] == {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_LOCALHOST_ONLY": "1"}[var]


def test_use_localhost_marks_the_environment_for_child_processes():
    env = {"CONE_PERCEPTION_DDS": "system"}
    ros_env.use_localhost(env)
    assert env["CONE_PERCEPTION_DDS"] == "localhost"
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"


def test_the_test_run_itself_is_localhost_only():
    assert os.environ["CONE_PERCEPTION_DDS"] == "localhost"  # tests/conftest.py
    assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(dds_profile_path("localhost"))
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"


def test_system_mode_touches_nothing():
    env = {"CONE_PERCEPTION_DDS": "System"}
    assert ros_env.apply(env) == {} and env == {"CONE_PERCEPTION_DDS": "System"}


def test_unknown_mode_is_a_clear_error_naming_the_allowed_values():
    with pytest.raises(ConfigError, match="CONE_PERCEPTION_DDS.*'lan'.*shm, localhost, system"):
        ros_env.apply({"CONE_PERCEPTION_DDS": "lan"})


def test_a_node_with_an_unknown_mode_stops_with_one_line():
    env = dict(os.environ, CONE_PERCEPTION_DDS="lan")
    p = subprocess.run([sys.executable, "-c", "import cone_perception.nodes._common"], env=env,
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 1
    assert "Traceback" not in p.stderr
    assert "CONE_PERCEPTION_DDS" in p.stderr and "shm, localhost, system" in p.stderr


def _transports(kind: str) -> dict[str, ET.Element]:
    root = ET.parse(dds_profile_path(kind)).getroot()
    return {t.findtext("p:transport_id", namespaces=NS): t for t in root.iterfind(".//p:transport_descriptor", NS)}


def test_profiles_shm_segment_and_udp_reach():
    for kind in ("shm", "localhost"):
        tr = _transports(kind)
        shm = [t for t in tr.values() if t.findtext("p:type", namespaces=NS) == "SHM"]
        assert len(shm) == 1 and int(shm[0].findtext("p:segment_size", namespaces=NS)) >= 32 * 2**20
        udp = [t for t in tr.values() if t.findtext("p:type", namespaces=NS) == "UDPv4"]
        assert len(udp) == 1
        allow = [a.text for a in udp[0].iterfind(".//p:address", NS)]
        assert allow == (["127.0.0.1"] if kind == "localhost" else [])  # shm: every interface, as the builtin one
