"""The far strip only where it is needed (issue 26): its cadence (``far_every``: which frames run the strip) and
the tiles between (detector/fartiles.py: windows around the last frame's far cones, one mosaic, boxes back in
full-image px), and their bad values refused naming the parameter."""

from __future__ import annotations

import numpy as np
import pytest

from cone_perception.crop import CropSpec
from cone_perception.detector.farband import FarBand
from cone_perception.detector.fartiles import FILL, TILE_GAP_PX, TILE_MARGIN_PX, FarTiles, mosaic_widths
from cone_perception.errors import ConfigError
from cone_perception.geometry.calib import load_calibration
from cone_perception.params import PARAMS
from cone_perception.pipeline import Pipeline
from cone_perception.records import boxes_from_arrays

from rosutil import ros  # noqa: F401 (a fixture)

CALIB = load_calibration("example_mainhoop")
STRIP = CropSpec(370, 466, 0, 1920, 1)


class _Boxes:
    """A detector double: records each call's image and crop and returns the boxes ``boxes(bgr, crop)`` says
    (``[(u1, v1, u2, v2), ...]`` in the image it is given, mapped to full-image px as a Detector does)."""

    def __init__(self, boxes=None):
        self.calls, self.boxes = [], boxes or (lambda bgr, crop: [])
        self.timing = {"preprocess_ms": 0.0, "forward_ms": 0.0, "postprocess_ms": 0.0}

    def detect(self, bgr, crop):
        self.calls.append((bgr.copy(), crop))
        a = np.array(self.boxes(bgr, crop), np.float32).reshape(-1, 4)
        a = crop.boxes_to_full(a) if len(a) else a
        return boxes_from_arrays(a, np.full(len(a), 0.9, np.float32), np.zeros(len(a), np.uint8))


def _frame() -> bytes:
    u = np.arange(1920, dtype=np.uint16) % 251  # each column's value says which column it is (mod 251)
    return np.ascontiguousarray(np.dstack([np.broadcast_to(u.astype(np.uint8), (1080, 1920))] * 3)).tobytes()


def _run(pipe: Pipeline, n: int) -> None:
    for i in range(n):
        pipe.process_raw("bgr8", 1920, 1080, 5760, _frame(), stamp_ns=i)


def test_the_strip_runs_on_every_nth_frame_and_the_band_alone_between():
    """far_every 3: the strip on frames 0, 3, 6 (cut and run), the band on every frame; counted."""
    band, strip = _Boxes(), _Boxes()
    pipe = Pipeline(CALIB, band, "fixed", far=FarBand(STRIP, strip), far_every=3)
    _run(pipe, 7)
    assert len(band.calls) == 7 and len(strip.calls) == 3
    assert pipe.strip_counts == {"frames": 3, "clamped": 0, "skipped": 4}
    every = Pipeline(CALIB, _Boxes(), "fixed", far=FarBand(STRIP, strip))  # the default: every frame
    _run(every, 2)
    assert len(strip.calls) == 5 and every.strip_counts == {"frames": 2, "clamped": 0}


@pytest.mark.parametrize("bad", [0, -2, 1.5, True, "2"])
def test_bad_far_every_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match="far_every"):
        Pipeline(CALIB, _Boxes(), "fixed", far=FarBand(STRIP, _Boxes()), far_every=bad)
    assert "far_every" in (PARAMS["far_every"].check(bad) or "")


def test_windows_merge_stay_even_inside_the_image_and_overflow_to_none():
    tiles = FarTiles({640: _Boxes()})
    b = boxes_from_arrays(np.array([[1001, 400, 1011, 420], [1050, 400, 1060, 420], [5, 400, 15, 420],
                                    [1900, 400, 1915, 420]], np.float32), np.ones(4, np.float32), np.zeros(4, np.uint8))
    m = TILE_MARGIN_PX
    want = [(0, 15 + m + 1), (1000 - m, 1060 + m), (1900 - m, 1920)]
    assert tiles.windows(b, 1920) == want
    assert all(a % 2 == 0 and c % 2 == 0 for a, c in want)
    assert tiles.windows(b[:0], 1920) == []
    assert FarTiles({192: _Boxes()}).windows(b, 1920) is None  # three windows do not fit 192 columns


def test_tile_boxes_land_in_full_image_coordinates_and_cut_ones_are_dropped():
    """Two windows in one mosaic: a cone in the second window's middle comes back at its place in the image; one
    crossing the gap between the windows and one touching a window's inner side are dropped; the mosaic holds
    the strip's columns and the grey between."""
    a, b = (100, 228), (1000, 1128)
    x2 = (a[1] - a[0]) + TILE_GAP_PX  # the second window's first column in the mosaic

    def boxes(bgr, crop):
        return [(x2 + 50, 20, x2 + 62, 60),  # a cone inside window 2: full image u 1050-1062, v 390-430
                (x2 - 10, 20, x2 + 6, 60),  # across the gap
                (x2 + 120, 20, x2 + 127.5, 60)]  # touching window 2's right side (the image goes on)

    det, narrow = _Boxes(boxes), _Boxes()
    tiles = FarTiles({256: narrow, 512: det})  # the two windows need 272 columns: the 512 one runs
    strip = np.ascontiguousarray(np.broadcast_to((np.arange(1920) % 251).astype(np.uint8)[None, :, None], (96, 1920, 3)))
    out = tiles.detect(strip, STRIP, [a, b], 1920)
    assert len(out) == 1
    assert (out["u1"][0], out["v1"][0], out["u2"][0], out["v2"][0]) == (1050, 390, 1062, 430)
    canvas, crop = det.calls[-1]
    assert canvas.shape == (96, 512, 3) and (crop.v0, crop.v1, crop.u0) == (370, 466, 0)
    assert canvas[0, 0, 0] == 100 % 251 and canvas[0, x2 + 5, 0] == 1005 % 251
    assert (canvas[:, a[1] - a[0]:x2] == FILL).all() and (canvas[:, x2 + 128:] == FILL).all()
    assert not narrow.calls
    tiles.detect(strip, STRIP, [b], 1920)  # one window: the narrowest mosaic
    assert narrow.calls[-1][0].shape == (96, 256, 3) and len(det.calls) == 1


def test_mosaic_widths_step_up_to_the_setting():
    assert mosaic_widths(1152) == [256, 512, 768, 1024, 1152] and mosaic_widths(256) == [256]
    assert mosaic_widths(192) == [192]


@pytest.mark.parametrize("concurrent", [False, True])
def test_pipeline_runs_tiles_around_the_last_frames_far_cones_between_the_strips(concurrent):
    """far_every 2 with tiles (memory: the last two frames): frame 0 runs the strip, which finds a cone at u 1500;
    frame 1 runs the tiles, one window around it, and the tile's box comes back at u 1500; from frame 2 on nothing
    is found: frame 2 the strip; frame 3 the tiles still (frame 1 saw the cone); frame 4 the strip; frame 5 has
    no far cone to look for in its last two frames: the band alone."""
    found = {"cone": True}

    def strip_boxes(bgr, crop):
        return [(1500, 20, 1510, 40)] if found["cone"] else []

    def tile_boxes(bgr, crop):  # the cone where it is in the mosaic: its window starts at 1500 - margin
        return [(TILE_MARGIN_PX, 20, TILE_MARGIN_PX + 10, 40)] if found["cone"] else []

    strip, tile = _Boxes(strip_boxes), _Boxes(tile_boxes)
    pipe = Pipeline(CALIB, _Boxes(), "fixed", far=FarBand(STRIP, strip), far_every=2, far_tiles=FarTiles({256: tile}),
                    concurrent=concurrent)  # concurrent: the strip's or the tiles' detect on a worker thread
    _run(pipe, 1)
    res = pipe.process_raw("bgr8", 1920, 1080, 5760, _frame(), stamp_ns=1)
    assert len(strip.calls) == 1 and len(tile.calls) == 1
    assert tile.calls[0][0][0, TILE_MARGIN_PX, 0] == 1500 % 251  # the window's columns, from the full-resolution strip
    assert len(res.boxes) == 1 and (res.boxes["u1"][0], res.boxes["v1"][0]) == (1500, 390)
    found["cone"] = False
    for frame, (strips, tiles) in enumerate(((2, 1), (2, 2), (3, 2), (3, 2)), start=2):
        res = pipe.process_raw("bgr8", 1920, 1080, 5760, _frame(), stamp_ns=frame)
        assert (len(strip.calls), len(tile.calls)) == (strips, tiles), frame
        assert len(res.boxes) == 0
    assert pipe.strip_counts == {"frames": 3, "clamped": 0, "skipped": 3, "tiles": 2, "tiles_full": 0}
    pipe.close()


def test_tile_box_comes_back_on_the_frame_result_and_its_network_times_the_frame():
    """The tile frame's box in full-image px on the FrameResult; its far_forward is the mosaic's network's (of the
    two widths, the one that ran), the strip frame's the strip's."""
    strip = _Boxes(lambda bgr, crop: [(1500, 20, 1510, 40)])
    tile = _Boxes(lambda bgr, crop: [(TILE_MARGIN_PX + 4, 22, TILE_MARGIN_PX + 14, 42)])
    wide = _Boxes()
    strip.timing["forward_ms"], tile.timing["forward_ms"], wide.timing["forward_ms"] = 6.0, 1.5, 3.0
    tiles = FarTiles({256: tile, 512: wide})
    pipe = Pipeline(CALIB, _Boxes(), "fixed", far=FarBand(STRIP, strip), far_every=2, far_tiles=tiles)
    assert pipe.process_raw("bgr8", 1920, 1080, 5760, _frame(), stamp_ns=0).timing_ms["far_forward"] == 6.0
    res = pipe.process_raw("bgr8", 1920, 1080, 5760, _frame(), stamp_ns=1)
    assert len(res.boxes) == 1 and (res.boxes["u1"][0], res.boxes["v1"][0]) == (1504, 392)
    assert res.timing_ms["far_forward"] == 1.5 and not wide.calls


@pytest.mark.parametrize("width", [100, 650, 4000])
def test_bad_far_tiles_widths_are_refused_naming_the_option(width):
    far = FarBand(STRIP, _Boxes())
    with pytest.raises(ConfigError, match="--far-tiles"):
        FarTiles.for_setting(None, width, far, 2, "--far-tiles")
    assert FarTiles.for_setting(None, 0, far, 2) is None and FarTiles.for_setting(None, 640, far, 1) is None


def test_replay_refuses_bad_far_every_and_far_tiles(tmp_path, capsys):
    from cone_perception.cli import main

    for args, name in ((["--far-every", "0"], "--far-every"), (["--far-tiles", "-1"], "--far-tiles"),
                       (["--far-every", "2", "--far-tiles", "640", "--box-behaviour", "real"], "--far-tiles")):
        assert main(["replay", str(tmp_path / "nothing"), *args, "--no-progress"]) == 2
        assert name in capsys.readouterr().err


def test_far_cones_the_mosaic_cannot_hold_run_the_whole_strip():
    """Three far cones across the width need three windows, more than a 192-column mosaic: frame 1 runs the whole
    strip (counted as tiles_full), the tiles' network never."""
    strip = _Boxes(lambda bgr, crop: [(200, 20, 210, 40), (900, 20, 910, 40), (1700, 20, 1710, 40)])
    tile = _Boxes()
    pipe = Pipeline(CALIB, _Boxes(), "fixed", far=FarBand(STRIP, strip), far_every=2, far_tiles=FarTiles({192: tile}))
    _run(pipe, 2)
    assert len(strip.calls) == 2 and not tile.calls
    assert pipe.strip_counts == {"frames": 2, "clamped": 0, "skipped": 1, "tiles": 0, "tiles_full": 1}


def test_pipeline_node_far_every_and_far_tiles(ros):  # noqa: F811 (ros is a fixture)
    """The node's far_every / far_tiles: the Pipeline gets the cadence and one tile network per mosaic width, the
    counts reach /diagnostics; a bad width or cadence stops the node naming the parameter."""
    from rclpy.exceptions import InvalidParameterValueException
    from rclpy.parameter import Parameter

    from cone_perception.nodes.pipeline import PipelineNode

    node = ros.add(PipelineNode(context=ros.context, parameter_overrides=[Parameter("far_every", value=2),
                                                                          Parameter("far_tiles", value=512)]))
    p = node.pipeline
    assert p.far_every == 2 and sorted(p.far_tiles.detectors) == [256, 512]
    assert all(d.input_size_for(w, 96) == (w, 96) for w, d in p.far_tiles.detectors.items())
    values = dict(node.health.assess(10**9).values)
    assert values["far_strip:skipped"] == "0" and values["far_strip:tiles"] == "0"
    with pytest.raises(ConfigError, match="parameter far_tiles: must be 0 .* a multiple of 32"):
        PipelineNode(context=ros.context, parameter_overrides=[Parameter("far_every", value=2),
                                                               Parameter("far_tiles", value=100)])
    with pytest.raises(InvalidParameterValueException, match="far_every out of range"):  # rclpy checks the range
        PipelineNode(context=ros.context, parameter_overrides=[Parameter("far_every", value=0)])
