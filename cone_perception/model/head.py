"""Anchor-free decoupled head with distribution-focal-loss box outputs.

Per level and cell: ``4 * reg_max`` box logits (a distribution over the
distance to each box side, in stride units) and ``num_classes`` class logits.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from .blocks import Conv, DWConv


class DecoupledHead(nn.Module):
    """Features at strides 8/16/32 -> list of (B, 4*reg_max + nc, H_i, W_i) raw logits.

    ``p2_in`` > 0: a first feature at stride 4 of ``p2_in`` channels, with its own branches
    ``reg_p2`` / ``cls_p2`` of ``p2_ch`` channels (``strides`` then starts with 4); the
    8/16/32 branches keep their names (``reg.0`` is stride 8 either way)."""

    def __init__(
        self,
        in_channels: tuple[int, ...],
        num_classes: int,
        reg_max: int = 16,
        strides: tuple[int, ...] = (8, 16, 32),
        reg_ch: int = 0,
        cls_ch: int = 0,
        dw: bool = True,
        p2_in: int = 0,
        p2_ch: int = 16,
    ):
        super().__init__()
        self.p2 = p2_in > 0
        if len(strides) != len(in_channels) + int(self.p2):
            raise ValueError(f"{len(strides)} strides for {len(in_channels) + int(self.p2)} feature levels")
        self.nc = num_classes
        self.reg_max = reg_max
        self.strides = tuple(strides)
        c_reg = reg_ch or max(16, in_channels[0] // 4, reg_max * 4)
        c_cls = cls_ch or max(in_channels[0], min(num_classes, 100))
        self.reg = nn.ModuleList(
            nn.Sequential(Conv(c, c_reg, 3), Conv(c_reg, c_reg, 3), nn.Conv2d(c_reg, 4 * reg_max, 1))
            for c in in_channels
        )
        if dw:
            self.cls = nn.ModuleList(
                nn.Sequential(
                    DWConv(c, c, 3), Conv(c, c_cls, 1), DWConv(c_cls, c_cls, 3), Conv(c_cls, c_cls, 1),
                    nn.Conv2d(c_cls, num_classes, 1),
                )
                for c in in_channels
            )
        else:
            self.cls = nn.ModuleList(
                nn.Sequential(Conv(c, c_cls, 3), Conv(c_cls, c_cls, 3), nn.Conv2d(c_cls, num_classes, 1))
                for c in in_channels
            )
        if self.p2:
            self.reg_p2 = nn.Sequential(Conv(p2_in, p2_ch, 3), Conv(p2_ch, p2_ch, 3), nn.Conv2d(p2_ch, 4 * reg_max, 1))
            self.cls_p2 = nn.Sequential(
                DWConv(p2_in, p2_in, 3), Conv(p2_in, p2_ch, 1), DWConv(p2_ch, p2_ch, 3), Conv(p2_ch, p2_ch, 1),
                nn.Conv2d(p2_ch, num_classes, 1),
            )
        self.init_bias()

    def _branches(self) -> list[tuple[nn.Module, nn.Module]]:
        """(box branch, class branch) per level, in the order of ``strides``."""
        levels = list(zip(self.reg, self.cls))
        return [(self.reg_p2, self.cls_p2)] + levels if self.p2 else levels

    def init_bias(self, image_px: int = 640) -> None:
        """Box logits start at 1; class logits at the prior of ~5 objects per image."""
        for (reg, cls), s in zip(self._branches(), self.strides):
            nn.init.constant_(reg[-1].bias, 1.0)
            nn.init.constant_(cls[-1].bias, math.log(5 / self.nc / (image_px / s) ** 2))

    def forward(self, feats: tuple[torch.Tensor, ...]) -> list[torch.Tensor]:
        return [torch.cat([reg(x), cls(x)], 1) for x, (reg, cls) in zip(feats, self._branches())]
