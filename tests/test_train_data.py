"""train's inputs and outputs as people expect them: Ultralytics data.yaml, the data.yaml files our own
tools write, the dataset summary, numbered run folders, one epoch numbering, results.png."""

from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pytest
import yaml

from cone_perception.classes import BLUE, LARGE_ORANGE, YELLOW
from cone_perception.cli import main as cli_main
from cone_perception.data.datasets import load_data_yaml, split_counts, summary_table
from cone_perception.errors import ConfigError
from cone_perception.train.report import next_run_dir

from synthetic_cones import write_dataset


def _yolo_layout(root, split_dirs=("images/train", "images/val"), n=3, seed=1):
    """Ultralytics layout under root: for each image folder its labels folder (images -> labels)."""
    src = write_dataset(root / "_src", n_images=n, size=(128, 64), seed=seed)
    for d in split_dirs:
        img = root / d
        lab = root / d.replace("images", "labels")
        shutil.copytree(src / "images", img)
        shutil.copytree(src / "labels", lab)
    shutil.rmtree(src)
    return root


def test_ultralytics_yaml_with_names_dict_maps_classes_by_name(tmp_path):
    root = _yolo_layout(tmp_path / "ds")
    # dataset ids 0..3 -> our names in another order: the class map must follow the names
    (root / "data.yaml").write_text(yaml.safe_dump({
        "path": ".", "train": "images/train", "val": "images/val", "nc": 4,
        "names": {0: "Yellow Cone", 1: "blue_cone", 2: "orange_cone", 3: "large_orange_cone"}}))
    tr, va, _ = load_data_yaml(root / "data.yaml")
    assert len(tr) == 1 and len(va) == 1 and len(tr[0].image_paths) == 3
    assert tr[0].class_map[:2] == [YELLOW, BLUE] and tr[0].class_map[3] == LARGE_ORANGE
    # label class 0 of the files is read as yellow, not blue
    raw = [int(l.split()[0]) for f in sorted((root / "labels/train").glob("*.txt")) for l in f.read_text().splitlines()]
    got = np.concatenate(tr[0].labels)[:, 0].astype(int).tolist()
    assert got == [tr[0].class_map[c] for c in raw]
    counts = split_counts(tr)
    assert counts["images"] == 3 and counts["boxes"] == len(raw)
    assert counts["per_class"]["yellow"] == raw.count(0)


def test_roboflow_layout_lists_and_test_split(tmp_path):
    """train/images -> train/labels; train as a list; test is read and counted."""
    root = _yolo_layout(tmp_path / "rf", split_dirs=("train/images", "valid/images", "test/images", "extra/images"))
    (root / "data.yaml").write_text(yaml.safe_dump({
        "train": ["train/images", "extra/images"], "val": "valid/images", "test": "test/images",
        "names": ["blue_cone", "yellow_cone", "orange_cone", "large_orange_cone"]}))
    tr, va, rest = load_data_yaml(root / "data.yaml")
    assert [len(e.image_paths) for e in tr] == [3, 3] and len(va[0].image_paths) == 3
    assert len(rest["test_entries"][0].image_paths) == 3
    table = summary_table({"train": tr, "val": va})
    assert table.splitlines()[1].split()[:2] == ["train", "6"]


@pytest.mark.parametrize("doc, key, text", [
    ({"train": "images/train", "val": "images/nope"}, "val", "images/nope not found"),
    ({"train": "images/train", "path": "missing_root"}, "path", "missing_root not found"),
    ({"train": "pictures"}, "train", "image folder"),
    ({"train": ["images/train", "images/gone"]}, "train[1]", "images/gone not found"),
    ({"train": "images/train", "names": ["blue_cone", "traffic_light"]}, "names[1]", "traffic_light"),
    ({"train": "images/train", "names": ["blue_cone"], "nc": 2}, "nc", "names lists 1"),
    ({"train": "list.txt"}, "train", "image-list"),
])
def test_bad_ultralytics_yaml_names_file_and_key(tmp_path, doc, key, text):
    root = _yolo_layout(tmp_path / "ds", split_dirs=("images/train",))
    doc = {"names": ["blue_cone", "yellow_cone", "orange_cone", "large_orange_cone"], **doc}
    (root / "data.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError) as e:
        load_data_yaml(root / "data.yaml")
    assert str(root / "data.yaml") in str(e.value) and f": {key}:" in str(e.value) and text in str(e.value)


def test_images_without_labels_folder_names_it(tmp_path):
    root = _yolo_layout(tmp_path / "ds", split_dirs=("images/train",))
    shutil.rmtree(root / "labels/train")
    (root / "data.yaml").write_text(yaml.safe_dump({"train": "images/train", "names": ["blue_cone"] * 4}))
    with pytest.raises(ConfigError, match=r"train: label folder .*labels/train .*not found"):
        load_data_yaml(root / "data.yaml")


def test_synth_dataset_yaml_trains_with_default_numbered_out(tmp_path, monkeypatch, capsys):
    """synth dataset -> train on its data.yaml, no --out: runs/train/exp, then exp2; summary, epochs, results.png."""
    data = tmp_path / "synth"
    assert cli_main(["synth", "dataset", "--n", "4", "--frames-per-track", "2", "--val-frac", "0.5", "--out", str(data),
                     "--size", "320x180", "--no-progress"]) == 0
    monkeypatch.chdir(tmp_path)
    args = ["train", "--data", str(data / "data.yaml"), "--model", "p", "--imgsz", "160x96", "--batch", "2",
            "--workers", "0", "--epochs", "2", "--no-progress", "--json"]
    capsys.readouterr()
    assert cli_main(args) == 0
    out, err = capsys.readouterr()
    summary = json.loads(out.strip().splitlines()[-1])
    run = tmp_path / "runs/train/exp"
    assert summary["out"] == "runs/train/exp" and (run / "best.pt").is_file()
    # the dataset summary came first, with images and boxes per class and split
    assert "split" in err and "blue" in err and "large_orange" in err
    assert err.index("dataset (") < err.index("epoch 1/2")
    gt = [json.loads(l) for l in (data / "gt.jsonl").read_text().splitlines()]
    n_train = sum(1 for g in gt if "/train/" in g["image"])
    assert f"train  {n_train}" in " ".join(err.split("\n")) or any(
        l.split()[:2] == ["train", str(n_train)] for l in err.splitlines())
    # one epoch numbering: log, results.csv, JSON summary, checkpoint
    assert "epoch 1/2 " in err and "epoch 2/2 " in err
    rows = list(csv.DictReader((run / "results.csv").open()))
    assert [r["epoch"] for r in rows] == ["1", "2"] and summary["last"]["epoch"] == 2
    assert 1 <= summary["best_epoch"] <= 2
    assert (run / "results.png").stat().st_size > 10_000
    # a second run never lands in the first one's folder
    assert cli_main(args) == 0
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["out"] == "runs/train/exp2"
    assert len(list(csv.DictReader((run / "results.csv").open()))) == 2
    # an explicit --out that holds a run is refused (not appended to) unless --resume
    assert cli_main(args + ["--out", str(run)]) == 2
    assert "already holds a training run" in capsys.readouterr().err


def test_next_run_dir_numbers(tmp_path):
    assert next_run_dir(tmp_path, "exp") == tmp_path / "exp"
    (tmp_path / "exp").mkdir()
    (tmp_path / "exp2").mkdir()
    assert next_run_dir(tmp_path, "exp") == tmp_path / "exp3"
    with pytest.raises(ConfigError, match="--name"):
        next_run_dir(tmp_path, "../x")


def test_restore_aspect_writes_a_trainable_data_yaml(tmp_path):
    src = write_dataset(tmp_path / "sq", n_images=3, size=(64, 64), seed=2)
    (src / "data.yaml").unlink()
    # bgracing-real has no data.yaml: names come from --names
    assert cli_main(["data", "restore-aspect", str(src), str(tmp_path / "out"), "--names",
                     "blue_cone,yellow_cone,orange_cone,large_orange_cone", "--no-progress"]) == 0
    tr, va, _ = load_data_yaml(tmp_path / "out" / "data.yaml")
    assert len(tr[0].image_paths) == 3 and tr[0].restore_aspect is None and va == []
    assert tr[0].labels[0].shape[1] == 5
    # without names anywhere: a clear error before any image is written
    assert cli_main(["data", "restore-aspect", str(src), str(tmp_path / "out2"), "--no-progress"]) == 2
    assert not (tmp_path / "out2").exists()


def test_resume_needs_out(tmp_path, capsys):
    src = write_dataset(tmp_path / "d", n_images=2, size=(64, 64))
    (src / "d.yaml").write_text(yaml.safe_dump({"train": [{"path": "."}]}))
    assert cli_main(["train", "--data", str(src / "d.yaml"), "--resume"]) == 2
    assert "--resume: needs --out" in capsys.readouterr().err


def test_synth_dataset_of_one_track_has_no_val_and_trains(tmp_path, capsys, caplog):
    """Issue 29: 12 frames are one track (--frames-per-track 20): no val split rather than an empty one the
    trainer refuses; train on that data.yaml trains (without validation, saying how to get one). A data.yaml
    that names an empty val folder (an older synth dataset) trains too, with a warning naming it."""
    import logging

    data = tmp_path / "synth"
    with caplog.at_level(logging.WARNING):
        assert cli_main(["synth", "dataset", "--n", "12", "--out", str(data), "--size", "320x180", "--no-progress"]) == 0
    assert "12 frames make one track (--frames-per-track 20): no val split" in caplog.text
    doc = yaml.safe_load((data / "data.yaml").read_text())
    assert doc["train"] == "images/train" and "val" not in doc and not (data / "images/val").exists()
    assert len(list((data / "images/train").glob("*.jpg"))) == 12
    args = ["train", "--model", "p", "--imgsz", "160x96", "--batch", "4", "--workers", "0", "--epochs", "1",
            "--max-batches", "2", "--no-progress", "--json", "--precision", "fp32"]
    capsys.readouterr()
    assert cli_main([*args, "--data", str(data / "data.yaml"), "--out", str(tmp_path / "run")]) == 0
    out, err = capsys.readouterr()
    assert "no val split: training without validation" in err and "name a folder of other frames under val:" in err
    assert json.loads(out.strip().splitlines()[-1])["last"]["epoch"] == 1 and (tmp_path / "run/best.pt").is_file()

    (data / "images/val").mkdir()
    (data / "labels/val").mkdir()
    (data / "old.yaml").write_text(yaml.safe_dump({**doc, "val": "images/val"}))
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        tr, va, _ = load_data_yaml(data / "old.yaml")
        assert cli_main([*args, "--data", str(data / "old.yaml"), "--out", str(tmp_path / "run2")]) == 0
    assert va == [] and len(tr[0].image_paths) == 12
    assert f"old.yaml: val: no images in {data / 'images/val'}: that split is left out" in caplog.text
    assert (tmp_path / "run2/best.pt").is_file()
    # a val folder emptied by a clip filter stays an error (a typo in clips must not drop the validation)
    (data / "clips.yaml").write_text(yaml.safe_dump({"train": [{"path": ".", "images": "images/train"}],
                                                        "val": [{"path": ".", "images": "images/train", "clips": ["accel"]}]}))
    with pytest.raises(ConfigError, match=r"val\[0\]\.path.*no images.*for clips \['accel'\]"):
        load_data_yaml(data / "clips.yaml")


@pytest.mark.parametrize("n, frames_per_track, val_frac, want", [
    (4, 2, 0.1, (2, 2)),   # two tracks: one in val although 0.1 of 2 rounds to 0
    (4, 2, 0.9, (2, 2)),   # 0.9 of 2 tracks rounds to 2: train keeps one
    (4, 2, 0.0, (4, 0)),   # asked for none: none
    (3, 4, 0.5, (3, 0)),   # one track: none
])
def test_synth_dataset_splits_whole_tracks_and_never_an_empty_one(tmp_path, n, frames_per_track, val_frac, want):
    out = tmp_path / "d"
    assert cli_main(["synth", "dataset", "--n", str(n), "--frames-per-track", str(frames_per_track), "--val-frac",
                     str(val_frac), "--out", str(out), "--size", "160x96", "--no-progress"]) == 0
    n_train = len(list((out / "images/train").glob("*.jpg")))
    n_val = len(list((out / "images/val").glob("*.jpg")))
    assert (n_train, n_val) == want
    assert ("val" in yaml.safe_load((out / "data.yaml").read_text())) == (n_val > 0)
    tr, va, _ = load_data_yaml(out / "data.yaml")  # what train reads: no empty split
    assert sum(len(e.image_paths) for e in tr) == n_train and sum(len(e.image_paths) for e in va) == n_val
