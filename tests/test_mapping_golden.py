"""The mapping stage gives the very same ``/cones`` bytes as before its boxes became one column view (issue 42, 5).

A short rendered drive (8 frames, seed :data:`SEED`) is replayed offline (:func:`~cone_perception.replay.offline_replay`)
through :class:`~cone_perception.pipeline.Pipeline` in three set-ups (:data:`VARIANTS`: the image attitude with the
far strip; the same with foot offsets from the box widths and the weak boxes split off at a score; the calibrated H
alone). The detectors play back the boxes the shipped band and far models drew on that drive, so everything after the
detector runs as in ``replay`` (the second box of a cone, the attitude fit, the strip following it, the flat boxes,
one cone per viewing ray, the covariances), and every frame's ``/cones`` (and weak cones) must equal the golden
``tests/data/mapping_golden.npz`` byte for byte.

The golden holds the recorded boxes and the cones of the code before the change (main at b275a31), written by this
file itself run with that code on the import path::

    git worktree add /tmp/base b275a31     # or a clone checked out at b275a31
    cd /tmp/base && PYTHONPATH=$PWD python /path/to/tests/test_mapping_golden.py --write /path/to/tests/data/mapping_golden.npz

(``--write`` renders the drive, runs the shipped models on it, records their boxes and replays them through the
three set-ups; it uses only the API both versions share). Bytes are compared with the records' padding zeroed
(:func:`canonical`): every field to the bit.

A change meant to change the cones rewrites only the cones, from the golden's own recorded boxes (so that the
models' float noise on another CPU stays out), and says so in its commit::

    PYTHONPATH=$PWD python tests/test_mapping_golden.py --rewrite-cones tests/data/mapping_golden.npz

Rewritten so: issue 41's parts of a cone (``mapping.one_box_per_cone``) and the band's box of a cone it sees
large (``farband.FAR_MAX_BAND_PX``); then the image attitude's settings per frame scaled by the frames' stamps
(``ImageAttitudeConfig.frame_s``: this 10 fps drive's frames are two of 20 fps), 2026-12-07.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cone_perception import records
from cone_perception.detector.farband import FarBand, far_rows_for
from cone_perception.geometry.calib import load_calibration
from cone_perception.pipeline import Pipeline
from cone_perception.records import BOX_DTYPE, CONE_DTYPE
from cone_perception.replay import offline_replay
from cone_perception.synth.config import SynthConfig
from cone_perception.synth.writers import write_scene_bag

GOLDEN = Path(__file__).parent / "data" / "mapping_golden.npz"
SEED = 4242  # not a training seed
SECONDS, FPS = 0.8, 10.0
RECORD_CONF = 0.15  # the detectors' score threshold when the boxes were recorded
#: name -> (attitude, far strip, foot offset from the box width, cones_conf)
VARIANTS = {
    "image_far": ("image", True, False, None),
    "width_weak": ("image", True, True, 0.4),
    "fixed_band": ("fixed", False, False, None),
}


def render(folder: Path) -> Path:
    bag = folder / "drive"
    write_scene_bag(SynthConfig(seed=SEED, jitter=True), SECONDS, FPS, bag, speed_mps=8.0, progress=False)
    return bag


class Playback:
    """A detector that hands out recorded boxes, one frame's per call, in order (``boxes``: a list of BOX_DTYPE)."""

    def __init__(self, boxes: list[np.ndarray]):
        self.boxes, self.k, self.timing = boxes, 0, {}

    def detect(self, bgr, crop) -> np.ndarray:
        self.k += 1
        return self.boxes[self.k - 1].copy()


class Recorder:
    """A detector's boxes, each call's kept (for :func:`write_golden`)."""

    def __init__(self, detector):
        self.detector, self.boxes, self.timing = detector, [], {}

    def detect(self, bgr, crop) -> np.ndarray:
        b = self.detector.detect(bgr, crop)
        self.timing = dict(self.detector.timing)
        self.boxes.append(b.astype(BOX_DTYPE))
        return b


def pipeline(variant: str, band_det, far_det) -> Pipeline:
    attitude, far, from_width, cones_conf = VARIANTS[variant]
    calib = load_calibration("example_mainhoop")
    if from_width:
        calib = replace(calib, foot_offset_from_width=True)
    band = None
    if far:
        fr = far_rows_for("auto", calib)
        band = FarBand(fr.crop, far_det, "far_model", fr.plan)
    return Pipeline(calib, band_det, attitude, far=band, cones_conf=cones_conf)


def replay(bag: Path, variant: str, band_det, far_det) -> tuple[dict, dict]:
    """(stamp -> /cones records, stamp -> weak cones or None) of ``bag`` through ``variant``."""
    pipe = pipeline(variant, band_det, far_det)
    weak = {}
    process_raw = pipe.process_raw

    def keep_weak(*args, **kw):
        r = process_raw(*args, **kw)
        weak[kw["stamp_ns"]] = r.weak_cones
        return r

    pipe.process_raw = keep_weak
    res = offline_replay(bag, pipe)
    assert not res.drops, res.drops
    return res.cones, weak


def canonical(records: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """``records`` as ``dtype`` with its padding bytes zero: every field as it was (a record array's padding, e.g.
    CONE_DTYPE's 3 bytes after ``class_id``, is whatever memory ``np.empty`` gave a copy, the same code or not; an
    ``.npz`` stores the fields packed)."""
    out = np.zeros(len(records), dtype)
    for name in records.dtype.names:
        out[name] = records[name]
    return out


def _pack(per_frame: list[np.ndarray | None], dtype) -> tuple[np.ndarray, np.ndarray]:
    n = np.array([-1 if a is None else len(a) for a in per_frame])
    parts = [canonical(a, dtype) for a in per_frame if a is not None]
    return (np.concatenate(parts) if parts else np.zeros(0, dtype)), n


def _unpack(flat: np.ndarray, n: np.ndarray, dtype: np.dtype) -> list[np.ndarray | None]:
    out, k = [], 0
    for m in n.tolist():
        out.append(None if m < 0 else canonical(flat[k : k + m], dtype))
        k += max(m, 0)
    return out


def write_golden(out: Path, folder: Path) -> None:
    from cone_perception.detector import Detector, default_model_path  # the shipped models: only to record

    bag = render(folder)
    calib = load_calibration("example_mainhoop")
    # at a low score threshold: weak boxes for the flat-box gate and the weak split too
    band = Recorder(Detector.load(default_model_path(), conf=RECORD_CONF, threads=1))
    far = FarBand.for_calibration(Path(default_model_path()).with_name("cone_detector_far.pt"), "auto", calib,
                                  conf=RECORD_CONF, threads=1)
    far_rec = Recorder(far.detector)
    replay(bag, "image_far", band, far_rec)
    arrays = {}
    arrays["band_boxes"], arrays["band_n"] = _pack(band.boxes, BOX_DTYPE)
    arrays["far_boxes"], arrays["far_n"] = _pack(far_rec.boxes, BOX_DTYPE)
    for v in VARIANTS:
        cones, weak = replay(bag, v, Playback(band.boxes), Playback(far_rec.boxes))
        stamps = sorted(cones)
        arrays["stamps"] = np.array(stamps, np.int64)
        arrays[f"{v}_cones"], arrays[f"{v}_cones_n"] = _pack([cones[s] for s in stamps], CONE_DTYPE)
        arrays[f"{v}_weak"], arrays[f"{v}_weak_n"] = _pack([weak[s] for s in stamps], CONE_DTYPE)
    np.savez_compressed(out, **arrays)


def rewrite_cones(path: Path, folder: Path) -> None:
    """The golden at ``path`` with its cones replayed by this code from its own recorded boxes."""
    g = dict(np.load(path))
    band, far = _unpack(g["band_boxes"], g["band_n"], BOX_DTYPE), _unpack(g["far_boxes"], g["far_n"], BOX_DTYPE)
    bag = render(folder)
    for v in VARIANTS:
        cones, weak = replay(bag, v, Playback(band), Playback(far))
        stamps = sorted(cones)
        assert stamps == g["stamps"].tolist()
        g[f"{v}_cones"], g[f"{v}_cones_n"] = _pack([cones[s] for s in stamps], CONE_DTYPE)
        g[f"{v}_weak"], g[f"{v}_weak_n"] = _pack([weak[s] for s in stamps], CONE_DTYPE)
    np.savez_compressed(path, **g)


@pytest.fixture(scope="module")
def drive(tmp_path_factory) -> Path:
    return render(tmp_path_factory.mktemp("golden"))


def test_the_mapping_stage_gives_the_golden_cones_bytes(drive) -> None:
    g = np.load(GOLDEN)
    bag = drive
    band, far = _unpack(g["band_boxes"], g["band_n"], BOX_DTYPE), _unpack(g["far_boxes"], g["far_n"], BOX_DTYPE)
    stamps = g["stamps"].tolist()
    assert len(stamps) == int(SECONDS * FPS) and len(band) == len(stamps) == len(far)
    seen = {"cones": 0, "weak": 0, "far_cones": 0}
    for v, (_, with_far, _, _) in VARIANTS.items():
        cones, weak = replay(bag, v, Playback(band), Playback(far))
        assert sorted(cones) == stamps
        want_cones = _unpack(g[f"{v}_cones"], g[f"{v}_cones_n"], CONE_DTYPE)
        want_weak = _unpack(g[f"{v}_weak"], g[f"{v}_weak_n"], CONE_DTYPE)
        for s, wc, ww in zip(stamps, want_cones, want_weak):
            assert cones[s].dtype == CONE_DTYPE
            assert canonical(cones[s], CONE_DTYPE).tobytes() == wc.tobytes(), f"{v}, frame {s}: /cones differ"
            assert (weak[s] is None) == (ww is None), f"{v}, frame {s}"
            if ww is not None:
                assert canonical(weak[s], CONE_DTYPE).tobytes() == ww.tobytes(), f"{v}, frame {s}: weak cones differ"
                seen["weak"] += len(ww)
            seen["cones"] += len(wc)
            seen["far_cones"] += len(wc) if with_far else 0
    # the golden is no empty drive: cones in every set-up, weak cones where split
    assert seen["cones"] > 50 and seen["weak"] > 0 and seen["far_cones"] > 0, seen


def test_a_frame_becomes_columns_once(drive, monkeypatch) -> None:
    """Every step of the mapping stage (one box per cone, the weak split, the attitude fit, the foot points, the
    widths, the flat boxes, the mapping of the weak boxes) reads the frame's one column view: the records are turned
    into arrays once a frame."""
    g = np.load(GOLDEN)
    calls = []
    to_arrays = records.boxes_to_arrays
    monkeypatch.setattr(records, "boxes_to_arrays", lambda r: calls.append(len(r)) or to_arrays(r))
    band, far = _unpack(g["band_boxes"], g["band_n"], BOX_DTYPE), _unpack(g["far_boxes"], g["far_n"], BOX_DTYPE)
    cones, weak = replay(drive, "width_weak", Playback(band), Playback(far))
    assert len(calls) == len(cones) == len(band) and sum(len(w) for w in weak.values()) > 0


if __name__ == "__main__":
    import argparse
    import tempfile

    ap = argparse.ArgumentParser(description="write the mapping stage's golden (run with the code before the change), "
                                             "or rewrite its cones from its recorded boxes (a change meant to change them)")
    how = ap.add_mutually_exclusive_group(required=True)
    how.add_argument("--write", type=Path, help="the .npz to write")
    how.add_argument("--rewrite-cones", type=Path, help="the .npz whose cones to replay again")
    a = ap.parse_args()
    out = a.write or a.rewrite_cones
    with tempfile.TemporaryDirectory() as d:
        (write_golden if a.write else rewrite_cones)(out, Path(d))
    print(f"wrote {out} ({out.stat().st_size} bytes)", file=sys.stderr)
