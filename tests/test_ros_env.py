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


@pytest.mark.parametrize("kind", ["shm", "localhost"])
def test_a_restart_can_take_a_participant_id_of_its_own(tmp_path, kind):
    shipped = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(dds_profile_path(kind))}
    env = dict(shipped)
    out = ros_env.with_participant_id(7, env, folder=tmp_path)
    assert out is not None and out.parent == tmp_path and env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(out)
    new, old = ET.parse(out).getroot(), ET.parse(dds_profile_path(kind)).getroot()
    assert new.tag == old.tag == "{%s}profiles" % NS["p"]  # the default namespace kept (Fast DDS reads plain names)
    assert "ns0:" not in out.read_text()
    rtps = new.find("p:participant[@is_default_profile='true']/p:rtps", NS)
    assert [e.text for e in rtps.findall("p:participantID", NS)] == ["7"]
    # everything else as shipped: the transports, the discovery settings
    strip = [e for e in rtps if e.tag != "{%s}participantID" % NS["p"]]
    assert [ET.tostring(e) for e in strip] == [ET.tostring(e) for e in old.find("p:participant/p:rtps", NS)]
    assert [ET.tostring(e) for e in new.find("p:transport_descriptors", NS)] == \
        [ET.tostring(e) for e in old.find("p:transport_descriptors", NS)]
    # again with another id: its own file, the first one unchanged; the same id again: the same file
    assert ros_env.with_participant_id(8, dict(shipped), folder=tmp_path) not in (out, None)
    assert ros_env.with_participant_id(7, dict(shipped), folder=tmp_path) == out
    assert ros_env.with_participant_id(9, env, folder=tmp_path) is None  # the copy is not the package's own


def test_a_users_own_profile_is_never_rewritten(tmp_path):
    env = {"FASTRTPS_DEFAULT_PROFILES_FILE": "/home/team/dds.xml"}
    assert ros_env.with_participant_id(3, env, folder=tmp_path) is None
    assert env == {"FASTRTPS_DEFAULT_PROFILES_FILE": "/home/team/dds.xml"} and not list(tmp_path.iterdir())


def test_an_unwritable_folder_leaves_the_profile_as_it_was(tmp_path):
    (tmp_path / "file").write_text("")
    env = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(dds_profile_path("localhost"))}
    assert ros_env.with_participant_id(3, env, folder=tmp_path / "file" / "dds") is None
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(dds_profile_path("localhost"))
