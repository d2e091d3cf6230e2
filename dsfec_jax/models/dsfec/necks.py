"""Necks that merge backbone stages into one map for the heads."""

from __future__ import annotations

import flax.linen as nn

from ...layers import Conv, ConvTranspose
from ...layers.conv import Kernels


class TopDownNeck(nn.Module):
    """PIXOR/FPN top-down path: 1x1 lateral on the deepest stage, then per finer stage a 3x3
    stride-2 deconv of the running map plus a 1x1 lateral of that stage, added (no activation,
    as in PIXOR). `widths[i]` is the width after merging the i-th stage counted from the deepest,
    so len(widths) stages are used and the output has the resolution of the finest one."""

    widths: tuple[int, ...] = (192, 128, 64)
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, stages: list, train: bool = False):
        used = stages[::-1][: len(self.widths)]
        k = self.kernels
        x = Conv(self.widths[0], 1, use_bias=True, kernels=k, name="lateral0")(used[0])
        for i, (width, lateral) in enumerate(zip(self.widths[1:], used[1:]), start=1):
            factor = lateral.shape[1] // x.shape[1]
            x = ConvTranspose(width, 3, factor, kernels=k, name=f"deconv{i}")(x)
            x = x + Conv(width, 1, use_bias=True, kernels=k, name=f"lateral{i}")(lateral)
        return x
