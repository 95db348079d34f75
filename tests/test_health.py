"""Losses counted and visible: stream monitoring and node health (ROS-free), and its /diagnostics."""

from __future__ import annotations

from cone_perception.stats import ERROR, OK, WARN, NodeHealth, StreamMonitor

MS = 1_000_000
PERIOD = 33 * MS  # a 30 Hz camera


def _feed(mon: StreamMonitor, stamps_ms, lag_ms: float = 5.0) -> list[list[str]]:
    return [mon.observe(int(s * MS), int((s + lag_ms) * MS)) for s in stamps_ms]


def test_a_steady_stream_has_no_faults() -> None:
    mon = StreamMonitor("/image_raw")
    faults = _feed(mon, [i * 33 for i in range(100)])
    assert not any(faults) and mon.counts() == {"received": 100, "ok": 0, "dropped": 0, "skipped": 0, "lost": 0,
                                                "backwards": 0, "repeated": 0, "stale": 0, "silences": 0}


def test_frames_replaced_in_the_queue_are_counted_from_stamp_gaps() -> None:
    """A depth-1 queue of a busy node keeps only the newest frame: the publisher's stamps jump."""
    mon = StreamMonitor("/image_raw")
    stamps = [i * 33 for i in range(10)]  # learn the period
    stamps += [33 * 12, 33 * 13, 33 * 18]  # 2 frames replaced, then 0, then 4
    faults = _feed(mon, stamps)
    assert mon.skipped == 2 + 4 and faults[10] == ["skipped"] and faults[11] == [] and faults[12] == ["skipped"]


def test_a_nominal_rate_counts_skips_of_a_node_that_is_always_late() -> None:
    """Every other frame replaced: learnt from the stamps, the period would be 2 frames."""
    learnt, nominal = StreamMonitor("/image_raw"), StreamMonitor("/image_raw", period_s=0.033)
    for mon in (learnt, nominal):
        _feed(mon, [i * 66 for i in range(20)])
    assert learnt.skipped == 0 and nominal.skipped == 19


def test_jitter_is_not_a_gap() -> None:
    mon = StreamMonitor("/image_raw")
    _feed(mon, [i * 33 + (4 if i % 2 else -4) for i in range(50)])
    assert mon.skipped == 0


def test_stamps_backwards_and_repeated() -> None:
    mon = StreamMonitor("/image_raw")
    faults = _feed(mon, [0, 33, 66, 66, 40, 99])
    assert faults[3] == ["repeated"] and faults[4] == ["backwards"]
    assert (mon.repeated, mon.backwards, mon.skipped) == (1, 1, 0)


def test_stale_frames_only_when_asked() -> None:
    mon = StreamMonitor("/image_raw", max_age_s=0.5)
    assert _feed(mon, [0, 33], lag_ms=600) == [["stale"], ["stale"]]
    assert _feed(mon, [66], lag_ms=10) == [[]]
    off = StreamMonitor("/image_raw")
    assert _feed(off, [0], lag_ms=10**6) == [[]]


def test_silence_and_missing_publisher_are_errors_with_the_cause() -> None:
    h = NodeHealth(timeout_s=1.0)
    h.stream("/image_raw", now_ns=0)
    rep = h.assess(500 * MS, {"/image_raw": 1})
    assert rep.level == OK
    rep = h.assess(1500 * MS, {"/image_raw": 1})
    assert rep.level == ERROR and "no message on /image_raw since start 1.5 s" in rep.message
    h.streams["/image_raw"].observe(0, 1600 * MS)
    h.stats.count_ok()
    assert h.assess(1700 * MS, {"/image_raw": 1}).level == OK
    rep = h.assess(3000 * MS, {"/image_raw": 0})
    assert rep.level == ERROR and "no publisher on /image_raw" in rep.message and "for 1.4 s" in rep.message
    assert h.streams["/image_raw"].silences == 2  # each silence counted once however long it lasts
    h.assess(3500 * MS, {"/image_raw": 0})
    assert h.streams["/image_raw"].silences == 2


def test_drops_and_faults_warn_for_the_period_they_happened_in() -> None:
    h = NodeHealth(timeout_s=0)
    mon = h.stream("/image_raw", now_ns=0)
    _feed(mon, [i * 33 for i in range(10)] + [33 * 12])  # 2 skipped
    h.stats.count_drop("too_large")
    h.stats.count_drop("exception_KeyError")
    rep = h.assess(10**9)
    assert rep.level == WARN
    for words in ("1 dropped (too_large)", "1 dropped (exception_KeyError)", "2 skipped before processing"):
        assert words in rep.message
    values = dict(rep.values)
    assert values["dropped_too_large"] == "1" and values["/image_raw:skipped"] == "2"
    assert h.assess(2 * 10**9).level == OK  # nothing new: OK again, the counts stay
    assert dict(h.assess(3 * 10**9).values)["/image_raw:skipped"] == "2"
    assert "skipped=2" in h.summary() and "2 dropped" in h.summary()


def test_a_watched_stage_reports_its_counts_and_warns_on_the_listed_ones() -> None:
    from collections import Counter

    h = NodeHealth(timeout_s=0)
    events = Counter()
    h.watch("tracker", events, warn=["gap", "twist_nan"])
    assert h.assess(10**9).level == OK
    events["merged"] += 3  # counted, not a fault
    rep = h.assess(2 * 10**9)
    assert rep.level == OK and dict(rep.values)["tracker:merged"] == "3"
    events["twist_nan"] += 2
    rep = h.assess(3 * 10**9)
    assert rep.level == WARN and "2 tracker twist_nan" in rep.message
    assert dict(rep.values)["tracker:twist_nan"] == "2"
    assert h.assess(4 * 10**9).level == OK  # nothing new
    assert "tracker: merged=3, twist_nan=2" in h.summary()


def test_the_node_publishes_its_health(ros) -> None:  # noqa: F811
    from cone_perception.nodes.driver_adapter import DriverAdapterNode

    node = ros.add(DriverAdapterNode(context=ros.context))
    sent = []
    node._diag_pub.publish = sent.append
    node.health.streams["/image_raw"].timeout_s = 1e-9  # silent at once
    node._publish_diagnostics()
    st = sent[-1].status[0]
    assert st.level == bytes([ERROR]) and "no publisher on /image_raw" in st.message
    assert "no message on /image_raw since start" in st.message
    assert {kv.key for kv in st.values} >= {"frames_ok", "/image_raw:skipped", "/image_raw:silences"}


from rosutil import ros  # noqa: E402,F401 (a fixture)


def test_middleware_lost_messages_are_counted_and_warned(ros) -> None:  # noqa: F811
    from types import SimpleNamespace

    from cone_perception.nodes.mapping import MappingNode

    node = ros.add(MappingNode(context=ros.context))
    sub = next(s for s in node.subscriptions if s.topic_name == "/cone_boxes")
    lost = [h for h in sub.event_handlers if "lost" in getattr(h.callback, "__name__", "")]
    assert len(lost) == 1  # Fast DDS reports sample-lost events
    lost[0].callback(SimpleNamespace(total_count=3, total_count_change=3))
    assert node.health.streams["/cone_boxes"].lost == 3
    rep = node.health.assess(node._now_ns(), {"/cone_boxes": 1})
    assert rep.level == WARN and "3 lost in transport" in rep.message


def test_frames_replaced_in_the_depth1_queue_add_up_through_dds(ros) -> None:  # noqa: F811
    """A burst through DDS into the best-effort depth-1 queue: the node takes only the newest, and
    received + skipped (stamp gaps at the camera's 30 Hz) + lost is every frame sent."""
    import time as _time

    from rclpy.parameter import Parameter
    from sensor_msgs.msg import Image

    from cone_perception.nodes.driver_adapter import DriverAdapterNode

    node = ros.add(DriverAdapterNode(context=ros.context, parameter_overrides=[Parameter("input_rate_hz", value=30.0)]))
    pub = ros.node("camera").create_publisher(Image, "image_raw", 10)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0)
    stream = node.health.streams["/image_raw"]

    def frame(i: int) -> Image:
        m = Image()
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(1_000_000_000 + i * 33_333_333, 10**9)
        m.encoding = "bogus"  # dropped at once: only the counting matters here
        return m

    assert ros.spin_until(lambda: (pub.publish(frame(0)) or True) and stream.received > 0)
    sent = 1 + 40
    for i in range(1, sent):  # a burst, nothing spun: the queue keeps the newest
        pub.publish(frame(i))
    _time.sleep(0.2)
    assert ros.spin_until(lambda: stream.last_stamp_ns == 1_000_000_000 + 40 * 33_333_333, 5)
    taken = stream.received - stream.repeated  # frame 0 may have been sent more than once
    assert taken < sent  # frames were replaced before the node took them ...
    assert taken + stream.skipped + stream.lost == sent  # ... and every one is accounted for
    assert stream.ok + stream.dropped == stream.received
