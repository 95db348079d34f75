"""Training crops of the far strip's verifier (:mod:`cone_perception.detector.verifier`).

``cone-perception data verifier-crops OUT.npz --rendered DIR PRED [...] [--real DIR]`` cuts the crops: around the
boxes a `detect` file of a rendered set (``synth dataset``) holds in each frame's far-strip rows (the rows its own
camera's strip takes, 48 px more each side), labelled by the set's ``gt.jsonl``: a cone where a box overlaps a
cone at IoU >= 0.4 (a third of it in view at least), no cone where it overlaps none at IoU 0.3 and its centre lies in
no cone's box (every rendered cone counts, labelled or not), else left out; around some of the set's own cones of
8-48 px; four random boxes of the strip's rows per frame on no cone (ground, paint, the verge); and, with
``--real``, around the labelled cones of 4-20 px of a real YOLO folder (three jittered crops each: the real cones
the second look must keep; their frames' unlabelled cones make no negatives). ``cone-perception train --data
CROPS.npz --out DIR`` trains :class:`~cone_perception.detector.verifier.VerifierNet` on them (AdamW, one-cycle, flips,
gain and offset, blur; a tenth held out) and writes ``DIR/verifier.pt`` with the thresholds.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from ..crop import crop_patch
from ..errors import ConfigError
from ..geometry.camera import MountPose, PinholeCamera
from ..geometry.strip import plan_strip
from ..mapping import box_iou
from ..records import boxes_from_arrays
from .datasets import IMAGE_SUFFIXES
from .farcrops import on_no_cone
from .predictions import read_predictions

#: The strip rows of a frame's camera, this many px more each side, are where its crops are cut.
ROW_MARGIN = 48
#: A detection on a cone: IoU at least this with a cone's box, a third of that cone in view.
CONE_IOU, CONE_VISIBLE = 0.4, 0.3
#: Box heights (px) cut around: detections, rendered cones, real labelled cones.
DET_PX, GT_PX, REAL_PX = (6.0, 60.0), (8.0, 48.0), (4.0, 20.0)


def _strip_rows(rec: dict) -> tuple[int, int] | None:
    c = rec.get("camera")
    if not c:
        return None
    cam = PinholeCamera(np.asarray(c["K"], np.float64), int(rec["width"]), int(rec["height"]), MountPose(**c["mount"]),
                        np.asarray(c.get("dist_coeffs") or [], np.float64))
    try:
        p = plan_strip(cam, source=rec["image"])
    except ConfigError:  # a camera pitched so that its strip leaves the image: no crops from it
        return None
    return p.top0 - ROW_MARGIN, p.top0 + p.height + ROW_MARGIN


def rendered_crops(root: Path, pred: Path, rng: np.random.Generator, progress: bool = True):
    """(patches, labels 1 = cone) of one rendered set and a `detect` file of its frames."""
    gt_path = root / "gt.jsonl"
    if not gt_path.is_file():
        raise ConfigError(str(root), None, "no gt.jsonl: --rendered needs a `synth dataset` folder")
    recs = {}
    for line in gt_path.read_text(encoding="utf-8").splitlines():
        if line.strip():
            d = json.loads(line)
            recs[Path(d["image"]).name] = d
    X, y = [], []
    preds = list(read_predictions(str(pred)))
    if not any(Path(p.image).name in recs for p in preds):
        raise ConfigError(str(pred), None, f"none of its images is a frame of {root}")
    for p in tqdm(preds, desc=f"crops {root.name}", unit="frame", disable=not progress, file=sys.stderr):
        d = recs.get(Path(p.image).name)
        rows = _strip_rows(d) if d else None
        if rows is None:
            continue
        img = cv2.imread(str(root / d["image"]))
        if img is None:
            continue
        v0, v1 = rows
        cones = d["cones"]
        gb = np.array([c["box"] for c in cones], np.float64).reshape(-1, 4)
        vis = np.array([c.get("visible_fraction", 1.0) for c in cones])
        b = p.boxes[p.boxes["score"] >= 0.1]
        h = b["v2"] - b["v1"]
        b = b[(h >= DET_PX[0]) & (h <= DET_PX[1]) & (b["v1"] >= v0) & (b["v2"] <= v1)]
        xyxy = np.c_[b["u1"], b["v1"], b["u2"], b["v2"]].astype(np.float64).reshape(-1, 4)
        if len(gb) and len(xyxy):
            iou = box_iou(b, boxes_from_arrays(gb.astype(np.float32), np.ones(len(gb), np.float32),
                                               np.zeros(len(gb), np.uint8)))
            best, j = iou.max(1), iou.argmax(1)
        else:
            best, j = np.zeros(len(xyxy)), np.zeros(len(xyxy), int)
        none = on_no_cone(b, gb.astype(np.float32))  # every rendered cone counts, labelled or not
        for i in range(len(xyxy)):
            if best[i] >= CONE_IOU and vis[j[i]] >= CONE_VISIBLE:
                X.append(crop_patch(img, xyxy[i], rng))
                y.append(1)
            elif none[i]:
                X.append(crop_patch(img, xyxy[i], rng))
                y.append(0)
        for _ in range(4):  # random boxes of the strip's rows on no cone
            hh = float(rng.uniform(8, 40))
            ww = hh * float(rng.uniform(0.6, 1.0))
            cy = float(rng.uniform(v0 + hh / 2, v1 - hh / 2))
            cx = float(rng.uniform(ww, d["width"] - ww))
            if len(gb) and ((gb[:, 0] - hh <= cx) & (cx <= gb[:, 2] + hh) & (gb[:, 1] - hh <= cy)
                            & (cy <= gb[:, 3] + hh)).any():
                continue
            X.append(crop_patch(img, (cx - ww / 2, cy - hh / 2, cx + ww / 2, cy + hh / 2), rng))
            y.append(0)
        for c in cones:  # the set's own cones of the strip's sizes (the detector's misses are cones too)
            bx = c["box"]
            hh = bx[3] - bx[1]
            if (GT_PX[0] <= hh <= GT_PX[1] and c.get("visible_fraction", 1.0) >= 0.6 and v0 <= bx[1] and bx[3] <= v1
                    and rng.random() < 0.3):
                X.append(crop_patch(img, bx, rng))
                y.append(1)
    return X, y


def real_crops(root: Path, rng: np.random.Generator, per: int = 3, progress: bool = True):
    """(patches, all 1) around the labelled cones of ``REAL_PX`` px of a YOLO folder (images/, labels/)."""
    imgs = sorted(p for p in (root / "images").rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES)
    if not imgs:
        raise ConfigError(str(root), None, "no images under images/: --real needs a YOLO folder")
    X, y = [], []
    for ip in tqdm(imgs, desc=f"crops {root.name}", unit="image", disable=not progress, file=sys.stderr):
        lp = root / "labels" / ip.relative_to(root / "images").with_suffix(".txt")
        if not lp.is_file():
            continue
        img = cv2.imread(str(ip))
        if img is None:
            continue
        H, W = img.shape[:2]
        for line in lp.read_text(encoding="utf-8").splitlines():
            t = line.split()
            if len(t) != 5:
                continue
            _, xc, yc, w, h = (float(v) for v in t)
            if REAL_PX[0] <= h * H <= REAL_PX[1]:
                box = ((xc - w / 2) * W, (yc - h / 2) * H, (xc + w / 2) * W, (yc + h / 2) * H)
                for _ in range(per):
                    X.append(crop_patch(img, box, rng))
                    y.append(1)
    return X, y


def verifier_crops(out: str | Path, rendered: list[tuple[str, str]], real: str | None = None, seed: int = 0,
                   progress: bool = True) -> dict:
    """Write the crops (``X`` patches, ``y`` 1 = cone, ``src`` 1 rendered / 2 real) to ``out`` (.npz); the counts."""
    if not rendered:
        raise ConfigError("--rendered", None, "needs at least one rendered set and its detect file")
    rng = np.random.default_rng(seed)
    X, y, src, counts = [], [], [], {}
    for root, pred in rendered:
        x1, y1 = rendered_crops(Path(root), Path(pred), rng, progress)
        X += x1
        y += y1
        src += [1] * len(y1)
        counts[str(root)] = {"cones": int(np.sum(y1)), "not_cones": int(len(y1) - np.sum(y1))}
    if real:
        x2, y2 = real_crops(Path(real), rng, progress=progress)
        X += x2
        y += y2
        src += [2] * len(y2)
        counts[str(real)] = {"cones": len(y2), "not_cones": 0}
    if not any(v == 0 for v in y) or not any(v == 1 for v in y):
        raise ConfigError(str(out), None, "the crops need cones and not-cones both")
    np.savez_compressed(out, X=np.stack(X), y=np.array(y, np.int8), src=np.array(src, np.int8))
    return counts
