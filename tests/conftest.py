"""Shared test set-up: DDS settings and a ROS domain of this test run's own."""

from __future__ import annotations

import os

from cone_perception import ros_env

# Each test run gets its own ROS_DOMAIN_ID so parallel runs (developers, CI) never see each other;
# TEST_DOMAINS stay apart from a soak's own (cone_perception.replay.soak.SOAK_DOMAINS).
TEST_DOMAINS = range(100, 200)
os.environ.setdefault("ROS_DOMAIN_ID", str(TEST_DOMAINS[os.getpid() % len(TEST_DOMAINS)]))
ros_env.use_localhost()  # tests never send traffic off this computer (nor do the node processes they start)
