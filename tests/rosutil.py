"""Helpers for tests with live rclpy nodes (in-process and as separate processes)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

BIN = Path(sys.executable).parent


def spin_until(executor: SingleThreadedExecutor, cond: Callable[[], bool], timeout_s: float = 10.0) -> bool:
    """Spin ``executor`` until ``cond()`` is true or ``timeout_s`` passes; returns ``cond()``."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return True
        executor.spin_once(timeout_sec=0.05)
    return cond()


def start_node_process(executable: str, *ros_args: str) -> subprocess.Popen:
    """Start a node executable of this venv with ``--ros-args ...``; stderr/stdout captured."""
    cmd = [str(BIN / executable)]
    if ros_args:
        cmd += ["--ros-args", *ros_args]
    return subprocess.Popen(cmd, env=dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def stop_process(p: subprocess.Popen, timeout_s: float = 10.0) -> str:
    """SIGINT the process, wait, return its output."""
    if p.poll() is None:
        p.send_signal(2)
        try:
            p.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            p.kill()
    out, _ = p.communicate()
    return out or ""


class RosFixture:
    """An rclpy context + executor for one test; nodes added are destroyed at the end."""

    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes = []

    def add(self, node):
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def node(self, name: str):
        return self.add(rclpy.create_node(name, context=self.context))

    def spin_until(self, cond: Callable[[], bool], timeout_s: float = 10.0) -> bool:
        return spin_until(self.executor, cond, timeout_s)

    def close(self) -> None:
        for n in self.nodes:
            self.executor.remove_node(n)
            n.destroy_node()
        self.executor.shutdown()
        rclpy.shutdown(context=self.context)


class Inbox:
    """A subscription callback that keeps every message it gets."""

    def __init__(self) -> None:
        self.msgs = []

    def __call__(self, m) -> None:
        self.msgs.append(m)


@pytest.fixture
def ros():
    """A :class:`RosFixture` for one test (``from rosutil import ros`` makes it a fixture of the module)."""
    r = RosFixture()
    yield r
    r.close()
