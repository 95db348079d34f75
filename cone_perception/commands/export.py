"""``cone-perception export``: a checkpoint -> TorchScript or ONNX (common YOLO layout), verified."""

from __future__ import annotations

import argparse
from pathlib import Path

from .train import parse_size

TOLERANCE = 1e-3


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", required=True, help="checkpoint (.pt) written by `cone-perception train`")
    p.add_argument("--format", choices=("torchscript", "onnx"), required=True, help="output format")
    p.add_argument("--imgsz", type=parse_size, default=None, help="input WxH px (default: the checkpoint's)")
    p.add_argument("--out", default=None, help="output file (default: next to the checkpoint, .torchscript / .onnx)")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from ..checkpoint import load_checkpoint
    from ..detector import Detector, write_sidecar
    from ..errors import ConfigError
    from ..export import export_model, max_abs_diff
    from ..train.trainer import round_imgsz

    ck = load_checkpoint(args.model)
    imgsz = round_imgsz(args.imgsz) if args.imgsz else ck.imgsz
    suffix = ".onnx" if args.format == "onnx" else ".torchscript"
    out = Path(args.out) if args.out else Path(args.model).with_suffix(suffix)
    if out.suffix != suffix:
        raise ConfigError(str(out), None, f"the output of format {args.format} must end in {suffix}")
    model = ck.build_model()
    export_model(model, imgsz, args.format, out)
    side = write_sidecar(out, ck.class_names, imgsz, {"source": str(args.model), "layout": "(1, 4 + nc, N): cx cy w h px, class scores"})

    # verify: the exported file, loaded the way users load it, against eager on random and grey inputs
    exported = Detector.load(out, backend=args.format)
    eager = Detector.load(args.model, backend="torch", imgsz=imgsz)
    rng = np.random.default_rng(0)
    w, h = imgsz
    worst = 0.0
    for blob in (rng.random((1, 3, h, w), dtype=np.float32), np.full((1, 3, h, w), 114 / 255, np.float32)):
        worst = max(worst, max_abs_diff(exported.raw(blob), eager.raw(blob)))
    if worst > TOLERANCE:
        out.unlink(missing_ok=True)
        raise ConfigError(str(out), None, f"exported model differs from eager by {worst:.3g} (> {TOLERANCE}); file removed")
    print(f"wrote {out} and {side} ({w}x{h}); verified against eager: max |diff| {worst:.2e} <= {TOLERANCE}")
    return 0
