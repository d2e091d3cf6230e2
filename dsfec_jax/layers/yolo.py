"""Ultralytics YOLOv8 building blocks (NHWC): Conv (conv + BN + SiLU), Bottleneck, C2f and SPPF.

Facts from ultralytics/ultralytics (the code here is ours):
- `nn/modules/conv.py` Conv: Conv2d(bias=False, padding=autopad(k) = k // 2 on every side), BN, SiLU.
  PyTorch pads symmetrically; TF/JAX 'SAME' pads one extra pixel at the high end only, so on an
  even-sized input a stride-2 3x3 conv would sample pixels shifted by one. `PaddedConv` pads like
  PyTorch, so a network here reads the same pixels as ultralytics' and its weights could be loaded.
- `utils/torch_utils.py` initialize_weights: every BatchNorm2d gets eps 1e-3 and momentum 0.03
  (PyTorch convention: new = 0.97 old + 0.03 batch), i.e. flax momentum 0.97; convs keep PyTorch's
  default init (kaiming_uniform with a = sqrt(5): U(+-1/sqrt(fan_in)), bias likewise).
- `nn/modules/block.py`: Bottleneck(c1, c2, shortcut, k=(3, 3), e) = Conv kxk to int(c2 e), Conv kxk
  to c2, residual add only when asked and c1 == c2; C2f(c1, c2, n, shortcut=False, e=0.5): 1x1 Conv to
  2c (c = int(c2 e)), split in two, chain n Bottlenecks(c, c, shortcut, e=1.0) on the second half,
  keeping every output, concatenate the (2 + n) c channels, 1x1 Conv to c2; SPPF(c1, c2, k=5): 1x1
  Conv to c1 // 2, three chained kxk stride-1 max pools (padding k // 2), concatenate the four,
  1x1 Conv to c2.
"""

from __future__ import annotations

import math

import flax.linen as nn
import jax
import jax.numpy as jnp
from jax import lax

from .conv import DIMS
from .silu import silu

BN_EPS = 1e-3  # ultralytics initialize_weights
BN_MOMENTUM = 0.97  # = 1 - PyTorch's 0.03
# PyTorch's default Conv2d init (kaiming_uniform, a = sqrt(5)) is U(+-1/sqrt(fan_in)): variance 1/(3 fan_in)
torch_kernel_init = nn.initializers.variance_scaling(1.0 / 3.0, "fan_in", "uniform")


def torch_bias_init(fan_in: int) -> nn.initializers.Initializer:
    """PyTorch's default conv bias init, U(+-1/sqrt(fan_in))."""
    bound = 1.0 / math.sqrt(fan_in)

    def init(key, shape, dtype=jnp.float32):
        return jax.random.uniform(key, shape, dtype, -bound, bound)

    return init


def yolo_batch_norm(train: bool, name: str | None = None) -> nn.BatchNorm:
    return nn.BatchNorm(use_running_average=not train, momentum=BN_MOMENTUM, epsilon=BN_EPS, name=name)


class PaddedConv(nn.Module):
    """KxK convolution padded like PyTorch (k // 2 on every side); bias optional.

    `bias_init` None is PyTorch's default (uniform over +-1/sqrt(fan_in)); a head's last conv
    passes its own. A 1x1 conv runs as a matmul (the same numbers; XLA's CPU dot is faster).
    """

    features: int
    kernel: int = 1
    stride: int = 1
    use_bias: bool = False
    bias_init: nn.initializers.Initializer | None = None

    @nn.compact
    def __call__(self, x_BxHxWxC):
        k, s, cin = self.kernel, self.stride, x_BxHxWxC.shape[-1]
        w = self.param("kernel", torch_kernel_init, (k, k, cin, self.features))
        if k == 1:
            y = jnp.dot(x_BxHxWxC[:, ::s, ::s], w[0, 0])
        else:
            p = k // 2
            y = lax.conv_general_dilated(x_BxHxWxC, w, (s, s), ((p, p), (p, p)), dimension_numbers=DIMS)
        if self.use_bias:
            init = self.bias_init if self.bias_init is not None else torch_bias_init(k * k * cin)
            y = y + self.param("bias", init, (self.features,))
        return y

    def macs(self, in_shape, out_shape) -> int:
        return math.prod(out_shape[:-1]) * self.kernel**2 * in_shape[-1] * self.features


class YoloConv(nn.Module):
    """ultralytics Conv: conv (no bias) + BN + SiLU (`act=False` leaves the activation out)."""

    features: int
    kernel: int = 1
    stride: int = 1
    act: bool = True

    @nn.compact
    def __call__(self, x, train: bool = False):
        x = yolo_batch_norm(train, "bn")(PaddedConv(self.features, self.kernel, self.stride, name="conv")(x))
        return silu(x) if self.act else x


def residual(x, y, shortcut: bool):
    """ultralytics' bottleneck residual: x + y when asked and the widths match, else y."""
    return x + y if shortcut and x.shape[-1] == y.shape[-1] else y


class Bottleneck(nn.Module):
    """kxk Conv to int(features * expansion), kxk Conv to features, residual when asked and widths match."""

    features: int
    shortcut: bool = True
    expansion: float = 0.5
    kernels: tuple[int, int] = (3, 3)

    @nn.compact
    def __call__(self, x, train: bool = False):
        hidden = int(self.features * self.expansion)
        y = YoloConv(hidden, self.kernels[0], name="cv1")(x, train)
        y = YoloConv(self.features, self.kernels[1], name="cv2")(y, train)
        return residual(x, y, self.shortcut)


class C2f(nn.Module):
    """CSP bottleneck with two convolutions: split, n chained Bottlenecks keeping every output, concat, 1x1."""

    features: int
    n: int = 1
    shortcut: bool = False
    expansion: float = 0.5

    @nn.compact
    def __call__(self, x, train: bool = False):
        block = lambda c, name: Bottleneck(c, self.shortcut, 1.0, name=name)
        return csp_chain(x, self.features, self.n, self.expansion, block, train)


def csp_chain(x, features: int, n: int, expansion: float, block, train: bool):
    """C2f's wiring, shared by C2f and C2fCIB (layers/yolo_v10.py); call it inside a compact method,
    whose module then holds `cv1`, `m0`..`m{n-1}` and `cv2`: 1x1 Conv `cv1` to 2c (c = int(features
    expansion)), split in two, n chained `block(c, name)`s on the second half keeping every output,
    concatenate the (2 + n) c channels, 1x1 Conv `cv2` to `features`."""
    c = int(features * expansion)
    ys = list(jnp.split(YoloConv(2 * c, 1, name="cv1")(x, train), 2, axis=-1))
    for i in range(n):
        ys.append(block(c, f"m{i}")(ys[-1], train))
    return YoloConv(features, 1, name="cv2")(jnp.concatenate(ys, axis=-1), train)


def max_pool_padded(x_BxHxWxC, k: int, stride: int, pad: int):
    """kxk max pool padded by `pad` on every side with -inf (PyTorch MaxPool2d's padding). The pad is
    explicit and the pool called by keyword with padding 'VALID' because that is the form jax2onnx's
    flax.linen.max_pool lowering accepts (keyword-only window_shape, string padding): ONNX Pad + MaxPool."""
    x = jnp.pad(x_BxHxWxC, ((0, 0), (pad, pad), (pad, pad), (0, 0)), constant_values=-jnp.inf)
    return nn.max_pool(x, window_shape=(k, k), strides=(stride, stride), padding="VALID")


def max_pool_same(x_BxHxWxC, k: int):
    """kxk stride-1 max pool padded by k // 2 with -inf: the size is kept."""
    return max_pool_padded(x_BxHxWxC, k, 1, k // 2)


class SPPF(nn.Module):
    """Spatial pyramid pooling, fast: three chained kxk max pools = pools of k, 2k-1, 3k-2."""

    features: int
    k: int = 5

    @nn.compact
    def __call__(self, x, train: bool = False):
        ys = [YoloConv(x.shape[-1] // 2, 1, name="cv1")(x, train)]
        for _ in range(3):
            ys.append(max_pool_same(ys[-1], self.k))
        return YoloConv(self.features, 1, name="cv2")(jnp.concatenate(ys, axis=-1), train)


def upsample_nearest(x_BxHxWxC, factor: int = 2):
    """nn.Upsample(scale_factor, mode='nearest'): each pixel repeated factor x factor times."""
    return jnp.repeat(jnp.repeat(x_BxHxWxC, factor, axis=1), factor, axis=2)
