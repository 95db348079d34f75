"""``cone-perception bench startup``'s ROS side: start the ``pipeline`` node as ``ros2 run`` does (its console
script, a process of its own), under a camera publishing at 30 Hz from before the exec, and time each start:
exec -> its ``/cones`` publisher in the ROS graph (ready) -> its first ``/cones``; cold (the node's ONNX cache
emptied before each start), warm (the cache present, the previous node stopped), and after ``kill -9`` (the
previous node killed under the camera, then started at once). The node's cache is a folder of the benchmark's own
(``XDG_CACHE_HOME`` of the node processes), so the user's cache is never touched. All DDS traffic stays on this
computer (localhost mode). The figures: :mod:`cone_perception.bench.startup`.
"""

from __future__ import annotations

from .. import ros_env

ros_env.use_localhost()  # the benchmark keeps all traffic on this computer, node processes too

from ..nodes._common import QOS_DATA  # noqa: E402,I001 (sets DDS env first)

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import Image, PointCloud2  # noqa: E402
from tqdm import tqdm  # noqa: E402

from ..bench.frames import rendered_frames  # noqa: E402
from ..bench.startup import CAMERA_HZ, Start, format_summary, summarize  # noqa: E402
from ..errors import ConfigError  # noqa: E402
from ..geometry.calib import load_calibration  # noqa: E402
from .live_replay import node_command  # noqa: E402

#: Seconds a start may take to its first /cones before it counts as failed.
START_TIMEOUT_S = 120.0
#: Seconds the node runs under the camera after its first /cones before its peak RSS is read and it is stopped.
RUN_AFTER_S = 1.0
#: The benchmark's ROS_DOMAIN_ID where none is set: the soak's range (replay/soak.py), from the process id.
DOMAINS = range(200, 233)


def peak_rss_mb(pid: int) -> float:
    """Peak resident set (``VmHWM``) of process ``pid`` so far, in MiB; NaN where unreadable."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


class _Camera:
    """A camera publishing ``frames`` (YUYV, looped, stamped now) at :data:`CAMERA_HZ` from its own thread, and the
    ``/cones`` it gets back (their arrival times) and the ``/cones`` publishers it has seen (endpoint gids)."""

    def __init__(self, frames: list[bytes], width: int, height: int) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("cone_perception_startup_bench", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        qos = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.pub = self.node.create_publisher(Image, "image_raw", qos)
        self.msgs = [Image(width=width, height=height, step=2 * width, encoding="yuv422_yuy2", data=f) for f in frames]
        self.cones: list[float] = []
        self.node.create_subscription(PointCloud2, "/cones", lambda m: self.cones.append(time.monotonic()), QOS_DATA,
                                      raw=True)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._publish, daemon=True)
        self.thread.start()

    def _publish(self) -> None:
        i, t0 = 0, time.monotonic()
        while not self.stop.is_set():
            msg = self.msgs[i % len(self.msgs)]
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
            self.pub.publish(msg)
            i += 1
            time.sleep(max(0.0, t0 + i / CAMERA_HZ - time.monotonic()))

    def publishers(self) -> set[bytes]:
        return {bytes(p.endpoint_gid) for p in self.node.get_publishers_info_by_topic("/cones")}

    def spin_until(self, cond, timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if cond():
                return True
            self.executor.spin_once(timeout_sec=0.005)
        return cond()

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=2.0)
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def _start(cam: _Camera, cmd: list[str], env: dict, phase: str, seen: set[bytes]) -> tuple[Start, subprocess.Popen]:
    """Exec the node and time it to ready and to its first /cones; it keeps running (its peak RSS read after
    :data:`RUN_AFTER_S` more)."""
    cam.spin_until(lambda: False, 0.05)  # what a killed node had in flight is delivered before the clock starts
    n0 = len(cam.cones)
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    s = Start(phase)

    def dead() -> bool:
        return proc.poll() is not None

    if cam.spin_until(lambda: bool(cam.publishers() - seen) or dead(), START_TIMEOUT_S) and not dead():
        s.ready_s = time.monotonic() - t0
        seen |= cam.publishers()
        if cam.spin_until(lambda: len(cam.cones) > n0 or dead(), START_TIMEOUT_S - s.ready_s) and len(cam.cones) > n0:
            s.first_cones_s = cam.cones[n0] - t0
            cam.spin_until(dead, RUN_AFTER_S)
    s.peak_rss_mb = peak_rss_mb(proc.pid)
    if dead():
        s.outcome = f"exited with code {proc.returncode}: {(proc.communicate()[0] or '').strip()[-300:]}"
    elif s.first_cones_s != s.first_cones_s:
        s.outcome = f"no /cones within {START_TIMEOUT_S:.0f} s"
    return s, proc


def _stop(proc: subprocess.Popen, kill: bool) -> None:
    if proc.poll() is None:
        if kill:
            os.kill(proc.pid, signal.SIGKILL)
        else:
            proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    proc.communicate()


def measure_starts(frames: list[bytes], width: int, height: int, node_args: list[str], cold: int, warm: int,
                   kills: int, cache_home: Path, progress: bool = True) -> list[Start]:
    """``cold`` starts with the node's ONNX cache (under ``cache_home``) emptied before each, then ``warm`` starts
    (each node stopped with SIGINT before the next), then ``kills`` restarts each right after a ``kill -9`` of the
    node before; the camera publishes ``frames`` throughout."""
    env = dict(os.environ, XDG_CACHE_HOME=str(cache_home))
    cmd = node_command("pipeline") + ["--ros-args", *node_args]
    cam = _Camera(frames, width, height)
    starts: list[Start] = []
    seen: set[bytes] = set()
    prime = 0 if cold else 1  # without cold starts, one start (not counted) fills the cache
    plan = ["cold"] * max(cold, prime) + ["warm"] * max(warm, 1 if kills else 0) + ["kill"] * kills
    bar = tqdm(total=len(plan), unit="start", desc="bench startup", file=sys.stderr, disable=not progress)
    try:
        proc = None
        for i, phase in enumerate(plan):
            if proc is not None:
                _stop(proc, kill=phase == "kill")
            if phase == "cold":
                shutil.rmtree(cache_home / "cone_perception" / "onnx", ignore_errors=True)
            s, proc = _start(cam, cmd, env, phase, seen)
            counted = (phase == "cold" and not prime) or (phase == "warm" and i - max(cold, prime) < warm) \
                or phase == "kill"  # not: the priming start, a warm start only there to be killed
            if counted:
                starts.append(s)
            bar.update(1)
        if proc is not None:
            _stop(proc, kill=False)
    finally:
        bar.close()
        cam.close()
    return starts


def run_startup(args: argparse.Namespace) -> int:
    """``cone-perception bench startup``: the table (or ``--json``); exit 1 where a target is missed."""
    if min(args.starts, args.cold_starts) < 0 or args.starts + args.cold_starts == 0:
        raise ConfigError("bench startup", "--starts", "--starts and --cold-starts must be >= 0, not both 0")
    os.environ.setdefault("ROS_DOMAIN_ID", str(DOMAINS[os.getpid() % len(DOMAINS)]))
    calib = load_calibration(args.calib)
    frames = rendered_frames(calib, 4)
    node_args = ["-p", f"calibration:={calib.source}"]
    if args.model:
        node_args += ["-p", f"model:={Path(args.model).resolve()}"]
    cache_home = Path(tempfile.mkdtemp(prefix="cone_perception_startup_"))
    try:
        starts = measure_starts(frames, calib.image_width, calib.image_height, node_args, args.cold_starts,
                                args.starts, args.starts, cache_home, not (args.no_progress or args.json))
    finally:
        shutil.rmtree(cache_home, ignore_errors=True)
    summary = summarize(starts)
    summary["node"] = " ".join(node_command("pipeline") + ["--ros-args", *node_args])
    print(json.dumps(summary, indent=1) if args.json else format_summary(summary))
    return 0 if all(ok for _, ok in summary["targets"].values()) else 1
