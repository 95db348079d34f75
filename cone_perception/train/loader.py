"""torch Datasets for training (augmented, weighted mix) and validation (letterboxed).

Reproducibility: the epoch's sample order comes from ``(seed, epoch)``, and
every sample's augmentation from ``(seed, epoch, position)``, so results do not
depend on the number of worker processes and an interrupted run resumes exactly.
"""

from __future__ import annotations

import numpy as np
import torch
from torch.utils.data import Dataset, Sampler

from ..data.datasets import DatasetEntry, labels_to_xyxy, read_image
from ..detector import letterbox
from .augment import AugmentConfig, cutout, fit_width, hflip, mosaic4, photometric, random_window
from .copy_paste import CopyPasteConfig, RowLaw, build_bank, fit_row_law


class _Items:
    """All images of several dataset entries, addressed by one flat index."""

    def __init__(self, entries: list[DatasetEntry]):
        self.entries = entries
        self.index = [(e, i) for e in entries for i in range(len(e.image_paths))]

    def __len__(self) -> int:
        return len(self.index)

    def load(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """BGR image (aspect restored) + (M, 4) boxes px + (M,) classes."""
        e, i = self.index[k]
        img = read_image(e.image_paths[i], e.restore_aspect)
        boxes, cls = labels_to_xyxy(e.labels[i], img.shape[1], img.shape[0])
        return img, boxes, cls


def epoch_order(entries: list[DatasetEntry], seed: int, epoch: int) -> np.ndarray:
    """Flat item indices of one epoch: round(weight x size) draws per entry (without replacement while
    possible), shuffled; deterministic from (seed, epoch)."""
    rng = np.random.default_rng([seed, epoch, 7])
    out, start = [], 0
    for e in entries:
        n = len(e.image_paths)
        want = max(1, int(round(e.weight * n)))
        full, rest = divmod(want, n)
        picks = [rng.permutation(n) for _ in range(full)] + [rng.permutation(n)[:rest]]
        out.append(np.concatenate(picks) + start)
        start += n
    order = np.concatenate(out)
    return order[rng.permutation(order.size)]


class EpochSampler(Sampler):
    """Yields (item, epoch, position) for the dataset; call :meth:`set_epoch` before each epoch."""

    def __init__(self, entries: list[DatasetEntry], seed: int):
        self.entries, self.seed, self.epoch = entries, seed, 0
        self.order = epoch_order(entries, seed, 0)

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch
        self.order = epoch_order(self.entries, self.seed, epoch)

    def __len__(self) -> int:
        return int(self.order.size)

    def __iter__(self):
        return iter([(int(k), self.epoch, pos) for pos, k in enumerate(self.order)])


class TrainSet(Dataset):
    """Augmented samples at input size (W, H): (3, H, W) uint8 RGB tensor, (M, 5) float targets (class, x1 y1 x2 y2 px)."""

    def __init__(self, entries: list[DatasetEntry], imgsz: tuple[int, int], aug: AugmentConfig, seed: int):
        self.items = _Items(entries)
        self.imgsz, self.aug, self.seed = imgsz, aug, seed
        self.mosaic_enabled = True
        w = np.concatenate([np.full(len(e.image_paths), e.weight / len(e.image_paths)) for e in entries])
        self.pick_p = w / w.sum()
        self.bank, self.entry_laws = None, {}
        if aug.copy_paste > 0:  # cone patches of every training frame, and each entry's row law as a fallback
            self.bank = build_bank(self.items, CopyPasteConfig(p=aug.copy_paste), seed, progress=True)
            for e in entries:
                lab = np.concatenate([l for l in e.labels if len(l)] or [np.zeros((0, 5))])
                b = np.stack([lab[:, 1] - lab[:, 3] / 2, lab[:, 2] - lab[:, 4] / 2,
                              lab[:, 1] + lab[:, 3] / 2, lab[:, 2] + lab[:, 4] / 2], 1)
                self.entry_laws[id(e)] = fit_row_law(b, lab[:, 0].astype(np.int64))

    def __len__(self) -> int:
        return len(self.items)

    def _fitted(self, k: int, rng: np.random.Generator | None = None):
        img, b, c = self.items.load(k)
        img, b = fit_width(img, b, self.imgsz[0])
        if self.bank is not None and rng is not None and rng.random() < self.aug.copy_paste:
            img, b, c = self.bank.paste(rng, img, b, c, self.row_law(k, img.shape[1], img.shape[0], b, c))
        return img, b, c

    def row_law(self, k: int, w: int, h: int, boxes: np.ndarray, cls: np.ndarray) -> RowLaw | None:
        """Box height vs foot row of item ``k``: its own (fitted on its labels) or else its entry's."""
        law = fit_row_law(boxes / np.array([w, h, w, h], np.float32), cls) if len(boxes) else None
        return law or self.entry_laws.get(id(self.items.index[k][0]))

    def __getitem__(self, key):
        k, epoch, pos = key
        rng = np.random.default_rng([self.seed, epoch, pos, k])
        cfg = self.aug
        if self.mosaic_enabled and cfg.mosaic and rng.random() < cfg.mosaic:
            others = rng.choice(len(self.items), 3, p=self.pick_p)
            parts = [self._fitted(k, rng)] + [self._fitted(int(o), rng) for o in others]
            canvas, b, c, centre = mosaic4(parts, self.imgsz, rng)
            img, b, c = random_window(rng, canvas, b, c, self.imgsz, cfg.scale, cfg, centre=centre)
        else:
            img, b, c = self._fitted(k, rng)
            img, b, c = random_window(rng, img, b, c, self.imgsz, cfg.scale, cfg)
        img = photometric(rng, img, cfg)
        if cfg.flip and rng.random() < cfg.flip:
            img, b = hflip(img, b)
        if cfg.cutout and rng.random() < cfg.cutout:
            img, b, c = cutout(rng, img, b, c)
        return _to_tensors(img, b, c)


class ValSet(Dataset):
    """Validation images letterboxed to (W, H), plus the same targets; no randomness."""

    def __init__(self, entries: list[DatasetEntry], imgsz: tuple[int, int]):
        self.items = _Items(entries)
        self.imgsz = imgsz

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, k: int):
        img, b, c = self.items.load(k)
        img, lb = letterbox(img, *self.imgsz)
        return _to_tensors(img, b * np.float32(lb.scale), c)


def _to_tensors(img: np.ndarray, boxes: np.ndarray, cls: np.ndarray):
    rgb = np.ascontiguousarray(img[:, :, ::-1].transpose(2, 0, 1))
    t = np.concatenate([cls.reshape(-1, 1).astype(np.float32), boxes.reshape(-1, 4).astype(np.float32)], 1)
    return torch.from_numpy(rgb), torch.from_numpy(t)


def collate(batch) -> tuple[torch.Tensor, torch.Tensor]:
    """-> images (B, 3, H, W) uint8, targets (M, 6) float: image index, class, x1 y1 x2 y2 px."""
    imgs = torch.stack([b[0] for b in batch])
    ts = [torch.cat([torch.full((len(t), 1), float(i)), t], 1) for i, (_, t) in enumerate(batch)]
    return imgs, torch.cat(ts) if ts else torch.zeros(0, 6)
