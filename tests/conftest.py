"""Shared test set-up: DDS settings, a ROS domain of this test run's own, and a user cache folder of its own."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

from cone_perception import ros_env

# Each test run gets its own ROS_DOMAIN_ID so parallel runs (developers, CI) never see each other;
# TEST_DOMAINS stay apart from a soak's own (cone_perception.replay.soak.SOAK_DOMAINS).
TEST_DOMAINS = range(100, 200)
os.environ.setdefault("ROS_DOMAIN_ID", str(TEST_DOMAINS[os.getpid() % len(TEST_DOMAINS)]))
ros_env.use_localhost()  # tests never send traffic off this computer (nor do the node processes they start)
# the ONNX cache (detector/onnx_cache.py) and TensorRT engines of this run, its node processes too: never the user's
os.environ["XDG_CACHE_HOME"] = tempfile.mkdtemp(prefix="cone_perception_test_cache_")
atexit.register(shutil.rmtree, os.environ["XDG_CACHE_HOME"], True)
