"""Dense KxK convolutions as one matrix product (im2col) where XLA's CPU convolution is slow: small
images with wide channels, as in the deep stages of Darknet-53 and YOLOv3's head. Inference only.

XLA's CPU backend runs such a conv well below its matrix-product speed (a 3x3 conv from 512 to
1024 channels on an 8 x 13 map is one 104 x 4608 by 4608 x 1024 product). Gathering the K*K
shifted views of the padded input into (pixels, K*K*C_in) rows and multiplying by the kernel
reshaped to (K*K*C_in, C_out) gives the same sums in another order (float rounding apart), and the
product runs at the matrix unit's speed; on large images the K*K-fold copy costs more than it
saves, so the conv stays XLA's there. The crossover, and the gain on whole networks, were measured
with `python -m experiments.bn_fold_speed --grid` and `--ab products` (docs/performance.md).

`product_call(call)` runs a network's apply with every conv that fits (`fits`) computed this way,
every strided conv of a thin input (a stem) over blocks of its pixels
(layers/conv_space_to_depth.py), and, where the kernels are known while tracing (the weights
compiled in as constants), every stride-1 3x3 conv as Winograd's products (`winograd_form`,
layers/winograd.py), through a flax method interceptor: nothing in the model changes,
so training, parameter counts and the ONNX export (where the runtime picks its own algorithm) keep
the plain convs. It acts on the CPU backend only; elsewhere the call runs as it is.
"""

from __future__ import annotations

from typing import Callable

import flax.linen as nn
import jax
import jax.numpy as jnp
from jax import lax

from . import conv, conv_space_to_depth, silu, winograd, yolo

MAX_PIXELS = 512  # output pixels at or below which the product form is used ...
MIN_CHANNELS = 128  # ... when both the input and the output are at least this wide
WINOGRAD_MIN_WEIGHTS = 32 * 24  # stride-1 3x3 convs with cin * cout from this on run as Winograd's products
F4_MIN_SIDE = 4  # output rows and columns from which F(4x4, 3x3) beats F(2x2, 3x3) ...
F4_MAX_WEIGHTS = 1 << 17  # ... while a kernel's cin * cout is at most this (F4 reads 36 copies of it, F2 16)

DENSE = (conv.Conv, yolo.PaddedConv)  # the zoo's dense conv modules; both call their input x_BxHxWxC


def geometry(module: nn.Module, x_BxHxWxC) -> tuple[int, tuple[tuple[int, int], tuple[int, int]]] | None:
    """(stride, ((top, bottom), (left, right)) pads) of a DENSE module applied to x; None for a 1x1
    kernel (a matrix product already)."""
    k, s = module.kernel, module.stride
    if k == 1:
        return None
    if isinstance(module, conv.Conv):  # TF 'SAME'
        return s, (conv.same_pads(x_BxHxWxC.shape[1], k, s), conv.same_pads(x_BxHxWxC.shape[2], k, s))
    return s, ((k // 2, k // 2), (k // 2, k // 2))  # PaddedConv: PyTorch's k // 2


def output_hw(x_BxHxWxC, k: int, stride: int, pads) -> tuple[int, int]:
    """The output size of a KxK conv with `stride` of x padded by `pads`."""
    (top, bottom), (left, right) = pads
    return ((x_BxHxWxC.shape[1] + top + bottom - k) // stride + 1,
            (x_BxHxWxC.shape[2] + left + right - k) // stride + 1)


def fits(x_BxHxWxC, kernel_KxKxIxO, stride: int, pads) -> bool:
    """Whether the product form beats XLA's conv for this shape (MAX_PIXELS, MIN_CHANNELS)."""
    k, _, cin, cout = kernel_KxKxIxO.shape
    ho, wo = output_hw(x_BxHxWxC, k, stride, pads)
    return ho * wo <= MAX_PIXELS and min(cin, cout) >= MIN_CHANNELS


def winograd_form(x_BxHxWxC, kernel_KxKxIxO, stride: int, pads) -> winograd.Minimal | None:
    """The Winograd transform a stride-1 3x3 conv runs as (None: not one): F(4x4, 3x3) on maps of at
    least F4_MIN_SIDE outputs a side with kernels of at most F4_MAX_WEIGHTS, else F(2x2, 3x3),
    whose four 2x2 tiles waste less of a thin map and whose 16 products read a large kernel fewer
    times (the grid: docs/performance.md). Only for a kernel known while tracing (the weights
    compiled in as constants: modalities/inference.py), transformed once; with the weights as
    arguments the transform would run in every call and cost more than it saves."""
    k, _, cin, cout = kernel_KxKxIxO.shape
    if isinstance(kernel_KxKxIxO, jax.core.Tracer) or k != 3 or stride != 1:
        return None
    if cin * cout < WINOGRAD_MIN_WEIGHTS or min(p for side in pads for p in side) < 0:
        return None
    small = min(output_hw(x_BxHxWxC, k, stride, pads)) < F4_MIN_SIDE or cin * cout > F4_MAX_WEIGHTS
    return winograd.F2 if small else winograd.F4


def conv_as_product(x_BxHxWxI, w_KxKxIxO, stride: int, pads):
    """The conv of x padded by `pads` with stride `stride`, as (pixels, K*K*I) @ (K*K*I, O)."""
    b, _, _, cin = x_BxHxWxI.shape
    k = w_KxKxIxO.shape[0]
    (top, bottom), (left, right) = pads
    xp = jnp.pad(x_BxHxWxI, ((0, 0), (top, bottom), (left, right), (0, 0)))
    ho, wo = output_hw(x_BxHxWxI, k, stride, pads)
    # columns ordered (row tap, column tap, channel): the kernel's own (K, K, I) order
    views = [lax.slice(xp, (0, i, j, 0), (b, i + stride * (ho - 1) + 1, j + stride * (wo - 1) + 1, cin),
                       (1, stride, stride, 1)) for i in range(k) for j in range(k)]
    return jnp.dot(jnp.concatenate(views, axis=-1), w_KxKxIxO.reshape(k * k * cin, -1))


def _intercept(next_fun, args, kwargs, context):
    module = context.module
    if context.method_name != "__call__" or not isinstance(module, DENSE):
        return next_fun(*args, **kwargs)
    x = args[0] if args else kwargs["x_BxHxWxC"]
    shape = geometry(module, x)
    kernel = module.get_variable("params", "kernel")
    if shape is None or kernel is None:  # a 1x1, or kernel None: being initialised
        return next_fun(*args, **kwargs)
    form = winograd_form(x, kernel, *shape)
    if form is not None:
        y = winograd.conv3x3_transformed(x, winograd.transformed_kernel(kernel, form), shape[1], form)
    elif fits(x, kernel, *shape):
        y = conv_as_product(x, kernel, *shape)
    elif conv_space_to_depth.fits(x, kernel, shape[0]):
        y = conv_space_to_depth.conv_as_space_to_depth(x, kernel, *shape)
    else:
        return next_fun(*args, **kwargs)
    return y + module.get_variable("params", "bias") if module.use_bias else y


def product_call(call: Callable) -> Callable:
    """`call` (fn(variables, *args) running a flax network), with the convs that fit computed as
    one matrix product on the CPU backend, and its SiLUs' logistic as a rational function there
    (layers/silu.py). An interceptor outside this one (bn_fold.folded_call)
    still sees each conv's call and adds what it adds after it."""

    def run(*args, **kwargs):
        if jax.default_backend() != "cpu":
            return call(*args, **kwargs)
        with nn.intercept_methods(_intercept), silu.rational_logistic():
            return call(*args, **kwargs)

    return run
