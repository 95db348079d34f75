"""Live replay: play a bag's camera frames (raw CDR) into live nodes and record what they publish.

The nodes run as separate processes, exactly as on the car: either the three nodes
(``driver_adapter``, ``detection``, ``mapping``) or the fused ``pipeline`` node. This process
plays the frames and records ``cone_boxes`` and ``/cones`` by header stamp. With ``track`` the
tracker runs too (the ``pipeline`` node with ``track: true``, or a ``cone_tracker`` node after the
three nodes; motion from the cones) and ``/cones/tracked`` is recorded as well.

Pacing: ``lockstep`` sends the next frame when the last one's ``/cones`` came back (as fast as
the pipeline takes them; nothing is dropped for being late; the latency of each frame is the
time from publishing the frame to receiving its ``/cones``), or ``rate`` at the recorded rate.
"""

from __future__ import annotations

from .. import ros_env

ros_env.use_localhost()  # replay --live and demo keep all traffic on this computer, node processes too

from ._common import QOS_DATA, run_node  # noqa: E402,F401,I001 (sets DDS env first)

import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CompressedImage, Image, PointCloud2

from ..data import bagio
from ..errors import ConfigError
from ..data.bags import BOXES_TOPIC, CONES_TOPIC, find_image_topic
from . import _msgs

MODES = {"separate": ("driver_adapter", "detection", "mapping"), "fused": ("pipeline",)}
TRACKED_TOPIC = "/cones/tracked"
#: how long lockstep waits for a frame's /cones/tracked once its /cones is back
TRACKED_WAIT_S = 2.0
_QOS_PLAY = QoSProfile(depth=2, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)


def node_command(executable: str) -> list[str]:
    """Command that starts one of this package's node executables here or on the car."""
    here = Path(sys.executable).parent / executable
    if here.is_file():
        return [str(here)]
    found = shutil.which(executable)
    if found:
        return [found]
    if shutil.which("ros2"):
        return ["ros2", "run", "cone_perception", executable]
    raise ConfigError(executable, None, "node executable not found (install the package, or source the workspace)")


@dataclass
class LiveResult:
    cones: dict[int, np.ndarray] = field(default_factory=dict)  # header stamp ns -> CONE_DTYPE
    boxes: dict[int, np.ndarray] = field(default_factory=dict)  # header stamp ns -> BOX_DTYPE
    tracked: dict[int, np.ndarray] = field(default_factory=dict)  # header stamp ns -> TRACKED_CONE_DTYPE (track=True)
    latency_ms: dict[int, float] = field(default_factory=dict)  # publish -> /cones received
    raw: list[tuple[str, int, bytes]] = field(default_factory=list)  # (topic, stamp, CDR) as received
    sent: int = 0
    lost: list[int] = field(default_factory=list)
    frame_id: str = ""
    node_output: dict[str, str] = field(default_factory=dict)
    wall_s: float = 0.0
    died: dict[str, int] = field(default_factory=dict)  # node that exited during the replay -> exit code


def _stamp_of(raw: bytes) -> tuple[int, PointCloud2]:
    msg = deserialize_message(raw, PointCloud2)
    return bagio.stamp_ns(msg.header), msg


def _primer(raw: bytes, msgtype: type, stamps: list[int]) -> tuple[int, bytes]:
    """A copy of the first frame under a stamp no recorded frame has (1 s before the first)."""
    msg = deserialize_message(raw, msgtype)
    stamp = min(stamps) - 10**9 if min(stamps) >= 10**9 else max(stamps) + 10**9
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 10**9)
    return stamp, serialize_message(msg)


def live_replay(
    bag: str | os.PathLike,
    *,
    mode: str = "fused",
    topic: str | None = None,
    params: dict[str, object] | None = None,
    pace: str = "lockstep",
    frame_timeout_s: float = 15.0,
    ready_timeout_s: float = 120.0,
    progress: Callable | None = None,
    track: bool = False,
) -> LiveResult:
    """Play ``bag``'s camera topic into freshly started node processes; returns what came back.

    ``params`` are node parameters (``calibration``, ``model``, ``backend``, ...) given to every
    node with ``-p``. Node processes are always stopped at the end.

    Before the first recorded frame, a primer (the first frame under another stamp) is sent until
    its ``/cones`` comes back: that proves every link of the chain is matched (the graph can list
    an endpoint before its publisher delivers to it) and warms the model up. The primer is not
    part of the result (with ``track`` the tracker starts from it: its tracks are predicted over the
    1 s gap to the first frame).
    """
    if mode not in MODES:
        raise ConfigError("live replay", "mode", f"must be one of {', '.join(MODES)}, got {mode!r}")
    if pace not in ("lockstep", "rate"):
        raise ConfigError("live replay", "pace", f"must be lockstep or rate, got {pace!r}")
    topic, msgtype = find_image_topic(bag, topic)
    compressed = msgtype == bagio.COMPRESSED_IMAGE
    frames, corrupt = [], []
    for m in bagio.read_messages(bag, topic):
        try:
            frames.append((m.log_stamp_ns, bagio.stamp_ns(m.msg.header), m.raw))
        except Exception:  # noqa: BLE001 - a corrupt message is not sent; reported in ``lost``
            corrupt.append(m.log_stamp_ns)

    ros_args = ["--ros-args"]
    for k, v in (params or {}).items():
        ros_args += ["-p", f"{k}:={v}"]
    if compressed:
        ros_args += ["-p", "input_transport:=compressed", "-r", f"image_raw/compressed:={topic}"]
    else:
        ros_args += ["-r", f"image_raw:={topic}"]
    exes = MODES[mode] + (("cone_tracker",) if track and mode == "separate" else ())
    track_args = ["-p", "odom_topic:=''"] + (["-p", "track:=true"] if mode == "fused" else [])
    procs = {}
    res = LiveResult()
    primer_stamp, primer_raw = _primer(frames[0][2], CompressedImage if compressed else Image,
                                       [s for _, s, _ in frames]) if frames else (None, b"")
    primer_seen: list[int] = []
    primer_tracked: list[int] = []
    sent_at: dict[int, float] = {}
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("cone_perception_live_replay", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        pub = node.create_publisher(CompressedImage if compressed else Image, topic, _QOS_PLAY)

        def on_cones(raw: bytes) -> None:
            stamp, msg = _stamp_of(raw)
            if stamp == primer_stamp:
                primer_seen.append(stamp)
                return
            if stamp in sent_at and stamp not in res.cones:
                res.latency_ms[stamp] = (time.monotonic() - sent_at[stamp]) * 1e3
            res.cones[stamp] = _msgs.cones_from_msg(msg)
            res.frame_id = msg.header.frame_id
            res.raw.append((CONES_TOPIC, stamp, raw))

        def on_boxes(raw: bytes) -> None:
            stamp, msg = _stamp_of(raw)
            if stamp == primer_stamp:
                return
            res.boxes[stamp] = _msgs.boxes_from_msg(msg)
            res.raw.append((BOXES_TOPIC, stamp, raw))

        def on_tracked(raw: bytes) -> None:
            stamp, msg = _stamp_of(raw)
            if stamp == primer_stamp:
                primer_tracked.append(stamp)
                return
            res.tracked[stamp] = _msgs.tracked_from_msg(msg)
            res.raw.append((TRACKED_TOPIC, stamp, raw))

        node.create_subscription(PointCloud2, "/cones", on_cones, QOS_DATA, raw=True)
        node.create_subscription(PointCloud2, "/cone_boxes", on_boxes, QOS_DATA, raw=True)
        if track:
            node.create_subscription(PointCloud2, TRACKED_TOPIC, on_tracked, QOS_DATA, raw=True)
        for exe in exes:
            args = ros_args + (track_args if track and exe in ("pipeline", "cone_tracker") else [])
            procs[exe] = subprocess.Popen(
                node_command(exe) + args, env=dict(os.environ), stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, text=True,
            )

        def ready() -> bool:
            for exe, p in procs.items():
                if p.poll() is not None:
                    out = p.communicate()[0]
                    raise ConfigError(exe, None, f"node exited with code {p.returncode} before the replay:\n{out}")
            ok = pub.get_subscription_count() > 0 and node.count_publishers("/cones") > 0
            if mode == "separate":
                ok = ok and node.count_subscribers("/image_cropped") > 0 and node.count_subscribers("/cone_boxes") > 1
            if track:
                ok = ok and node.count_publishers(TRACKED_TOPIC) > 0
            return ok

        end = time.monotonic() + ready_timeout_s
        while not ready():
            if time.monotonic() > end:
                raise ConfigError("live replay", None, f"nodes not ready after {ready_timeout_s:.0f} s")
            executor.spin_once(timeout_sec=0.1)
        def primed() -> bool:
            return bool(primer_seen) and (not track or bool(primer_tracked))

        while frames and not primed():
            if time.monotonic() > end:
                raise ConfigError("live replay", None, f"no /cones for the primer frame after {ready_timeout_s:.0f} s")
            pub.publish(primer_raw)
            resend = time.monotonic() + 2.0
            while not primed() and time.monotonic() < resend:
                executor.spin_once(timeout_sec=0.05)

        items = progress(frames, len(frames)) if progress else frames
        t0_wall = time.monotonic()
        t0_bag = frames[0][0] if frames else 0
        def dead() -> bool:
            for exe, p in procs.items():
                if p.poll() is not None and exe not in res.died:
                    res.died[exe] = p.returncode
            return bool(res.died)

        for log_ns, stamp, raw in items:
            if dead():  # the frames left cannot come back: stop, and say which node died
                break
            if pace == "rate":
                due = t0_wall + (log_ns - t0_bag) / 1e9
                while time.monotonic() < due:
                    executor.spin_once(timeout_sec=max(0.0, min(0.01, due - time.monotonic())))
            sent_at[stamp] = time.monotonic()
            pub.publish(raw)
            res.sent += 1
            if pace == "lockstep":
                deadline = time.monotonic() + frame_timeout_s
                while stamp not in res.cones and time.monotonic() < deadline and not dead():
                    executor.spin_once(timeout_sec=0.01)
                tracked_by = time.monotonic() + TRACKED_WAIT_S
                while track and stamp in res.cones and stamp not in res.tracked and time.monotonic() < tracked_by and not dead():
                    executor.spin_once(timeout_sec=0.01)
            else:
                executor.spin_once(timeout_sec=0.0)
        grace = time.monotonic() + (2.0 if pace == "rate" else 0.3)
        while time.monotonic() < grace:
            executor.spin_once(timeout_sec=0.02)
        res.wall_s = time.monotonic() - t0_wall
        dead()
        res.lost = [s for _, s, _ in frames if s not in res.cones] + corrupt
    finally:
        for exe, p in procs.items():
            if p.poll() is None:
                p.send_signal(2)
        for exe, p in procs.items():
            try:
                out, _ = p.communicate(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                out, _ = p.communicate()
            res.node_output[exe] = out or ""
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    return res


def write_result_bag(res: LiveResult, out: str | os.PathLike) -> None:
    """Write the recorded ``/cone_boxes``, ``/cones`` and ``/cones/tracked`` (raw CDR, header stamps as log time)."""
    topics = {BOXES_TOPIC: bagio.POINTCLOUD2, CONES_TOPIC: bagio.POINTCLOUD2}
    if res.tracked:
        topics[TRACKED_TOPIC] = bagio.POINTCLOUD2
    with bagio.BagWriter(Path(out), topics) as w:
        for topic, stamp, raw in sorted(res.raw, key=lambda x: (x[1], x[0])):
            w.write_raw(topic, stamp, raw)
