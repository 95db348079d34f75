"""Timing runs of ``cone-perception bench``: the fused pipeline, the driver adapter, the tracker.

Each returns the result document that ``bench`` prints (``--json``) and ``bench table`` tabulates.
"""

from __future__ import annotations

import time

import numpy as np

from ..adapter import DriverAdapter
from ..attitude import ImageAttitudeConfig
from ..attitude.box_files import box_model_for
from ..crop import CropSpec
from ..data import bagio
from ..detector import Detector, default_model_path
from ..evaluation.tracking import simulated_drive
from ..pipeline import Pipeline
from ..records import to_pointcloud2
from ..timing import StageTimer, peak_rss_mb
from ..tracking import ConeTracker, FieldOfView, TrackerConfig
from ..vis.debug_image import DebugImage
from .frames import synthetic_frames

#: Bytes per pixel of the raw encodings ``bench adapter`` times.
BYTES_PER_PX = {"yuv422_yuy2": 2, "bgr8": 3, "rgb8": 3}


def bench_pipeline(calib, det, frames: list[bytes], n_frames: int, warmup: int = 20, far=None,
                   concurrent: bool = False, far_every: int = 1, far_tiles=None) -> dict:
    """Time ``det`` in the fused pipeline of ``calib`` (its crop and downscale) on raw YUYV ``frames``
    (cycled): per stage, end to end with the packing of ``cone_boxes`` and ``/cones``. The result
    of ``bench pipeline`` (and one row of ``bench table``). ``far``: a far band (``detector/farband.py``) or None;
    ``concurrent``: its forward at the same time as the band's (``detector/parallel.py``); ``far_every``: its strip
    on every this-many-th frame only (the frame rate is then bimodal: ``fps_mean`` reads the mean), ``far_tiles``
    its tiles between (``detector/fartiles.py``). The image attitude reads
    the boxes as the nodes' ``box_model: auto`` does (the model's box model, the rendered table for a synthetic
    camera), so its stage costs what it costs on the car."""
    bm, _ = box_model_for("auto", det.source, calib.camera == "synth")
    with Pipeline(calib, det, far=far, concurrent=concurrent, attitude_config=ImageAttitudeConfig(box_model=bm),
                  far_every=far_every, far_tiles=far_tiles) as pipe:
        return _time_pipeline(pipe, calib, det, frames, n_frames, warmup)


def _time_pipeline(pipe: Pipeline, calib, det, frames: list[bytes], n_frames: int, warmup: int) -> dict:
    debug = DebugImage(pipe.mapper)
    w, h = calib.image_width, calib.image_height
    crop = calib.crop
    timer = StageTimer()
    n_boxes = 0
    for i in range(warmup + n_frames):
        data = frames[i % len(frames)]
        t0 = time.perf_counter()
        res = pipe.process_raw("yuv422_yuy2", w, h, 2 * w, data)
        t1 = time.perf_counter()
        hdr = bagio.header(i, "camera")
        to_pointcloud2(res.boxes, hdr, bagio.PointCloud2, bagio.PointField)
        to_pointcloud2(res.cones, bagio.header(i, calib.frame_id), bagio.PointCloud2, bagio.PointField)
        t2 = time.perf_counter()
        np.ascontiguousarray(debug.render(res.band, res.boxes, crop)).tobytes()  # + its Image message's copy
        t3 = time.perf_counter()
        if i < warmup:
            continue
        for k, v in res.timing_ms.items():
            timer.add(k, v / 1e3)
        timer.add("packing", t2 - t1)
        timer.add("end_to_end", t2 - t0)
        timer.add("debug_image", t3 - t2)  # not in end_to_end: opt-in, at most debug_image_hz per second
        n_boxes += len(res.boxes)
    s = timer.summary()
    in_w, in_h = det.input_size_for(crop.out_width, crop.out_height)
    return {
        "target": "pipeline",
        "input": f"{w}x{h} yuv422_yuy2 (rendered scenes)",
        "output": f"band {crop.out_width}x{crop.out_height}, boxes + cones",
        "crop": {"v0": crop.v0, "v1": crop.v1, "u0": crop.u0, "u1": crop.u1, "downscale": crop.downscale},
        "model_input": [in_w, in_h],
        "model": det.source,
        "backend": det.backend,
        "runs_on": det.runs_on,
        "fps": 1000.0 / s["end_to_end"]["median_ms"],
        "fps_mean": 1000.0 / s["end_to_end"]["mean_ms"],
        "boxes_per_frame": n_boxes / n_frames,
        "non_forward_median_ms": s["end_to_end"]["median_ms"] - s["forward"]["median_ms"],
        "stages": s,
        "peak_rss_mb": peak_rss_mb(),
    }


def load_for_crop(model: str | None, backend: str, crop: CropSpec, threads: int, **kw):
    """The detector for a band (:meth:`Detector.load_for_band`): no setting is letterboxed into another size."""
    return Detector.load_for_band(model or default_model_path(), (crop.out_width, crop.out_height),
                                  backend=backend, threads=threads, **kw)


def bench_adapter(calib, encoding: str, n_frames: int, warmup: int) -> dict:
    """Time :meth:`DriverAdapter.from_raw` (raw ``encoding`` frame -> the calibration's band, BGR) on
    synthetic frames at the calibration's image size: the result of ``bench adapter``."""
    adapter = DriverAdapter(calib.crop, calib.image_width, calib.image_height)
    w, h = calib.image_width, calib.image_height
    step = w * BYTES_PER_PX[encoding]
    frames = synthetic_frames(w, h, encoding, 16)
    timer = StageTimer()
    for i in range(warmup):
        adapter.from_raw(encoding, w, h, step, frames[i % len(frames)])
    for i in range(n_frames):
        with timer("adapter"):
            adapter.from_raw(encoding, w, h, step, frames[i % len(frames)])
    s = timer.summary()
    result = {
        "target": "adapter",
        "input": f"{w}x{h} {encoding}",
        "output": f"{calib.crop.out_width}x{calib.crop.out_height} bgr8",
        "fps": 1000.0 / s["adapter"]["median_ms"],
        "stages": s,
        "peak_rss_mb": peak_rss_mb(),
    }
    return result


def bench_tracker(calib, rows: int, n_frames: int, warmup: int) -> dict:
    """Time :meth:`ConeTracker.update` (motion from the cones: registration, association, Kalman update)
    per frame of a simulated drive through ``rows`` rows of cones, seen through the calibration's band:
    the result of ``bench tracker``."""
    fov = FieldOfView.from_calibration(calib)
    rows_m = tuple(float(s * (1.75 + 3.5 * (k // 2))) for k, s in zip(range(rows), [1, -1] * rows))
    trk = ConeTracker(TrackerConfig(), fov)
    timer, n_tracks, n_cones = StageTimer(), [], []
    frames = list(simulated_drive(warmup + n_frames, fov, rows_m=rows_m, spacing_m=1.5))
    for k, (_, cones) in enumerate(frames):
        if k < warmup:
            trk.update(k * 50_000_000, cones)
            continue
        with timer("tracker"):
            trk.update(k * 50_000_000, cones)
        n_tracks.append(len(trk))
        n_cones.append(len(cones))
    s = timer.summary()
    result = {"target": "tracker", "frames": n_frames, "tracks_mean": float(np.mean(n_tracks)),
              "cones_per_frame": float(np.mean(n_cones)), "stages": s, "events": dict(trk.events)}
    return result
