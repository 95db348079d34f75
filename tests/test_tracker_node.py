"""Live ROS 2 tests of the tracker in nodes: ``cone_tracker`` (``/cones`` + ``odom`` in, ``/cones/tracked``
out) and the ``pipeline`` node with ``track: true`` (localhost DDS, tests/conftest.py)."""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import Marker, MarkerArray

from cone_perception.classes import BLUE, YELLOW
from cone_perception.nodes import _msgs
from cone_perception.nodes.cone_tracker import ConeTrackerNode
from cone_perception.records import CONE_DTYPE
from cone_perception.stats import WARN

from rosutil import Inbox, RosFixture, ros  # noqa: F401 (ros is a fixture)

WORLD = np.array([[8.0, 2.0], [8.0, -2.0], [12.0, 2.0], [12.0, -2.0], [16.0, 2.0], [16.0, -2.0]])
CLS = [BLUE, YELLOW] * 3


def _cones_msg(stamp_ns: int, x_car: float) -> PointCloud2:
    local = WORLD - (x_car, 0.0)
    c = np.zeros(len(local), CONE_DTYPE)
    c["x"], c["y"], c["class_id"], c["score"] = local[:, 0], local[:, 1], CLS, 0.8
    c["cov_xx"] = c["cov_yy"] = 0.01
    msg = _msgs.cones_msg(c, PointCloud2().header)
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.header.frame_id = "rear_axle"
    return msg


def _odom(stamp_ns: int, vx: float) -> Odometry:
    m = Odometry()
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    m.twist.twist.linear.x = vx
    return m


def test_cone_tracker_node_tracks_with_odometry_and_drops_bad_stamps(ros: RosFixture) -> None:
    node = ros.add(ConeTrackerNode(context=ros.context))
    t = ros.node("tester")
    tracked, markers = Inbox(), Inbox()
    t.create_subscription(PointCloud2, "/cones/tracked", tracked, 50)
    t.create_subscription(MarkerArray, "/cones/tracked/markers", markers, 50)
    pub = t.create_publisher(PointCloud2, "/cones", 50)
    odom = t.create_publisher(Odometry, "odom", 50)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0 and odom.get_subscription_count() > 0
                          and tracked.msgs is not None and t.count_publishers("/cones/tracked") > 0)
    base = 1_700_000_000 * 1_000_000_000
    for k in range(8):
        stamp = base + k * 50_000_000
        odom.publish(_odom(stamp - 10_000_000, 8.0))
        ros.spin_until(lambda: len(node.tracking.stage.twists.stamps) > k, 5)
        pub.publish(_cones_msg(stamp, 0.4 * k))
        assert ros.spin_until(lambda: len(tracked.msgs) > k, 10)
    last = _msgs.tracked_from_msg(tracked.msgs[-1])
    assert sorted(last["track_id"].tolist()) == [1, 2, 3, 4, 5, 6]
    assert tracked.msgs[-1].header.stamp.sec == (base + 7 * 50_000_000) // 1_000_000_000
    assert tracked.msgs[-1].header.stamp.nanosec == (base + 7 * 50_000_000) % 1_000_000_000
    assert node.tracking.stage.last_info.motion_source == "odometry"
    np.testing.assert_allclose(np.sort(last["x"]), np.sort(WORLD[:, 0] - 2.8), atol=0.05)
    ma = markers.msgs[-1].markers
    texts = [m.text for m in ma if m.type == Marker.TEXT_VIEW_FACING]
    assert sorted(texts) == [str(i) for i in range(1, 7)]
    # a repeated stamp: not fused, counted as a dropped frame, the node goes on
    pub.publish(_cones_msg(base + 7 * 50_000_000, 2.8))
    assert ros.spin_until(lambda: node.stats.dropped.get("stamp_repeated", 0) == 1, 10)
    pub.publish(_cones_msg(base + 8 * 50_000_000, 3.2))
    assert ros.spin_until(lambda: len(tracked.msgs) == 9, 10)


def test_cone_tracker_node_twist_input_nan_counted(ros: RosFixture) -> None:
    node = ros.add(ConeTrackerNode(context=ros.context, parameter_overrides=[
        Parameter("odom_topic", value="twist"), Parameter("odom_type", value="twist")]))
    node._diag_timer.cancel()  # the test takes the diagnostics itself
    t = ros.node("tester")
    pub = t.create_publisher(TwistStamped, "twist", 10)
    cones = t.create_publisher(PointCloud2, "/cones", 10)  # an upstream: no ERROR for a missing one
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0 and cones.get_subscription_count() > 0)
    m = TwistStamped()
    m.header.stamp.sec = 5
    m.twist.linear.x = float("nan")
    assert ros.spin_until(lambda: (pub.publish(m) or True) and node.tracking.stage.events["twist_nan"] >= 1, 10)
    assert not node.tracking.stage.twists.stamps
    # on /diagnostics: the count as a value, the period WARNs
    st = _diagnostics(node)
    assert st.level == bytes([WARN]) and "tracker twist_nan" in st.message
    assert int({kv.key: kv.value for kv in st.values}["tracker:twist_nan"]) >= 1


def _diagnostics(node):
    """The node's next /diagnostics status (published at once, captured)."""
    sent = []
    pub, node._diag_pub.publish = node._diag_pub.publish, sent.append
    try:
        node._publish_diagnostics()
    finally:
        node._diag_pub.publish = pub
    return sent[-1].status[0]


def test_pipeline_node_with_track_publishes_tracked_cones(ros: RosFixture, tmp_path) -> None:
    from sensor_msgs.msg import Image

    from cone_perception.data import bagio
    from cone_perception.nodes.pipeline import PipelineNode
    from cone_perception.synth.config import SynthConfig
    from cone_perception.synth.writers import bag_side_paths, write_scene_bag

    bag = tmp_path / "drive"
    write_scene_bag(SynthConfig(seed=4242, jitter=False), 0.4, 10.0, bag, speed_mps=6.0, progress=False)
    frames = []
    for m in bagio.read_messages(bag, "/camera/image_raw"):
        src, img = m.msg, Image()
        img.header.stamp.sec, img.header.stamp.nanosec = int(src.header.stamp.sec), int(src.header.stamp.nanosec)
        img.height, img.width, img.encoding, img.step = int(src.height), int(src.width), src.encoding, int(src.step)
        img.data = bytes(src.data)
        frames.append(img)
    node = ros.add(PipelineNode(context=ros.context, parameter_overrides=[
        Parameter("calibration", value=str(bag_side_paths(bag)[0])), Parameter("track", value=True),
        Parameter("odom_topic", value="")]))
    node._diag_timer.cancel()  # the test takes the diagnostics itself
    t = ros.node("tester")
    tracked, cones = Inbox(), Inbox()
    t.create_subscription(PointCloud2, "/cones/tracked", tracked, 10)
    t.create_subscription(PointCloud2, "/cones", cones, 10)
    pub = t.create_publisher(Image, "image_raw", 10)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0 and t.count_publishers("/cones/tracked") > 0)
    for k, img in enumerate(frames):
        assert ros.spin_until(lambda: (pub.publish(img) or True) and len(tracked.msgs) > k, 30)
    assert len(tracked.msgs) == len(frames) == 4
    assert [m.header.stamp for m in tracked.msgs] == [f.header.stamp for f in frames]
    last = _msgs.tracked_from_msg(tracked.msgs[-1])
    assert len(last) >= 3 and len(set(last["track_id"].tolist())) == len(last)
    # the same frame again: /cones goes out, its tracking is dropped and counted
    n_cones, d0 = len(cones.msgs), node.stats.dropped.get("tracker_stamp_repeated", 0)
    assert ros.spin_until(lambda: (pub.publish(frames[-1]) or True) and node.stats.dropped.get("tracker_stamp_repeated", 0) > d0, 30)
    assert ros.spin_until(lambda: len(cones.msgs) > n_cones, 10)
    assert len(tracked.msgs) == 4
    _diagnostics(node)  # the period of the repeated stamp
    # a frame 2 s after the last: tracks predicted over the gap, counted, on /diagnostics
    late = frames[-1]
    late.header.stamp.sec += 2
    assert ros.spin_until(lambda: (pub.publish(late) or True) and len(tracked.msgs) == 5, 30)
    st = _diagnostics(node)
    assert st.level == bytes([WARN]) and "1 tracker gap" in st.message
    values = {kv.key: kv.value for kv in st.values}
    # stamp_repeated: the repeated frame, plus any copy of a frame the loops above published again before its
    # /cones/tracked came back (one executor, so how many is a matter of callback order): what the tracker counted
    n_rep = node.tracking.stage.events["stamp_repeated"]
    assert values["tracker:gap"] == "1" and n_rep >= 1 and values["tracker:stamp_repeated"] == str(n_rep)
