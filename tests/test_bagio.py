"""rosbag2 (MCAP) writing and reading through cone_perception.data.bagio."""

import cv2
import numpy as np
import pytest

from cone_perception.adapter import crop_raw_to_bgr, decode_compressed, raw_frame_view
from cone_perception.crop import CropSpec
from cone_perception.data import bagio
from cone_perception.errors import ConfigError
from cone_perception.records import CONE_DTYPE, from_pointcloud2, to_pointcloud2


def _image(seed: int, w: int = 64, h: int = 32) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = cv2.resize(rng.integers(0, 255, (h // 8, w // 8, 3), dtype=np.uint8), (w, h), interpolation=cv2.INTER_LINEAR)
    return img


def test_round_trip_image_compressed_and_cloud(tmp_path):
    path = tmp_path / "bag"
    stamps = [1_700_000_000_000_000_000 + i * 50_000_000 for i in range(3)]
    recs = []
    msgs = []
    for i, t in enumerate(stamps):
        img = _image(i)
        msgs.append(("/cam/raw", t, bagio.image_msg_from_bgr(img, t, "camera")))
        msgs.append(("/cam/bgr", t, bagio.image_msg_from_bgr(img, t, "camera", encoding="bgr8")))
        msgs.append(("/cam/jpeg", t, bagio.compressed_msg_from_bgr(img, t, "camera", quality=95)))
        r = np.zeros(i + 1, dtype=CONE_DTYPE)
        r["x"] = np.arange(i + 1) + 0.5
        r["y"] = -1.25
        r["class_id"] = i
        r["score"] = 1.0
        recs.append(r)
        msgs.append(("/cones_gt", t, to_pointcloud2(r, bagio.header(t, "rear_axle"), bagio.PointCloud2, bagio.PointField)))
    topics = {"/cam/raw": bagio.IMAGE, "/cam/bgr": bagio.IMAGE, "/cam/jpeg": bagio.COMPRESSED_IMAGE, "/cones_gt": bagio.POINTCLOUD2}
    counts = bagio.write_bag(path, topics, msgs)
    assert counts == {t: 3 for t in topics}
    assert list(path.glob("*.mcap")), "storage must be MCAP"
    assert bagio.bag_topics(path) == {t: (ty, 3) for t, ty in topics.items()}

    bgr = list(bagio.read_messages(path, "/cam/bgr"))
    assert [m.log_stamp_ns for m in bgr] == stamps
    for i, m in enumerate(bgr):
        assert bagio.stamp_ns(m.msg.header) == stamps[i] and m.msg.header.frame_id == "camera"
        got = np.asarray(m.msg.data).reshape(m.msg.height, m.msg.width, 3)
        assert np.array_equal(got, _image(i))
    for i, m in enumerate(bagio.read_messages(path, "/cam/raw")):
        assert m.msg.encoding == "yuv422_yuy2" and m.msg.step == 2 * m.msg.width
        name, view = raw_frame_view(m.msg.encoding, m.msg.width, m.msg.height, m.msg.step, m.msg.data)
        back = crop_raw_to_bgr(name, view, CropSpec.full_image(m.msg.width, m.msg.height))
        assert np.abs(back.astype(int) - _image(i).astype(int)).mean() < 6  # YUYV halves the chroma
    for i, m in enumerate(bagio.read_messages(path, "/cam/jpeg")):
        assert m.msg.format == "jpeg"
        assert np.abs(decode_compressed(m.msg.data).astype(int) - _image(i).astype(int)).mean() < 6
    clouds = list(bagio.read_messages(path, ["/cones_gt"]))
    for i, m in enumerate(clouds):
        back = from_pointcloud2(m.msg, CONE_DTYPE)
        assert np.array_equal(back, recs[i])
        # raw CDR equals a fresh serialisation of the deserialised message
        assert bytes(bagio.TYPESTORE.serialize_cdr(m.msg, m.msgtype)) == m.raw
    # all topics interleaved in time order
    everything = list(bagio.read_messages(path))
    assert len(everything) == 12
    assert [m.log_stamp_ns for m in everything] == sorted(m.log_stamp_ns for m in everything)


def test_errors_name_the_bag_and_topic(tmp_path):
    path = tmp_path / "bag"
    bagio.write_bag(path, {"/a": bagio.IMAGE}, [("/a", 1, bagio.image_msg_from_bgr(_image(0), 1, "c"))])
    with pytest.raises(ConfigError, match="/b.*topic not in bag"):
        list(bagio.read_messages(path, "/b"))
    with pytest.raises(ConfigError, match="already exists"):
        bagio.BagWriter(path, {"/a": bagio.IMAGE})
    with pytest.raises(ConfigError, match="does not exist"):
        list(bagio.read_messages(tmp_path / "nope"))
    (tmp_path / "notabag").mkdir()
    with pytest.raises(ConfigError, match="cannot open as rosbag2"):
        bagio.bag_topics(tmp_path / "notabag")
