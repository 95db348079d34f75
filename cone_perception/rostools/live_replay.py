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

from ..nodes._common import QOS_DATA  # noqa: E402,I001 (sets DDS env first)

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
from ..data.bags import BOXES_TOPIC, CONES_TOPIC, TRACKED_TOPIC, find_image_topic
from ..errors import ConfigError
from ..nodes import _msgs

MODES = {"separate": ("driver_adapter", "detection", "mapping"), "fused": ("pipeline",)}
PACES = ("lockstep", "rate")
#: how long lockstep waits for a frame's /cones/tracked once its /cones is back
TRACKED_WAIT_S = 2.0


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


def check_options(mode: str, pace: str) -> None:
    """:class:`ConfigError` for an unknown mode or pace."""
    if mode not in MODES:
        raise ConfigError("live replay", "mode", f"must be one of {', '.join(MODES)}, got {mode!r}")
    if pace not in PACES:
        raise ConfigError("live replay", "pace", f"must be lockstep or rate, got {pace!r}")


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


def read_frames(bag: str | os.PathLike, topic: str | None) -> tuple[str, bool, list[tuple[int, int, bytes]], list[int]]:
    """The camera topic to play, whether it is compressed, its frames ``(log stamp, header stamp, CDR)`` and
    the log stamps of the messages that do not deserialise (not sent; reported as lost)."""
    topic, msgtype = find_image_topic(bag, topic)
    frames, corrupt = [], []
    for m in bagio.read_messages(bag, topic):
        try:
            frames.append((m.log_stamp_ns, bagio.stamp_ns(m.msg.header), m.raw))
        except Exception:  # noqa: BLE001 - a corrupt message is not sent; reported in ``lost``
            corrupt.append(m.log_stamp_ns)
    return topic, msgtype == bagio.COMPRESSED_IMAGE, frames, corrupt


def node_processes(mode: str, track: bool) -> tuple[str, ...]:
    """The node executables of ``mode`` (and the tracker's after the separate nodes)."""
    return MODES[mode] + (("cone_tracker",) if track and mode == "separate" else ())


def node_arguments(params: dict[str, object] | None, topic: str, compressed: bool) -> list[str]:
    """``--ros-args`` of every node: ``params`` with ``-p``, the camera topic remapped to the bag's."""
    ros_args = ["--ros-args"]
    for k, v in (params or {}).items():
        ros_args += ["-p", f"{k}:={v}"]
    if compressed:
        ros_args += ["-p", "input_transport:=compressed", "-r", f"image_raw/compressed:={topic}"]
    else:
        ros_args += ["-r", f"image_raw:={topic}"]
    return ros_args


def tracking_arguments(mode: str) -> list[str]:
    """The extra ``--ros-args`` of the node that tracks (motion from the cones; the fused node's ``track``)."""
    return ["-p", "odom_topic:=''"] + (["-p", "track:=true"] if mode == "fused" else [])


def write_result_bag(res: LiveResult, out: str | os.PathLike) -> None:
    """Write the recorded ``/cone_boxes``, ``/cones`` and ``/cones/tracked`` (raw CDR, header stamps as log time)."""
    topics = {BOXES_TOPIC: bagio.POINTCLOUD2, CONES_TOPIC: bagio.POINTCLOUD2}
    if res.tracked:
        topics[TRACKED_TOPIC] = bagio.POINTCLOUD2
    with bagio.BagWriter(Path(out), topics) as w:
        for topic, stamp, raw in sorted(res.raw, key=lambda x: (x[1], x[0])):
            w.write_raw(topic, stamp, raw)


_QOS_PLAY = QoSProfile(depth=2, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)


def _stamp_of(raw: bytes) -> tuple[int, PointCloud2]:
    msg = deserialize_message(raw, PointCloud2)
    return bagio.stamp_ns(msg.header), msg


def _primer(raw: bytes, msgtype: type, stamps: list[int]) -> tuple[int, bytes]:
    """A copy of the first frame under a stamp no recorded frame has (1 s before the first)."""
    msg = deserialize_message(raw, msgtype)
    stamp = min(stamps) - 10**9 if min(stamps) >= 10**9 else max(stamps) + 10**9
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 10**9)
    return stamp, serialize_message(msg)


class _Recorder:
    """Records what the nodes publish into a :class:`LiveResult`, by header stamp; the primer apart."""

    def __init__(self, res: LiveResult, primer_stamp: int | None):
        self.res, self.primer_stamp = res, primer_stamp
        self.primer_back: set[str] = set()  # the topics the primer has come back on
        self.sent_at: dict[int, float] = {}

    def subscribe(self, node, track: bool) -> None:
        node.create_subscription(PointCloud2, "/cones", self.on_cones, QOS_DATA, raw=True)
        node.create_subscription(PointCloud2, "/cone_boxes", self.on_boxes, QOS_DATA, raw=True)
        if track:
            node.create_subscription(PointCloud2, TRACKED_TOPIC, self.on_tracked, QOS_DATA, raw=True)

    def primed(self, track: bool) -> bool:
        """The primer came back on every recorded topic: each publisher has matched this node's subscription
        (``/cones`` alone would not prove it for ``cone_boxes``, whose other subscriber is the mapping node)."""
        return ({CONES_TOPIC, BOXES_TOPIC} | ({TRACKED_TOPIC} if track else set())) <= self.primer_back

    def on_cones(self, raw: bytes) -> None:
        stamp, msg = _stamp_of(raw)
        if stamp == self.primer_stamp:
            self.primer_back.add(CONES_TOPIC)
            return
        res = self.res
        if stamp in self.sent_at and stamp not in res.cones:
            res.latency_ms[stamp] = (time.monotonic() - self.sent_at[stamp]) * 1e3
        res.cones[stamp] = _msgs.cones_from_msg(msg)
        res.frame_id = msg.header.frame_id
        res.raw.append((CONES_TOPIC, stamp, raw))

    def on_boxes(self, raw: bytes) -> None:
        stamp, msg = _stamp_of(raw)
        if stamp == self.primer_stamp:
            self.primer_back.add(BOXES_TOPIC)
            return
        self.res.boxes[stamp] = _msgs.boxes_from_msg(msg)
        self.res.raw.append((BOXES_TOPIC, stamp, raw))

    def on_tracked(self, raw: bytes) -> None:
        stamp, msg = _stamp_of(raw)
        if stamp == self.primer_stamp:
            self.primer_back.add(TRACKED_TOPIC)
            return
        self.res.tracked[stamp] = _msgs.tracked_from_msg(msg)
        self.res.raw.append((TRACKED_TOPIC, stamp, raw))


def _start_nodes(procs: dict, exes: tuple[str, ...], ros_args: list[str], track_args: list[str]) -> None:
    """Start the node processes into ``procs`` (filled as they start, so a failure stops those started)."""
    for exe in exes:
        args = ros_args + (track_args if track_args and exe in ("pipeline", "cone_tracker") else [])
        procs[exe] = subprocess.Popen(
            node_command(exe) + args, env=dict(os.environ), stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True,
        )


def _wait_ready(node, executor, pub, procs: dict, mode: str, track: bool, timeout_s: float) -> float:
    """Spin until every link of the chain is matched; returns the deadline (monotonic s) it was given."""

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

    end = time.monotonic() + timeout_s
    while not ready():
        if time.monotonic() > end:
            raise ConfigError("live replay", None, f"nodes not ready after {timeout_s:.0f} s")
        executor.spin_once(timeout_sec=0.1)
    return end


def _stop_nodes(procs: dict, res: LiveResult) -> None:
    """SIGINT every node still running, then collect each one's output (killed after 15 s)."""
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
    its ``/cones`` and ``cone_boxes`` come back: that proves every link of the chain is matched (the graph can list
    an endpoint before its publisher delivers to it) and warms the model up. The primer is not
    part of the result (with ``track`` the tracker starts from it: its tracks are predicted over the
    1 s gap to the first frame).
    """
    check_options(mode, pace)
    topic, compressed, frames, corrupt = read_frames(bag, topic)
    ros_args = node_arguments(params, topic, compressed)
    procs = {}
    res = LiveResult()
    primer_stamp, primer_raw = _primer(frames[0][2], CompressedImage if compressed else Image,
                                       [s for _, s, _ in frames]) if frames else (None, b"")
    rec = _Recorder(res, primer_stamp)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("cone_perception_live_replay", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        pub = node.create_publisher(CompressedImage if compressed else Image, topic, _QOS_PLAY)
        rec.subscribe(node, track)
        _start_nodes(procs, node_processes(mode, track), ros_args, tracking_arguments(mode) if track else [])
        end = _wait_ready(node, executor, pub, procs, mode, track, ready_timeout_s)
        while frames and not rec.primed(track):
            if time.monotonic() > end:
                raise ConfigError("live replay", None, "the primer frame did not come back on /cones and cone_boxes "
                                  f"after {ready_timeout_s:.0f} s")
            pub.publish(primer_raw)
            resend = time.monotonic() + 2.0
            while not rec.primed(track) and time.monotonic() < resend:
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
            rec.sent_at[stamp] = time.monotonic()
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
        _stop_nodes(procs, res)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    return res
