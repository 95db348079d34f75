"""Inference: checkpoint validation, backends agree with eager, external YOLO layout, crop mapping, export."""

from __future__ import annotations

import logging

import cv2
import numpy as np
import pytest
import torch
import yaml

from cone_perception import records
from cone_perception.classes import CLASS_NAMES
from cone_perception.cli import main as cli_main
from cone_perception.crop import CropSpec
from cone_perception.detector import Detector, default_model_path, resolve_backend, write_sidecar
from cone_perception.detector.export import export_model, onnx_bytes
from cone_perception.errors import ConfigError
from cone_perception.model import ConeYOLO, model_config
from cone_perception.model.checkpoint import load_checkpoint, save_checkpoint

from synthetic_cones import SMOKE_SIZE, assert_same_cones, trained_smoke_model


@pytest.fixture(scope="module")
def trained():
    ckpt, root, _ = trained_smoke_model()
    images = sorted((root / "images").glob("*.png"))
    return ckpt, [cv2.imread(str(p)) for p in images]


def _as_arrays(recs):
    b, s, c = records.boxes_to_arrays(recs)
    return b, s, c


def test_default_model_path_is_under_models():
    p = default_model_path()
    assert p.parent.name == "models" and p.suffix == ".pt"


@pytest.mark.parametrize("backend", ["torchscript", "onnx"])
def test_backends_give_eager_boxes(trained, backend):
    ckpt, images = trained
    eager = Detector.load(ckpt, backend="torch")
    other = Detector.load(ckpt, backend=backend)
    # the same numbers up to float rounding (1e-3 allowed): a cone within that of the threshold may cross it
    n_pairs = sum(assert_same_cones(eager, other, img, box_px=1e-3, score_tol=1e-3) for img in images)
    assert n_pairs >= len(images)



def _spinning(det) -> str:
    """The ``session.intra_op.allow_spinning`` entry of an ONNX Runtime detector's session ("" if unset)."""
    opts = det._run.session.get_session_options()
    try:
        return opts.get_session_config_entry("session.intra_op.allow_spinning")
    except Exception:  # noqa: BLE001 - onnxruntime raises when the entry was never set
        return ""


def test_onnx_pool_threads_do_not_spin_and_the_boxes_stay(trained):
    """An ONNX Runtime session with an intra-op pool (threads >= 2, or 0 = one a core) has its threads sleep
    after their work (``allow_spinning`` 0: a spinning pool lost ticks to other work, docs/benchmarks.md);
    a one-thread session keeps ONNX Runtime's default; the boxes are the same either way."""
    ckpt, images = trained
    one, two, auto = (Detector.load(ckpt, backend="onnx", threads=t) for t in (1, 2, 0))
    assert _spinning(one) == "" and _spinning(two) == "0" and _spinning(auto) == "0"
    assert two._run.session.get_session_options().intra_op_num_threads == 2
    n_pairs = sum(assert_same_cones(one, two, img, box_px=1e-4, score_tol=1e-4) for img in images)
    assert n_pairs >= len(images)


def test_auto_backend_picks_onnx_runtime_on_the_cpu_and_keeps_the_boxes(trained, monkeypatch, tmp_path):
    """``auto`` (the default): ONNX Runtime for a checkpoint on the CPU, with eager torch's boxes;
    torch where ONNX Runtime cannot serve (bf16, a GPU, not installed); an exported file its own."""
    ckpt, images = trained
    det = Detector.load(ckpt)
    assert det.backend == "onnx" and "backend onnx" in det.describe()
    eager = Detector.load(ckpt, backend="torch")
    for img in images[:3]:
        np.testing.assert_allclose(_as_arrays(det.detect_image(img))[0], _as_arrays(eager.detect_image(img))[0], atol=1e-3)
    assert Detector.load(ckpt, bf16=True).backend == "torch"
    assert resolve_backend("auto", "m.pt", device="cuda") == "torch"
    assert resolve_backend("auto", "m.pt", fp16=True) == "torch"
    assert resolve_backend("auto", "m.onnx") == "onnx" and resolve_backend("auto", "m.torchscript") == "torchscript"
    assert resolve_backend("torch", "m.pt") == "torch"
    modules = __import__("sys").modules
    with monkeypatch.context() as m:  # onnx missing: torch's exporter cannot build the ONNX network
        m.setitem(modules, "onnx", None)
        m.setenv("XDG_CACHE_HOME", str(tmp_path))  # an empty ONNX cache: the graph must be exported
        assert Detector.load(ckpt).backend == "torch"
        with pytest.raises(ConfigError, match="pip install onnx"):
            Detector.load(ckpt, backend="onnx")
    monkeypatch.setitem(modules, "onnxruntime", None)  # import fails: not installed
    assert resolve_backend("auto", "m.pt") == "torch"
    assert Detector.load(ckpt).backend == "torch"
    with pytest.raises(ConfigError, match="unknown backend 'tensorrt'.*auto, torch"):
        Detector.load(ckpt, backend="tensorrt")

def test_bf16_gives_the_fp32_boxes_and_is_refused_where_it_does_not_apply(trained, tmp_path):
    """bf16 autocast on the CPU: the same cones (box decoding stays fp32, so boxes within a fraction of a
    pixel and scores within bf16 rounding, 0.03); a cone may appear or vanish only where its fp32 score
    lies within that of the threshold, on any CPU (the smoke model and its near-threshold cones differ by
    CPU), also with the threshold set to a cone's own score; refused for other backends, GPUs and exported
    files."""
    ckpt, images = trained
    fp32 = Detector.load(ckpt, backend="torch")
    bf16 = Detector.load(ckpt, backend="torch", bf16=True)
    assert (fp32.precision, bf16.precision) == ("fp32", "bf16")
    pairs = sum(assert_same_cones(fp32, bf16, img, box_px=1.0, score_tol=0.03) for img in images)
    assert pairs >= len(images)
    _, s0, _ = _as_arrays(fp32.detect_image(images[0]))
    fp32.conf = bf16.conf = float(np.median(s0))  # a cone exactly at the threshold: fp32 drops it, bf16 may not
    for img in images[:2]:
        assert_same_cones(fp32, bf16, img, box_px=1.0, score_tol=0.03)
    for kw in ({"backend": "onnx"}, {"backend": "torchscript"}):
        with pytest.raises(ConfigError, match="bf16"):
            Detector.load(ckpt, bf16=True, **kw)
    onnx = tmp_path / "m.onnx"
    export_model(load_checkpoint(ckpt).build_model(), SMOKE_SIZE, "onnx", onnx)
    with pytest.raises(ConfigError, match="bf16.*exported"):
        Detector.load(onnx, backend="onnx", bf16=True)



def test_bf16_on_a_cpu_without_native_bf16_says_it_is_slower(trained, monkeypatch, caplog):
    """bf16 stays allowed where the CPU emulates it (same boxes), with a warning that fp32 is faster there;
    a cap on oneDNN's instruction set (ONEDNN_MAX_CPU_ISA=AVX512_CORE) counts as such a CPU."""
    from cone_perception.detector import torch_backend

    ckpt, _ = trained
    monkeypatch.setenv("ONEDNN_MAX_CPU_ISA", "avx512_core")
    assert not torch_backend.native_bf16()
    with caplog.at_level(logging.WARNING):
        assert Detector.load(ckpt, backend="torch", bf16=True).precision == "bf16"
        Detector.load(ckpt, backend="torch")
    assert [r.message for r in caplog.records if "bf16" in r.message] == [
        "bf16: this CPU has no native bfloat16 (AVX512-BF16 or AMX), so autocast emulates it and runs slower than "
        "fp32; leave bf16 off here (the boxes are the same)"]
    caplog.clear()
    monkeypatch.setattr(torch_backend, "native_bf16", lambda: True)
    with caplog.at_level(logging.WARNING):
        Detector.load(ckpt, backend="torch", bf16=True)
    assert not [r for r in caplog.records if "bf16" in r.message]


def test_detect_maps_crop_and_downscale_to_full_image(trained):
    ckpt, images = trained
    det = Detector.load(ckpt, backend="torch")
    img = images[0]
    crop = CropSpec(v0=400, v1=400 + 2 * img.shape[0], u0=100, u1=100 + 2 * img.shape[1], downscale=2)
    full = det.detect(img, crop)
    local = det.detect_image(img)
    assert len(full) == len(local) > 0
    b_full, _, _ = _as_arrays(full)
    b_loc, _, _ = _as_arrays(local)
    np.testing.assert_allclose(b_full, b_loc * 2 + np.array([100, 400, 100, 400]), atol=1e-3)
    assert set(det.timing) == {"preprocess_ms", "forward_ms", "postprocess_ms"}
    assert full.dtype == records.BOX_DTYPE
    assert "backend torch" in det.describe() and "size p" in det.describe()


def test_size_not_multiple_of_32_is_padded_and_said_once(trained, caplog):
    ckpt, images = trained
    det = Detector.load(ckpt, backend="torch")
    img = images[1]
    odd = np.ascontiguousarray(img[:90, :250])  # 250x90 -> padded to 256x96
    with caplog.at_level(logging.WARNING):
        a = det.detect_image(img)
        b = det.infer(odd)
        det.infer(odd)
    assert sum("padded to 256x96" in r.message for r in caplog.records) == 1
    assert len(b[0]) > 0
    assert b[0][:, 2].max() <= 250 and b[0][:, 3].max() <= 90
    del a



def test_fixed_size_backend_says_padded_or_letterboxed(trained, caplog):
    """A fixed-size network pads an image that fits at scale 1 (as eager torch does) and says so
    (the runtime table's 960x540 in 960x544); only an image that must be scaled is called letterboxed."""
    ckpt, images = trained
    det = Detector.load(ckpt, backend="onnx")
    w, h = det.imgsz
    with caplog.at_level(logging.WARNING):
        det.infer(np.ascontiguousarray(images[1][: h - 6, :w]))  # full width: scale 1, rows padded
        det.infer(cv2.resize(images[1], (2 * w, 2 * h)))
    msgs = [r.message for r in caplog.records]
    assert f"image {w}x{h - 6} padded to the model input {w}x{h}" in msgs
    assert f"image {2 * w}x{2 * h} letterboxed to the model input {w}x{h}" in msgs

def test_external_layout_with_permuted_class_names(tmp_path, trained):
    """An export in the common layout whose classes are in another tool's order and naming."""
    ckpt, images = trained
    ck = load_checkpoint(ckpt)
    model = ck.build_model().fuse()
    perm = [3, 0, 2, 1, 4]  # external class k = project class perm[k]
    foreign_names = ["large_orange_cone", "blue_cone", "orange_cone", "yellow_cone", "unknown_cone"]

    class Foreign(torch.nn.Module):
        def __init__(self, m):
            super().__init__()
            self.m = m

        def forward(self, x):
            y = self.m(x)
            return torch.cat([y[:, :4], y[:, 4:][:, perm]], 1)

    w, h = SMOKE_SIZE
    ts = torch.jit.trace(Foreign(model).eval(), torch.rand(1, 3, h, w))
    ts_path = tmp_path / "foreign.torchscript"
    ts.save(str(ts_path))
    write_sidecar(ts_path, foreign_names, SMOKE_SIZE)
    onnx_path = tmp_path / "foreign_onnx.onnx"
    torch.onnx.export(Foreign(model).eval(), (torch.rand(1, 3, h, w),), str(onnx_path), opset_version=17, dynamo=False)
    # ONNX sidecar as {index: name} and without imgsz: the ONNX input shape gives it
    (tmp_path / "foreign_onnx.yaml").write_text(yaml.safe_dump({"names": {i: n for i, n in enumerate(foreign_names)}}))

    eager = Detector.load(ckpt, backend="torch")
    for path, backend in ((ts_path, "torchscript"), (onnx_path, "onnx")):
        det = Detector.load(path, backend=backend)
        assert det.imgsz == SMOKE_SIZE
        assert sum(assert_same_cones(eager, det, img, box_px=1e-3, score_tol=1e-3) for img in images[:3]) > 0


def test_external_model_bad_output_shape_and_names(tmp_path):
    class Wrong(torch.nn.Module):
        def forward(self, x):
            return x.mean(1, keepdim=True).flatten(2).repeat(1, 7, 1)  # (1, 7, N): 3 classes, not 5

    p = tmp_path / "wrong.onnx"
    torch.onnx.export(Wrong(), (torch.rand(1, 3, 64, 64),), str(p), opset_version=17, dynamo=False)
    write_sidecar(p, ["blue", "yellow", "orange", "large_orange", "unknown"], (64, 64))
    with pytest.raises(ConfigError, match=r"expected output \(1, 4 \+ 5, N\)"):
        Detector.load(p, backend="onnx")
    write_sidecar(p, ["blue", "yellow", "traffic_light"], (64, 64))
    with pytest.raises(ConfigError, match=r"names\[2\]|class_names\[2\]"):
        Detector.load(p, backend="onnx")
    (tmp_path / "wrong.onnx.yaml").unlink()
    with pytest.raises(ConfigError, match="sidecar"):
        Detector.load(p, backend="onnx")
    with pytest.raises(ConfigError, match="backend 'onnx'"):
        write_sidecar(p, list(CLASS_NAMES), (64, 64))
        Detector.load(p, backend="torch")


def test_bad_checkpoints(tmp_path):
    missing = tmp_path / "nope.pt"
    with pytest.raises(ConfigError, match="not found.*git checkout models/"):
        Detector.load(missing)
    m = ConeYOLO(model_config("p"))
    good = tmp_path / "good.pt"
    save_checkpoint(good, m, (320, 96))
    ck = load_checkpoint(good)
    assert ck.cfg == m.cfg and ck.imgsz == (320, 96) and ck.class_names == list(CLASS_NAMES)

    truncated = tmp_path / "trunc.pt"
    truncated.write_bytes(good.read_bytes()[:5000])
    with pytest.raises(ConfigError, match="truncated or corrupt"):
        load_checkpoint(truncated)

    obj = torch.load(good, weights_only=False)
    wrong_arch = dict(obj, arch=model_config("n").to_dict())
    torch.save(wrong_arch, tmp_path / "arch.pt")
    with pytest.raises(ConfigError, match="state_dict: weights do not fit architecture 'n'"):
        load_checkpoint(tmp_path / "arch.pt")

    torch.save(dict(obj, class_names=["blue", "yellow", "orange", "large_orange", "pylon"]), tmp_path / "names.pt")
    with pytest.raises(ConfigError, match=r"class_names\[4\]"):
        load_checkpoint(tmp_path / "names.pt")

    torch.save(dict(obj, imgsz=[300, 96]), tmp_path / "size.pt")
    with pytest.raises(ConfigError, match="imgsz"):
        load_checkpoint(tmp_path / "size.pt")

    torch.save({"weights": 1}, tmp_path / "foreign.pt")
    with pytest.raises(ConfigError, match="format"):
        load_checkpoint(tmp_path / "foreign.pt")
    with pytest.raises(ConfigError, match="backend"):
        Detector.load(good, backend="tensorrt")


@pytest.mark.parametrize("fmt", ["onnx", "torchscript"])
def test_export_command_verifies(tmp_path, trained, capsys, fmt):
    ckpt, images = trained
    suffix = ".onnx" if fmt == "onnx" else ".torchscript"
    out = tmp_path / f"model{suffix}"
    rc = cli_main(["export", "--model", str(ckpt), "--format", fmt, "--out", str(out)])
    assert rc == 0
    assert "verified against eager" in capsys.readouterr().out
    side = yaml.safe_load(out.with_name(out.name + ".yaml").read_text())
    assert side["names"] == list(CLASS_NAMES) and side["imgsz"] == list(SMOKE_SIZE)
    det = Detector.load(out, backend=fmt)
    eager = Detector.load(ckpt, backend="torch")
    assert_same_cones(eager, det, images[2], box_px=1e-3, score_tol=1e-3)


def test_external_names_embedded_like_other_yolo_tools(tmp_path, trained):
    """No sidecar: names (and imgsz as [h, w]) from ONNX metadata / TorchScript config.txt."""
    import json

    import onnx

    ckpt, images = trained
    ck = load_checkpoint(ckpt)
    w, h = SMOKE_SIZE
    names = "{0: 'blue_cone', 1: 'yellow_cone', 2: 'orange_cone', 3: 'large_orange_cone', 4: 'unknown_cone'}"
    proto = onnx.load_from_string(onnx_bytes(ck.build_model(), SMOKE_SIZE))
    for k, v in (("names", names), ("imgsz", f"[{h}, {w}]")):
        prop = proto.metadata_props.add()
        prop.key, prop.value = k, v
    onnx.save(proto, str(tmp_path / "ext.onnx"))
    model = ck.build_model().fuse()
    ts = torch.jit.trace(model, torch.rand(1, 3, h, w))
    torch.jit.save(ts, str(tmp_path / "ext.torchscript"),
                   _extra_files={"config.txt": json.dumps({"names": {str(i): n for i, n in enumerate(CLASS_NAMES)}, "imgsz": [h, w]})})
    eager = Detector.load(ckpt, backend="torch")
    for f, backend in (("ext.onnx", "onnx"), ("ext.torchscript", "torchscript")):
        det = Detector.load(tmp_path / f, backend=backend)
        assert det.imgsz == SMOKE_SIZE
        assert_same_cones(eager, det, images[0], box_px=1e-3, score_tol=1e-3)


def test_speed_command_reports_each_case(capsys):
    import json

    rc = cli_main(["speed", "--sizes", "p", "--backends", "torch", "onnx", "--bf16", "--imgsz", "128x64", "--frames", "3", "--json"])
    assert rc == 0
    rows = json.loads(capsys.readouterr().out)
    assert [(r["model"], r["backend"]) for r in rows] == [("p", "torch"), ("p", "onnx"), ("p", "torch-bf16")]
    assert all(0 < r["min_ms"] <= r["median_ms"] <= r["max_ms"] for r in rows) and rows[0]["gflops"] > 0


def test_detect_command_writes_boxes_and_the_model_input_scale(trained, tmp_path):
    ckpt, images = trained
    folder = tmp_path / "imgs"
    folder.mkdir()
    h, w = images[0].shape[:2]
    for k, img in enumerate(images[:2]):
        big = cv2.resize(img, (2 * w, 2 * h), interpolation=cv2.INTER_NEAREST)  # a band twice the model input
        cv2.imwrite(str(folder / f"f{k}.png"), big)
    out = tmp_path / "p.jsonl"
    assert cli_main(["detect", str(folder), "--model", str(ckpt), "--crop", f"0,{2 * h}", "--downscale", "2",
                     "--out", str(out), "--no-progress"]) == 0
    from cone_perception.data.predictions import read_predictions

    preds = list(read_predictions(out))
    det = Detector.load(ckpt)
    assert [p.image for p in preds] == ["f0.png", "f1.png"]
    for p in preds:
        assert (p.width, p.height, p.input_scale) == (2 * w, 2 * h, 0.5)
        img = cv2.imread(str(folder / p.image))
        want = det.detect(cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA), CropSpec(0, 2 * h, 0, 2 * w, 2))
        assert len(p.boxes) == len(want) > 0
        np.testing.assert_allclose(_as_arrays(p.boxes)[0], _as_arrays(want)[0], atol=0.02)  # file keeps 2 decimals
    # letterboxed to another input size: the scale is the letterbox ratio
    assert cli_main(["detect", str(folder), "--model", str(ckpt), "--imgsz", f"{w}x{2 * h}", "--out", str(out), "--no-progress"]) == 0
    assert {p.input_scale for p in read_predictions(out)} == {0.5}


def test_detect_command_onnx_band_runs_at_its_own_size(trained, tmp_path):
    """A fixed-size backend built from a checkpoint is rebuilt for a band of another size: the same
    boxes as eager torch at the band's native size (not letterboxed into the checkpoint's input)."""
    ckpt, images = trained
    folder = tmp_path / "imgs"
    folder.mkdir()
    h, w = images[0].shape[:2]
    big = cv2.resize(images[0], (2 * w, 2 * h), interpolation=cv2.INTER_NEAREST)
    cv2.imwrite(str(folder / "f0.png"), big)
    from cone_perception.data.predictions import read_predictions

    got = {}
    for backend in ("torch", "onnx"):
        out = tmp_path / f"{backend}.jsonl"
        assert cli_main(["detect", str(folder), "--model", str(ckpt), "--backend", backend, "--crop", f"0,{2 * h}",
                         "--out", str(out), "--no-progress"]) == 0
        (p,) = read_predictions(out)
        got[backend] = _as_arrays(p.boxes)
    assert len(got["torch"][0]) == len(got["onnx"][0]) > 0
    np.testing.assert_allclose(got["onnx"][0], got["torch"][0], atol=0.02)
    np.testing.assert_allclose(got["onnx"][1], got["torch"][1], atol=2e-3)


def test_load_for_band_sizes_checkpoints_but_not_exported_files(trained, tmp_path):
    ckpt, _ = trained
    band = (500, 190)  # -> padded to 512x192
    for backend in ("torch", "onnx"):
        assert Detector.load_for_band(ckpt, band, backend=backend).imgsz == (512, 192)
    onnx_path = export_model(load_checkpoint(ckpt).build_model(), SMOKE_SIZE, "onnx", tmp_path / "m.onnx")
    write_sidecar(onnx_path, list(CLASS_NAMES), SMOKE_SIZE)
    assert Detector.load_for_band(onnx_path, band, backend="onnx").imgsz == SMOKE_SIZE  # a fixed graph keeps its size
