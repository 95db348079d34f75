"""detect on video files, its exit codes, and the band in --save-vis."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cone_perception.cli import main as cli_main
from cone_perception.data.predictions import read_predictions

from synthetic_cones import trained_smoke_model


@pytest.fixture(scope="module")
def smoke():
    ckpt, root, _ = trained_smoke_model()
    frames = [cv2.imread(str(p)) for p in sorted((root / "images").glob("*.png"))]
    return ckpt, frames


def _write_video(path, frames, fourcc):
    h, w = frames[0].shape[:2]
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 10.0, (w, h))
    assert vw.isOpened(), f"this OpenCV cannot write {fourcc}"
    for f in frames:
        vw.write(f)
    vw.release()


@pytest.mark.parametrize("suffix, fourcc", [(".mp4", "mp4v"), (".avi", "MJPG")])
def test_detect_reads_videos_every_n_with_frame_index(smoke, tmp_path, suffix, fourcc, capsys):
    ckpt, frames = smoke
    video = tmp_path / f"clip{suffix}"
    _write_video(video, frames[:7], fourcc)
    out = tmp_path / "p.jsonl"
    assert cli_main(["detect", str(video), "--model", str(ckpt), "--every", "3", "--out", str(out),
                     "--no-progress", "--save-vis", str(tmp_path / "vis")]) == 0
    preds = list(read_predictions(out))
    assert [p.image for p in preds] == ["clip_000000", "clip_000003", "clip_000006"]
    h, w = frames[0].shape[:2]
    assert all((p.width, p.height) == (w, h) for p in preds)
    assert sum(len(p.boxes) for p in preds) > 0  # the smoke model finds its cones in the (compressed) frames
    assert sorted(f.name for f in (tmp_path / "vis").iterdir()) == ["clip_000000.jpg", "clip_000003.jpg", "clip_000006.jpg"]
    assert "3 images ->" in capsys.readouterr().out


def test_video_that_cannot_be_opened_exits_2_naming_it(smoke, tmp_path, capsys):
    ckpt, _ = smoke
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"not a video at all" * 10)
    assert cli_main(["detect", str(bad), "--model", str(ckpt), "--out", str(tmp_path / "p.jsonl"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "video" in err


def test_no_readable_image_is_an_error(smoke, tmp_path, capsys):
    ckpt, _ = smoke
    folder = tmp_path / "imgs"
    folder.mkdir()
    (folder / "a.jpg").write_bytes(b"garbage")
    (folder / "b.png").write_bytes(b"garbage")
    assert cli_main(["detect", str(folder), "--model", str(ckpt), "--out", str(tmp_path / "p.jsonl"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "no image could be read (2 inputs skipped" in err and "a.jpg" in err
    assert cli_main(["detect", str(folder), "--model", str(ckpt), "--every", "0", "--out", str(tmp_path / "p.jsonl"),
                     "--no-progress"]) == 2


def test_save_vis_with_crop_draws_the_band(smoke, tmp_path):
    ckpt, frames = smoke
    h, w = frames[0].shape[:2]
    big = np.vstack([np.full((h, w, 3), 200, np.uint8), frames[0], np.full((h, w, 3), 200, np.uint8)])
    folder = tmp_path / "imgs"
    folder.mkdir()
    cv2.imwrite(str(folder / "f.png"), big)
    assert cli_main(["detect", str(folder), "--model", str(ckpt), "--crop", f"{h},{2 * h}", "--out",
                     str(tmp_path / "p.jsonl"), "--no-progress", "--save-vis", str(tmp_path / "vis")]) == 0
    vis = cv2.imread(str(tmp_path / "vis" / "f.jpg"))
    # outside the band darkened, the band's outline drawn in green
    assert vis[5:h - 5, 5:w - 5].mean() < 0.7 * 200
    assert vis[2 * h + 30:, :].mean() < 0.7 * 200
    edge = vis[h - 1 : h + 2, w // 2]
    assert (edge[:, 1].astype(int) - edge[:, 2].astype(int)).max() > 100  # green line at the band's top


def test_detect_on_a_bag_every_n_names_frames_by_stamp(smoke, tmp_path):
    import json

    ckpt, _ = smoke
    bag = tmp_path / "drive"
    assert cli_main(["synth", "bag", "--seconds", "0.5", "--fps", "10", "--out", str(bag), "--size", "320x180",
                     "--no-progress"]) == 0
    stamps = [json.loads(l)["stamp_ns"] for l in (tmp_path / "drive_gt.jsonl").read_text().splitlines()]
    out = tmp_path / "p.jsonl"
    assert cli_main(["detect", str(bag), "--model", str(ckpt), "--every", "2", "--out", str(out), "--no-progress"]) == 0
    assert [p.image for p in read_predictions(out)] == [str(s) for s in stamps[::2]]
