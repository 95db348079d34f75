"""Experiment: kill -9 + restart N times; time from ready to first output; stale files left. Usage: killexp.py EXE N"""
import os, sys, time, signal
sys.path.insert(0, "/work/wt-30/tests")
os.environ.setdefault("ROS_DOMAIN_ID", str(100 + os.getpid() % 100))
from cone_perception import ros_env
ros_env.use_localhost()
import rclpy
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, PointCloud2
from rosutil import RosFixture, start_node_process, stop_process
from test_recovery import owned_shm, still_there, SHM, pin, unpin, _base
from cone_perception import shm
exe, n = sys.argv[1], int(sys.argv[2])
ros = RosFixture()
node = ros.node("camera")
pub = node.create_publisher(Image, "image_raw", QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT))
out_topic = "/image_cropped" if exe == "driver_adapter" else "/cones"
got = []
node.create_subscription(Image if exe == "driver_adapter" else PointCloud2, out_topic, lambda m: got.append(time.monotonic()), 10)
frame = Image(width=1920, height=1080, step=3840, encoding="yuv422_yuy2", data=bytes(1920 * 1080 * 2))
last = [0.0]; seq=[0]
def pump(cond, t):
    end = time.monotonic() + t
    while time.monotonic() < end:
        if time.monotonic() - last[0] >= 1 / 30:
            last[0] = time.monotonic(); seq[0]+=1
            frame.header.stamp.sec, frame.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
            pub.publish(frame)
        if cond(): return True
        ros.executor.spin_once(timeout_sec=0.005)
    return cond()
dead = {}
mine = pin(owned_shm(os.getpid()))
seen = set()
def gids():
    return {bytes(i.endpoint_gid) for i in node.get_publishers_info_by_topic(out_topic)}
for trial in range(n + 1):
    t0 = time.monotonic()
    p = start_node_process(exe)
    n0 = len(got)
    ok = pump(lambda: bool(gids() - seen), 120)
    t_ready = time.monotonic()
    seen |= gids()
    back = pump(lambda: len(got) > n0, 20)
    left = still_there(dead); unpin(dead)
    mine_gone = sorted(set(mine) - still_there(mine))
    print(f"trial {trial}: start->ready {t_ready - t0:.1f} s, ready->first output {(time.monotonic() - t_ready) if back else float('nan'):.2f} s, start->first output {time.monotonic() - t0:.1f} s, dead files left {sorted(left)}, live files replaced {mine_gone}", flush=True)
    pump(lambda: False, 1.0)
    dead = owned_shm(p.pid)
    if trial == n:
        print(stop_process(p)[-1500:]); break
    os.kill(p.pid, signal.SIGKILL); p.wait()
    st = set(shm.stale()); dead = pin(f for f in dead if _base(f) in st)
ros.close()
