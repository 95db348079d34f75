"""export: the file carries its own description (ONNX metadata_props, TorchScript config.txt), the loader
reads it so the sidecar is optional, and each exported file has its own sidecar."""

from __future__ import annotations

import ast
import json
import shutil

import pytest
import torch
import yaml

from cone_perception.classes import CLASS_NAMES
from cone_perception.cli import main as cli_main
from cone_perception.detector import Detector
from synthetic_cones import SMOKE_SIZE, assert_same_cones, trained_smoke_model


@pytest.fixture(scope="module")
def smoke():
    ckpt, root, _ = trained_smoke_model()
    import cv2

    return ckpt, cv2.imread(str(sorted((root / "images").glob("*.png"))[0]))


def test_onnx_and_torchscript_to_one_stem_carry_metadata_and_own_sidecars(smoke, tmp_path, capsys):
    import onnx

    ckpt, img = smoke
    w, h = SMOKE_SIZE
    for fmt, suffix in (("onnx", ".onnx"), ("torchscript", ".torchscript")):
        assert cli_main(["export", "--model", str(ckpt), "--format", fmt, "--out", str(tmp_path / f"m{suffix}")]) == 0
    capsys.readouterr()
    # one sidecar per file, each naming its own file's facts; they do not overwrite each other
    s_onnx = yaml.safe_load((tmp_path / "m.onnx.yaml").read_text())
    s_ts = yaml.safe_load((tmp_path / "m.torchscript.yaml").read_text())
    assert s_onnx["names"] == s_ts["names"] == list(CLASS_NAMES) and s_onnx["imgsz"] == [w, h]
    assert not (tmp_path / "m.yaml").exists()
    # ONNX metadata_props: names, input size, stride, model version, source checkpoint
    meta = {p.key: p.value for p in onnx.load(str(tmp_path / "m.onnx")).metadata_props}
    assert ast.literal_eval(meta["names"]) == dict(enumerate(CLASS_NAMES))
    assert ast.literal_eval(meta["imgsz"]) == [h, w]
    assert meta["stride"] == "32" and meta["model_version"].startswith("cone_perception.detector v")
    assert meta["source"] == str(ckpt)
    extra = {"config.txt": ""}
    torch.jit.load(str(tmp_path / "m.torchscript"), _extra_files=extra)
    assert json.loads(extra["config.txt"])["source"] == str(ckpt)
    # moved without their sidecars, both load and give eager's boxes
    moved = tmp_path / "moved"
    moved.mkdir()
    shutil.copy(tmp_path / "m.onnx", moved / "m.onnx")
    shutil.copy(tmp_path / "m.torchscript", moved / "m.torchscript")
    eager = Detector.load(ckpt, backend="torch")
    for f, backend in (("m.onnx", "onnx"), ("m.torchscript", "torchscript")):
        det = Detector.load(moved / f, backend=backend)
        assert det.imgsz == SMOKE_SIZE
        assert assert_same_cones(eager, det, img, box_px=1e-3, score_tol=1e-3) > 0
    # a sidecar in the old <stem>.yaml place is still read (other tools, older exports)
    (moved / "m.yaml").write_text(yaml.safe_dump({"names": ["blue", "yellow", "traffic_light"]}))
    from cone_perception.errors import ConfigError

    with pytest.raises(ConfigError, match=r"m\.yaml.*names\[2\]|class_names\[2\]"):
        Detector.load(moved / "m.onnx", backend="onnx")
