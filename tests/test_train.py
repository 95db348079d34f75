"""Trainer: overfit smoke test, exact resume, datasets with bad inputs, augmentation keeps colours."""

from __future__ import annotations

import logging

import cv2
import numpy as np
import pytest
import yaml

from cone_perception.data.datasets import load_data_yaml
from cone_perception.errors import ConfigError
from cone_perception.train.augment import AugmentConfig, hflip, hsv_jitter, random_window
from cone_perception.train.loader import EpochSampler, TrainSet, collate, epoch_order
from cone_perception.train.trainer import TrainConfig, round_imgsz, train

from synthetic_cones import trained_smoke_model, write_dataset


def test_overfits_8_synthetic_images():
    """The loss and the assigner learn: 40 epochs on 8 images reach mAP@0.5 >= 0.9 on them.

    The issue's budget is 3 minutes on CPU; the run takes ~8 s on a quiet 2-core machine
    (speed is not asserted here: a timed test would fail on a busy machine, not on a bug)."""
    ckpt, _, result = trained_smoke_model()
    hist = result["history"]
    assert hist[-1]["map50"] >= 0.9, [round(h["map50"], 3) for h in hist]
    assert hist[-1]["box_loss"] < 0.5 * hist[0]["box_loss"]
    assert ckpt.is_file() and (ckpt.parent / "last.pt").is_file()


def _tiny_cfg(root, out, epochs, precision="fp32"):
    return TrainConfig(
        data=str(root / "d.yaml"), out=str(out), model="p", epochs=epochs, batch=4, imgsz=(128, 64), lr0=0.005,
        workers=0, threads=2, warmup_epochs=0, warmup_min_iters=2, close_mosaic=1, seed=3, patience=100,
        augment=AugmentConfig(mosaic=0.5, cutout=0.5, blur=0.5, noise=0.5), precision=precision,
    )


@pytest.mark.parametrize("precision", ["fp32", "bf16"])
def test_resume_reproduces_the_loss_curve(tmp_path, precision):
    root = write_dataset(tmp_path / "d", n_images=8, size=(128, 64), seed=1)
    (root / "d.yaml").write_text(yaml.safe_dump({"train": [{"path": "."}], "val": [{"path": "."}]}))
    full = train(_tiny_cfg(root, tmp_path / "full", 4, precision), progress=False)["history"]
    train(_tiny_cfg(root, tmp_path / "part", 4, precision), progress=False, stop_after=2)  # the session is cut
    resumed = train(_tiny_cfg(root, tmp_path / "part", 4, "fp32"), resume=True, progress=False)["history"]  # keeps its own
    assert [h["epoch"] for h in resumed] == [1, 2, 3, 4]
    for a, b in zip(full, resumed):
        for k in ("box_loss", "cls_loss", "dfl_loss", "map50"):
            assert a[k] == pytest.approx(b[k], rel=1e-5, abs=1e-6), (a["epoch"], k)
    with pytest.raises(ConfigError, match="nothing to resume"):
        train(_tiny_cfg(root, tmp_path / "none", 2), resume=True, progress=False)


def test_bf16_training_learns_and_keeps_fp32_weights(tmp_path):
    """bf16 autocast (channels-last) overfits the same 8 images as the fp32 smoke test; the checkpoint
    holds fp32 weights that load into a plain model, and a pre-precision run resumes as fp32."""
    import torch

    from cone_perception.model.checkpoint import load_checkpoint
    from cone_perception.train.trainer import resolve_precision

    from synthetic_cones import SMOKE_SIZE

    root = write_dataset(tmp_path / "d", n_images=8, size=SMOKE_SIZE, seed=0)
    (root / "o.yaml").write_text(yaml.safe_dump({"train": [{"path": "."}], "val": [{"path": "."}]}))
    cfg = TrainConfig(data=str(root / "o.yaml"), out=str(tmp_path / "run"), model="p", epochs=40, batch=4, imgsz=SMOKE_SIZE,
                      lr0=0.01, workers=0, threads=1, augment=AugmentConfig.off(), warmup_epochs=0, warmup_min_iters=10,
                      patience=1000, close_mosaic=0, ema_tau=20, seed=0, precision="bf16")
    hist = train(cfg, progress=False)["history"]
    assert hist[-1]["map50"] >= 0.9, [round(h["map50"], 3) for h in hist]
    ck = load_checkpoint(tmp_path / "run" / "last.pt")
    assert all(v.dtype == torch.float32 for v in ck.state_dict.values() if v.is_floating_point())
    assert ck.train["config"]["precision"] == "bf16"
    model = ck.build_model().eval()
    with torch.no_grad():
        assert torch.isfinite(model(torch.rand(1, 3, SMOKE_SIZE[1], SMOKE_SIZE[0]))).all()

    # a run saved before the precision setting existed resumes in fp32, as it was trained
    del ck.train["config"]["precision"]
    torch.save({**torch.load(tmp_path / "run" / "last.pt", weights_only=False), "train": ck.train}, tmp_path / "run" / "last.pt")
    cfg2 = TrainConfig(**{**cfg.__dict__, "epochs": 41, "precision": "auto"})
    assert len(train(cfg2, resume=True, progress=False)["history"]) == 41
    assert load_checkpoint(tmp_path / "run" / "last.pt").train["config"]["precision"] == "fp32"

    assert resolve_precision("fp32") == "fp32" and resolve_precision("bf16") == "bf16"
    assert resolve_precision("auto") in ("fp32", "bf16")
    with pytest.raises(ConfigError, match="precision"):
        resolve_precision("fp8")


def test_dataset_bad_lines_missing_images_and_names(tmp_path, caplog):
    root = write_dataset(tmp_path / "d", n_images=3, size=(128, 64), seed=2)
    lab = root / "labels" / "synth-000.txt"
    good = lab.read_text()
    lab.write_text(good + "1 0.5 0.5\nx 0.5 0.5 0.1 0.1\n9 0.5 0.5 0.1 0.1\n2 0.5 0.5 -0.1 0.1\n")
    (root / "labels" / "ghost-000.txt").write_text("0 0.5 0.5 0.1 0.1\n")
    (root / "d.yaml").write_text(yaml.safe_dump({"train": [{"path": ".", "weight": 2}]}))
    with caplog.at_level(logging.WARNING):
        tr, va, _ = load_data_yaml(root / "d.yaml")
    text = caplog.text
    assert f"{lab}:{len(good.splitlines()) + 1}" in text and "got 3 fields" in text
    assert "not numbers" in text and "class 9 outside" in text and "out of range" in text
    assert "no image ghost-000" in text
    s = tr[0].summary()
    assert s["bad_label_lines"] == 4 and s["labels_without_image"] == 1 and s["images"] == 3
    assert len(tr[0].labels[0]) == len(good.splitlines())  # good lines kept
    assert va == []
    # weight 2 -> twice the images per epoch
    assert len(epoch_order(tr, seed=0, epoch=0)) == 6

    (root / "bad.yaml").write_text(yaml.safe_dump({"train": [{"path": ".", "names": ["blue", "pylon"]}]}))
    with pytest.raises(ConfigError, match=r"train\[0\].*class_names\[1\]|names"):
        load_data_yaml(root / "bad.yaml")
    (root / "nodir.yaml").write_text(yaml.safe_dump({"train": [{"path": "missing"}]}))
    with pytest.raises(ConfigError, match="image folder"):
        load_data_yaml(root / "nodir.yaml")


def test_imgsz_rounded_up_and_said(caplog):
    with caplog.at_level(logging.WARNING):
        assert round_imgsz((250, 90)) == (256, 96)
    assert "rounded up to 256x96" in caplog.text
    assert round_imgsz((960, 288)) == (960, 288)


def test_clip_filter_and_restore_aspect(tmp_path):
    root = tmp_path / "sq"
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    for clip in ("autox3_mp4", "accel_mp4"):
        cv2.imwrite(str(root / "images" / f"{clip}-1_jpg_ab.jpg"), np.full((64, 64, 3), 100, np.uint8))
        (root / "labels" / f"{clip}-1_jpg_ab.txt").write_text("0 0.5 0.5 0.2 0.4\n")
    doc = {"train": [{"path": ".", "names": ["blue_cone"], "restore_aspect": [16, 9], "exclude_clips": ["accel"]}],
           "val": [{"path": ".", "names": ["blue_cone"], "restore_aspect": [16, 9], "clips": ["accel"]}]}
    (root / "d.yaml").write_text(yaml.safe_dump(doc))
    tr, va, _ = load_data_yaml(root / "d.yaml")
    assert [p.name for p in tr[0].image_paths] == ["autox3_mp4-1_jpg_ab.jpg"]
    assert [p.name for p in va[0].image_paths] == ["accel_mp4-1_jpg_ab.jpg"]
    ds = TrainSet(tr, (64, 64), AugmentConfig.off(), seed=0)
    img, t = ds[(0, 0, 0)]
    # 64x64 squeezed -> 64x36 restored, placed in a 64x64 input: the box keeps its true 16:9 shape
    assert img.shape == (3, 64, 64)
    bw, bh = float(t[0, 3] - t[0, 1]), float(t[0, 4] - t[0, 2])
    assert bw == pytest.approx(12.8, abs=0.6) and bh == pytest.approx(14.4, abs=0.6)


def test_augmentations_keep_boxes_inside_and_colours():
    rng = np.random.default_rng(0)
    img = np.full((90, 160, 3), 120, np.uint8)
    img[20:60, 30:50] = (200, 80, 10)  # a blue cone body
    boxes = np.array([[30, 20, 50, 60]], np.float32)
    cls = np.array([0])
    f_img, f_boxes = hflip(img, boxes)
    np.testing.assert_allclose(f_boxes, [[110, 20, 130, 60]])
    assert (f_img[30, 115] == img[30, 35]).all()
    for _ in range(20):
        out, b, c = random_window(rng, img, boxes, cls, (96, 64), (0.5, 1.5), AugmentConfig())
        assert out.shape == (64, 96, 3)
        if len(b):
            assert b.min() >= 0 and (b[:, 2] <= 96).all() and (b[:, 3] <= 64).all() and c.tolist() == [0]
    hue0 = cv2.cvtColor(img[30:31, 35:36], cv2.COLOR_BGR2HSV)[0, 0, 0]
    for _ in range(20):
        j = hsv_jitter(rng, img, 0.01, 0.5, 0.4)
        hue = cv2.cvtColor(j[30:31, 35:36], cv2.COLOR_BGR2HSV)[0, 0, 0]
        assert abs(int(hue) - int(hue0)) <= 3  # <= 6 degrees: blue stays blue


def test_epoch_samples_are_reproducible_and_worker_independent(tmp_path):
    root = write_dataset(tmp_path / "d", n_images=4, size=(128, 64), seed=4)
    (root / "d.yaml").write_text(yaml.safe_dump({"train": [{"path": "."}]}))
    tr, _, _ = load_data_yaml(root / "d.yaml")
    ds = TrainSet(tr, (128, 64), AugmentConfig(mosaic=1.0), seed=5)
    s = EpochSampler(tr, seed=5)
    s.set_epoch(3)
    keys = list(s)
    a = collate([ds[k] for k in keys])
    b = collate([ds[k] for k in reversed(keys)][::-1])
    assert np.array_equal(a[0].numpy(), b[0].numpy()) and np.array_equal(a[1].numpy(), b[1].numpy())
    s.set_epoch(4)
    assert list(s) != keys


def test_train_command_writes_checkpoints_and_resumes(tmp_path, capsys):
    import json

    from cone_perception.cli import main as cli_main
    from cone_perception.model.checkpoint import load_checkpoint

    root = write_dataset(tmp_path / "d", n_images=4, size=(128, 64), seed=6)
    (root / "d.yaml").write_text(yaml.safe_dump({"train": [{"path": "."}], "val": [{"path": "."}]}))
    args = ["train", "--data", str(root / "d.yaml"), "--model", "p", "--imgsz", "120x64", "--batch", "2",
            "--workers", "0", "--out", str(tmp_path / "run"), "--json"]
    assert cli_main(args + ["--epochs", "1"]) == 0
    first = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert first["last"]["epoch"] == 1 and "map50" in first["last"]
    assert cli_main(args + ["--epochs", "2", "--resume"]) == 0
    second = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert second["last"]["epoch"] == 2
    ck = load_checkpoint(tmp_path / "run" / "last.pt")
    assert ck.imgsz == (128, 64)  # 120 rounded up to a multiple of 32
    assert ck.data["train"][0]["images"] == 4 and ck.metrics["epoch"] == 2 and ck.train["epoch"] == 2
    assert len((tmp_path / "run" / "results.csv").read_text().splitlines()) == 3


def test_native_bf16_follows_a_onednn_isa_cap(monkeypatch):
    """ONEDNN_MAX_CPU_ISA below AVX512_CORE_BF16 (how one tries a CPU without native bf16 on one with it)
    makes ``auto`` precision fp32, as on such a CPU; a cap that keeps bf16 leaves the CPU's own answer."""
    from cone_perception.train import trainer

    monkeypatch.delenv("ONEDNN_MAX_CPU_ISA", raising=False)
    monkeypatch.delenv("DNNL_MAX_CPU_ISA", raising=False)
    own = trainer.native_bf16()
    for cap in ("AVX2", "avx512_core", "AVX512_CORE_VNNI"):
        monkeypatch.setenv("ONEDNN_MAX_CPU_ISA", cap)
        assert not trainer.native_bf16(), cap
        assert trainer.resolve_precision("auto") == "fp32"
    monkeypatch.setenv("ONEDNN_MAX_CPU_ISA", "AVX512_CORE_AMX")
    assert trainer.native_bf16() == own
    monkeypatch.delenv("ONEDNN_MAX_CPU_ISA")
    monkeypatch.setenv("DNNL_MAX_CPU_ISA", "AVX2")
    assert not trainer.native_bf16()
