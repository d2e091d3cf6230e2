"""YOLOv9 (GELAN) building blocks as ultralytics builds them (NHWC): RepConvN, RepBottleneck, RepCSP,
RepNCSPELAN4, ELAN1, AConv, ADown and SPPELAN.

Facts from ultralytics/ultralytics (`ultralytics/nn/modules/block.py` and `conv.py`; the code here is
ours; every Conv is layers/yolo.py's YoloConv: conv without bias + BN + SiLU, PyTorch padding):
- RepConv(c1, c2, k=3, bn=False), the "RepConvN" of WongKinYiu/yolov9 inside RepNCSPELAN4: a 3x3
  Conv and a 1x1 Conv, both without activation, summed, then SiLU. With bn=False (what RepBottleneck
  uses) there is no identity-BN branch. At deploy time the 1x1 folds into the 3x3 (`fuse`), which is
  why ultralytics' "fused" summaries count fewer parameters.
- RepBottleneck(c1, c2, shortcut=True, e=1.0 in RepCSP): Bottleneck whose first Conv is a RepConv:
  RepConv 3x3 to int(c2 e), Conv 3x3 to c2, residual add when shortcut and c1 == c2.
- RepCSP(c1, c2, n, e=0.5) = C3 with RepBottlenecks: cv1, cv2 1x1 Convs to c_ = int(c2 e); n chained
  RepBottleneck(c_, c_) on cv1's output; cv3 1x1 Conv on concat(m(cv1(x)), cv2(x)) to c2.
- RepNCSPELAN4(c1, c2, c3, c4, n): cv1 1x1 Conv to c3, split in two halves (c3 // 2 each);
  cv2 = RepCSP(c3 // 2, c4, n) then Conv 3x3 c4, on the second half; cv3 = RepCSP(c4, c4, n) then
  Conv 3x3 c4, on cv2's output; cv4 1x1 Conv on concat(half1, half2, cv2, cv3) (c3 + 2 c4) to c2.
- ELAN1(c1, c2, c3, c4): RepNCSPELAN4's wiring with plain 3x3 Convs for cv2 and cv3.
- AConv(c1, c2): avg_pool2d(2, stride 1, no padding) then Conv 3x3 stride 2 padding 1.
- ADown(c1, c2): the same average pool, split in two halves; half 1 -> Conv 3x3 stride 2 to c2 // 2;
  half 2 -> max_pool2d(3, stride 2, padding 1) -> Conv 1x1 to c2 // 2; concat.
- SPPELAN(c1, c2, c3, k=5): 1x1 Conv to c3, three chained kxk stride-1 max pools, concat the four,
  1x1 Conv to c2 (SPPF with a free hidden width).
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

from .silu import silu
from .yolo import YoloConv, max_pool_padded, max_pool_same, residual


class RepConvN(nn.Module):
    """3x3 Conv-BN + 1x1 Conv-BN, summed, SiLU (ultralytics RepConv with bn=False)."""

    features: int
    stride: int = 1

    @nn.compact
    def __call__(self, x, train: bool = False):
        y = YoloConv(self.features, 3, self.stride, act=False, name="conv1")(x, train)
        y = y + YoloConv(self.features, 1, self.stride, act=False, name="conv2")(x, train)
        return silu(y)


class RepBottleneck(nn.Module):
    """RepConvN 3x3 to int(features * expansion), Conv 3x3 to features, residual when widths match."""

    features: int
    shortcut: bool = True
    expansion: float = 1.0

    @nn.compact
    def __call__(self, x, train: bool = False):
        y = RepConvN(int(self.features * self.expansion), name="cv1")(x, train)
        y = YoloConv(self.features, 3, name="cv2")(y, train)
        return residual(x, y, self.shortcut)


class RepCSP(nn.Module):
    """C3 with n chained RepBottlenecks on one 1x1 branch, a plain 1x1 branch beside it, 1x1 to features."""

    features: int
    n: int = 1
    shortcut: bool = True
    expansion: float = 0.5

    @nn.compact
    def __call__(self, x, train: bool = False):
        c = int(self.features * self.expansion)
        y = YoloConv(c, 1, name="cv1")(x, train)
        for i in range(self.n):
            y = RepBottleneck(c, self.shortcut, 1.0, name=f"m{i}")(y, train)
        side = YoloConv(c, 1, name="cv2")(x, train)
        return YoloConv(self.features, 1, name="cv3")(jnp.concatenate([y, side], axis=-1), train)


class RepNCSPELAN4(nn.Module):
    """CSP-ELAN: 1x1 to `hidden`, split, two chained (RepCSP + 3x3 Conv) stages of `stage` channels,
    concat every piece, 1x1 to `features`."""

    features: int  # c2
    hidden: int  # c3
    stage: int  # c4
    n: int = 1

    @nn.compact
    def __call__(self, x, train: bool = False):
        ys = list(jnp.split(YoloConv(self.hidden, 1, name="cv1")(x, train), 2, axis=-1))
        for name in ("cv2", "cv3"):
            y = RepCSP(self.stage, self.n, name=f"{name}_csp")(ys[-1], train)
            ys.append(YoloConv(self.stage, 3, name=f"{name}_conv")(y, train))
        return YoloConv(self.features, 1, name="cv4")(jnp.concatenate(ys, axis=-1), train)


class ELAN1(nn.Module):
    """RepNCSPELAN4's wiring with a single 3x3 Conv per stage."""

    features: int
    hidden: int
    stage: int

    @nn.compact
    def __call__(self, x, train: bool = False):
        ys = list(jnp.split(YoloConv(self.hidden, 1, name="cv1")(x, train), 2, axis=-1))
        for name in ("cv2", "cv3"):
            ys.append(YoloConv(self.stage, 3, name=name)(ys[-1], train))
        return YoloConv(self.features, 1, name="cv4")(jnp.concatenate(ys, axis=-1), train)


def avg_pool_2x2_stride1(x_BxHxWxC):
    """avg_pool2d(2, 1, 0): every 2x2 window, one row and column fewer (the AConv/ADown prefilter)."""
    return nn.avg_pool(x_BxHxWxC, window_shape=(2, 2), strides=(1, 1), padding="VALID")  # keywords: jax2onnx


class AConv(nn.Module):
    """2x2 stride-1 average pool, then Conv 3x3 stride 2: (H, W) -> (H / 2, W / 2) for even sides."""

    features: int

    @nn.compact
    def __call__(self, x, train: bool = False):
        return YoloConv(self.features, 3, 2, name="cv1")(avg_pool_2x2_stride1(x), train)


class ADown(nn.Module):
    """WongKinYiu's GELAN downsampler: average pool, then half by a stride-2 3x3 Conv and half by a
    stride-2 3x3 max pool + 1x1 Conv, concatenated (features // 2 each)."""

    features: int

    @nn.compact
    def __call__(self, x, train: bool = False):
        x1, x2 = jnp.split(avg_pool_2x2_stride1(x), 2, axis=-1)
        c = self.features // 2
        x1 = YoloConv(c, 3, 2, name="cv1")(x1, train)
        x2 = max_pool_padded(x2, 3, 2, 1)
        return jnp.concatenate([x1, YoloConv(c, 1, name="cv2")(x2, train)], axis=-1)


class SPPELAN(nn.Module):
    """1x1 Conv to `hidden`, three chained kxk max pools, concat the four, 1x1 Conv to `features`."""

    features: int
    hidden: int
    k: int = 5

    @nn.compact
    def __call__(self, x, train: bool = False):
        ys = [YoloConv(self.hidden, 1, name="cv1")(x, train)]
        for _ in range(3):
            ys.append(max_pool_same(ys[-1], self.k))
        return YoloConv(self.features, 1, name="cv5")(jnp.concatenate(ys, axis=-1), train)
