"""YOLOv10 building blocks as ultralytics builds them (NHWC): depthwise Conv, SCDown, RepVGGDW, CIB,
C2fCIB, the multi-head Attention and PSA.

Facts from ultralytics/ultralytics (`ultralytics/nn/modules/block.py`, `conv.py`; after THU-MIG/yolov10;
the code here is ours):
- Conv(c, c, k, s, g=c): a depthwise conv (one kxk filter per channel, no bias, padding k // 2) + BN
  (+ SiLU unless act=False): k k c + 2 c parameters.
- SCDown(c1, c2, k, s): Conv 1x1 to c2 (SiLU), then depthwise Conv kxk stride s without activation.
- RepVGGDW(c): depthwise 7x7 Conv-BN and depthwise 3x3 Conv-BN (both without activation), summed,
  SiLU (the 3x3 folds into the 7x7 at deploy time).
- CIB(c1, c2, shortcut, e, lk): depthwise 3x3 Conv (c1), Conv 1x1 to 2 c_ (c_ = int(c2 e)),
  RepVGGDW(2 c_) when lk else depthwise 3x3 Conv, Conv 1x1 to c2, depthwise 3x3 Conv (c2), all with
  SiLU; residual add when shortcut and c1 == c2.
- C2fCIB(c1, c2, n, shortcut, lk, e=0.5): C2f whose n blocks are CIB(c, c, shortcut, e=1.0, lk).
- Attention(dim, num_heads, attn_ratio=0.5): head_dim = dim // heads, key_dim = int(head_dim
  attn_ratio); qkv = Conv 1x1 (no act) to dim + 2 key_dim heads, laid out per head as
  [q (key_dim), k (key_dim), v (head_dim)]; attention softmax(q^T k / sqrt(key_dim)) over the H W
  positions; out = proj(attn(v) + pe(v)), pe a depthwise 3x3 Conv (no act) on v seen as (dim, H, W),
  proj a 1x1 Conv (no act).
- PSA(c1, c2 = c1, e=0.5): c = int(c1 e); Conv 1x1 to 2 c, split (a, b); b += Attention(c, heads =
  c // 64)(b); b += FFN(b) with FFN = Conv 1x1 to 2 c (SiLU), Conv 1x1 to c (no act); Conv 1x1 on
  concat(a, b) to c1.
"""

from __future__ import annotations

import math

import flax.linen as nn
import jax
import jax.numpy as jnp
from jax import lax

from .conv import DIMS
from .silu import silu
from .yolo import YoloConv, csp_chain, residual, torch_kernel_init, yolo_batch_norm


class DepthwiseConv(nn.Module):
    """kxk depthwise convolution, no bias, padded like PyTorch (k // 2 on every side)."""

    kernel: int = 3
    stride: int = 1

    @nn.compact
    def __call__(self, x_BxHxWxC):
        k, s, c = self.kernel, self.stride, x_BxHxWxC.shape[-1]
        # PyTorch's fan_in for a grouped conv is (c_in / groups) k k = k k: the same init rule
        w = self.param("kernel", torch_kernel_init, (k, k, 1, c))
        p = k // 2
        return lax.conv_general_dilated(x_BxHxWxC, w, (s, s), ((p, p), (p, p)), dimension_numbers=DIMS,
                                        feature_group_count=c)

    def macs(self, in_shape, out_shape) -> int:
        return math.prod(out_shape) * self.kernel**2


class YoloDWConv(nn.Module):
    """ultralytics Conv(c, c, k, s, g=c): depthwise conv + BN + SiLU (`act=False` leaves it out)."""

    kernel: int = 3
    stride: int = 1
    act: bool = True

    @nn.compact
    def __call__(self, x, train: bool = False):
        x = yolo_batch_norm(train, "bn")(DepthwiseConv(self.kernel, self.stride, name="conv")(x))
        return silu(x) if self.act else x


class SCDown(nn.Module):
    """Spatial-channel decoupled downsampling: 1x1 Conv to `features`, depthwise kxk stride-s Conv."""

    features: int
    kernel: int = 3
    stride: int = 2

    @nn.compact
    def __call__(self, x, train: bool = False):
        x = YoloConv(self.features, 1, name="cv1")(x, train)
        return YoloDWConv(self.kernel, self.stride, act=False, name="cv2")(x, train)


class RepVGGDW(nn.Module):
    """Depthwise 7x7 Conv-BN + depthwise 3x3 Conv-BN, summed, SiLU."""

    @nn.compact
    def __call__(self, x, train: bool = False):
        y = YoloDWConv(7, act=False, name="conv")(x, train) + YoloDWConv(3, act=False, name="conv1")(x, train)
        return silu(y)


class CIB(nn.Module):
    """Compact inverted block: depthwise 3x3, 1x1 up to 2 c_, depthwise (RepVGGDW when `large_kernel`),
    1x1 to features, depthwise 3x3; residual when asked and widths match."""

    features: int
    shortcut: bool = True
    expansion: float = 0.5
    large_kernel: bool = False

    @nn.compact
    def __call__(self, x, train: bool = False):
        hidden = 2 * int(self.features * self.expansion)
        y = YoloDWConv(3, name="cv1_0")(x, train)
        y = YoloConv(hidden, 1, name="cv1_1")(y, train)
        y = RepVGGDW(name="cv1_2")(y, train) if self.large_kernel else YoloDWConv(3, name="cv1_2")(y, train)
        y = YoloConv(self.features, 1, name="cv1_3")(y, train)
        y = YoloDWConv(3, name="cv1_4")(y, train)
        return residual(x, y, self.shortcut)


class C2fCIB(nn.Module):
    """C2f with CIB blocks: 1x1 to 2c, split, n chained CIBs keeping every output, concat, 1x1."""

    features: int
    n: int = 1
    shortcut: bool = False
    large_kernel: bool = False
    expansion: float = 0.5

    @nn.compact
    def __call__(self, x, train: bool = False):
        block = lambda c, name: CIB(c, self.shortcut, 1.0, self.large_kernel, name=name)
        return csp_chain(x, self.features, self.n, self.expansion, block, train)


class Attention(nn.Module):
    """Multi-head self-attention over the H W positions with a depthwise positional term on v."""

    num_heads: int
    attn_ratio: float = 0.5

    @nn.compact
    def __call__(self, x, train: bool = False):
        b, h, w, dim = x.shape
        head_dim = dim // self.num_heads
        key_dim = int(head_dim * self.attn_ratio)
        qkv = YoloConv(dim + 2 * key_dim * self.num_heads, 1, act=False, name="qkv")(x, train)
        qkv = qkv.reshape(b, h * w, self.num_heads, 2 * key_dim + head_dim)  # per head [q, k, v]
        q, k, v = jnp.split(qkv, [key_dim, 2 * key_dim], axis=-1)  # (B, N, heads, d)
        logits = jnp.einsum("bihd,bjhd->bhij", q, k) * key_dim**-0.5
        attended = jnp.einsum("bhij,bjhd->bihd", jax.nn.softmax(logits, axis=-1), v)
        v_map = v.reshape(b, h, w, dim)  # channels head-major, as PyTorch's view(B, C, H, W)
        y = attended.reshape(b, h, w, dim) + YoloDWConv(3, act=False, name="pe")(v_map, train)
        return YoloConv(dim, 1, act=False, name="proj")(y, train)


class PSA(nn.Module):
    """Partial self-attention: half the channels through Attention + FFN (both residual), concat, 1x1."""

    features: int
    expansion: float = 0.5

    @nn.compact
    def __call__(self, x, train: bool = False):
        c = int(self.features * self.expansion)
        a, b = jnp.split(YoloConv(2 * c, 1, name="cv1")(x, train), 2, axis=-1)
        # ultralytics: c // 64 heads (0, and a crash, below 64 channels; one head here)
        b = b + Attention(max(c // 64, 1), 0.5, name="attn")(b, train)
        ffn = YoloConv(2 * c, 1, name="ffn_0")(b, train)
        b = b + YoloConv(c, 1, act=False, name="ffn_1")(ffn, train)
        return YoloConv(self.features, 1, name="cv2")(jnp.concatenate([a, b], axis=-1), train)

