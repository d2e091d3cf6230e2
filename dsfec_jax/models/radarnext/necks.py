"""RadarNeXt's necks over the Rep-DWC stages (x2: H/2, x1: H/4, x0: H/8), all ending in one
384-channel map at H/4. Facts from the public RadarNeXt code (github Pay246-git468/RadarNeXt, commit
72676df): projects/RadarNeXt/radarnext/MDFENNeck.py and projects/RadarNeXt/configs/{radarnext,
radarnext_fpn_variant, radarnext_pan_variant}.py; the code is ours.

- FPN: mmdet3d SECONDFPN, upsample strides (0.5, 1, 2), 128 channels each, concatenated.
- PAN: a top-down path and a bottom-up path of RepBlocks (here: Rep-DWC layers), then a fusion of
  the three bottom-up maps at H/4.
- MDFEN: the PAN with DCNv3 layers at the `dcn_positions` of the paper's Figure 2 (④ by default).

Where Figure 2 puts each position is not in the text; our reading, checked against Table III's
parameter column (a DCNv3 over C channels holds 2C^2 + 122C + 108 parameters):
  ① backbone output x0 (256 ch, H/8)          1.694M, paper 1.694M
  ② top-down concat at H/4 (256 ch)           1.694M, paper 1.694M
  ③ backbone output x2 (64 ch, H/2)           1.547M, paper 1.630M (no single map fits 1.630M)
  ④ top-down concat at H/2 (128 ch)           1.580M, paper 1.580M (the MDFEN default)
  ⑤ top-down 1x1 output f1 (64 ch, H/4)       1.547M, paper 1.547M
"""

from __future__ import annotations

import flax.linen as nn
import jax.numpy as jnp

from ...layers import ConvBNAct, ConvTranspose, DCNv3, RepDWSeparable
from ...layers.conv import Conv, DepthwiseImpl, batch_norm

DCN_POSITIONS = (1, 2, 3, 4, 5)


class SECONDFPN(nn.Module):
    """Each stage to `channels` at H/4 (stride-2 conv, 1x1 deconv, 2x2 stride-2 deconv; BN, ReLU;
    no bias), concatenated."""

    channels: int = 128
    kernels: str = "auto"  # layers.conv.Kernels

    @nn.compact
    def __call__(self, stages: list, train: bool = False):
        x2, x1, x0 = stages
        k = self.kernels
        ups = [
            Conv(self.channels, 2, 2, kernels=k, name="down0")(x2),
            ConvTranspose(self.channels, 1, 1, use_bias=False, kernels=k, name="up1")(x1),
            ConvTranspose(self.channels, 2, 2, use_bias=False, kernels=k, name="up2")(x0),
        ]
        return jnp.concatenate([nn.relu(batch_norm(train, f"bn{i}", k)(u)) for i, u in enumerate(ups)], -1)


class PANeck(nn.Module):
    """The PAN / MDFEN neck (channels_list 64,128,256,128,64,128,256; one RepBlock per step)."""

    dcn_positions: tuple[int, ...] = ()
    dcn_groups: int = 4
    dcn_offset_scale: float = 2.0
    branches: int = 1
    deploy: bool = False
    depthwise_impl: DepthwiseImpl = "shifted"
    kernels: str = "auto"  # layers.conv.Kernels

    def _dcn(self, position: int, x):
        if position not in self.dcn_positions:
            return x
        return DCNv3(x.shape[-1], self.dcn_groups, 3, self.dcn_offset_scale, name=f"dcn{position}")(x)

    def _rep(self, features: int, name: str):
        return RepDWSeparable(features, 1, self.branches, self.deploy, self.depthwise_impl, self.kernels, name=name)

    @nn.compact
    def __call__(self, stages: list, train: bool = False):
        x2, x1, x0 = stages
        x2, x0 = self._dcn(3, x2), self._dcn(1, x0)
        k = self.kernels
        # top-down
        f0 = ConvBNAct(128, 1, 1, "relu", k, name="reduce0")(x0, train)                      # H/8
        up0 = ConvTranspose(128, 2, 2, kernels=k, name="upsample0")(f0)
        t1 = self._rep(128, "rep_td1")(self._dcn(2, jnp.concatenate([up0, x1], -1)), train)  # H/4
        f1 = self._dcn(5, ConvBNAct(64, 1, 1, "relu", k, name="reduce1")(t1, train))
        up1 = ConvTranspose(64, 2, 2, kernels=k, name="upsample1")(f1)
        p2 = self._rep(64, "rep_td2")(self._dcn(4, jnp.concatenate([up1, x2], -1)), train)   # H/2
        # bottom-up
        d2 = ConvBNAct(64, 3, 2, "relu", k, name="down2")(p2, train)
        p1 = self._rep(128, "rep_bu1")(jnp.concatenate([d2, f1], -1), train)                # H/4
        d1 = ConvBNAct(128, 3, 2, "relu", k, name="down1")(p1, train)
        p0 = self._rep(256, "rep_bu0")(jnp.concatenate([d1, f0], -1), train)                # H/8
        # fusion at H/4
        return jnp.concatenate([
            ConvBNAct(128, 3, 2, "relu", k, name="fuse2")(p2, train),
            ConvTranspose(128, 1, 1, kernels=k, name="fuse1")(p1),
            ConvTranspose(128, 2, 2, kernels=k, name="fuse0")(p0),
        ], -1)
