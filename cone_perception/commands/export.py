"""``cone-perception export``: a checkpoint -> TorchScript or ONNX (common YOLO layout), verified;
with ``--int8`` also a statically quantised ONNX (``<stem>.int8.onnx``) calibrated on real frames."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._args import parse_crop, size_arg

TOLERANCE = 1e-3
VERIFY_FRAMES = 8


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..train.quantize import ACTIVATION_TYPES, CALIB_METHODS, DEFAULT_CALIB_FRAMES, MIN_MATCHED, MIN_MEAN_IOU

    p.description = (
        "Export a detector checkpoint to TorchScript or ONNX, verified against eager (max |diff| <= "
        f"{TOLERANCE}). With --int8 (ONNX only) the fp32 ONNX is then quantised with ONNX Runtime "
        "(static, QDQ, convolutions only; the box decoding stays float), calibrated on real frames "
        "preprocessed as the detector does at run time, written as <stem>.int8.onnx + <stem>.int8.yaml "
        f"and checked on real frames: at least {MIN_MATCHED:.0%} of the float model's boxes must have an "
        f"int8 box of the same class (IoU >= 0.5) and the pairs' mean IoU must be >= {MIN_MEAN_IOU}."
    )
    p.add_argument("--model", required=True, help="checkpoint (.pt) written by `cone-perception train`")
    p.add_argument("--format", choices=("torchscript", "onnx"), required=True, help="output format")
    p.add_argument("--imgsz", type=size_arg, default=None, help="input WxH px (default: the checkpoint's)")
    p.add_argument("--out", default=None, help="output file (default: next to the checkpoint, .torchscript / .onnx)")
    p.add_argument("--force", action="store_true", help="overwrite existing output files (the model and its sidecar <file>.yaml; with --int8 those of the int8 file too)")
    q = p.add_argument_group("int8 (ONNX only)")
    q.add_argument("--int8", action="store_true", help="also write <stem>.int8.onnx, statically quantised")
    q.add_argument("--calib-images", type=Path, default=None, metavar="DIR",
                   help="folder of real frames to calibrate on (searched recursively); frames of the validation "
                        "clips autox4, autox2, accel are always left out")
    q.add_argument("--calib-frames", type=int, default=DEFAULT_CALIB_FRAMES, metavar="N",
                   help="calibration frames, spread evenly over the folder (default %(default)s)")
    q.add_argument("--calib-clips", default=None, metavar="CLIPS", help="use only frames of these clips, comma-separated (e.g. autox3,autox6)")
    q.add_argument("--calib-crop", type=parse_crop, default=None, metavar="V0,V1[,U0,U1]",
                   help="cut this band (rows, optionally columns, in the frames' px) before the model, as the car's "
                        "adapter does (e.g. 32,224 in 640x360 frames = rows 96-672 of 1080); default: the whole frame, "
                        "letterboxed")
    q.add_argument("--calib-downscale", type=int, default=1, choices=[1, 2, 4], help="with --calib-crop: integer downscale")
    q.add_argument("--calib-method", choices=CALIB_METHODS, default="minmax",
                   help="activation ranges: min-max over the frames (default) or the 99.999th percentile "
                        "(keeps every activation of every frame in memory: ~55 MB a frame at 960x288)")
    q.add_argument("--int8-activations", choices=ACTIVATION_TYPES, default="uint8",
                   help="activation type (default %(default)s: x86 runs uint8 x int8 fastest)")
    q.add_argument("--per-tensor", action="store_true", help="one weight scale per conv instead of one per output channel")
    q.add_argument("--int8-head", action="store_true", help="quantise the last head convs too (default: kept float)")
    q.add_argument("--int8-ops", choices=("conv", "all"), default="conv",
                   help="conv: quantise convolutions only (default); all: every op ONNX Runtime can quantise "
                        "(SiLU, add, concat, pooling, resize) except the box decoding")
    q.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from ..data.outfiles import refuse_existing
    from ..detector import Detector, sidecar_path, write_sidecar
    from ..detector.export import export_metadata, export_model, worst_diff_to_eager
    from ..errors import ConfigError
    from ..model.checkpoint import load_checkpoint
    from ..train.trainer import round_imgsz

    int8_flags = [f"--{k.replace('_', '-')}" for k in ("calib_images", "calib_clips", "calib_crop") if getattr(args, k) is not None]
    if not args.int8 and int8_flags:
        raise ConfigError(int8_flags[0], None, "calibration options need --int8")
    if args.int8:
        if args.format != "onnx":
            raise ConfigError("--int8", None, f"int8 quantisation needs --format onnx, not {args.format}")
        if args.calib_images is None:
            raise ConfigError("--int8", "calib-images", "give a folder of real frames to calibrate on (--calib-images DIR)")
        if args.calib_frames < 1:
            raise ConfigError("--calib-frames", None, f"must be >= 1, got {args.calib_frames}")
        from ..train.quantize import int8_frame_pool

        # the calibration frames are checked before anything is exported
        pool, dropped = int8_frame_pool(args.calib_images, args.calib_clips.split(",") if args.calib_clips else None)

    ck = load_checkpoint(args.model)
    imgsz = round_imgsz(args.imgsz) if args.imgsz else ck.imgsz
    suffix = ".onnx" if args.format == "onnx" else ".torchscript"
    out = Path(args.out) if args.out else Path(args.model).with_suffix(suffix)
    if out.suffix != suffix:
        raise ConfigError(str(out), None, f"the output of format {args.format} must end in {suffix}")
    model = ck.build_model()
    int8_out = out.with_suffix(".int8.onnx")
    outputs = [out, sidecar_path(out)] + ([int8_out, sidecar_path(int8_out)] if args.int8 else [])
    refuse_existing(outputs, args.force, "export")
    meta = export_metadata(ck.class_names, imgsz, max(model.strides), str(args.model))
    export_model(model, imgsz, args.format, out, meta)
    side = write_sidecar(out, ck.class_names, imgsz, {k: v for k, v in meta.items() if k not in ("names", "imgsz")})

    # verify: the exported file, loaded the way users load it, against eager on random and grey inputs
    exported = Detector.load(out, backend=args.format)
    eager = Detector.load(args.model, backend="torch", imgsz=imgsz)
    w, h = imgsz
    worst = worst_diff_to_eager(exported, eager, imgsz)
    if worst > TOLERANCE:
        out.unlink(missing_ok=True)
        raise ConfigError(str(out), None, f"exported model differs from eager by {worst:.3g} (> {TOLERANCE}); file removed")
    print(f"wrote {out} ({w}x{h}; class names, input size, stride and source embedded) and {side}; "
          f"verified against eager: max |diff| {worst:.2e} <= {TOLERANCE}")
    if args.int8:
        _int8(args, ck, out, imgsz, eager, pool, dropped)
    return 0


def _int8(args, ck, fp32_path: Path, imgsz: tuple[int, int], eager, pool: list[Path], dropped: int) -> None:
    """Quantise ``fp32_path`` into ``<stem>.int8.onnx``, calibrated on frames of ``pool``, and check it."""
    from ..detector import Detector, write_sidecar
    from ..errors import ConfigError
    from ..model.decode import postprocess
    from ..train.quantize import (
        MIN_MATCHED, MIN_MEAN_IOU, QuantOptions, calibration_blobs, compare_detections, quantize_onnx, spread,
    )

    files = spread(pool, args.calib_frames)
    opts = QuantOptions(activation=args.int8_activations, per_channel=not args.per_tensor,
                        exclude_head=not args.int8_head, method=args.calib_method, ops=args.int8_ops)
    out = fp32_path.with_suffix(".int8.onnx")
    print(f"calibrating on {len(files)} frames of {args.calib_images}"
          + (f" ({dropped} frames of validation clips left out)" if dropped else "") + f"; {opts.describe()}")
    summary = quantize_onnx(fp32_path, out, calibration_blobs(files, imgsz, args.calib_crop, args.calib_downscale),
                            opts, total=len(files), progress=not args.no_progress)
    from ..detector.export import export_metadata, with_onnx_metadata

    meta = export_metadata(ck.class_names, imgsz, max(ck.cfg.strides), str(args.model), {
        "quantisation": opts.describe(), "calibration": f"{len(files)} frames of {args.calib_images}"})
    out.write_bytes(with_onnx_metadata(out.read_bytes(), meta))
    side = write_sidecar(out, ck.class_names, imgsz, {k: v for k, v in meta.items() if k not in ("names", "imgsz")})

    # check: boxes of the int8 file, loaded the way users load it, against eager on real frames
    # (frames not used for calibration if the folder has them)
    used = set(files)
    held_out = [f for f in pool if f not in used]
    vfiles = spread(held_out or files, VERIFY_FRAMES)
    q = Detector.load(out, backend="onnx")
    pairs = [(postprocess(eager.raw(b), eager.conf, eager.iou, eager.max_det), postprocess(q.raw(b), q.conf, q.iou, q.max_det))
             for b in calibration_blobs(vfiles, imgsz, args.calib_crop, args.calib_downscale)]
    r = compare_detections(pairs)
    what = (f"{len(summary['conv_int8'])} of {len(summary['conv_int8']) + len(summary['conv_float'])} convs int8; "
            f"on {len(vfiles)} {'held-out ' if held_out else ''}frames at conf {eager.conf}: ")
    if r["ref_boxes"] == 0:
        what += "the float model finds no boxes there, nothing to compare"
    else:
        what += (f"{r['matched']:.0%} of {r['ref_boxes']} float boxes matched ({r['test_boxes']} int8 boxes), "
                 f"IoU mean {r['mean_iou']:.3f} min {r['min_iou']:.3f}, max corner deviation {r['max_dev_px']:.2f} px, "
                 f"max score difference {r['max_score_diff']:.3f}")
    if not r["ok"]:
        out.unlink(missing_ok=True)
        side.unlink(missing_ok=True)
        raise ConfigError(str(out), None, f"int8 model too far from eager: {what} (need >= {MIN_MATCHED:.0%} matched, "
                          f"mean IoU >= {MIN_MEAN_IOU}); files removed. Try more --calib-frames, --calib-method "
                          "percentile, or without --int8-head / --per-tensor")
    print(f"wrote {out} and {side}; {what}")
