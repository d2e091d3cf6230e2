"""ShuffleNetV2 unit (Ma et al., ECCV 2018), NHWC, with the kernel size and activation as parameters
(Shuffle-YOLOv3 uses 5x5 depthwise kernels and h-swish in its deep layers).

Facts from pytorch/vision:torchvision/models/shufflenetv2.py `InvertedResidual` (the code here is ours):
- stride 1: split the channels in two halves; the second half goes through 1x1 + BN + act,
  depthwise kxk + BN (no activation), 1x1 + BN + act; concatenate [untouched half, branch]; channel
  shuffle with 2 groups.
- stride 2: both branches read the whole input. Left ("proj"): depthwise kxk s2 + BN, 1x1 + BN + act
  to features / 2. Right ("main"): 1x1 + BN + act to features / 2, depthwise kxk s2 + BN, 1x1 + BN +
  act. Concatenate [left, right] (features channels), channel shuffle.

`split` picks the convention of the channel split (both are in public code):
- "chunk" (torchvision, the default): the halves are channels [:C/2] and [C/2:], and every unit
  ends with the channel shuffle of `channel_shuffle` (interleave the two halves).
- "even_odd" (megvii-model/ShuffleNet-Series, and CnybTseng/YOLOv3's shufflenetv2.py): the halves
  are the even and the odd channels, and no unit shuffles its output: the even/odd split of the
  next unit is the shuffle, deferred. The two conventions give the same units and parameter
  counts; they order channels differently, so weights do not carry over between them.
  (Megvii's stride-2 unit also gives its left branch C_in channels rather than features / 2; here
  both conventions use torchvision's features / 2 per branch.)
"""

from __future__ import annotations

from typing import Literal

import flax.linen as nn
import jax.numpy as jnp

from .activations import activation
from .conv import Conv, DepthwiseConv, DepthwiseImpl, Kernels, batch_norm

Split = Literal["chunk", "even_odd"]
SPLITS = ("chunk", "even_odd")


def channel_shuffle(x_BxHxWxC, groups: int = 2):
    """torchvision's channel_shuffle on NHWC: view C as (groups, C / groups), transpose, flatten.
    With 2 groups, output channel 2j + g is input channel g * C/2 + j: the halves interleaved."""
    *lead, c = x_BxHxWxC.shape
    if c % groups:
        raise ValueError(f"channel_shuffle: {c} channels do not split into {groups} groups")
    x = x_BxHxWxC.reshape(*lead, groups, c // groups)
    return jnp.swapaxes(x, -1, -2).reshape(*lead, c)


def split_channels(x_BxHxWxC, split: Split):
    """The (kept, processed) halves of a stride-1 unit's input under the `split` convention."""
    c = x_BxHxWxC.shape[-1]
    if c % 2:
        raise ValueError(f"a ShuffleNetV2 unit splits its input in two: {c} channels is odd")
    if split == "chunk":
        return x_BxHxWxC[..., : c // 2], x_BxHxWxC[..., c // 2 :]
    if split == "even_odd":
        return x_BxHxWxC[..., 0::2], x_BxHxWxC[..., 1::2]
    raise ValueError(f"split={split!r}; valid: {', '.join(map(repr, SPLITS))}")


class ShuffleUnit(nn.Module):
    """One ShuffleNetV2 unit: `features` output channels (even), `stride` 1 (then C_in must equal
    `features`) or 2 (H and W halved, any C_in), depthwise `kernel` (3 or 5), activation `act`
    after the 1x1 convs ('relu' in ShuffleNetV2, 'hard_swish' in Shuffle-YOLOv3's deep layers)."""

    features: int
    stride: int = 1
    kernel: int = 3
    act: str = "relu"
    split: Split = "chunk"
    depthwise_impl: DepthwiseImpl = "shifted"
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x_BxHxWxC, train: bool = False):
        cin, half = x_BxHxWxC.shape[-1], self.features // 2
        if self.features % 2:
            raise ValueError(f"ShuffleUnit.features={self.features} must be even (two branches)")
        if self.split not in SPLITS:
            raise ValueError(f"ShuffleUnit.split={self.split!r}; valid: {', '.join(map(repr, SPLITS))}")
        if self.stride == 1:
            if cin != self.features:
                raise ValueError(f"a stride-1 ShuffleUnit keeps its width: input {cin} != features {self.features}")
            kept, x = split_channels(x_BxHxWxC, self.split)
            y = jnp.concatenate([kept, self._branch(x, half, "main", train)], axis=-1)
        elif self.stride == 2:
            left = self._depthwise(x_BxHxWxC, "proj_dw", train)
            left = self._pointwise(left, half, "proj_pw", train)
            y = jnp.concatenate([left, self._branch(x_BxHxWxC, half, "main", train)], axis=-1)
        else:
            raise ValueError(f"ShuffleUnit.stride={self.stride}; expected 1 or 2")
        return channel_shuffle(y, 2) if self.split == "chunk" else y

    def _pointwise(self, x, features: int, name: str, train: bool):
        x = Conv(features, 1, kernels=self.kernels, name=name)(x)
        return activation(self.act)(batch_norm(train, f"{name}_bn", self.kernels)(x))

    def _depthwise(self, x, name: str, train: bool):
        x = DepthwiseConv(self.kernel, self.stride, self.depthwise_impl, self.kernels, name=name)(x)
        return batch_norm(train, f"{name}_bn", self.kernels)(x)

    def _branch(self, x, features: int, name: str, train: bool):
        """1x1 + BN + act, depthwise kxk (the unit's stride) + BN, 1x1 + BN + act."""
        x = self._pointwise(x, features, f"{name}_pw1", train)
        x = self._depthwise(x, f"{name}_dw", train)
        return self._pointwise(x, features, f"{name}_pw2", train)
