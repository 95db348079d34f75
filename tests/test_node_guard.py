"""No message can end a node: every callback guarded, camera_info validated, the band rule of the detection node."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

from cone_perception.crop import MAX_IMAGE_SIDE_PX, camera_info_crop
from cone_perception.data.hostile import jpeg_bomb, png_bomb
from cone_perception.errors import FrameError
from cone_perception.geometry.calib import load_calibration
from cone_perception.nodes import _msgs
from cone_perception.nodes.driver_adapter import DriverAdapterNode

from rosutil import RosFixture, ros  # noqa: F401 (ros is a fixture)

CALIB = load_calibration("example_mainhoop")
W, H = 1920, 1080
GOOD = dict(width=W, height=H, roi_x=0, roi_y=CALIB.crop.v0, roi_w=1920, roi_h=576, binning_x=2, binning_y=2)


def callback(node, msgtype):
    """The (guarded) callback the node subscribed for ``msgtype``: called directly, no DDS."""
    subs = [s for s in node.subscriptions if s.msg_type is msgtype and not s.raw]  # not the counting path
    assert len(subs) == 1
    return getattr(subs[0].callback, "message_only", subs[0].callback)


def test_a_good_camera_info_gives_the_calibration_crop() -> None:
    assert camera_info_crop(**GOOD) == CALIB.crop


@pytest.mark.parametrize("change, field", [
    (dict(width=0), "width/height"),
    (dict(height=MAX_IMAGE_SIDE_PX + 1), "width/height"),
    (dict(binning_x=1000, binning_y=1000), "binning"),
    (dict(binning_x=2, binning_y=1), "binning"),
    (dict(binning_x=3, binning_y=3), "binning"),
    (dict(roi_y=600), "roi.y_offset/height"),  # rows 600..1176 of a 1080-row image
    (dict(roi_x=100), "roi.x_offset/width"),  # columns 100..2020 of 1920
    (dict(roi_x=0, roi_y=0, roi_w=1, roi_h=1, binning_x=2, binning_y=2), "roi"),  # 1x1 px band: zero size
])
def test_bad_camera_info_is_a_frame_error_naming_the_field(change: dict, field: str) -> None:
    with pytest.raises(FrameError) as e:
        camera_info_crop(**{**GOOD, **change})
    assert e.value.reason == "bad_camera_info" and field in str(e.value)


def test_a_roi_outside_the_image_is_refused_not_mapped() -> None:
    """Issue 20: roi outside the image was accepted and moved a cone at 3.32 m to (0.70, -1.76) m."""
    with pytest.raises(FrameError):
        camera_info_crop(**{**GOOD, "roi_x": 1000, "roi_y": 1000})


def test_unexpected_exceptions_are_dropped_counted_by_type_and_logged(ros: RosFixture, caplog) -> None:
    node = ros.add(DriverAdapterNode(context=ros.context))
    on_raw = callback(node, Image)
    msg = Image()
    calls = []

    def explode(*a):
        calls.append(1)
        raise (KeyError if len(calls) % 2 else MemoryError)("boom")

    node.adapter.from_raw = explode
    debug = []
    node.get_logger().debug = lambda m, **k: debug.append(m)
    for _ in range(5):
        on_raw(msg)  # must not raise
    assert dict(node.stats.dropped) == {"exception_KeyError": 3, "exception_MemoryError": 2}
    assert node.stats.ok == 0 and node.stats.received == 5
    assert len(debug) == 2 and all("Traceback" in d for d in debug)  # once per type, with the traceback
    st = node.health.streams["/image_raw"]
    assert (st.received, st.ok, st.dropped) == (5, 0, 5)


def test_compressed_bombs_do_not_kill_the_adapter_node(ros: RosFixture) -> None:
    node = ros.add(DriverAdapterNode(context=ros.context,
                                     parameter_overrides=[Parameter("input_transport", value="compressed")]))
    on_compressed = callback(node, CompressedImage)
    for data in (png_bomb(), jpeg_bomb(), b"\x00garbage", b""):
        msg = CompressedImage()
        msg.data = data
        on_compressed(msg)
    good = CompressedImage()
    import cv2

    good.data = cv2.imencode(".jpg", np.zeros((H, W, 3), np.uint8))[1].tobytes()
    on_compressed(good)
    assert node.stats.ok == 1
    assert dict(node.stats.dropped) == {"too_large": 2, "unsupported_format": 1, "undecodable": 1}


class _FakeDetector:
    """A fixed-size network for one band (as ONNX Runtime from a checkpoint)."""

    def __init__(self, band):
        self.band, self.imgsz = band, band

    def runs_band_as_is(self, band) -> bool:
        return tuple(band) == tuple(self.band)


def test_detection_node_validates_camera_info_and_builds_at_most_a_few_networks(ros: RosFixture) -> None:
    from cone_perception.nodes.detection import MAX_NETWORK_BANDS, DetectionNode

    node = ros.add(DetectionNode(context=ros.context, parameter_overrides=[Parameter("backend", value="torch")]))
    built = []
    node.loader.load = lambda band=None: built.append(band) or _FakeDetector(band)
    node.detector = node.networks[0] = _FakeDetector((960, 288))
    on_info = callback(node, CameraInfo)

    def info(**change) -> CameraInfo:
        f = CALIB.crop.camera_info_fields(W, H)
        msg = _msgs.camera_info(f, Image().header)
        for k, v in change.items():
            obj, attr = (msg.roi, k[4:]) if k.startswith("roi_") else (msg, k)
            setattr(obj, attr, v)
        return msg

    on_info(info())
    assert node.crop == CALIB.crop and built == []
    for bad in (dict(width=0), dict(roi_x_offset=1000, roi_y_offset=1000), dict(binning_x=1000, binning_y=1000),
                dict(roi_width=2, roi_height=1, binning_x=2, binning_y=2)):
        on_info(info(**bad))  # must not raise
    assert node.stats.dropped["bad_camera_info"] == 4 and node.crop == CALIB.crop
    bands = [(1920, 576), (960, 540), (480, 144), (1920, 1080)]
    for b in bands:  # each full-image px band at downscale 1 (or 2, 4)
        ds = {(1920, 576): 1, (960, 540): 2, (480, 144): 4, (1920, 1080): 1}[b]
        on_info(info(roi_height=b[1] * ds, roi_y_offset=H - b[1] * ds, binning_x=ds, binning_y=ds))
        on_info(info(roi_height=b[1] * ds, roi_y_offset=H - b[1] * ds, binning_x=ds, binning_y=ds))  # again
    assert built == bands[:MAX_NETWORK_BANDS]  # each band built once, then refused
    assert node.stats.dropped["band_limit"] == 2
    on_info(info())  # back to the model's own band: no rebuild
    assert node.detector.band == (960, 288) and len(built) == MAX_NETWORK_BANDS
    assert node.stats.ok == 0  # camera_info is not a frame, but every one is counted on its topic
    st = node.health.streams["/image_cropped/camera_info"]
    assert st.received == st.ok + st.dropped == 1 + 4 + 8 + 1 and st.dropped == 4 + 2


def test_the_counting_path_counts_every_frame_and_survives_any_bytes(ros, monkeypatch) -> None:  # noqa: F811
    """Where callbacks get no sequence numbers (Humble), the image input's second subscription (raw
    bytes, own callback group) reads only the stamp of every frame."""
    from rclpy.serialization import serialize_message

    from cone_perception.nodes import _common
    from cone_perception.nodes.driver_adapter import DriverAdapterNode

    monkeypatch.setattr(_common, "COUNTING_PATH", True)

    node = ros.add(DriverAdapterNode(context=ros.context))
    counting = [s for s in node.subscriptions if s.msg_type is Image and s.raw]
    assert len(counting) == 1 and counting[0].callback_group is not node.default_callback_group
    st = node.health.streams["/image_raw"]
    m = Image()
    m.header.stamp.sec = 5
    for raw in (b"", b"\xff" * 3, b"\x00\x01" + b"\xff" * 40, serialize_message(m)):
        counting[0].callback(raw)
    assert st.arrived == 4 and st.counted and st.last_stamp_ns == 5 * 10**9
