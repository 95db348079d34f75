"""Knowledge distillation: a slower, more accurate detector teaches the fast one on every training image.

Both models see the same augmented batch; the teacher's raw head output (eval mode, no
gradient) gives dense soft targets at every cell of the three strides:

* classes: the teacher's probabilities, as a KL-form binary cross-entropy (zero where the
  student's probabilities equal the teacher's), normalised by the teacher's score mass;
* boxes: the teacher's expected side distances (``dfl_expectation``) as targets of the
  student's distribution focal loss, weighted per cell by the teacher's highest class
  probability, so that only where the teacher sees a cone does its box count.

The two models may differ in width, depth, backbone and ``reg_max``; they must share the
strides, the class list and the input size (checked by :func:`check_teacher` before training).
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from ..errors import ConfigError
from ..model.decode import dfl_expectation


def check_teacher(teacher: nn.Module, student: nn.Module, teacher_path: str) -> None:
    """ConfigError naming ``teacher_path`` and the field when the teacher cannot teach this student."""
    t, s = teacher.cfg, student.cfg
    if tuple(t.strides) != tuple(s.strides):
        raise ConfigError(teacher_path, "strides", f"teacher strides {tuple(t.strides)} differ from the student's "
                                                   f"{tuple(s.strides)}: distillation matches cell by cell")
    if t.num_classes != s.num_classes:
        raise ConfigError(teacher_path, "num_classes", f"teacher has {t.num_classes} classes, the student "
                                                       f"{s.num_classes}")


class DistillLoss(nn.Module):
    """Dense teacher-to-student loss on raw head outputs (lists of (B, 4*reg_max + nc, H_i, W_i))."""

    def __init__(self, num_classes: int, reg_max_student: int, reg_max_teacher: int, cls_gain: float = 0.5,
                 box_gain: float = 1.5):
        super().__init__()
        self.nc, self.rs, self.rt = num_classes, reg_max_student, reg_max_teacher
        self.cls_gain, self.box_gain = cls_gain, box_gain

    def _flat(self, feats: list[torch.Tensor], reg_max: int) -> tuple[torch.Tensor, torch.Tensor]:
        b = feats[0].shape[0]
        x = torch.cat([f.float().reshape(b, 4 * reg_max + self.nc, -1) for f in feats], 2)
        box, cls = x.split((4 * reg_max, self.nc), 1)
        return box, cls  # (B, 4*reg_max, N), (B, nc, N)

    def forward(self, student: list[torch.Tensor], teacher: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """-> (loss scaled by batch size, (2,) detached class / box parts)."""
        if [f.shape[2:] for f in student] != [f.shape[2:] for f in teacher]:
            raise ValueError("student and teacher feature maps differ in size: "
                             f"{[tuple(f.shape[2:]) for f in student]} vs {[tuple(f.shape[2:]) for f in teacher]}")
        b = student[0].shape[0]
        s_box, s_cls = self._flat(student, self.rs)
        with torch.no_grad():
            t_box, t_cls = self._flat(teacher, self.rt)
            p_t = t_cls.sigmoid()
            mass = max(p_t.sum().item(), 1.0)
            w = p_t.max(1).values  # (B, N): how sure the teacher is that a cone is there
            t_ltrb = dfl_expectation(t_box, self.rt).clamp(0, self.rs - 1 - 0.01)  # (B, 4, N) stride units
        # KL form of the binary cross-entropy: BCE(s, p_t) - BCE(t, p_t) >= 0, zero when the student agrees
        ent = F.binary_cross_entropy(p_t, p_t, reduction="none")
        loss_cls = (F.binary_cross_entropy_with_logits(s_cls, p_t, reduction="none") - ent).sum() / mass
        # distribution focal loss of the student's box bins against the teacher's expected distances
        logits = s_box.view(b, 4, self.rs, -1).permute(0, 3, 1, 2).reshape(-1, self.rs)  # (B*N*4, rs)
        target = t_ltrb.permute(0, 2, 1).reshape(-1)  # (B*N*4,)
        tl = target.long()
        wl = (tl + 1).float() - target
        dfl = (F.cross_entropy(logits, tl, reduction="none") * wl
               + F.cross_entropy(logits, (tl + 1).clamp(max=self.rs - 1), reduction="none") * (1 - wl))
        # minus the entropy of the two-bin target, so the box part is zero when the student puts it exactly there
        h = -(wl * wl.clamp_min(1e-12).log() + (1 - wl) * (1 - wl).clamp_min(1e-12).log())
        dfl = (dfl - h).view(b, -1, 4).mean(-1)  # (B, N)
        loss_box = (dfl * w).sum() / max(w.sum().item(), 1.0)
        parts = torch.stack((loss_cls * self.cls_gain, loss_box * self.box_gain))
        return parts.sum() * b, parts.detach()
