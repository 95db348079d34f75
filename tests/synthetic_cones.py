"""Tiny synthetic cone images for tests: cone-shaped coloured polygons with stripes on a grey
textured background, written in YOLO txt layout with a names list. Deterministic from a seed."""

from __future__ import annotations

import functools
import tempfile
from pathlib import Path

import cv2
import numpy as np
import yaml

# project class -> (body BGR, stripe BGR, number of stripes, size factor)
_LOOK = {
    0: ((200, 80, 10), (250, 250, 250), 1, 1.0),  # blue, white stripe
    1: ((20, 210, 240), (20, 20, 20), 1, 1.0),  # yellow, black stripe
    2: ((10, 110, 250), (250, 250, 250), 1, 1.0),  # small orange
    3: ((20, 90, 235), (250, 250, 250), 2, 1.5),  # large orange, two stripes
}
NAMES = ["blue_cone", "yellow_cone", "orange_cone", "large_orange_cone"]  # dataset ids 0..3 (project 0..3)


def draw_cone(img: np.ndarray, cls: int, x1: int, y2: int, w: int, h: int) -> None:
    """A cone with base (x1..x1+w, y2) and height h."""
    body, stripe, n, _ = _LOOK[cls]
    cx = x1 + w / 2
    top = w * 0.18

    def poly(v0: float, v1: float) -> np.ndarray:  # trapezoid between heights v0..v1 (fractions from the top)
        ya, yb = y2 - h + v0 * h, y2 - h + v1 * h
        ha, hb = (top + (w - top) * v0) / 2, (top + (w - top) * v1) / 2
        return np.array([[cx - ha, ya], [cx + ha, ya], [cx + hb, yb], [cx - hb, yb]], np.int32)

    cv2.fillPoly(img, [poly(0, 1)], body)
    for k in range(n):
        a = 0.35 + 0.25 * k
        cv2.fillPoly(img, [poly(a, a + 0.15)], stripe)


def make_image(rng: np.random.Generator, w: int, h: int, n_cones: int) -> tuple[np.ndarray, list]:
    g = rng.normal(125, 12, (h // 4 + 1, w // 4 + 1)).clip(0, 255).astype(np.uint8)
    bg = cv2.resize(g, (w, h), interpolation=cv2.INTER_LINEAR)
    img = cv2.merge([bg, bg, bg])
    labels, taken = [], []
    for _ in range(n_cones * 10):
        if len(labels) == n_cones:
            break
        cls = int(rng.integers(0, 4))
        ch = int(rng.uniform(0.25, 0.6) * h * _LOOK[cls][3])
        ch = min(ch, h - 2)
        cw = int(ch * 0.7)
        x1 = int(rng.uniform(0, w - cw))
        y2 = int(rng.uniform(ch + 1, h))
        box = (x1, y2 - ch, x1 + cw, y2)
        if any(not (box[2] < t[0] or box[0] > t[2] or box[3] < t[1] or box[1] > t[3]) for t in taken):
            continue
        taken.append(box)
        draw_cone(img, cls, x1, y2, cw, ch)
        labels.append((cls, (box[0] + box[2]) / 2 / w, (box[1] + box[3]) / 2 / h, cw / w, ch / h))
    return img, labels


def write_dataset(root: Path, n_images: int = 8, size: tuple[int, int] = (256, 96), seed: int = 0, cones: int = 3) -> Path:
    """Write ``root/images/*.png``, ``root/labels/*.txt`` and ``root/data.yaml`` (names); returns root."""
    rng = np.random.default_rng(seed)
    (root / "images").mkdir(parents=True, exist_ok=True)
    (root / "labels").mkdir(parents=True, exist_ok=True)
    for i in range(n_images):
        img, labels = make_image(rng, size[0], size[1], cones)
        cv2.imwrite(str(root / "images" / f"synth-{i:03d}.png"), img)
        (root / "labels" / f"synth-{i:03d}.txt").write_text(
            "".join(f"{c} {cx:.6f} {cy:.6f} {bw:.6f} {bh:.6f}\n" for c, cx, cy, bw, bh in labels)
        )
    (root / "data.yaml").write_text(yaml.safe_dump({"names": NAMES}))
    return root


SMOKE_SIZE = (256, 96)  # (W, H) of the smoke-test images and model input


@functools.lru_cache(maxsize=1)
def trained_smoke_model() -> tuple[Path, Path, dict]:
    """Train the ``p`` model to overfit 8 synthetic images (once per test process, ~8 s on a quiet 2-core machine; 1 thread, which is as fast here and does not stall when the cores are shared).

    Returns (checkpoint best.pt, dataset root, training result)."""
    from cone_perception.train.augment import AugmentConfig
    from cone_perception.train.trainer import TrainConfig, train

    work = Path(tempfile.mkdtemp(prefix="cone_smoke_"))
    root = write_dataset(work / "data", n_images=8, size=SMOKE_SIZE, seed=0)
    (root / "overfit.yaml").write_text(yaml.safe_dump({"train": [{"path": "."}], "val": [{"path": "."}]}))
    cfg = TrainConfig(
        data=str(root / "overfit.yaml"), out=str(work / "run"), model="p", epochs=40, batch=4, imgsz=SMOKE_SIZE,
        lr0=0.01, workers=0, threads=1, augment=AugmentConfig.off(), warmup_epochs=0, warmup_min_iters=10,
        patience=1000, close_mosaic=0, ema_tau=20, seed=0, precision="fp32",
    )
    result = train(cfg, progress=False)
    return work / "run" / "best.pt", root, result


def assert_same_cones(ref, other, img: np.ndarray, box_px: float, score_tol: float) -> int:
    """Assert that detector ``other`` finds ``ref``'s cones in ``img`` (``detect_image``), as far as a
    difference of ``score_tol`` in the scores allows: pairs (same class, IoU >= 0.5) within ``box_px`` px
    and ``score_tol``; a cone found by one of them only where ``ref`` scores it within ``score_tol`` of the
    threshold (``ref.conf``; a score there may cross it either way). Which cones sit near the threshold
    depends on the smoke model, and so on the CPU that trained it; this rule does not. Returns the pairs."""
    import copy

    from cone_perception import records
    from cone_perception.evaluation.metrics import match_by_class

    assert (ref.conf, ref.iou) == (other.conf, other.iou)
    rb, rs, rc = records.boxes_to_arrays(ref.detect_image(img))
    ob, os_, oc = records.boxes_to_arrays(other.detect_image(img))
    to_ref, _ = match_by_class(ob, oc, rb, rc, np.zeros(len(rb), bool), 0.5)
    pair = to_ref >= 0
    np.testing.assert_allclose(ob[pair], rb[to_ref[pair]], atol=box_px)
    np.testing.assert_allclose(os_[pair], rs[to_ref[pair]], atol=score_tol)
    lost = np.setdiff1d(np.arange(len(rb)), to_ref[pair])
    assert np.all(rs[lost] <= ref.conf + score_tol), f"cones lost: boxes {rb[lost]}, reference scores {rs[lost]}"
    extra = np.flatnonzero(~pair)
    if len(extra):  # the reference's own score of each: under the threshold, by at most score_tol
        low = copy.copy(ref)
        low.conf = ref.conf - score_tol
        lb, ls, lc = records.boxes_to_arrays(low.detect_image(img))
        to_low, _ = match_by_class(ob[extra], oc[extra], lb, lc, np.zeros(len(lb), bool), 0.5)
        assert np.all(to_low >= 0), f"cones found only by {other.describe()}: boxes {ob[extra]}, scores {os_[extra]}"
        assert np.all(ls[to_low] <= ref.conf + 1e-6), (ls[to_low], ref.conf)
        np.testing.assert_allclose(ob[extra], lb[to_low], atol=box_px)
    return int(pair.sum())
