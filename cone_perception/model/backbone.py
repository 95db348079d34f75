"""CSP backbone: stem, four stride-2 stages with C2f blocks, SPPF at stride 32."""

from __future__ import annotations

import torch
from torch import nn

from .blocks import C2f, SPPF, Conv


class CSPBackbone(nn.Module):
    """Image (B, 3, H, W) -> features at strides 8, 16, 32 (4, 8, 16, 32 when ``p2``).

    ``channels`` = (stem, s4, s8, s16, s32); ``depths`` = bottlenecks at s4..s32.
    """

    def __init__(self, channels: tuple[int, ...], depths: tuple[int, ...], p2: bool = False):
        super().__init__()
        c0, c1, c2, c3, c4 = channels
        d1, d2, d3, d4 = depths
        self.stem = Conv(3, c0, 3, 2)
        self.stage4 = nn.Sequential(Conv(c0, c1, 3, 2), C2f(c1, c1, d1))
        self.stage8 = nn.Sequential(Conv(c1, c2, 3, 2), C2f(c2, c2, d2))
        self.stage16 = nn.Sequential(Conv(c2, c3, 3, 2), C2f(c3, c3, d3))
        self.stage32 = nn.Sequential(Conv(c3, c4, 3, 2), C2f(c4, c4, d4), SPPF(c4, c4))
        self.p2 = bool(p2)
        self.out_channels = (c1, c2, c3, c4) if self.p2 else (c2, c3, c4)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, ...]:
        x = self.stage4(self.stem(x))
        p3 = self.stage8(x)
        p4 = self.stage16(p3)
        p5 = self.stage32(p4)
        return (x, p3, p4, p5) if self.p2 else (p3, p4, p5)
