"""The ``cone-perception export`` run: a checkpoint to TorchScript or ONNX, verified against eager torch,
and the int8 ONNX (:mod:`.quantize`) when asked; ``export --cache``: the ONNX cache (:mod:`~..detector.onnx_cache`)
filled with what the pipeline node loads, before driving.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..data.outfiles import refuse_existing
from ..detector import Detector, default_model_path, sidecar_path, write_sidecar
from ..detector.export import export_metadata, export_model, with_onnx_metadata, worst_diff_to_eager
from ..detector.farband import band_rows_for, band_split_for, far_rows_for
from ..detector.fartiles import mosaic_widths
from ..detector.onnx_cache import onnx_cache_dir
from ..detector.verifier import load_verifier
from ..errors import ConfigError
from ..geometry.calib import load_calibration
from ..params import PARAMS
from ..resources import far_model_for
from ..model.checkpoint import load_checkpoint
from ..model.postprocess import postprocess
from ..train.quantize import (
    MIN_MATCHED, MIN_MEAN_IOU, QuantOptions, calibration_blobs, compare_detections, int8_frame_pool, quantize_onnx,
    spread,
)
from ..train.trainer import round_imgsz

#: largest |exported - eager| output allowed
TOLERANCE = 1e-3
#: frames the export is verified on
VERIFY_FRAMES = 8


def run_export(args: argparse.Namespace) -> int:
    if args.cache:
        return run_cache(args)
    if args.model is None or args.format is None:
        raise ConfigError("export", "--model" if args.model is None else "--format",
                          "needed (but for --cache: the ONNX cache of the pipeline node)")
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
    files = spread(pool, args.calib_frames)
    opts = QuantOptions(activation=args.int8_activations, per_channel=not args.per_tensor,
                        exclude_head=not args.int8_head, method=args.calib_method, ops=args.int8_ops)
    out = fp32_path.with_suffix(".int8.onnx")
    print(f"calibrating on {len(files)} frames of {args.calib_images}"
          + (f" ({dropped} frames of validation clips left out)" if dropped else "") + f"; {opts.describe()}")
    summary = quantize_onnx(fp32_path, out, calibration_blobs(files, imgsz, args.calib_crop, args.calib_downscale),
                            opts, total=len(files), progress=not args.no_progress)

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


def node_graphs(values: dict[str, str]) -> tuple[list[tuple[Path, tuple[int, int]]], bool]:
    """((model file, input size (W, H)) of every detector the ``pipeline`` node loads with the parameters ``values``
    (name -> text, as ``-p name:=value``; the schema's default for the rest), in the node's order: the band (or its
    two parts with ``band_split``), the far strip's model at the strip's size, the far tiles' mosaics; whether the
    node runs the far strip (and so loads its verifier))."""
    p = {k: s.default for k, s in PARAMS.items()}
    for k, v in values.items():
        if k not in PARAMS:
            raise ConfigError("--param", k, "not a parameter of the pipeline node (see `pipeline --help`)")
        p[k] = type(p[k])(int(v)) if isinstance(p[k], int) and not isinstance(p[k], bool) else v
    calib = load_calibration(p["calibration"])
    model = Path(p["model"]) if p["model"] else default_model_path()
    calib = band_rows_for(p["band_rows"], calib, p["far_rows"], "parameter band_rows").apply(calib)
    far = far_rows_for(p["far_rows"], calib, "parameter far_rows").crop
    split = band_split_for(p["band_split"], calib, "parameter band_split")
    crops = [calib.crop] if split.upper is None else [split.upper, split.near]
    out = [(model, (c.out_width, c.out_height)) for c in crops]
    if far is not None:
        far_model = Path(far_model_for(p["far_model"], model))
        out.append((far_model, (far.out_width, far.out_height)))
        if int(p["far_tiles"]) and int(p["far_every"]) > 1:
            out += [(far_model, (w, far.height_full_px)) for w in mosaic_widths(int(p["far_tiles"]))]
    return out, far is not None


def run_cache(args: argparse.Namespace) -> int:
    """``export --cache``: the ONNX cache filled with the graphs the pipeline node loads with ``--param``s (and the
    far strip's verifier): a start then imports no torch. Says which were there and which it exported."""
    values = {}
    for item in args.param:
        name, sep, value = item.partition(":=")
        if not sep:
            raise ConfigError("--param", None, f"expected NAME:=VALUE, got {item!r}")
        values[name.strip()] = value.strip()
    if args.model:
        values.setdefault("model", args.model)
    before = set(onnx_cache_dir().glob("*.onnx"))
    graphs, far = node_graphs(values)
    for model, size in graphs:
        Detector.load_for_band(model, size, backend="onnx")
    verifier = far and load_verifier(values.get("far_verifier", PARAMS["far_verifier"].default),
                                     "parameter far_verifier") is not None
    new = sorted(set(onnx_cache_dir().glob("*.onnx")) - before)
    print(f"ONNX cache {onnx_cache_dir()}: {len(graphs)} detector graph(s) for the pipeline node "
          f"({', '.join(f'{m.name} {w}x{h}' for m, (w, h) in graphs)}){' and its verifier' if verifier else ''}; "
          f"{len(new)} written now{': ' + ', '.join(p.name for p in new) if new else ''}")
    return 0
