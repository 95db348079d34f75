"""Task-aligned label assignment (TOOD / YOLOv8): which cells learn which cone.

For each ground-truth box, the cells whose centre lies inside the box are
candidates; each candidate is scored by ``score^alpha * IoU^beta`` (how well
its class score and its box already agree with the truth), the ``topk`` best
become positives, and a cell claimed by several boxes keeps the box it
overlaps most. Target class scores are the one-hot class scaled by the
normalised alignment, so the classifier learns to predict box quality.

Tiny boxes (far cones) are widened to at least ``min_size_px`` for the
candidate test only, so a cone smaller than a stride-8 cell still gets cells.
"""

from __future__ import annotations

import torch
from torch import nn

from .iou import bbox_iou


class TaskAlignedAssigner(nn.Module):
    def __init__(self, topk: int = 10, alpha: float = 0.5, beta: float = 6.0, min_size_px: float = 8.0, eps: float = 1e-9):
        super().__init__()
        self.topk, self.alpha, self.beta, self.min_size_px, self.eps = topk, alpha, beta, min_size_px, eps

    @torch.no_grad()
    def forward(
        self,
        pd_scores: torch.Tensor,
        pd_bboxes: torch.Tensor,
        anchors_px: torch.Tensor,
        gt_labels: torch.Tensor,
        gt_bboxes: torch.Tensor,
        mask_gt: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Assign targets.

        pd_scores (B, N, nc) sigmoid scores; pd_bboxes (B, N, 4) xyxy px;
        anchors_px (N, 2) cell centres px; gt_labels (B, M, 1) long; gt_bboxes
        (B, M, 4) xyxy px; mask_gt (B, M, 1) 1 for real boxes (rest is padding).
        Returns target_labels (B, N) long, target_bboxes (B, N, 4) xyxy px,
        target_scores (B, N, nc), fg_mask (B, N) bool.
        """
        b, n, nc = pd_scores.shape
        m = gt_bboxes.shape[1]
        device = pd_scores.device
        if m == 0:
            return (
                torch.zeros(b, n, dtype=torch.long, device=device),
                torch.zeros_like(pd_bboxes),
                torch.zeros_like(pd_scores),
                torch.zeros(b, n, dtype=torch.bool, device=device),
            )
        mask_in = self._candidates_in_gts(anchors_px, gt_bboxes)  # (B, M, N)
        align, overlaps = self._metrics(pd_scores, pd_bboxes, gt_labels, gt_bboxes, mask_in * mask_gt)
        mask_topk = self._topk(align, mask_gt.expand(-1, -1, self.topk).bool())
        mask_pos = mask_topk * mask_in * mask_gt
        gt_idx, fg_mask, mask_pos = self._resolve_multiple(mask_pos, overlaps, m)

        batch_ind = torch.arange(b, device=device).unsqueeze(-1)
        flat_idx = gt_idx + batch_ind * m  # (B, N)
        target_labels = gt_labels.long().flatten()[flat_idx].clamp_(0, nc - 1)
        target_bboxes = gt_bboxes.view(-1, 4)[flat_idx]
        target_scores = torch.nn.functional.one_hot(target_labels, nc).to(pd_scores.dtype)
        target_scores = target_scores * fg_mask.unsqueeze(-1)

        align = align * mask_pos
        pos_align = align.amax(-1, keepdim=True)  # (B, M, 1)
        pos_overlaps = (overlaps * mask_pos).amax(-1, keepdim=True)
        norm = (align * pos_overlaps / (pos_align + self.eps)).amax(-2).unsqueeze(-1)  # (B, N, 1)
        return target_labels, target_bboxes, target_scores * norm, fg_mask.bool()

    def _candidates_in_gts(self, anchors_px: torch.Tensor, gt_bboxes: torch.Tensor) -> torch.Tensor:
        c = (gt_bboxes[..., :2] + gt_bboxes[..., 2:]) / 2
        half = ((gt_bboxes[..., 2:] - gt_bboxes[..., :2]) / 2).clamp(min=self.min_size_px / 2)
        lt, rb = c - half, c + half  # (B, M, 2)
        a = anchors_px.view(1, 1, -1, 2)
        deltas = torch.cat((a - lt.unsqueeze(2), rb.unsqueeze(2) - a), -1)  # (B, M, N, 4)
        return (deltas.amin(-1) > self.eps).to(gt_bboxes.dtype)

    def _metrics(self, pd_scores, pd_bboxes, gt_labels, gt_bboxes, mask):
        b, n, _ = pd_scores.shape
        m = gt_bboxes.shape[1]
        mask = mask.bool()
        overlaps = torch.zeros((b, m, n), dtype=pd_bboxes.dtype, device=pd_bboxes.device)
        scores = torch.zeros_like(overlaps)
        bi = torch.arange(b, device=pd_scores.device).view(-1, 1).expand(-1, m)
        cls = gt_labels.squeeze(-1).long()
        scores[mask] = pd_scores[bi, :, cls][mask]  # (B, M, N) score of the gt's class per cell
        pd = pd_bboxes.unsqueeze(1).expand(-1, m, -1, -1)[mask]
        gt = gt_bboxes.unsqueeze(2).expand(-1, -1, n, -1)[mask]
        overlaps[mask] = bbox_iou(gt, pd, ciou=True).squeeze(-1).clamp_(0)
        align = scores.pow(self.alpha) * overlaps.pow(self.beta)
        return align, overlaps

    def _topk(self, metrics: torch.Tensor, topk_mask: torch.Tensor) -> torch.Tensor:
        k = min(self.topk, metrics.shape[-1])
        _, idxs = torch.topk(metrics, k, dim=-1, largest=True)
        idxs.masked_fill_(~topk_mask[..., :k], 0)
        count = torch.zeros(metrics.shape, dtype=torch.int8, device=metrics.device)
        ones = torch.ones_like(idxs[:, :, :1], dtype=torch.int8)
        for j in range(k):
            count.scatter_add_(-1, idxs[:, :, j : j + 1], ones)
        count.masked_fill_(count > 1, 0)
        return count.to(metrics.dtype)

    @staticmethod
    def _resolve_multiple(mask_pos: torch.Tensor, overlaps: torch.Tensor, m: int):
        fg = mask_pos.sum(-2)  # (B, N)
        if fg.max() > 1:
            multi = (fg.unsqueeze(1) > 1).expand(-1, m, -1)
            best = overlaps.argmax(1)
            is_max = torch.zeros_like(mask_pos).scatter_(1, best.unsqueeze(1), 1)
            mask_pos = torch.where(multi, is_max, mask_pos).float()
            fg = mask_pos.sum(-2)
        return mask_pos.argmax(-2), fg, mask_pos
