"""Replay on bad bags: a missing topic, a corrupt bag, corrupt frames among good ones."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cone_perception.cli import main
from cone_perception.data import bagio
from cone_perception.data.bags import find_image_topic
from cone_perception.detector import Detector, default_model_path
from cone_perception.errors import ConfigError
from cone_perception.geometry.calib import load_calibration
from cone_perception.pipeline import Pipeline
from cone_perception.replay import offline_replay


def _frame(i: int) -> np.ndarray:
    rng = np.random.default_rng(i)
    return rng.integers(60, 200, (1080, 1920, 3), dtype=np.uint8)


@pytest.fixture(scope="module")
def bad_bag(tmp_path_factory) -> Path:
    """6 frames: 0, 2, 5 good; 1 odd-width YUYV, 3 unknown encoding, 4 CDR bytes cut short."""
    path = tmp_path_factory.mktemp("bad") / "bag"
    with bagio.BagWriter(path, {"/camera/image_raw": bagio.IMAGE}) as w:
        for i in range(6):
            stamp = 1_000_000_000 + i * 50_000_000
            msg = bagio.image_msg_from_bgr(_frame(i), stamp, "camera")
            if i == 1:
                msg.width = 1919
            if i == 3:
                msg.encoding = "mono16"
            raw = bagio.TYPESTORE.serialize_cdr(msg, bagio.IMAGE)
            if i == 4:
                raw = raw[: len(raw) // 3]
            w.write_raw("/camera/image_raw", stamp, raw)
    return path


def test_corrupt_frames_are_dropped_counted_and_the_rest_processed(bad_bag: Path) -> None:
    det = Detector.load(default_model_path())
    res = offline_replay(bad_bag, Pipeline(load_calibration("example_mainhoop"), det))
    assert res.stats.ok == 3 and sorted(res.cones) == [1_000_000_000, 1_100_000_000, 1_250_000_000]
    assert dict(res.stats.dropped) == {"odd_width": 1, "unknown_encoding": 1, "corrupt_message": 1}
    assert len(res.drops) == 3


def test_replay_command_reports_the_dropped_frames(bad_bag: Path, capsys) -> None:
    assert main(["replay", str(bad_bag), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "3 frames processed" in out and "3 dropped" in out and "odd_width=1" in out


def test_bag_without_the_topic(bad_bag: Path, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="/nope") as e:
        find_image_topic(bad_bag, "/nope")
    assert str(bad_bag) in str(e.value)
    only_gt = tmp_path / "gt_only"
    with bagio.BagWriter(only_gt, {"/cones_gt": bagio.POINTCLOUD2}):
        pass
    with pytest.raises(ConfigError, match="no sensor_msgs/Image"):
        find_image_topic(only_gt)
    assert main(["replay", str(only_gt), "--no-progress"]) == 2


def test_corrupt_and_missing_bags(bad_bag: Path, tmp_path: Path, capsys) -> None:
    broken = tmp_path / "broken"
    broken.mkdir()
    for f in bad_bag.iterdir():
        data = f.read_bytes()
        (broken / f.name).write_bytes(data if f.suffix == ".yaml" else data[: len(data) // 2])
    assert main(["replay", str(broken), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "broken" in err and "error" in err
    assert main(["replay", str(tmp_path / "missing"), "--no-progress"]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_header_bombs_in_a_bag_are_dropped_and_the_rest_processed(tmp_path: Path, capsys) -> None:
    """Issue 20: one 69-byte PNG declaring 100000x100000 px killed replay and detect."""
    from cone_perception.data.hostile import jpeg_bomb, png_bomb

    path = tmp_path / "bombs"
    with bagio.BagWriter(path, {"/camera/image_raw/compressed": bagio.COMPRESSED_IMAGE}) as w:
        for i in range(4):
            stamp = 1_000_000_000 + i * 50_000_000
            msg = bagio.compressed_msg_from_bgr(_frame(i), stamp, "camera")
            if i in (1, 2):
                msg.data = np.frombuffer(png_bomb() if i == 1 else jpeg_bomb(), np.uint8)
            w.write("/camera/image_raw/compressed", stamp, msg)
    res = offline_replay(path, Pipeline(load_calibration("example_mainhoop"), Detector.load(default_model_path())))
    assert res.stats.ok == 2 and dict(res.stats.dropped) == {"too_large": 2}
    assert main(["detect", str(path), "--out", str(tmp_path / "p.jsonl"), "--no-progress"]) == 0
    assert "2 images" in capsys.readouterr().out
