"""Soak: publish a drive's frames (looped, re-stamped) at a fixed rate into a live node process and
record what its accounting, memory and latency do over time (``cone-perception soak``).

The node runs as a separate process, as on the car; this process publishes the camera topic (raw
CDR, the stamp rewritten in the bytes: :func:`~cone_perception.records.with_cdr_stamp`), receives
``/cones`` (latency: publish -> /cones received, by stamp) and the node's ``/diagnostics`` (its own
counts), and samples the node's RSS. All DDS traffic stays on this computer (localhost mode).
"""

from __future__ import annotations

from .. import ros_env

ros_env.use_localhost()  # the soak keeps all traffic on this computer, node processes too

from ..nodes._common import QOS_DATA  # noqa: E402,I001 (sets DDS env first)

import os  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Callable  # noqa: E402

import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402
from sensor_msgs.msg import CompressedImage, Image, PointCloud2  # noqa: E402

from ..data import bagio  # noqa: E402
from ..data.bags import find_image_topic  # noqa: E402
from ..errors import ConfigError  # noqa: E402
from ..bench.soak import SoakWindow  # noqa: E402
from ..records import cdr_stamp_ns, with_cdr_stamp  # noqa: E402
from ..synth.config import SynthConfig  # noqa: E402
from ..synth.writers import bag_side_paths, write_scene_bag  # noqa: E402
from ..timing import rss_mb  # noqa: E402
from .live_replay import _QOS_PLAY, node_command  # noqa: E402

#: how long after the last frame the node gets to settle and report its final counts
SETTLE_S = 3.0


@dataclass
class SoakRun:
    sent: int = 0
    wall_s: float = 0.0
    windows: list = field(default_factory=list)  # SoakWindow
    base: dict = field(default_factory=dict)  # /diagnostics values before the first frame
    final: dict = field(default_factory=dict)  # ... after the last was settled
    cones: int = 0
    topic: str = ""
    node_output: str = ""
    died: int | None = None


def drive_frames(bag: Path | None, topic: str | None, tmp: Path, drive_seconds: float = 3.0, seed: int = 2026,
                 calib: str | None = None, progress: bool = True) -> tuple[list[bytes], bool, str, str | None]:
    """(serialized frames, compressed, topic, calibration) of ``bag``'s camera topic, or of a synthetic
    drive of ``drive_seconds`` at 20 Hz rendered into ``tmp`` (its calibration unless ``calib``)."""
    if bag is None:
        bag = tmp / "drive"
        print(f"soak: rendering a {drive_seconds:g} s synthetic drive (seed {seed})", file=sys.stderr)
        write_scene_bag(SynthConfig(seed=seed), drive_seconds, 20.0, bag, progress=progress)
        calib = calib or str(bag_side_paths(bag)[0])
    topic, msgtype = find_image_topic(bag, topic)
    frames = [m.raw for m in bagio.read_messages(bag, topic)]
    return frames, msgtype == bagio.COMPRESSED_IMAGE, topic, calib


class _Receiver:
    """/cones (latency by stamp) and the node's /diagnostics, from the executor thread."""

    def __init__(self, node_name: str) -> None:
        self.status_name = f"cone_perception/{node_name}"
        self.lock = threading.Lock()
        self.sent_at: dict[int, float] = {}
        self.latencies_ms: list[float] = []
        self.cones = 0
        self.stamps_back: set[int] = set()
        self.diag: dict[str, str] = {}
        self.diag_at = 0.0
        self.diag_count = 0

    def on_cones(self, raw: bytes) -> None:
        now = time.monotonic()
        stamp = cdr_stamp_ns(raw)
        with self.lock:
            self.cones += 1
            if stamp is not None:
                self.stamps_back.add(stamp)
                t = self.sent_at.pop(stamp, None)
                if t is not None:
                    self.latencies_ms.append((now - t) * 1e3)

    def on_diag(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name == self.status_name:
                with self.lock:
                    self.diag = {kv.key: kv.value for kv in st.values}
                    self.diag_at = time.monotonic()
                    self.diag_count += 1

    def take_latencies(self) -> list[float]:
        with self.lock:
            out, self.latencies_ms = self.latencies_ms, []
            return out


def soak(frames: list[bytes], compressed: bool, topic: str, rate_hz: float, seconds: float,
         node_args: list[str], executable: str = "pipeline", window_s: float = 10.0,
         ready_timeout_s: float = 180.0, progress: Callable[[float], None] | None = None) -> SoakRun:
    """Publish ``frames`` (serialized, looped) at ``rate_hz`` for ``seconds`` on ``topic`` into a new
    ``executable`` process started with ``--ros-args node_args``; returns the run's record. The
    node is always stopped at the end."""
    if not frames:
        raise ConfigError("soak", None, "no frames to publish")
    if not rate_hz > 0 or not seconds > 0:
        raise ConfigError("soak", None, f"rate and time must be > 0, got {rate_hz} Hz, {seconds} s")
    run = SoakRun(topic=topic)
    proc = subprocess.Popen(node_command(executable) + ["--ros-args", *node_args], env=dict(os.environ),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("cone_perception_soak", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    rx = _Receiver(executable)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set() and context.ok():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    try:
        pub = node.create_publisher(CompressedImage if compressed else Image, topic, _QOS_PLAY)
        node.create_subscription(PointCloud2, "/cones", rx.on_cones, QOS_DATA, raw=True)
        node.create_subscription(DiagnosticArray, "/diagnostics", rx.on_diag, QoSProfile(depth=10))
        spinner.start()
        period_ns = int(round(1e9 / rate_hz))
        start_stamp = time.time_ns() // period_ns * period_ns + 10 * 10**9

        def alive() -> bool:
            if not context.ok():  # rclpy's SIGINT handler shut the context down: Ctrl-C
                raise KeyboardInterrupt
            if proc.poll() is not None and run.died is None:
                run.died = proc.returncode
            return run.died is None

        # ready: the image input subscribed (and its counting path, where the node has one) and /cones out
        end = time.monotonic() + ready_timeout_s
        while not (pub.get_subscription_count() >= 1 and node.count_publishers("/cones") > 0):
            if not alive():
                raise ConfigError(executable, None, f"node exited with code {run.died} before the soak")
            if time.monotonic() > end:
                raise ConfigError("soak", None, f"node not ready after {ready_timeout_s:.0f} s")
            time.sleep(0.1)
        # primer: warms the model up and proves the chain; stamps spaced at the soak's period, 3 s
        # before its first frame (a silence, not missing frames, for the node)
        j, primer = 0, None
        while primer is None or primer not in rx.stamps_back:
            if not alive():
                raise ConfigError(executable, None, f"node exited with code {run.died} during the primer")
            if time.monotonic() > end:
                raise ConfigError("soak", None, f"no /cones for the primer after {ready_timeout_s:.0f} s")
            primer = start_stamp - 3 * 10**9 + j * period_ns
            j += 1
            pub.publish(with_cdr_stamp(frames[0], primer))
            resend = time.monotonic() + 2.0
            while primer not in rx.stamps_back and time.monotonic() < resend:
                time.sleep(0.01)
        start_stamp = max(start_stamp, primer + 3 * 10**9)  # each resend's stamp is a period later: still 3 s
        t_primed = time.monotonic()
        while rx.diag_at < t_primed + 1.2:  # a report after the primer has settled
            if not alive() or time.monotonic() > end:
                raise ConfigError("soak", None, "no /diagnostics from the node after the primer")
            time.sleep(0.05)
        with rx.lock:
            run.base = dict(rx.diag)
            rx.cones = 0
        # the soak
        n = int(round(seconds * rate_hz))
        t0 = time.monotonic()
        win = SoakWindow(t_s=window_s)
        for i in range(n):
            due = t0 + i / rate_hz
            now = time.monotonic()
            if due > now:
                time.sleep(due - now)
            if now - t0 >= win.t_s:
                win.latencies_ms = rx.take_latencies()
                win.rss_mb = rss_mb(proc.pid)
                run.windows.append(win)
                win = SoakWindow(t_s=win.t_s + window_s)
                if progress:
                    progress(now - t0)
                if not alive():
                    break
            if i % 32 == 0 and not alive():
                break
            stamp = start_stamp + i * period_ns
            raw = with_cdr_stamp(frames[i % len(frames)], stamp)
            with rx.lock:
                rx.sent_at[stamp] = time.monotonic()
            pub.publish(raw)
            run.sent += 1
            win.sent += 1
        run.wall_s = time.monotonic() - t0
        # settle: the node takes its last frame and reports its counts
        t_last = time.monotonic()
        while alive() and (rx.diag_at < t_last + SETTLE_S) and time.monotonic() < t_last + SETTLE_S + 10:
            time.sleep(0.05)
        win.latencies_ms = rx.take_latencies()
        win.rss_mb = rss_mb(proc.pid)
        win.t_s = min(win.t_s, run.wall_s)
        if run.windows and win.t_s - run.windows[-1].t_s < window_s / 2:  # a sliver: part of the last window
            last = run.windows[-1]
            last.sent += win.sent
            last.latencies_ms += win.latencies_ms
        else:
            run.windows.append(win)
        with rx.lock:
            run.final = dict(rx.diag)
            run.cones = rx.cones
        counts_by_window(run, rx)
    finally:
        stop.set()
        if spinner.is_alive():
            spinner.join(timeout=2)
        if proc.poll() is None:
            proc.send_signal(2)
        try:
            out, _ = proc.communicate(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
        run.node_output = out or ""
        executor.shutdown()
        node.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)
    return run


def counts_by_window(run: SoakRun, rx: _Receiver) -> None:
    """/cones per window from the latencies recorded (one per frame whose /cones came back)."""
    for w in run.windows:
        w.cones = len(w.latencies_ms)
