"""Kill a node with ``kill -9`` and start it again N times while a 30 Hz camera publishes 4 MB frames;
per restart: seconds from start to ready (its publisher in the graph), from ready to its first output,
the killed node's shared-memory files still there after the restart, and this (live) process's files
recreated under it. The figures of docs/robustness.md "Recovery after a crash".

    .venv/bin/python docs/experiments/kill_restart.py [driver_adapter|pipeline] [N]
    CONE_PERCEPTION_SHM_CLEAN=0 .venv/bin/python docs/experiments/kill_restart.py driver_adapter 10  # no clean-up
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(HERE / "tests"))
os.environ.setdefault("ROS_DOMAIN_ID", str(100 + os.getpid() % 100))

from cone_perception import ros_env  # noqa: E402
from cone_perception.nodes import _shm as shm  # noqa: E402

ros_env.use_localhost()

from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosutil import RosFixture, start_node_process, stop_process  # noqa: E402
from sensor_msgs.msg import Image, PointCloud2  # noqa: E402
from test_recovery import _base, owned_shm, pin, still_there, unpin  # noqa: E402


def main() -> int:
    exe = sys.argv[1] if len(sys.argv) > 1 else "driver_adapter"
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 10
    ros = RosFixture()
    node = ros.node("camera")
    pub = node.create_publisher(Image, "image_raw", QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                                                               reliability=ReliabilityPolicy.BEST_EFFORT))
    out_topic = "/image_cropped" if exe == "driver_adapter" else "/cones"
    got = []
    node.create_subscription(Image if exe == "driver_adapter" else PointCloud2, out_topic,
                             lambda m: got.append(time.monotonic()), 10)
    frame = Image(width=1920, height=1080, step=3840, encoding="yuv422_yuy2", data=bytes(1920 * 1080 * 2))
    last = [0.0]

    def pump(cond, timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if time.monotonic() - last[0] >= 1 / 30:
                last[0] = time.monotonic()
                frame.header.stamp.sec, frame.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
                pub.publish(frame)
            if cond():
                return True
            ros.executor.spin_once(timeout_sec=0.005)
        return cond()

    def gids() -> set[bytes]:
        return {bytes(i.endpoint_gid) for i in node.get_publishers_info_by_topic(out_topic)}

    dead, seen = {}, set()
    mine = pin(owned_shm(os.getpid()))
    for trial in range(n + 1):
        t0, n0 = time.monotonic(), len(got)
        p = start_node_process(exe)
        pump(lambda: bool(gids() - seen), 120)
        t_ready = time.monotonic()
        seen |= gids()
        back = pump(lambda: len(got) > n0, 20)
        left = sorted(still_there(dead))
        unpin(dead)
        replaced = sorted(set(mine) - still_there(mine))
        first = f"{time.monotonic() - t_ready:.2f} s" if back else "none in 20 s"
        print(f"trial {trial}: start->ready {t_ready - t0:.1f} s, ready->first output {first}, "
              f"killed node's files left {left}, live files recreated {replaced}", flush=True)
        pump(lambda: False, 1.0)
        dead = owned_shm(p.pid)
        if trial == n:
            stop_process(p)
            break
        os.kill(p.pid, signal.SIGKILL)
        p.wait()
        stale = set(shm.stale())
        dead = pin(f for f in dead if _base(f) in stale or "_port" not in f)
    ros.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
