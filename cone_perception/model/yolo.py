"""The detector: backbone + neck + head, built from a :class:`ModelConfig`."""

from __future__ import annotations

import torch
from torch import nn

from .backbone import CSPBackbone
from .blocks import Conv, fuse_conv_bn
from .config import ModelConfig
from .decode import decode_outputs
from .head import DecoupledHead
from .neck import PAFPN
from .pretrained import PretrainedBackbone


class ConeYOLO(nn.Module):
    """YOLO-style single-stage cone detector.

    ``forward(x)``: x (B, 3, H, W) float RGB in 0..1, H and W multiples of 32.
    Training mode returns the raw head output (list per stride); eval mode
    returns (B, 4 + nc, N): cx, cy, w, h in input px, then class scores (the
    common YOLO export layout).
    """

    def __init__(self, cfg: ModelConfig):
        super().__init__()
        cfg.validate()
        self.cfg = cfg
        if cfg.backbone == "csp":
            self.backbone = CSPBackbone(cfg.channels, cfg.depths, p2=cfg.has_p2)
        else:  # ImageNet weights are loaded by the trainer (load_imagenet); a checkpoint brings its own
            self.backbone = PretrainedBackbone(cfg.backbone, tuple(cfg.channels[2:]))
        self.neck = PAFPN(self.backbone.out_channels, cfg.neck_depth, p2_ch=cfg.head_p2_ch if cfg.has_p2 else 0)
        levels = self.backbone.out_channels[-3:]  # strides 8/16/32; a stride-4 level is a side branch of its own
        self.head = DecoupledHead(
            levels, cfg.num_classes, cfg.reg_max, cfg.strides,
            reg_ch=cfg.head_reg_ch, cls_ch=cfg.head_cls_ch, dw=cfg.head_dw,
            p2_in=cfg.head_p2_ch if cfg.has_p2 else 0, p2_ch=cfg.head_p2_ch,
        )
        self.strides = tuple(cfg.strides)
        self.fused = False

    def forward_raw(self, x: torch.Tensor) -> list[torch.Tensor]:
        return self.head(self.neck(self.backbone(x)))

    def forward(self, x: torch.Tensor):
        feats = self.forward_raw(x)
        if self.training:
            return feats
        # decoding in fp32 whatever the network computed in (bf16 autocast: DFL expectations need the bits)
        return decode_outputs([f.float() for f in feats], self.strides, self.cfg.reg_max, self.cfg.num_classes)

    @torch.no_grad()
    def fuse(self) -> "ConeYOLO":
        """Fold every batch-norm into its convolution (inference only; in place)."""
        if isinstance(self.backbone, PretrainedBackbone):
            self.backbone.fuse_bn()
        for m in self.modules():
            if isinstance(m, Conv) and hasattr(m, "bn"):
                m.conv = fuse_conv_bn(m.conv, m.bn)
                del m.bn
                m.forward = m.forward_fused
        self.fused = True
        return self

    def num_params(self) -> int:
        return sum(p.numel() for p in self.parameters())
