"""Convolution primitives (NHWC) that know their own multiply-accumulate count.

Every primitive has `macs(in_shape, out_shape)`, which the profiler reads through a method
interceptor, so analytic FLOPs always describe the network that actually runs.
"""

from __future__ import annotations

import functools
import math
from typing import Literal

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from . import depthwise_grad_cpu, winograd
from .batch_norm import BatchNorm
from .kernels import KERNELS, Kernels, check_kernels, hand_written  # noqa: F401  (re-exported)

DIMS = ("NHWC", "HWIO", "NHWC")
DepthwiseImpl = Literal["shifted", "grouped"]
kernel_init = nn.initializers.variance_scaling(2.0, "fan_in", "truncated_normal")


def same_pads(size: int, kernel: int, stride: int) -> tuple[int, int]:
    """TF/JAX 'SAME' padding (extra pixel at the high end), as the paper's TF model used."""
    out = -(-size // stride)
    total = max((out - 1) * stride + kernel - size, 0)
    return total // 2, total - total // 2


class Conv(nn.Module):
    """Dense KxK convolution, optional bias."""

    features: int
    kernel: int = 3
    stride: int = 1
    use_bias: bool = False
    bias_init: nn.initializers.Initializer = nn.initializers.zeros
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x_BxHxWxC):
        k, cin = self.kernel, x_BxHxWxC.shape[-1]
        w = self.param("kernel", kernel_init, (k, k, cin, self.features))
        fast = hand_written(self.kernels)
        if k == 1 and fast:
            # a 1x1 conv is a matmul: XLA's CPU dot beats its conv, forward and weight gradient
            y = pointwise_conv(x_BxHxWxC[:, :: self.stride, :: self.stride], w[0, 0])
        elif fast and self.stride == 1 and min(cin, self.features) >= FAST_CONV_MIN_CHANNELS:
            y = fast_conv(x_BxHxWxC, w)
        else:
            y = lax.conv_general_dilated(
                x_BxHxWxC, w, (self.stride, self.stride), "SAME", dimension_numbers=DIMS
            )
        if self.use_bias:
            y = y + self.param("bias", self.bias_init, (self.features,))
        return y

    def macs(self, in_shape, out_shape) -> int:
        return math.prod(out_shape[:-1]) * self.kernel**2 * in_shape[-1] * self.features


FAST_CONV_MIN_CHANNELS = 16  # below this the per-tap products are too thin to beat XLA's own


def plain_conv(x_BxHxWxC, w_KxKxIxO, pads=None):
    """Stride-1 dense convolution, XLA's: 'SAME', or explicit `pads` ((low, high), (low, high))."""
    return lax.conv_general_dilated(x_BxHxWxC, w_KxKxIxO, (1, 1), "SAME" if pads is None else pads,
                                    dimension_numbers=DIMS)


@functools.partial(jax.custom_vjp, nondiff_argnums=(2,))
def fast_conv(x_BxHxWxC, w_KxKxIxO, pads=None):
    """`plain_conv` (the same forward, bit for bit) with a hand-written backward of the same value.

    XLA's CPU backend computes a conv's kernel gradient as a convolution whose window is the whole
    image (3x3 outputs, 96x96 taps): single-threaded and several times the forward's time, the
    largest op of a DSFEC head's backward pass. Here it is, for 3x3 kernels from
    `WINOGRAD_MIN_CHANNELS` on, Winograd's F(3x3, 4x4) (winograd.py: 36 batched products), and
    otherwise K*K matrix products per image, g^T (O x HW) times the image's tap view (HW x I),
    summed over images. The input gradient is Winograd's F(4x4, 3x3) on large wide images,
    otherwise XLA's (a plain conv of the output gradient). The timings of each form are in
    docs/profiler.md; `python -m dsfec_jax.profile.conv_backward` re-measures them.
    """
    return plain_conv(x_BxHxWxC, w_KxKxIxO, pads)


def _fast_conv_fwd(x, w, pads):
    return plain_conv(x, w, pads), (x, w)


def _fast_conv_bwd(pads, residuals, g_BxHxWxO):
    x, w = residuals
    k, cin, cout = w.shape[0], w.shape[2], w.shape[3]
    full_pads = explicit_pads(x.shape, k, pads)
    flat_pads = [p for side in full_pads for p in side]  # the tiles need 0 <= pad < 3
    winograd_fits = (k == winograd.TAPS and min(cin, cout) >= WINOGRAD_MIN_CHANNELS
                     and 0 <= min(flat_pads) and max(flat_pads) < winograd.TAPS)
    if winograd_fits and g_BxHxWxO.shape[1] * g_BxHxWxO.shape[2] >= WINOGRAD_INPUT_GRAD_MIN_PIXELS:
        dx = winograd.conv3x3_input_grad(g_BxHxWxO, w, full_pads)
    else:
        dx = jax.vjp(lambda x_: plain_conv(x_, w, pads), x)[1](g_BxHxWxO)[0]
    if winograd_fits:
        return dx, winograd.conv3x3_kernel_grad(x, g_BxHxWxO, full_pads)
    return dx, conv_kernel_grad(x, g_BxHxWxO, k, pads)


# Where Winograd's F(4x4, 3x3) beats the other 3x3 backward forms, read from `python -m
# dsfec_jax.profile.conv_backward` (batch 8, 2 threads, each part alone; the table and the step's
# gain: docs/profiler.md, "Winograd's algorithm"). Kernel gradient: from 32 channels on both sides
# (at 24, DSFEC-S's heads, it does not pay, so those keep the tap products). Input gradient: from
# 48x48 and 32 channels on (below, the tile transforms outweigh the product).
WINOGRAD_MIN_CHANNELS = 32
WINOGRAD_INPUT_GRAD_MIN_PIXELS = 48 * 48


def explicit_pads(x_shape, k: int, pads=None) -> tuple[tuple[int, int], tuple[int, int]]:
    """`pads` of a stride-1 conv as ((top, bottom), (left, right)); None is TF 'SAME'."""
    if pads is None:
        return same_pads(x_shape[1], k, 1), same_pads(x_shape[2], k, 1)
    return tuple(pads[0]), tuple(pads[1])


# Below this many output pixels per image, one product per tap over the whole batch beats one per
# image (measured alone, batch 8, from 12x12 to 48x48: docs/profiler.md, "small images' kernel
# gradients"; re-measure with `python -m dsfec_jax.profile.conv_backward`).
PER_IMAGE_KERNEL_GRAD_MIN_PIXELS = 1024


def conv_kernel_grad(x_BxHxWxI, g_BxHoxWoxO, k: int, pads=None):
    """d w[i, j] = sum over images and output pixels of tap (i, j)'s view of the padded input
    times g: (K, K, I, O). Large images one at a time, so their tap views stay in cache; small
    ones all at once, so each product has enough rows to keep the cores busy. `pads`: as in
    `plain_conv` (None: 'SAME')."""
    cin = x_BxHxWxI.shape[-1]
    _, ho, wo, cout = g_BxHoxWoxO.shape
    ph, pw = explicit_pads(x_BxHxWxI.shape, k, pads)
    xp = jnp.pad(x_BxHxWxI, ((0, 0), ph, pw, (0, 0)))
    if ho * wo < PER_IMAGE_KERNEL_GRAD_MIN_PIXELS:
        taps = [jnp.einsum("bhwi,bhwo->io", xp[:, i:i + ho, j:j + wo], g_BxHoxWoxO) for i in range(k) for j in range(k)]
        return jnp.stack(taps).reshape(k, k, cin, cout)

    def image(pair):
        xp_1, g_1 = pair
        g_t = g_1.reshape(ho * wo, cout).T
        return jnp.stack([g_t @ xp_1[i:i + ho, j:j + wo].reshape(ho * wo, cin) for i in range(k) for j in range(k)])

    per_tap = lax.map(image, (xp, g_BxHoxWoxO)).sum(0)  # (K*K, O, I)
    return per_tap.transpose(0, 2, 1).reshape(k, k, cin, cout)


fast_conv.defvjp(_fast_conv_fwd, _fast_conv_bwd)


@jax.custom_vjp
def pointwise_conv(x_BxHxWxI, w_IxO):
    """A 1x1 convolution, `x @ w`, with a hand-written backward of the same value.

    Autodiff transposes the forward's dot: for the kernel gradient XLA's CPU layout assignment
    then writes the output gradient out transposed (O x BHW) and hands Eigen a product whose long
    contracted dimension it packs slowly. Stated directly as `einsum('...i,...o->io')`, XLA keeps
    both operands in their row-major layout (the gain: docs/profiler.md, "1x1 convs"; re-measure:
    `dsfec bench --train --compare kernels=plain`).
    """
    return jnp.dot(x_BxHxWxI, w_IxO)


def _pointwise_fwd(x, w):
    return jnp.dot(x, w), (x, w)


def _pointwise_bwd(residuals, g_BxHxWxO):
    x, w = residuals
    return jnp.dot(g_BxHxWxO, w.T), jnp.einsum("...i,...o->io", x, g_BxHxWxO)


pointwise_conv.defvjp(_pointwise_fwd, _pointwise_bwd)


class DepthwiseConv(nn.Module):
    """Depthwise KxK convolution with one weight tensor and two kernels.

    `impl="shifted"` sums K*K shifted, strided slices (XLA on CPU runs this several times faster
    than a grouped conv; `dsfec bench --runtimes jax,onnx` sets it against ONNX Runtime's grouped
    conv); `impl="grouped"` is `feature_group_count=C`, which exports to ONNX as a
    single `Conv(group=C)`. Both read the same (K, K, 1, C) kernel. With `kernels="fast"` the
    shifted form has a hand-written gradient (`fast_shifted_depthwise`); "plain" is autodiff's.
    """

    kernel: int = 3
    stride: int = 1
    impl: DepthwiseImpl = "shifted"
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x_BxHxWxC):
        c = x_BxHxWxC.shape[-1]
        w = self.param("kernel", kernel_init, (self.kernel, self.kernel, 1, c))
        if self.impl == "grouped":
            return lax.conv_general_dilated(
                x_BxHxWxC, w, (self.stride, self.stride), "SAME",
                dimension_numbers=DIMS, feature_group_count=c,
            )
        if self.impl == "shifted":
            fast = hand_written(self.kernels)
            return (fast_shifted_depthwise if fast else shifted_depthwise)(x_BxHxWxC, w[:, :, 0, :], self.stride)
        raise ValueError(f"DepthwiseConv.impl={self.impl!r}; valid: 'shifted', 'grouped'")

    def macs(self, in_shape, out_shape) -> int:
        return math.prod(out_shape[:-1]) * self.kernel**2 * out_shape[-1]


def shifted_depthwise(x_BxHxWxC, w_KxKxC, stride: int, pads: tuple[int, int] | None = None):
    """Depthwise conv as K*K multiply-adds of shifted views of the padded input. `pads`
    (low, high) on both axes; default TF 'SAME'."""
    k = w_KxKxC.shape[0]
    xp, ho, wo = _padded(x_BxHxWxC, k, stride, pads)
    out = None
    for i in range(k):
        for j in range(k):
            term = _tap(xp, i, j, ho, wo, stride) * w_KxKxC[i, j]
            out = term if out is None else out + term
    return out


def _padded(x_BxHxWxC, k: int, stride: int, pads):
    """The padded input and the output size (ho, wo) of a KxK window at `stride`."""
    _, h, w, _ = x_BxHxWxC.shape
    ph, pw = (same_pads(h, k, stride), same_pads(w, k, stride)) if pads is None else (pads, pads)
    xp = jnp.pad(x_BxHxWxC, ((0, 0), ph, pw, (0, 0)))
    return xp, (h + sum(ph) - k) // stride + 1, (w + sum(pw) - k) // stride + 1


def _tap(xp, i: int, j: int, ho: int, wo: int, stride: int):
    """The strided view of the padded input that kernel tap (i, j) multiplies."""
    return xp[:, i : i + (ho - 1) * stride + 1 : stride, j : j + (wo - 1) * stride + 1 : stride, :]


DW_GRAD_CHUNK = 2  # images per pass of the kernel-gradient sums: one pair's taps stay in cache


@functools.partial(jax.custom_vjp, nondiff_argnums=(2, 3))
def fast_shifted_depthwise(x_BxHxWxC, w_KxKxC, stride: int, pads: tuple[int, int] | None = None):
    """`shifted_depthwise` (same `pads`, default TF 'SAME') with a hand-written gradient of the same value.

    Autodiff of the shifted form keeps all K*K shifted views of the input for the backward pass
    (9 activation-sized copies per 3x3 layer, the largest memory traffic of a DSFEC training
    step). This keeps only the input: the input gradient is the flipped-kernel depthwise conv of
    the (stride-dilated) output gradient, and the kernel gradient re-reads each tap view, summed
    over a few images at a time so they stay in cache.
    """
    return shifted_depthwise(x_BxHxWxC, w_KxKxC, stride, pads)


def _depthwise_fwd(x_BxHxWxC, w_KxKxC, stride: int, pads):
    return shifted_depthwise(x_BxHxWxC, w_KxKxC, stride, pads), (x_BxHxWxC, w_KxKxC)


def _depthwise_bwd(stride: int, pads, residuals, g_BxHoxWoxC):
    x, w = residuals
    return (_depthwise_input_grad(g_BxHoxWoxC, w, x.shape, stride, pads),
            _depthwise_kernel_grad(x, g_BxHoxWoxC, w.shape[0], stride, pads))


def _depthwise_input_grad(g, w_KxKxC, x_shape, stride: int, pads):
    """d x: output o*s + t - pad_low reads input row m, so m gets g[o] * w[t]: a stride-1 conv of
    g dilated by s with the flipped kernel, padded to cover every input row."""
    k = w_KxKxC.shape[0]
    low_h, low_w = _low_pads(x_shape, k, stride, pads)
    ho, wo = g.shape[1], g.shape[2]
    pad_h = (k - 1 - low_h, x_shape[1] - 1 + low_h - (ho - 1) * stride, stride - 1)
    pad_w = (k - 1 - low_w, x_shape[2] - 1 + low_w - (wo - 1) * stride, stride - 1)
    gd = lax.pad(g, jnp.zeros((), g.dtype), ((0, 0, 0), pad_h, pad_w, (0, 0, 0)))
    return shifted_depthwise(gd, w_KxKxC[::-1, ::-1], 1, pads=(0, 0))


def _low_pads(x_shape, k: int, stride: int, pads) -> tuple[int, int]:
    """The padding before the first row and column (TF 'SAME' unless `pads` is given)."""
    if pads is None:
        return same_pads(x_shape[1], k, stride)[0], same_pads(x_shape[2], k, stride)[0]
    return pads[0], pads[0]


def _depthwise_kernel_grad(x, g, k: int, stride: int, pads):
    """d w[i, j] = sum over images and pixels of tap (i, j) times g: on the CPU a compiled loop that
    reads x and g in place (depthwise_grad_cpu.py), elsewhere XLA's sums over tap views."""
    if not depthwise_grad_cpu.supported(x.dtype):
        return _xla_depthwise_kernel_grad(x, g, k, stride, pads)
    low_h, low_w = _low_pads(x.shape, k, stride, pads)
    return lax.platform_dependent(
        x, g, cpu=lambda x, g: depthwise_grad_cpu.kernel_grad(x, g, k, stride, low_h, low_w),
        default=lambda x, g: _xla_depthwise_kernel_grad(x, g, k, stride, pads))


def _xla_depthwise_kernel_grad(x, g, k: int, stride: int, pads):
    """`_depthwise_kernel_grad` in XLA: each tap's view (a copy) times g, summed a few images at a time."""
    xp, ho, wo = _padded(x, k, stride, pads)

    def chunk(pair):
        xp_c, g_c = pair
        return jnp.stack([jnp.sum(_tap(xp_c[None], i, j, ho, wo, stride)[0] * g_c, (0, 1))
                          for i in range(k) for j in range(k)])

    per_image = lax.map(chunk, (xp, g), batch_size=DW_GRAD_CHUNK)
    return per_image.sum(0).reshape(k, k, -1)


fast_shifted_depthwise.defvjp(_depthwise_fwd, _depthwise_bwd)


class ConvTranspose(nn.Module):
    """KxK transposed convolution ('deconv') that upsamples by `stride`, bias optional (PIXOR: with).

    `kernels="fast"` runs it as one dense conv to stride^2 x features channels and a
    depth-to-space (`subpixel_conv_transpose`): the same numbers, but XLA's CPU backend computes
    the dilated form's weight gradient as a window-sized convolution, the slowest op of a DSFEC
    training step. `kernels="plain"` is `lax.conv_transpose`. Both
    read the same (K, K, C_in, C_out) kernel.
    """

    features: int
    kernel: int = 3
    stride: int = 2
    use_bias: bool = True
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x_BxHxWxC):
        cin = x_BxHxWxC.shape[-1]
        w = self.param("kernel", kernel_init, (self.kernel, self.kernel, cin, self.features))
        if hand_written(self.kernels):
            y = subpixel_conv_transpose(x_BxHxWxC, w, self.stride,
                                        fast_grad=min(cin, self.features) >= FAST_CONV_MIN_CHANNELS)
        else:
            y = lax.conv_transpose(x_BxHxWxC, w, (self.stride, self.stride), "SAME", dimension_numbers=DIMS)
        return y + self.param("bias", nn.initializers.zeros, (self.features,)) if self.use_bias else y

    def macs(self, in_shape, out_shape) -> int:
        # Each input pixel scatters a KxK patch: zero taps of the dilated form are not counted.
        return math.prod(in_shape[:-1]) * self.kernel**2 * in_shape[-1] * self.features


def transpose_pads(kernel: int, stride: int) -> tuple[int, int]:
    """(low, high) padding of the stride-dilated input in `lax.conv_transpose(..., "SAME")`
    (jax/_src/lax/convolution.py, `_conv_transpose_padding`), which the sub-pixel form mirrors."""
    total = kernel + stride - 2
    low = kernel - 1 if stride > kernel - 1 else -(-total // 2)
    return low, total - low


@functools.lru_cache(maxsize=None)
def _phase_taps(kernel: int, stride: int) -> tuple[np.ndarray, int, int]:
    """For each output phase p (o = stride*a + p) and window slot j over input rows
    a + lo .. a + hi: the kernel tap it multiplies, or `kernel` (a zero tap) -> ((stride, m), lo, hi).
    Output o reads dilated row o + t - pad, a real input row only when that is a multiple of the stride."""
    pad = transpose_pads(kernel, stride)[0]
    offsets = {(p, t): (p + t - pad) // stride for p in range(stride) for t in range(kernel)
               if (p + t - pad) % stride == 0}
    lo, hi = min(offsets.values()), max(offsets.values())
    taps = np.full((stride, hi - lo + 1), kernel, np.int32)
    for (p, t), d in offsets.items():
        taps[p, d - lo] = t
    return taps, lo, hi


def subpixel_conv_transpose(x_BxHxWxC, w_KxKxIxO, stride: int, fast_grad: bool = False):
    """`lax.conv_transpose(x, w, (s, s), "SAME")` as a dense conv of the undilated input with a
    kernel that holds every output phase's taps (zeros where a phase has none), then
    depth-to-space (the sub-pixel convolution of Shi et al., CVPR 2016). `fast_grad`: that dense
    conv's kernel gradient is `conv_kernel_grad`'s per-tap products, not XLA's single-threaded
    whole-image window (docs/profiler.md, "The sub-pixel deconv's")."""
    k, _, cin, cout = w_KxKxIxO.shape
    b, h, wd, _ = x_BxHxWxC.shape
    taps, lo, hi = _phase_taps(k, stride)
    w_ext = jnp.pad(w_KxKxIxO, ((0, 1), (0, 1), (0, 0), (0, 0)))  # index k is the zero tap
    # (m, m, s, s, I, O): slot (jr, jc) of phase (pr, pc) holds tap (taps[pr, jr], taps[pc, jc])
    kern = w_ext[taps.T[:, None, :, None], taps.T[None, :, None, :]]
    m = taps.shape[1]
    kern = kern.transpose(0, 1, 4, 2, 3, 5).reshape(m, m, cin, stride * stride * cout)
    pads = ((max(-lo, 0), max(hi, 0)),) * 2
    y = (fast_conv if fast_grad else plain_conv)(x_BxHxWxC, kern, pads)
    y = y[:, max(lo, 0) : max(lo, 0) + h, max(lo, 0) : max(lo, 0) + wd]
    y = y.reshape(b, h, wd, stride, stride, cout).transpose(0, 1, 3, 2, 4, 5)
    return y.reshape(b, h * stride, wd * stride, cout)


class PointLinear(nn.Module):
    """A 1x1 conv over points (PointPillars' per-point linear layer): (..., D) -> (..., F).
    `kernels="fast"` trains it as `pointwise_conv`: autodiff's kernel gradient here is an
    Eigen dot over a transposed operand, outside YNNPACK (the gain: docs/profiler.md, "Per-point
    linears"; re-measure: `dsfec bench --train --compare kernels=plain`)."""

    features: int
    use_bias: bool = True
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x):
        w = self.param("kernel", nn.initializers.lecun_normal(), (x.shape[-1], self.features))
        y = (pointwise_conv if hand_written(self.kernels) else jnp.dot)(x, w)
        if self.use_bias:
            y = y + self.param("bias", nn.initializers.zeros, (self.features,))
        return y

    def macs(self, in_shape, out_shape) -> int:
        return math.prod(in_shape[:-1]) * in_shape[-1] * self.features


# Keras defaults (the paper trained in TensorFlow); search's BN recalibration inverts this momentum.
BN_MOMENTUM = 0.99
BN_EPS = 1e-3


def batch_norm(train: bool, name: str | None = None, kernels: Kernels = "auto") -> BatchNorm:
    return BatchNorm(use_running_average=not train, momentum=BN_MOMENTUM, epsilon=BN_EPS, kernels=kernels, name=name)
