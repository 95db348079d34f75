"""Geometry-aware copy-paste: the row law, pasted sizes on it, labels added, nothing outside the
image, occlusion order, rare classes oversampled, and the training set's hook."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from cone_perception.classes import BLUE, LARGE_ORANGE, ORANGE, YELLOW
from cone_perception.train.copy_paste import (
    LARGE_H, SMALL_H, ConeBank, CopyPasteConfig, RowLaw, cone_matte, fit_row_law,
)

from synthetic_cones import NAMES, draw_cone

W, H = 480, 270
LAW = RowLaw(a=0.5, b=-0.2)  # cones from 8 px tall at row 0.46 H to 81 px at the bottom


def _scene(rng: np.random.Generator, n: int = 8, law: RowLaw = LAW):
    """A grey road with ``n`` cones standing on it by ``law`` (large orange ones LARGE_H / SMALL_H taller)."""
    img = np.full((H, W, 3), 110, np.uint8)
    img[: int(0.4 * H)] = (200, 170, 140)  # sky
    boxes, cls = [], []
    while len(boxes) < n:
        c = int(rng.integers(0, 4))
        y2 = float(rng.uniform(0.5, 0.98)) * H
        h = float(law.height(y2 / H)) * H * (LARGE_H / SMALL_H if c == LARGE_ORANGE else 1.0)
        w = 0.7 * h
        x1 = float(rng.uniform(0, W - w))
        box = np.array([x1, y2 - h, x1 + w, y2], np.float32)
        if box[1] < 0 or any(not (box[2] < b[0] or box[0] > b[2] or box[3] < b[1] or box[1] > b[3]) for b in boxes):
            continue
        draw_cone(img, c, int(x1), int(y2), int(w), int(h))
        boxes.append(np.round(box))
        cls.append(c)
    return img, np.array(boxes, np.float32), np.array(cls, np.int64)


def _bank(cfg: CopyPasteConfig, seed: int = 0) -> ConeBank:
    rng = np.random.default_rng(seed)
    bank = ConeBank(cfg)
    for _ in range(12):
        img, b, c = _scene(rng)
        bank.add_frame(img, b, c)
    assert all(bank.counts()[k] > 0 for k in (BLUE, YELLOW, ORANGE, LARGE_ORANGE))
    return bank


def test_row_law_fit_recovers_the_ground_plane_law():
    img, b, c = _scene(np.random.default_rng(1), n=10)
    law = fit_row_law(b / np.array([W, H, W, H], np.float32), c)
    assert law is not None and law.a == pytest.approx(LAW.a, abs=0.03) and law.b == pytest.approx(LAW.b, abs=0.02)
    bn = b / np.array([W, H, W, H], np.float32)
    assert fit_row_law(bn[:3], c[:3]) is None  # too few cones
    flat = bn.copy()
    flat[:, 1] = flat[:, 3] - 0.1  # all one height
    flat[:, 3] = 0.7
    assert fit_row_law(flat, c) is None  # no spread of foot rows
    inverted = bn.copy()
    inverted[:, 1] = inverted[:, 3] - (1.2 - inverted[:, 3]) * 0.3  # taller further up: not a ground plane
    assert fit_row_law(inverted, c) is None


def test_pasted_cones_follow_the_row_law_stay_inside_and_are_labelled():
    cfg = CopyPasteConfig(p=1.0, max_cones=4, min_source_px=10)
    bank = _bank(cfg)
    rng = np.random.default_rng(5)
    n_pasted = 0
    for trial in range(30):
        img, b, c = _scene(np.random.default_rng(100 + trial))
        out, b2, c2 = bank.paste(rng, img, b, c, LAW)
        assert out.shape == img.shape and out.dtype == np.uint8
        assert np.array_equal(b2[: len(b)], b) and np.array_equal(c2[: len(c)], c)  # own labels first, unchanged
        new_b, new_c = b2[len(b):], c2[len(c):]
        n_pasted += len(new_b)
        assert np.all(new_b[:, :2] >= 0) and np.all(new_b[:, 2] <= W) and np.all(new_b[:, 3] <= H)
        for box, cls in zip(new_b, new_c):
            want = LAW.height(box[3] / H) * H * (LARGE_H / SMALL_H if cls == LARGE_ORANGE else 1.0)
            assert box[3] - box[1] == pytest.approx(want, abs=1.0)  # rounded to whole px
            assert box[3] - box[1] >= cfg.min_height_px
        # pixels change only inside the pasted boxes
        changed = np.any(out != img, axis=2)
        inside = np.zeros_like(changed)
        for x1, y1, x2, y2 in new_b.astype(int):
            inside[y1:y2, x1:x2] = True
        assert not np.any(changed & ~inside)
        if len(new_b):
            assert np.any(changed)
    assert n_pasted >= 30  # about 2 per frame: not a paste that silently does nothing


def test_nothing_is_pasted_without_a_law_or_enough_cones():
    bank = _bank(CopyPasteConfig(p=1.0, min_source_px=10))
    img, b, c = _scene(np.random.default_rng(3))
    rng = np.random.default_rng(0)
    out, b2, c2 = bank.paste(rng, img, b, c, None)
    assert out is img and len(b2) == len(b)
    out, b2, _ = bank.paste(rng, img, b[:2], c[:2], LAW)
    assert out is img and len(b2) == 2


def test_rare_classes_are_oversampled():
    cfg = CopyPasteConfig(p=1.0, max_cones=4, min_source_px=10, class_weights=(1.0, 1.0, 2.0, 3.0, 0.0))
    bank = _bank(cfg)
    rng = np.random.default_rng(9)
    counts = np.zeros(5)
    for trial in range(40):
        img, b, c = _scene(np.random.default_rng(200 + trial))
        _, b2, c2 = bank.paste(rng, img, b, c, LAW)
        counts += np.bincount(c2[len(c):], minlength=5)
    assert counts[4] == 0
    assert counts[LARGE_ORANGE] > 1.5 * counts[BLUE] and counts[ORANGE] > 1.2 * counts[YELLOW]


def test_a_nearer_labelled_cone_stays_in_front_of_a_pasted_one():
    cfg = CopyPasteConfig(p=1.0, max_cones=4, min_source_px=10, max_overlap=0.3)
    bank = _bank(cfg)
    seen = 0
    for seed in range(200):
        img, b, c = _scene(np.random.default_rng(300 + seed), n=10)
        out, b2, _ = bank.paste(np.random.default_rng(seed), img, b, c, LAW)
        for pb in b2[len(b):]:
            for ob in b:
                if ob[3] > pb[3] and ob[0] < pb[2] and ob[2] > pb[0] and ob[1] < pb[3]:  # labelled cone is nearer, overlaps
                    x1, y1 = int(ob[0]), int(ob[1])
                    m = cone_matte(int(ob[2] - ob[0]), int(ob[3] - ob[1]), 0.0) > 0.99
                    ys, xs = np.nonzero(m)
                    ys, xs = ys + y1, xs + x1
                    sel = (xs >= pb[0]) & (xs < pb[2]) & (ys >= pb[1]) & (ys < pb[3])
                    if sel.sum() >= 5:
                        assert np.array_equal(out[ys[sel], xs[sel]], img[ys[sel], xs[sel]])
                        seen += 1
        if seen >= 3:
            break
    assert seen >= 3


def test_training_set_pastes_only_when_asked(tmp_path):
    import cv2

    from cone_perception.data.datasets import load_data_yaml
    from cone_perception.train.augment import AugmentConfig
    from cone_perception.train.loader import TrainSet

    root = tmp_path / "d"
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    rng = np.random.default_rng(0)
    for i in range(6):
        img, b, c = _scene(rng)
        cv2.imwrite(str(root / "images" / f"f{i}.png"), img)
        # dataset ids = NAMES order = project ids 0..3
        lines = [f"{k} {(x1 + x2) / 2 / W:.6f} {(y1 + y2) / 2 / H:.6f} {(x2 - x1) / W:.6f} {(y2 - y1) / H:.6f}\n"
                 for (x1, y1, x2, y2), k in zip(b, c)]
        (root / "labels" / f"f{i}.txt").write_text("".join(lines))
    (root / "data.yaml").write_text(yaml.safe_dump({"names": NAMES}))
    (root / "o.yaml").write_text(yaml.safe_dump({"train": [{"path": "."}]}))
    entries, _, _ = load_data_yaml(root / "o.yaml")
    off = AugmentConfig.off()
    from dataclasses import replace

    plain = TrainSet(entries, (W, H), off, seed=0)
    pasted = TrainSet(entries, (W, H), replace(off, copy_paste=1.0), seed=0)
    assert plain.bank is None and pasted.bank is not None and sum(pasted.bank.counts()) > 20
    more = 0
    for k in range(6):
        _, t0 = plain[(k, 0, k)]
        _, t1 = pasted[(k, 0, k)]
        assert len(t1) >= len(t0)
        more += len(t1) - len(t0)
    assert more >= 3
