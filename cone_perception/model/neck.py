"""Path-aggregation neck (PAFPN): top-down then bottom-up fusion of strides 8/16/32."""

from __future__ import annotations

import torch
from torch import nn

from .blocks import C2f, Conv


class PAFPN(nn.Module):
    """(P3, P4, P5) -> (N3, N4, N5) with the same channels as the inputs.

    With four inputs (P2, P3, P4, P5): one more top-down step, N3 upsampled and fused with
    P2 into N2 of ``p2_ch`` channels; N3..N5 are computed exactly as without it (a side
    branch: the 3-level neck's modules, names and outputs are unchanged)."""

    def __init__(self, in_channels: tuple[int, ...], depth: int = 1, p2_ch: int = 0):
        super().__init__()
        self.p2 = len(in_channels) == 4
        if self.p2:
            if p2_ch < 1:
                raise ValueError("a stride-4 level needs p2_ch >= 1")
            c2, c3, c4, c5 = in_channels
            self.td2 = C2f(c3 + c2, p2_ch, depth, shortcut=False)
        else:
            c3, c4, c5 = in_channels
        self.up = nn.Upsample(scale_factor=2, mode="nearest")
        self.td4 = C2f(c5 + c4, c4, depth, shortcut=False)
        self.td3 = C2f(c4 + c3, c3, depth, shortcut=False)
        self.down3 = Conv(c3, c3, 3, 2)
        self.bu4 = C2f(c3 + c4, c4, depth, shortcut=False)
        self.down4 = Conv(c4, c4, 3, 2)
        self.bu5 = C2f(c4 + c5, c5, depth, shortcut=False)

    def forward(self, feats: tuple[torch.Tensor, ...]) -> tuple[torch.Tensor, ...]:
        p3, p4, p5 = feats[-3:]
        t4 = self.td4(torch.cat([self.up(p5), p4], 1))
        n3 = self.td3(torch.cat([self.up(t4), p3], 1))
        n4 = self.bu4(torch.cat([self.down3(n3), t4], 1))
        n5 = self.bu5(torch.cat([self.down4(n4), p5], 1))
        if self.p2:
            return self.td2(torch.cat([self.up(n3), feats[0]], 1)), n3, n4, n5
        return n3, n4, n5
