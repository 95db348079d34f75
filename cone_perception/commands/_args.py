"""Argument types and options shared by several commands (argparse only: no command imports another)."""

from __future__ import annotations

import argparse

from ..attitude import ATTITUDE_MODES
from ..detector import BACKEND_CHOICES, DEFAULT_BACKEND, RUNTIME_THREADS
from ..errors import ConfigError
from ..params import DEFAULT_CONF, PARAMS
from ..words import parse_size


def size_arg(text: str, option: str = "--imgsz", square: bool = True) -> tuple[int, int]:
    """argparse type of a size ``WxH`` (``--imgsz``; with ``square`` a single number means a square; another
    ``option``: ``functools.partial``)."""
    try:
        return parse_size(text, option, "WxH (e.g. 960x288)", square=square)
    except ConfigError as e:
        raise argparse.ArgumentTypeError(e.message) from None


def parse_crop(text: str) -> tuple[int, ...]:
    try:
        vals = tuple(int(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"crop must be V0,V1 or V0,V1,U0,U1 (integers), got {text!r}") from None
    if len(vals) not in (2, 4):
        raise argparse.ArgumentTypeError(f"crop must be V0,V1 or V0,V1,U0,U1, got {text!r}")
    return vals


def add_far_model(p: argparse.ArgumentParser, scope: str = "", after: str = "") -> None:
    """``--far-model auto|band|PATH``, the far band's model (one text for every command that runs the strip);
    ``scope``: what it applies to (``"pipeline: "``), ``after``: the command's own note (``"; live: ..."``)."""
    p.add_argument("--far-model", default=None, metavar="auto|band|PATH",
                   help=f"{scope}the far band's model: auto (default) = the shipped far-strip model "
                        f"(models/cone_detector_far.pt), band = the band's own model, or a model file; its classes "
                        f"must be the band model's{after}")


def add_band_split(p: argparse.ArgumentParser, scope: str = "", after: str = "") -> None:
    """``--band-split none|auto|N0,U1``, the row-scaled band (one text for every command that runs it); ``scope``
    and ``after`` as :func:`add_far_model`."""
    p.add_argument("--band-split", default=None, metavar="none|auto|N0,U1",
                   help=f"{scope}the band in two (docs/detector.md 'Row-scaled band'): none (default) = one band; auto = "
                        f"split from the calibration, the near rows at a quarter of full resolution; N0,U1 = the near "
                        f"band from row N0, the upper band to row U1{after}")


def add_far_verifier(p: argparse.ArgumentParser, scope: str = "") -> None:
    """``--far-verifier auto|none|PATH``: the far strip's second look at its doubtful boxes (detector/verifier.py)."""
    p.add_argument("--far-verifier", default=None, metavar="auto|none|PATH",
                   help=f"{scope}a second look at the far strip's doubtful boxes (scored low, small): a tiny "
                        "classifier on a crop around each drops those where it sees no cone (docs/detector.md, Far "
                        "band). none (default) = off, auto = the shipped models/cone_verifier.pt (opt-in: it dropped "
                        "real far cones on a sharp camera), or a verifier file")


def add_far_box_model(p: argparse.ArgumentParser) -> None:
    """``--far-box-model band|own``: which measured box model reads the far strip's boxes (the nodes' ``far_box_model``)."""
    p.add_argument("--far-box-model", choices=("band", "own"), default="band",
                   help="the image attitude on a real camera: which measured box model reads the far strip's boxes: band "
                        "(default) = the band model's, at each box's size in its input px; own = the far model's own "
                        "(measured on 640x360 video), its sizes without measurements through the band's")


def add_far_box_reading(p: argparse.ArgumentParser) -> None:
    """``--far-model`` of the tools that read a `detect` prediction file (``map``, ``eval``): the model that drew the
    boxes the file marks as the far strip's, and ``--far-box-model`` (:func:`add_far_box_model`)."""
    p.add_argument("--far-model", default=None, metavar="auto|band|PATH",
                   help="--attitude image: the model that drew the boxes a prediction file marks as the far strip's (its "
                        "`far` key, written by `detect` with a far strip); the fit reads them through the box model "
                        "--far-box-model names. auto (default) = the shipped far-strip model, band = the --model")
    add_far_box_model(p)


def add_pipeline_settings(p) -> None:
    """The pipeline settings ``replay`` runs a bag with and ``validate`` judges (the node's parameters, offline): the
    model, backend, threshold, threads, far strip, band rows, attitude, box model and the mapping's gates."""
    p.add_argument("--model", default=None, help="model file (default: the shipped default model)")
    p.add_argument("--backend", default=DEFAULT_BACKEND, choices=BACKEND_CHOICES,
                   help="inference backend (default %(default)s: ONNX Runtime on the CPU where installed, else torch)")
    p.add_argument("--conf", type=float, default=DEFAULT_CONF, help="confidence threshold (default %(default)s)")
    p.add_argument("--threads", type=int, default=RUNTIME_THREADS,
                   help="torch / ONNX Runtime threads of the network (default %(default)s, as the nodes; 0 = library default)")
    p.add_argument("--far-rows", default=None, metavar="auto|none|V0,V1",
                   help="the far band, image rows also run at full resolution, the whole width (docs/detector.md "
                        "'Far band'): auto (default) = the calibration's far strip, moved each frame with the attitude; "
                        "V0,V1 = these rows, fixed; none (or off) = the band alone. Live: the pipeline node's far_rows (fused only)")
    p.add_argument("--far-every", type=int, default=PARAMS["far_every"].default, metavar="N",
                   help="the far band's cadence: its strip on every N-th frame only, the band alone between (a far cone "
                        "is seen up to N-1 frames late; docs/detector.md 'Far band'; default %(default)s = every frame). "
                        "Live: the pipeline node's far_every (fused only)")
    p.add_argument("--far-tiles", type=int, default=PARAMS["far_tiles"].default, metavar="W",
                   help="with --far-every above 1, on the frames between: the strip's windows around the last two frames' "
                        "far cones in one mosaic at most W columns wide (docs/detector.md 'Far band'); 0 (default) = off, the "
                        "band alone between. Live: the pipeline node's far_tiles (fused only)")
    p.add_argument("--band-rows", default=None, metavar="crop|auto|V0,V1",
                   help="the band's rows (docs/detector.md 'Band rows'): crop (default) = the calibration's crop, auto = "
                        "placed from the calibration, V0,V1 = these rows; the cones expected in view follow the band. "
                        "Live: the pipeline node's band_rows (fused only)")
    add_band_split(p, after=". Offline only (live: the pipeline node's band_split)")
    add_far_model(p, after="; live: the node's far_model")
    add_far_verifier(p)
    add_far_box_model(p)
    p.add_argument("--min-height-ratio", type=float, default=PARAMS["min_height_ratio"].default, metavar="R",
                   help="offline: a box lower than R x the height a cone of its class has where its foot maps is a mark "
                        "on the ground, not a cone: dropped and counted (summary: boxes dropped); 0 = off (default "
                        "%(default)s; live: the nodes' min_height_ratio)")
    p.add_argument("--one-ray-range", type=float, default=PARAMS["one_ray_range_m"].default, metavar="M",
                   help="offline: two cones of one class (two classes from 15 m on) nearly on one viewing ray (under "
                        "0.15 m across, 2 m along it), the better-scored nearer than M m, are one cone seen twice: the "
                        "other is dropped and counted (summary: boxes dropped, one_ray); 0 = off (default %(default)s; "
                        "live: the nodes' one_ray_range_m)")
    p.add_argument("--attitude", choices=ATTITUDE_MODES, default=None,
                   help="camera attitude per frame: fixed (the calibration's H), image (from the cone boxes), imu (the "
                        "bag's IMU), fused (IMU + image); all but fixed need mount_pose in the calibration. Default: "
                        "fused when the bag has the IMU topic, else image, fixed without a mount pose")
    p.add_argument("--box-model", choices=("auto", "model", "rendered"), default="auto",
                   help="attitude image/fused (live: the nodes' box_model): which box model the image fit reads the detector's boxes with: "
                        "model (measured on real frames, MODEL.box_model.yaml beside the model file; a model without one "
                        "gets a conservative default and a warning), rendered (the rendered drives' table, for synthetic "
                        "bags), auto (rendered with --gt-topic, i.e. a synthetic drive with truth, unless --box-behaviour "
                        "real; else model; default %(default)s)")
    p.add_argument("--box-behaviour", choices=("as-is", "real"), default="as-is",
                   help="offline, synthetic bags: real gives the detector's boxes the real frames' behaviour of its box "
                        "model (MODEL.box_model.yaml: heights 0.97-0.99x, tops 1-3 %% low, the top scattered by the "
                        "measured spread; synth/boxlook.py; the far strip's boxes its far model's, that model's rendered "
                        "offset taken out first), as-is keeps them (default %(default)s)")
