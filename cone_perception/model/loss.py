"""Training loss: BCE classification + CIoU box loss + distribution focal loss.

Targets come from the :class:`~.assign.TaskAlignedAssigner`. ``targets`` of a
batch is an (M, 6) float tensor: image index in the batch, project class id,
x1 y1 x2 y2 in input px.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn
from torch.nn import functional as F

from .assign import TaskAlignedAssigner
from .decode import bbox2dist, dfl_expectation, dist2bbox, make_anchors
from .iou import bbox_iou


@dataclass
class LossGains:
    box: float = 7.5
    cls: float = 0.5
    dfl: float = 1.5


class DetectionLoss(nn.Module):
    def __init__(self, num_classes: int, reg_max: int, strides: tuple[int, ...], gains: LossGains | None = None):
        super().__init__()
        self.nc, self.reg_max, self.strides = num_classes, reg_max, tuple(strides)
        self.gains = gains or LossGains()
        self.assigner = TaskAlignedAssigner(topk=10, alpha=0.5, beta=6.0)

    def forward(self, feats: list[torch.Tensor], targets: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Raw head output + targets -> (loss scaled by batch size, (3,) detached box/cls/dfl parts)."""
        b = feats[0].shape[0]
        no = 4 * self.reg_max + self.nc
        x = torch.cat([f.view(b, no, -1) for f in feats], 2)
        box_logits, cls_logits = x.split((4 * self.reg_max, self.nc), 1)
        box_logits = box_logits.permute(0, 2, 1).contiguous()  # (B, N, 4*reg_max)
        cls_logits = cls_logits.permute(0, 2, 1).contiguous()  # (B, N, nc)
        anchors, stride_t = make_anchors(feats, self.strides)  # (N, 2) stride units, (N, 1)

        gt_labels, gt_bboxes, mask_gt = self._pad_targets(targets, b, x.device)
        ltrb = dfl_expectation(box_logits.permute(0, 2, 1), self.reg_max).permute(0, 2, 1)  # (B, N, 4)
        pred_bboxes = dist2bbox(ltrb, anchors.unsqueeze(0), xywh=False)  # stride units

        _, target_bboxes, target_scores, fg = self.assigner(
            cls_logits.detach().sigmoid(),
            (pred_bboxes.detach() * stride_t).to(gt_bboxes.dtype),
            anchors * stride_t,
            gt_labels,
            gt_bboxes,
            mask_gt,
        )
        tss = max(target_scores.sum().item(), 1.0)
        loss_cls = F.binary_cross_entropy_with_logits(cls_logits, target_scores, reduction="none").sum() / tss

        loss_box = torch.zeros((), device=x.device)
        loss_dfl = torch.zeros((), device=x.device)
        if fg.any():
            target_bboxes = target_bboxes / stride_t
            weight = target_scores.sum(-1)[fg].unsqueeze(-1)
            iou = bbox_iou(pred_bboxes[fg], target_bboxes[fg], ciou=True)
            loss_box = ((1.0 - iou) * weight).sum() / tss
            target_ltrb = bbox2dist(anchors.unsqueeze(0).expand(b, -1, -1)[fg], target_bboxes[fg], self.reg_max)
            loss_dfl = (self._dfl(box_logits[fg].view(-1, self.reg_max), target_ltrb) * weight).sum() / tss

        g = self.gains
        parts = torch.stack((loss_box * g.box, loss_cls * g.cls, loss_dfl * g.dfl))
        return parts.sum() * b, parts.detach()

    def _dfl(self, logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """Distribution focal loss: cross-entropy to the two bins around each target distance; (K, 1)."""
        tl = target.long()
        tr = tl + 1
        wl = tr - target
        wr = 1 - wl
        ce_l = F.cross_entropy(logits, tl.view(-1), reduction="none").view(tl.shape)
        ce_r = F.cross_entropy(logits, tr.view(-1), reduction="none").view(tl.shape)
        return (ce_l * wl + ce_r * wr).mean(-1, keepdim=True)

    @staticmethod
    def _pad_targets(targets: torch.Tensor, b: int, device) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(M, 6) targets -> labels (B, Mmax, 1), boxes (B, Mmax, 4), mask (B, Mmax, 1)."""
        if targets.numel() == 0:
            z = torch.zeros(b, 0, 1, device=device)
            return z.long(), torch.zeros(b, 0, 4, device=device), z
        idx = targets[:, 0].long()
        counts = torch.bincount(idx, minlength=b)
        mmax = int(counts.max())
        labels = torch.zeros(b, mmax, 1, dtype=torch.long, device=device)
        boxes = torch.zeros(b, mmax, 4, device=device)
        mask = torch.zeros(b, mmax, 1, device=device)
        for i in range(b):
            sel = idx == i
            k = int(sel.sum())
            if k:
                labels[i, :k, 0] = targets[sel, 1].long()
                boxes[i, :k] = targets[sel, 2:6]
                mask[i, :k] = 1
        return labels, boxes, mask
