"""Dataset converters: FSOCO Supervisely -> YOLO (border crop, per-team split) and 16:9 restore."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import yaml

from cone_perception.cli import main as cli_main
from cone_perception.data.convert import content_rect, fsoco_to_yolo, restore_aspect
from cone_perception.errors import ConfigError

BORDER = 20


def _fsoco(root, teams=("teamA", "teamB"), per_team=5):
    """Images 200x120 with a 20 px black border holding a white 'logo', one blue box each."""
    (root / "meta.json").parent.mkdir(parents=True, exist_ok=True)
    (root / "meta.json").write_text(json.dumps({"classes": []}))
    for t in teams:
        (root / t / "ann").mkdir(parents=True)
        (root / t / "img").mkdir(parents=True)
        for i in range(per_team):
            img = np.zeros((120, 200, 3), np.uint8)
            img[BORDER:-BORDER, BORDER:-BORDER] = 90 + i
            img[125 - 20 - 10 : 120 - 5, 150:190] = 255  # logo in the bottom border
            img[105 - 12 : 105, 150:190] = 255
            name = f"{t}_{i:02d}.jpg"
            cv2.imwrite(str(root / t / "img" / name), img)
            objs = [
                {"classTitle": "blue_cone", "geometryType": "rectangle", "points": {"exterior": [[50, 40], [70, 80]], "interior": []}},
                {"classTitle": "traffic_cone_xl", "geometryType": "rectangle", "points": {"exterior": [[10, 10], [20, 20]], "interior": []}},
                {"classTitle": "yellow_cone", "geometryType": "polygon", "points": {"exterior": [[1, 1], [2, 2], [3, 1]], "interior": []}},
            ]
            (root / t / "ann" / f"{name}.json").write_text(json.dumps({"size": {"height": 120, "width": 200}, "objects": objs}))


def test_content_rect_ignores_logo_in_border():
    img = np.zeros((120, 200, 3), np.uint8)
    img[20:100, 20:180] = 100
    img[105:115, 150:190] = 255  # logo
    assert content_rect(img) == (20, 20, 180, 100)
    assert content_rect(np.full((10, 10, 3), 50, np.uint8)) == (0, 0, 10, 10)


def test_fsoco_to_yolo_crops_shifts_and_splits_per_team(tmp_path):
    _fsoco(tmp_path / "fsoco")
    rep = fsoco_to_yolo(tmp_path / "fsoco", tmp_path / "out", progress=False)
    assert rep.images == 10 and rep.boxes == 10
    assert rep.per_split == {"train": 8, "val": 2}
    assert rep.skipped == {"unknown_class": 10, "not_rectangle": 10}
    val = sorted(p.name for p in (tmp_path / "out" / "images" / "val").iterdir())
    assert len(val) == 2 and val[0].startswith("teamA_") and val[1].startswith("teamB_")  # one per team
    name = sorted((tmp_path / "out" / "labels" / "train").iterdir())[0]
    img = cv2.imread(str(tmp_path / "out" / "images" / "train" / (name.stem + ".jpg")))
    assert img.shape[:2] == (80, 160)  # border cropped
    c, cx, cy, w, h = (float(v) for v in name.read_text().split())
    assert c == 0
    # box (50,40)-(70,80) in the original -> (30,20)-(50,60) in the cropped 160x80 image
    np.testing.assert_allclose([cx * 160, cy * 80, w * 160, h * 80], [40, 40, 20, 40], atol=1e-3)
    doc = yaml.safe_load((tmp_path / "out" / "data.yaml").read_text())
    assert doc["names"][0] == "blue" and doc["train"][0]["images"] == "images/train"
    with pytest.raises(ConfigError, match="Supervisely"):
        fsoco_to_yolo(tmp_path / "out", tmp_path / "out2", progress=False)


def test_restore_aspect_command(tmp_path, capsys):
    src = tmp_path / "sq"
    (src / "images").mkdir(parents=True)
    (src / "labels").mkdir()
    cv2.imwrite(str(src / "images" / "a-1.jpg"), np.full((64, 64, 3), 100, np.uint8))
    (src / "labels" / "a-1.txt").write_text("0 0.5 0.5 0.1 0.2\n")
    cv2.imwrite(str(src / "images" / "b-1.jpg"), np.full((64, 64, 3), 100, np.uint8))
    (src / "README.md").write_text("x")
    (src / "classes.txt").write_text("blue_cone\n")
    rc = cli_main(["data", "restore-aspect", str(src), str(tmp_path / "out"), "--aspect", "16:9"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "wrote 2 images, 1 box " in out and "no_label: 1" in out
    assert cv2.imread(str(tmp_path / "out" / "images" / "a-1.jpg")).shape[:2] == (36, 64)
    assert (tmp_path / "out" / "labels" / "a-1.txt").read_text() == "0 0.5 0.5 0.1 0.2\n"
    assert (tmp_path / "out" / "README.md").is_file()
    assert yaml.safe_load((tmp_path / "out" / "data.yaml").read_text()) == {"train": "images", "names": ["blue_cone"]}
    with pytest.raises(ConfigError):
        restore_aspect(src, src, progress=False)
    # car-size copy of one clip: width set, other clips left out, labels unchanged
    rc = cli_main(["data", "restore-aspect", str(src), str(tmp_path / "big"), "--width", "128", "--clips", "a"])
    assert rc == 0 and "wrote 1 image, 1 box " in capsys.readouterr().out
    assert cv2.imread(str(tmp_path / "big" / "images" / "a-1.jpg")).shape[:2] == (72, 128)
    assert not (tmp_path / "big" / "images" / "b-1.jpg").exists()
    assert (tmp_path / "big" / "labels" / "a-1.txt").read_text() == "0 0.5 0.5 0.1 0.2\n"
    with pytest.raises(ConfigError, match="no images of clips"):
        restore_aspect(src, tmp_path / "none", clips=["zzz"], progress=False)
