"""Static int8 quantisation of an exported ONNX detector (ONNX Runtime, QDQ format).

    pool, dropped = int8_frame_pool(folder)                    # real frames, validation clips left out
    blobs = calibration_blobs(spread(pool, 64), imgsz, crop=(32, 224))  # exactly the detector's preprocessing
    quantize_onnx(fp32_path, int8_path, blobs, QuantOptions())  # -> <stem>.int8.onnx

Only the convolutions are quantised (per-channel int8 weights, 8-bit activations calibrated on
the frames); everything after the last convolutions - the head's concat, the DFL softmax and
expectation, the box arithmetic and the class sigmoid - stays float (one 8-bit scale cannot hold
pixel coordinates up to 960 and 0..1 scores; a YOLO11n quantised throughout lost its box decoding).
:func:`qdq_summary` tells what a quantised graph holds (used by the export check and the tests).
"""

from __future__ import annotations

import tempfile
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

import cv2
import numpy as np

from ..crop import CropSpec
from ..errors import ConfigError

DEFAULT_CALIB_FRAMES = 64
ACTIVATION_TYPES = ("uint8", "int8")
#: minmax: each tensor's range over the frames; percentile: its 99.999th percentile (ONNX Runtime's
#: default). No "entropy": quantize_static runs ONNX Runtime's entropy calibrator with as many histogram
#: bins as quantised bins (128), so it returns the min-max ranges (the files came out byte-identical).
CALIB_METHODS = ("minmax", "percentile")
QDQ_OPS = ("QuantizeLinear", "DequantizeLinear")


@dataclass(frozen=True)
class QuantOptions:
    """How to quantise. ``exclude_head``: keep the last convolution of each head branch float
    (their outputs are the box-distribution and class logits the decoding reads). ``ops``:
    ``"conv"`` quantises convolutions only; ``"all"`` every op ONNX Runtime can quantise (SiLU's
    sigmoid and product, add, concat, max-pool, resize) - the box decoding always stays float."""

    activation: str = "uint8"
    per_channel: bool = True
    exclude_head: bool = True
    method: str = "minmax"
    ops: str = "conv"

    def describe(self) -> str:
        ops = "Conv only" if self.ops == "conv" else "all ops but the box decoding"
        return (f"{ops}, QDQ, {'per-channel' if self.per_channel else 'per-tensor'} int8 weights, "
                f"{self.activation} activations, {self.method} calibration, "
                f"last head convs {'float' if self.exclude_head else 'int8'}")


def int8_frame_pool(folder: str | Path, clips: Iterable[str] | None = None) -> tuple[list[Path], int]:
    """The images of ``folder`` (searched recursively, sorted) that int8 calibration may use, and how
    many were dropped because they belong to the validation clips
    (:data:`~cone_perception.data.datasets.VALIDATION_CLIPS`, never used; naming one in ``clips`` is an error).
    ``clips`` keeps only frames of these clips (file name before the first '-')."""
    from ..data.datasets import IMAGE_SUFFIXES, VALIDATION_CLIPS, in_clips

    folder = Path(folder)
    src = str(folder)
    if not folder.is_dir():
        raise ConfigError(src, "calib-images", "calibration image folder not found" if not folder.exists() else "is not a folder")
    files = sorted(p for p in folder.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    if not files:
        raise ConfigError(src, "calib-images", f"no images ({', '.join(IMAGE_SUFFIXES)}) found")
    val = set(VALIDATION_CLIPS)
    if clips is not None:
        clips = {c.strip() for c in clips if c.strip()}
        bad = sorted(clips & val)
        if bad:
            raise ConfigError(src, "calib-clips", f"{', '.join(bad)}: validation clips are never used for calibration")
        files = [p for p in files if in_clips(p.stem, clips)]
        if not files:
            raise ConfigError(src, "calib-clips", f"no images of clips {', '.join(sorted(clips))}")
    kept = [p for p in files if not in_clips(p.stem, val)]
    dropped = len(files) - len(kept)
    if not kept:
        raise ConfigError(src, "calib-images", f"all {dropped} images belong to the validation clips "
                          f"{', '.join(VALIDATION_CLIPS)}, which are never used for calibration")
    return kept, dropped


def spread(files: list[Path], n: int) -> list[Path]:
    """Up to ``n`` of ``files``, evenly spread over the list (deterministic)."""
    if int(n) < 1:
        raise ConfigError("calib-frames", None, f"must be >= 1, got {n}")
    if not files:
        return []
    idx = np.unique(np.linspace(0, len(files) - 1, min(int(n), len(files))).round().astype(int))
    return [files[i] for i in idx]


def calibration_blobs(files: list[Path], imgsz: tuple[int, int], crop: tuple[int, ...] | None = None,
                      downscale: int = 1) -> Iterator[np.ndarray]:
    """Network inputs of the calibration frames, made as the detector makes them at run time.

    With ``crop`` (V0, V1[, U0, U1] in each frame's px; without U0, U1 the full width) the band is
    cut and downscaled like the car's adapter does (:func:`~.adapter.crop_bgr`); then
    :func:`~.detector.preprocess` fits it to the model input ``imgsz`` (W, H)."""
    from ..adapter import crop_bgr
    from ..detector.preprocess import preprocess

    for f in files:
        img = cv2.imread(str(f), cv2.IMREAD_COLOR)
        if img is None:
            raise ConfigError(str(f), None, "unreadable calibration image")
        if crop is not None:
            h, w = img.shape[:2]
            spec = CropSpec(*(crop if len(crop) == 4 else (*crop, 0, w)), downscale)
            spec.validate(w, h, f"--calib-crop for {f}")
            img = crop_bgr(img, spec)
        yield preprocess(img, *imgsz)[0]


def head_output_convs(model) -> list[str]:
    """Names of the convolutions whose outputs reach the graph output through no other convolution:
    the last conv of every head branch (box-distribution and class logits)."""
    producer = {o: n for n in model.graph.node for o in n.output}
    found, seen = [], set()
    stack = [o.name for o in model.graph.output]
    while stack:
        t = stack.pop()
        node = producer.get(t)
        if node is None or node.name in seen:
            continue
        seen.add(node.name)
        if node.op_type == "Conv":
            found.append(node.name)
            continue
        if node.op_type == "DequantizeLinear":  # a quantised conv's output QDQ pair: look through it
            stack.append(node.input[0])
            continue
        stack.extend(node.input)
    return sorted(found)


def decode_nodes(model, last_convs: list[str]) -> list[str]:
    """Names of the nodes after ``last_convs`` (the box decoding): never quantised."""
    consumers: dict[str, list] = {}
    for n in model.graph.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    out, stack = set(), [o for n in model.graph.node if n.name in set(last_convs) for o in n.output]
    while stack:
        for c in consumers.get(stack.pop(), []):
            if c.name not in out:
                out.add(c.name)
                stack.extend(c.output)
    return sorted(out)


def qdq_summary(model) -> dict:
    """What a (quantised) ONNX graph holds: convolutions with int8 weights / float weights, the ops
    that read a DequantizeLinear output, and the ops between the last convs and the output."""
    producer = {o: n for n in model.graph.node for o in n.output}
    consumers: dict[str, list] = {}
    for n in model.graph.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    conv_q, conv_f = [], []
    for n in model.graph.node:
        if n.op_type == "Conv":
            w = producer.get(n.input[1])
            (conv_q if w is not None and w.op_type == "DequantizeLinear" else conv_f).append(n.name)
    dq_readers = Counter(c.op_type for n in model.graph.node if n.op_type == "DequantizeLinear"
                         for c in consumers.get(n.output[0], []))
    # ops after the last convs (the decoding), not counting the QDQ pair right on a quantised conv's output
    decode, seen = Counter(), set()

    def walk(tensor: str, skip_qdq: bool) -> None:
        for c in consumers.get(tensor, []):
            if skip_qdq and c.op_type in QDQ_OPS:
                walk(c.output[0], c.op_type == "QuantizeLinear")
            elif c.name not in seen:
                seen.add(c.name)
                decode[c.op_type] += 1
                for o in c.output:
                    walk(o, False)

    last = set(head_output_convs(model))
    for n in model.graph.node:
        if n.name in last:
            walk(n.output[0], True)
    return {
        "conv_int8": sorted(conv_q), "conv_float": sorted(conv_f), "dq_readers": dict(dq_readers),
        "decode_ops": dict(decode),
        "op_types": dict(Counter(n.op_type for n in model.graph.node)),
    }


class _Reader:
    """ONNX Runtime calibration data reader over an iterator of blobs, with a progress bar."""

    def __init__(self, input_name: str, blobs: Iterator[np.ndarray], total: int | None, progress: bool):
        from tqdm import tqdm

        self.input_name, self.blobs = input_name, iter(blobs)
        self.bar = tqdm(total=total, unit="frame", desc="calibrating", disable=not progress)

    def get_next(self):
        blob = next(self.blobs, None)
        if blob is None:
            self.bar.close()
            return None
        self.bar.update(1)
        return {self.input_name: blob}

    def rewind(self):  # part of the reader protocol; one pass is all static calibration needs
        pass


def quantize_onnx(fp32_path: str | Path, out_path: str | Path, blobs: Iterable[np.ndarray], opts: QuantOptions = QuantOptions(),
                  total: int | None = None, progress: bool = True) -> dict:
    """Quantise the fp32 ONNX model at ``fp32_path`` into ``out_path`` (QDQ, Conv only), calibrated
    on ``blobs`` ((1, 3, H, W) float32 network inputs). Returns :func:`qdq_summary` of the result."""
    import onnx
    from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    if opts.activation not in ACTIVATION_TYPES:
        raise ConfigError(str(fp32_path), "activation", f"must be one of {', '.join(ACTIVATION_TYPES)}, got {opts.activation!r}")
    if opts.ops not in ("conv", "all"):
        raise ConfigError(str(fp32_path), "int8-ops", f"must be conv or all, got {opts.ops!r}")
    if opts.method not in CALIB_METHODS:
        raise ConfigError(str(fp32_path), "calib-method", f"must be one of {', '.join(CALIB_METHODS)}, got {opts.method!r}")
    fp32_path, out_path = Path(fp32_path), Path(out_path)
    with tempfile.TemporaryDirectory(prefix="cone_int8_") as tmp:
        pre = Path(tmp) / "pre.onnx"
        # shape inference + graph clean-up first, as ONNX Runtime recommends before quantize_static
        quant_pre_process(str(fp32_path), str(pre), skip_symbolic_shape=True)
        model = onnx.load(str(pre))
        last = head_output_convs(model)
        exclude = (last if opts.exclude_head else []) + decode_nodes(model, last)
        reader = _Reader(model.graph.input[0].name, blobs, total, progress)
        method = {"minmax": CalibrationMethod.MinMax, "percentile": CalibrationMethod.Percentile}[opts.method]
        quantize_static(
            str(pre), str(out_path), reader,
            quant_format=QuantFormat.QDQ,
            op_types_to_quantize=["Conv"] if opts.ops == "conv" else None,
            per_channel=opts.per_channel,
            reduce_range=False,
            activation_type=QuantType.QUInt8 if opts.activation == "uint8" else QuantType.QInt8,
            weight_type=QuantType.QInt8,
            nodes_to_exclude=exclude,
            calibrate_method=method,
        )
    return qdq_summary(onnx.load(str(out_path)))


#: The int8 check of ``cone-perception export --int8``: on real frames, the int8 boxes are paired
#: with the float model's (same class, IoU >= MATCH_IOU, greedy by score); it passes when at least
#: MIN_MATCHED of the float boxes have a partner and the pairs' mean IoU is at least MIN_MEAN_IOU.
#: (int8 cannot be within the 1e-3 of the float exports: boxes move by a pixel or so and scores
#: near the threshold flip.)
MATCH_IOU = 0.5
MIN_MATCHED = 0.9
MIN_MEAN_IOU = 0.9


def compare_detections(pairs: Iterable[tuple[tuple, tuple]]) -> dict:
    """Pair the boxes of a test model with a reference model's, frame by frame.

    ``pairs``: per frame ((boxes, scores, classes) reference, (boxes, scores, classes) test), as
    :func:`~.model.decode.postprocess` returns them (x1 y1 x2 y2, best first). Returns the counts,
    the share of reference boxes matched, the mean / min IoU of the pairs, the largest corner
    deviation (px) and score difference of a pair, and ``ok`` (the check above)."""
    from ..evaluation.metrics import greedy_match

    n_ref = n_test = 0
    ious, dev, sdiff = [], 0.0, 0.0
    for (rb, rs, rc), (tb, ts, tc) in pairs:
        n_ref, n_test = n_ref + len(rb), n_test + len(tb)
        for c in np.unique(np.concatenate([rc, tc])):
            ri, ti = np.flatnonzero(rc == c), np.flatnonzero(tc == c)
            to_ref, _ = greedy_match(tb[ti], rb[ri], np.zeros(len(ri), bool), MATCH_IOU)
            for k, j in enumerate(to_ref):
                if j < 0:
                    continue
                a, b = tb[ti[k]].astype(np.float64), rb[ri[j]].astype(np.float64)
                inter = max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
                union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
                ious.append(inter / union if union > 0 else 0.0)
                dev = max(dev, float(np.abs(a - b).max()))
                sdiff = max(sdiff, abs(float(ts[ti[k]]) - float(rs[ri[j]])))
    matched = len(ious) / n_ref if n_ref else float("nan")
    mean_iou = float(np.mean(ious)) if ious else float("nan")
    ok = n_ref == 0 or (matched >= MIN_MATCHED and mean_iou >= MIN_MEAN_IOU)
    return {"ref_boxes": n_ref, "test_boxes": n_test, "matched": matched, "mean_iou": mean_iou,
            "min_iou": float(np.min(ious)) if ious else float("nan"), "max_dev_px": dev, "max_score_diff": sdiff, "ok": ok}
