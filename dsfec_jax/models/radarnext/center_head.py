"""CenterHead (CenterPoint / PillarNeXt, as RadarNeXt configures it in the public RadarNeXt code:
github Pay246-git468/RadarNeXt, commit 72676df, projects/RadarNeXt/radarnext/radarnext_head.py).

384-channel neck map at H/4 -> shared 3x3 conv (64) -> 2x2 stride-2 deconv (64) -> one small
sub-head per output at H/2: reg 2 (centre offset), height 1, dim 3 (log l, w, h), rot 2 (sin,
cos), iou 1, hm (one channel per class, bias -2.19 so sigmoid starts near 0.1) and, for training
only, corner_hm 1. Convs that feed a BN carry a bias, as in the CenterPoint code the public
count follows (7 x 64 = 448 parameters of the 1,579,832).
"""

from __future__ import annotations

import flax.linen as nn

from ...layers import ConvTranspose
from ...layers.conv import Conv, batch_norm

HM_BIAS = -2.19
BOX_OUTPUTS = (("reg", 2), ("height", 1), ("dim", 3), ("rot", 2), ("iou", 1))


def conv_bias_bn_relu(x, features: int, train: bool, name: str, kernels: str = "auto"):
    x = Conv(features, 3, 1, use_bias=True, kernels=kernels, name=name)(x)
    return nn.relu(batch_norm(train, f"{name}_bn", kernels)(x))


class CenterHead(nn.Module):
    num_classes: int
    width: int = 64
    corner_head: bool = True  # an auxiliary training target; dropped from the deployed model
    kernels: str = "auto"  # layers.conv.Kernels

    @nn.compact
    def __call__(self, x, train: bool = False) -> dict:
        x = conv_bias_bn_relu(x, self.width, train, "shared", self.kernels)
        x = ConvTranspose(self.width, 2, 2, use_bias=False, kernels=self.kernels, name="deblock")(x)
        x = nn.relu(batch_norm(train, "deblock_bn", self.kernels)(x))
        outputs = list(BOX_OUTPUTS) + [("hm", self.num_classes)] + ([("corner_hm", 1)] if self.corner_head else [])
        maps = {}
        for name, n in outputs:
            h = conv_bias_bn_relu(x, self.width, train, f"{name}_conv", self.kernels)
            bias_init = nn.initializers.constant(HM_BIAS if name.endswith("hm") else 0.0)
            maps[name] = Conv(n, 3, 1, use_bias=True, bias_init=bias_init, kernels=self.kernels,
                              name=f"{name}_out")(h)
        return maps
