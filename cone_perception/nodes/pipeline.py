"""pipeline node: the three stages fused in one process (no image crosses a process boundary).

``image_raw`` (or ``image_raw/compressed``) in; ``cone_boxes``, ``/cones`` and ``/cones/markers`` out.

The network is built for the calibration's band at start-up; with ``track: true`` the tracker stage
runs too and gets each frame's attitude.

Parameters (generated from cone_perception/params.py by ``cone-perception params --write``):
  far_rows (string, default auto; auto, none, or V0,V1): the far band: image rows also run at full
    resolution, the whole width, for small, far cones (a second forward; docs/detector.md, Far
    band). auto = the calibration's far strip (the rows where cones 15-40 m ahead stand, moved each
    frame with the attitude; none where the calibration has no camera_matrix); V0,V1 = these rows,
    fixed; none or empty = no far band (not off: ROS reads off as a boolean)
  band_rows (string, default crop; crop, auto, or V0,V1): the band's image rows (its columns and
    downscale stay the calibration's): crop = the calibration's crop (the default); auto = placed
    from the calibration: from the tops of cones as far as the far strip's near end (without a
    strip: max_range_m) to the crop's bottom, with the strip's attitude margins, a multiple of 32
    rows at the band's scale (docs/detector.md, Band rows; on the shipped calibrations it is not
    smaller than their crop); V0,V1 = these rows
  band_split (string, default none; none, auto, or N0,U1): the band in two (docs/detector.md,
    Row-scaled band): none = one band at the calibration's downscale (the default); auto = split
    from the calibration: the near rows, where every cone is at least 48 px tall, at a quarter of
    full resolution, the rows above at the band's half, overlapping by a cone (refused naming
    band_split where the calibration leaves nothing to split); N0,U1 = the near band from row N0,
    the upper band to row U1
  far_model (string, default auto; auto, band, or a model file): the far band's model: auto = the
    shipped far-strip model (models/cone_detector_far.pt, trained for its full-resolution scale:
    more small cones; the image attitude reads its boxes through its own box model, box_model); band
    or empty = the band's own model; else a model file (its box model: MODEL.box_model.yaml). Its
    classes must be the band model's (refused at start-up otherwise)
  far_box_model (string, default band; band | own): which measured box model the image attitude
    reads the far strip's boxes through on a real camera (box_model model; docs/attitude.md, Box
    model): band = the band model's, at each box's size in its input px (the default: the far
    model's own was measured on 640x360 video and has no measurement at the sizes where 15-25 m
    cones fall on a sharp camera); own = the far model's own box model (MODEL.box_model.yaml), its
    sizes without measurements read through the band's (counted on /diagnostics:
    boxes_read_by_band_model)
  far_verifier (string, default none; none, auto, or a verifier file): a second look at the far
    strip's doubtful boxes (scored under the verifier's verify_below, small): a tiny classifier on a
    crop around each box drops those where it sees no cone, such as worn paint (docs/detector.md,
    Far band; counted on /diagnostics: far_strip verifier_dropped). Opt-in: trained on 640x360 video
    and rendered negatives, it dropped real far cones on a sharp camera. none or empty = off (the
    default), auto = the shipped models/cone_verifier.pt (none where it is not installed), else a
    verifier file
  far_every (int, default 1; 1 .. 100): the far band's cadence: its strip runs on every this-many-th
    frame only, the frames between run the band alone (a far cone is seen up to far_every - 1 frames
    late; the tracker carries it meanwhile; docs/detector.md, Far band); 1 = every frame
  far_tiles (int, default 0; 0 .. 8192): with far_every above 1, on the frames between: the strip's
    full-resolution windows around the last two frames' far cones (64 px each side), side by side in
    one mosaic at most this many columns wide, one forward of the far model (the whole strip where
    they do not fit; the band alone where there are none; docs/detector.md, Far band); 0 = off (the
    band alone between); else a multiple of 32 from 192 to the strip's width
  track (bool, default false): also the tracker stage: /cones/tracked out (the parameters of
    cone_tracker); it gets each frame's attitude, which a separate cone_tracker does not
  Also those of driver_adapter (calibration, input_transport); those of detection (model, backend,
    device, fp16, bf16, threads, conf, iou, max_det, debug_image, debug_image_hz); those of mapping
    (publish_markers, attitude, imu_rest_deg, box_model, min_height_ratio, one_ray_range_m); those
    of cone_tracker, with track: true (odom_topic, odom_type, odom_max_age_s,
    publish_tracked_markers); those of every node (input_timeout_s, max_frame_age_s, input_rate_hz).
"""

from __future__ import annotations

from ._common import QOS_DATA, PerceptionNode, run_node  # noqa: I001 (sets DDS env first)

import time

from sensor_msgs.msg import CompressedImage, Image, PointCloud2

from ..detector.farband import SplitDetector, band_rows_for, band_split_for, far_rows_for
from ..resources import far_model_for
from ..geometry.calib import load_calibration
from ..errors import FrameError
from ..pipeline import FrameResult, Pipeline
from . import _msgs
from ._attitude import declare_attitude, declare_box_model, report_attitude
from ._debug import DebugImagePublisher
from ._detector_params import DetectorLoader
from ._params import RuntimeParameters, declare
from ._tracking import NodeTracking


class PipelineNode(PerceptionNode):
    def _far_band(self, fr, model):
        """The far band of ``far_rows`` resolved (:func:`~cone_perception.detector.farband.far_rows_for`; ``auto``:
        the calibration's strip) with a detector of ``model`` (None: the band's) built for its size, or None when
        off; which it is goes to the log."""
        from ..detector.farband import FarBand

        self.get_logger().info(fr.what)
        if fr.crop is None:
            return None
        # warmed like the band's; the Pipeline refuses a far model of other classes before the first frame
        det = self.loader.load((fr.crop.out_width, fr.crop.out_height), model)
        from ..detector.verifier import load_verifier

        verifier = load_verifier(declare(self, "far_verifier"), "parameter far_verifier")
        if verifier is not None:
            self.get_logger().info(f"far strip: second look at its doubtful boxes by {verifier.source}")
        return FarBand(fr.crop, det, "parameter far_model", fr.plan, verifier)

    def _far_tiles(self, far, every: int, model):
        """The far tiles of ``far_tiles`` (detector/fartiles.py; a detector of the far band's ``model`` built for the
        mosaic) between the far band ``far``'s strips, every ``every``-th frame, or None."""
        from ..detector.fartiles import FarTiles, mosaic_widths

        width = int(declare(self, "far_tiles"))
        if not FarTiles.wanted(width, far, every, "parameter far_tiles"):
            return None
        return FarTiles({w: self.loader.load((w, far.crop.height_full_px), model) for w in mosaic_widths(width)})

    def _set_threshold(self, name: str, value) -> None:
        self.loader.set_threshold(self.pipeline.detector, name, value)
        if self.pipeline.far is not None:
            self.loader.set_threshold(self.pipeline.far.detector, name, value)
        if self.pipeline.far_tiles is not None:
            for det in self.pipeline.far_tiles.detectors.values():
                self.loader.set_threshold(det, name, value)

    def __init__(self, **node_kwargs):
        super().__init__("pipeline", **node_kwargs)
        calib = load_calibration(declare(self, "calibration"))
        transport = declare(self, "input_transport")
        markers = bool(declare(self, "publish_markers"))
        self.loader = DetectorLoader(self)
        far_value = declare(self, "far_rows")
        band = band_rows_for(declare(self, "band_rows"), calib, far_value, "parameter band_rows")
        self.get_logger().info(band.what)
        calib = band.apply(calib)  # the band's rows: crop (the calibration's), auto (placed from it) or V0,V1
        far_rows = far_rows_for(far_value, calib, "parameter far_rows")  # auto: the calibration's strip
        plan = self.loader.plan_threads(far_rows.crop is not None)  # with a strip and threads >= 2: both forwards at once
        split = band_split_for(declare(self, "band_split"), calib, "parameter band_split")
        if split.upper is None:
            detector = self.loader.load((calib.crop.out_width, calib.crop.out_height))
        else:  # the band in two: its upper rows at its downscale, its near rows at a quarter
            self.get_logger().info(split.what)
            detector = SplitDetector(*(self.loader.load((c.out_width, c.out_height)) for c in (split.upper, split.near)),
                                     split)
        self.advertise_cones(calib.frame_id, markers)
        mode, imu = declare_attitude(self)
        far_model = far_model_for(declare(self, "far_model"), None)  # None: the band's model
        # the box model of each network: the band's, and the far strip's own model's for its boxes
        att_config, box_model = declare_box_model(self, calib, self.loader.model,
                                                  far_model if far_rows.crop is not None else None,
                                                  str(declare(self, "far_box_model")))
        far, every = self._far_band(far_rows, far_model), int(declare(self, "far_every"))
        self.pipeline = Pipeline(calib, detector, mode, imu, far,
                                 attitude_config=att_config, concurrent=plan.concurrent,
                                 min_height_ratio=float(declare(self, "min_height_ratio")),
                                 one_ray_range_m=float(declare(self, "one_ray_range_m")),
                                 far_every=every, far_tiles=self._far_tiles(far, every, far_model))
        self.health.watch("boxes_dropped", self.pipeline.mapper.dropped)  # by cause (mapping.DROP_CAUSES)
        report_attitude(self, self.pipeline.attitude_mode, self.pipeline.attitude, box_model)
        if self.pipeline.far is not None:  # /diagnostics: frames with the strip, those clamped to the image (WARN)
            self.health.watch("far_strip", self.pipeline.strip_counts, warn=["clamped"])
        self.pub_boxes = self.create_publisher(PointCloud2, "cone_boxes", QOS_DATA)
        self.runtime = RuntimeParameters(self)
        self.runtime.register("publish_markers", lambda v: setattr(self, "publish_markers", bool(v)))
        for name in DetectorLoader.RUNTIME:
            self.runtime.register(name, lambda v, name=name: self._set_threshold(name, v))
        self.debug = DebugImagePublisher(self, self.pipeline.mapper, self.runtime)
        self.tracking = None
        if bool(declare(self, "track")):
            self.tracking = NodeTracking(self, calib)
        self.subscribe_camera(transport)
        self.get_logger().info(f"calibration {calib.source}, frame {calib.frame_id}, attitude {self.pipeline.attitude_mode}"
                               + (f", box model {box_model}" if self.pipeline.attitude else ""))

    def destroy_node(self):
        if getattr(self, "pipeline", None) is not None:
            self.pipeline.close()  # joins the far strip's worker thread, if one runs
        return super().destroy_node()

    def on_raw(self, msg: Image) -> None:
        t0 = time.perf_counter()
        res = self.pipeline.process_raw(msg.encoding, msg.width, msg.height, msg.step, msg.data,
                                        stamp_ns=_msgs.stamp_ns(msg.header))
        self._publish(res, msg.header, t0)

    def on_compressed(self, msg: CompressedImage) -> None:
        t0 = time.perf_counter()
        self._publish(self.pipeline.process_compressed(msg.data, stamp_ns=_msgs.stamp_ns(msg.header)), msg.header, t0)

    def _publish(self, res: FrameResult, header, t0: float) -> None:
        self.pub_boxes.publish(_msgs.boxes_msg(res.boxes, header))
        self.publish_cones(res.cones, header)
        self.debug.publish(res.band, res.boxes, self.pipeline.calib.crop, header)
        self.publish_attitude(res.attitude, header)
        if self.tracking is not None:
            try:
                self.tracking.process(res.cones, header, res.attitude)
            except FrameError as e:  # /cones went out; only this frame's tracking is dropped
                reason = f"tracker_{e.reason}"
                n = self.stats.count_drop(reason)
                if self._may_warn(reason):  # the guard's throttle: one warning per cause every 2 s
                    self.get_logger().warning(f"tracker: frame not fused ({e.reason}, {n} so far): {e}")
        self.get_logger().debug(
            f"{len(res.boxes)} boxes, {len(res.cones)} cones in {(time.perf_counter() - t0) * 1e3:.1f} ms "
            + " ".join(f"{k}={v:.1f}" for k, v in res.timing_ms.items())
        )


def main(args=None) -> int:
    return run_node(PipelineNode, args, "pipeline")


if __name__ == "__main__":
    raise SystemExit(main())
