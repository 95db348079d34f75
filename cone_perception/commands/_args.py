"""Argument types and options shared by several commands (argparse only: no command imports another)."""

from __future__ import annotations

import argparse

from ..errors import ConfigError
from ..words import parse_size


def size_arg(text: str) -> tuple[int, int]:
    """argparse type of a model input ``WxH`` (``--imgsz``); a single number means a square."""
    try:
        return parse_size(text, "--imgsz", "WxH (e.g. 960x288)", square=True)
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
