"""The band's and the far strip's forwards at once (detector/parallel.py): the rule, the same boxes as one
after the other, a worker's exception as the frame's error, no thread left after close()."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from cone_perception.bench.frames import rendered_frames
from cone_perception.crop import CropSpec
from cone_perception.detector import Detector, default_model_path
from cone_perception.detector.farband import FarBand
from cone_perception.detector.parallel import WORKER_NAME, ForwardPlan, PairRunner
from cone_perception.errors import FrameError
from cone_perception.geometry.calib import load_calibration
from cone_perception.pipeline import Pipeline
from cone_perception.records import boxes_from_arrays

from rosutil import ros  # noqa: F401 (a fixture)

STRIP = CropSpec(384, 480, 0, 1920, 1)


def _workers() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith(WORKER_NAME)]


@pytest.mark.parametrize("threads, strip, plan", [
    (1, True, ForwardPlan(False, 1)),  # the car's default: one thread, one forward after the other
    (2, True, ForwardPlan(True, 1)),   # two threads: both forwards at once, one intra-op thread each
    (3, True, ForwardPlan(True, 1)),
    (4, True, ForwardPlan(True, 2)),
    (2, False, ForwardPlan(False, 2)),  # no strip: the band's network gets them all
    (0, True, ForwardPlan(False, 0)),  # the library's default: left to it
])
def test_the_rule_runs_the_forwards_at_once_from_two_threads_with_a_strip(threads, strip, plan):
    assert ForwardPlan.of(threads, strip) == plan
    with pytest.raises(ValueError, match="threads"):
        ForwardPlan.of(-1, True)


class _Recorder:
    """A detector double: one box per call at its ``u``, and the thread it ran on. ``meet``: a barrier both
    detectors wait at inside their detect (passed only when they run at the same time)."""

    def __init__(self, u: float, meet: threading.Barrier | None = None, error: Exception | None = None):
        self.u, self.meet, self.error = u, meet, error
        self.threads: list[str] = []
        self.timing = {"preprocess_ms": 0.0, "forward_ms": 0.0, "postprocess_ms": 0.0}
        self.iou = 0.45

    def detect(self, bgr, crop):
        self.threads.append(threading.current_thread().name)
        if self.meet is not None:
            self.meet.wait()  # BrokenBarrierError after its timeout unless the other detect runs meanwhile
        if self.error is not None:
            raise self.error
        v = crop.v0 + 20.0
        return boxes_from_arrays(np.array([[self.u, v, self.u + 10, v + 20]], np.float32), np.array([0.9], np.float32),
                                 np.array([0], np.uint8))


def _frame(calib):
    return np.zeros(calib.image_width * calib.image_height * 2, np.uint8).tobytes()


def _process(pipe, calib, data):
    return pipe.process_raw("yuv422_yuy2", calib.image_width, calib.image_height, 2 * calib.image_width, data)


def test_the_strip_runs_on_the_worker_beside_the_band_and_close_joins_it():
    calib = load_calibration("example_mainhoop")
    meet = threading.Barrier(2, timeout=10)
    band, strip = _Recorder(100.0, meet), _Recorder(900.0, meet)
    before = len(_workers())
    pipe = Pipeline(calib, band, "fixed", far=FarBand(STRIP, strip), concurrent=True)
    assert pipe.concurrent and len(_workers()) == before  # no thread before the first frame
    res = _process(pipe, calib, _frame(calib))  # both detects inside at once, or the barrier breaks
    assert sorted(res.boxes["u1"].tolist()) == [100.0, 900.0]  # both detectors' boxes, merged
    assert band.threads == [threading.current_thread().name] and strip.threads[0].startswith(WORKER_NAME)
    assert {"far_band", "far_wait"} <= set(res.timing_ms)
    assert len(_workers()) == before + 1
    pipe.close()
    assert len(_workers()) == before and not pipe._pair.alive
    pipe.close()  # idempotent
    _process(pipe, calib, _frame(calib))  # a later frame starts a new worker ...
    with pipe:  # ... which the context manager joins
        pass
    assert len(_workers()) == before


def test_one_thread_or_no_strip_never_starts_a_worker():
    calib = load_calibration("example_mainhoop")
    before = len(_workers())
    seq = Pipeline(calib, _Recorder(100.0), "fixed", far=FarBand(STRIP, _Recorder(900.0)), concurrent=False)
    alone = Pipeline(calib, _Recorder(100.0), "fixed", concurrent=True)  # no strip: nothing to run beside the band
    for pipe in (seq, alone):
        _process(pipe, calib, _frame(calib))
        assert not pipe._pair.alive and len(_workers()) == before
    assert seq.far.detector.threads == [threading.current_thread().name]
    assert not alone.concurrent


def test_a_frame_error_of_the_strip_is_the_frames_error_and_the_next_frame_runs():
    calib = load_calibration("example_mainhoop")
    err = FrameError("far_strip_bad", "the strip's detector refused the frame")
    strip = _Recorder(900.0, error=err)
    with Pipeline(calib, _Recorder(100.0), "fixed", far=FarBand(STRIP, strip), concurrent=True) as pipe:
        with pytest.raises(FrameError) as got:
            _process(pipe, calib, _frame(calib))
        assert got.value is err and got.value.reason == "far_strip_bad"  # the same error: counted by its cause
        strip.error = None
        assert len(_process(pipe, calib, _frame(calib)).boxes) == 2


def test_an_error_of_the_band_waits_for_the_strip_first():
    """The band's detect fails at once while the strip's runs 100 ms: the error comes after the strip ended,
    so the strip's detector is never busy with one frame while the next one starts."""
    ended = []

    def slow():
        time.sleep(0.1)
        ended.append(True)

    def fail():
        raise ValueError("band failed")

    with PairRunner(True) as runner:
        with pytest.raises(ValueError, match="band failed"):
            runner.run(fail, slow)
        assert ended == [True]
    assert not runner.alive


@pytest.mark.parametrize("backend", ["onnx", "torch"])
def test_concurrent_and_sequential_give_the_same_boxes(backend):
    """The shipped model on rendered scenes, band + 96-row strip, both networks on one intra-op thread:
    the same boxes, scores and cones whether the strip's forward runs after the band's or beside it."""
    calib = load_calibration("example_mainhoop")
    det = Detector.load_for_band(default_model_path(), (calib.crop.out_width, calib.crop.out_height), threads=1,
                                 backend=backend)
    far = FarBand.load(default_model_path(), "384,480", calib.image_width, calib.image_height, calib.crop, threads=1,
                       backend=backend)
    frames = rendered_frames(calib, 4)
    seq = Pipeline(calib, det, "fixed", far=far)
    with Pipeline(calib, det, "fixed", far=far, concurrent=True) as conc:
        for data in frames:
            a, b = _process(seq, calib, data), _process(conc, calib, data)
            assert len(a.boxes) > 0
            np.testing.assert_array_equal(a.boxes, b.boxes)
            np.testing.assert_array_equal(a.cones, b.cones)
            assert {"far_forward", "far_band", "far_wait"} <= set(b.timing_ms)


def test_the_pipeline_node_runs_both_forwards_at_once_on_two_threads_and_joins_at_destroy(ros):  # noqa: F811
    """``threads: 2`` with ``far_rows``: both networks on one intra-op thread, the forwards at once, the boxes
    of the sequential core pipeline; destroying the node leaves no worker thread. ``threads: 1``: sequential."""
    from rclpy.parameter import Parameter

    from cone_perception.nodes.pipeline import PipelineNode

    calib = load_calibration("example_mainhoop")
    before = len(_workers())
    node = PipelineNode(context=ros.context, parameter_overrides=[Parameter("far_rows", value="384,480"),
                                                                   Parameter("threads", value=2)])
    try:
        pipe = node.pipeline
        assert pipe.concurrent
        for det in (pipe.detector, pipe.far.detector):
            assert det._run.session.get_session_options().intra_op_num_threads == 1
        det = Detector.load_for_band(default_model_path(), (calib.crop.out_width, calib.crop.out_height), threads=1)
        far = FarBand.load(default_model_path(), "384,480", calib.image_width, calib.image_height, calib.crop, threads=1)
        data = rendered_frames(calib, 1)[0]
        want = _process(Pipeline(calib, det, far=far), calib, data).boxes
        np.testing.assert_array_equal(_process(pipe, calib, data).boxes, want)
        assert len(_workers()) == before + 1
    finally:
        node.destroy_node()
    assert len(_workers()) == before
    one = PipelineNode(context=ros.context, parameter_overrides=[Parameter("far_rows", value="384,480")])
    try:
        assert not one.pipeline.concurrent
        assert one.pipeline.far.detector._run.session.get_session_options().intra_op_num_threads == 1
    finally:
        one.destroy_node()


def test_the_strip_is_cut_on_the_worker_and_the_band_on_the_calling_thread(monkeypatch):
    """The strip's rows are cut and converted on the worker, beside the band's cut and forward: the frame waits for
    the later of the two, not for both cuts first; the band the frame returns is the adapter's band."""
    import cone_perception.adapter as adapter_mod

    calib = load_calibration("example_mainhoop")
    det = Detector.load_for_band(default_model_path(), (calib.crop.out_width, calib.crop.out_height), threads=1,
                                 backend="onnx")
    far = FarBand.load(default_model_path(), "384,480", calib.image_width, calib.image_height, calib.crop, threads=1,
                       backend="onnx")
    cut_on: dict[int, str] = {}
    real_cut = adapter_mod.crop_raw_to_bgr

    def cut(name, view, crop):
        cut_on[crop.v1 - crop.v0] = threading.current_thread().name
        return real_cut(name, view, crop)

    monkeypatch.setattr(adapter_mod, "crop_raw_to_bgr", cut)
    data = rendered_frames(calib, 1)[0]
    with Pipeline(calib, det, "fixed", far=far, concurrent=True) as pipe:
        res = _process(pipe, calib, data)
    assert cut_on[STRIP.height_full_px].startswith(WORKER_NAME)
    assert cut_on[calib.crop.height_full_px] == threading.main_thread().name
    band = pipe.adapter.from_raw("yuv422_yuy2", calib.image_width, calib.image_height, 2 * calib.image_width, data)
    np.testing.assert_array_equal(res.band, band)
    assert res.timing_ms["adapter"] > 0 and res.timing_ms["far_band"] > res.timing_ms["far_forward"]
