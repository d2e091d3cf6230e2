"""A strided conv of a thin input (an image's 3 channels: a network's stem) as a stride-1 conv over
stride x stride blocks of it (space to depth), on the CPU. Inference only.

XLA's CPU backend hands a conv to YNNPACK's kernels only when it is wider than 16 channels on one
side, so a 3 -> 16 stem runs on XLA's own conv, far below YNNPACK's speed, and gathering its
27-wide im2col rows (the product form, layers/conv_product.py) costs as much again in copies.
(A stem wider than 16 outputs is YNNPACK's already and keeps its plain conv.)
Regrouping each stride x stride block of pixels into one pixel of stride^2 x C channels (a
reshape and transpose of the input) turns the stride-s KxK conv into a stride-1 conv with
ceil-sized kernel over the blocks, with the same taps in another order (zeros where a block tap
falls outside the original kernel); its output channels are padded to PADDED_WIDTH where
both sides are still narrow, so that YNNPACK takes it, and the padding sliced off. Measured per conv and on whole
networks with `python -m experiments.conv_gap` and `experiments.bn_fold_speed` (docs/performance.md).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
from jax import lax

from .conv import DIMS

THIN_INPUT = 4  # input channels at or below which a strided conv is computed over blocks
YNNPACK_MIN_WIDTH = 16  # XLA's CPU backend keeps a conv whose widths are all <= this on its own kernel
PADDED_WIDTH = 32  # the output width a narrow block conv is padded to (17 and 24 ran slower, measured)


def fits(x_BxHxWxC, kernel_KxKxIxO, stride: int) -> bool:
    """Whether the block form is used for this conv: a strided conv of a thin input to at most
    YNNPACK_MIN_WIDTH outputs, which XLA would keep on its own kernel. A wider stem (3 -> 24) runs
    in YNNPACK already, and over blocks it ran slower (measured: docs/performance.md)."""
    _, _, cin, cout = kernel_KxKxIxO.shape
    return stride > 1 and cin <= THIN_INPUT and cout <= YNNPACK_MIN_WIDTH


def _block_taps(k: int, stride: int, pad_low: int) -> tuple[int, int, list[tuple[int, int]]]:
    """Along one axis: (block taps kb, block padding at the low end, [(block tap, sub-position)] of
    each of the k original taps). Output r reads input s*r + i - pad_low = block r + (i - pad_low) // s."""
    first = math.floor(-pad_low / stride)
    taps = [((i - pad_low) // stride - first, (i - pad_low) % stride) for i in range(k)]
    return (k - 1 - pad_low) // stride - first + 1, -first, taps


def block_kernel(kernel_KxKxIxO, stride: int, pads) -> tuple[jnp.ndarray, tuple[int, int]]:
    """The (kb, kb, s*s*I, O) kernel over blocks (channels ordered sub-row, sub-column, input
    channel, as `blocks` lays them out) and the block padding at the low ends (rows, columns)."""
    k, _, cin, cout = kernel_KxKxIxO.shape
    (kb_h, low_h, taps_h), (kb_w, low_w, taps_w) = (_block_taps(k, stride, p[0]) for p in pads)
    # one gather from the k*k taps plus a zero row: which source fills each block-kernel slot
    source = np.full((kb_h, kb_w, stride, stride), k * k)
    for i, (bh, sh) in enumerate(taps_h):
        for j, (bw, sw) in enumerate(taps_w):
            source[bh, bw, sh, sw] = i * k + j
    flat = jnp.concatenate([kernel_KxKxIxO.reshape(k * k, cin, cout), jnp.zeros((1, cin, cout), kernel_KxKxIxO.dtype)])
    return flat[source.ravel()].reshape(kb_h, kb_w, stride * stride * cin, cout), (low_h, low_w)


def blocks(x_BxHxWxC, stride: int) -> jnp.ndarray:
    """(B, ceil(H/s), ceil(W/s), s*s*C): each s x s block of pixels as one pixel (zeros past the edge)."""
    b, h, w, c = x_BxHxWxC.shape
    hb, wb = -(-h // stride), -(-w // stride)
    x = jnp.pad(x_BxHxWxC, ((0, 0), (0, hb * stride - h), (0, wb * stride - w), (0, 0)))
    x = x.reshape(b, hb, stride, wb, stride, c).transpose(0, 1, 3, 2, 4, 5)
    return x.reshape(b, hb, wb, stride * stride * c)


def conv_as_space_to_depth(x_BxHxWxI, w_KxKxIxO, stride: int, pads):
    """The conv of x padded by `pads` with `stride`, as a stride-1 conv over the input's blocks."""
    k, cout = w_KxKxIxO.shape[0], w_KxKxIxO.shape[3]
    out_h, out_w = ((n + lo + hi - k) // stride + 1 for n, (lo, hi) in zip(x_BxHxWxI.shape[1:3], pads))
    x = blocks(x_BxHxWxI, stride)
    kernel, (low_h, low_w) = block_kernel(w_KxKxIxO, stride, pads)
    if max(kernel.shape[2], cout) <= YNNPACK_MIN_WIDTH:
        kernel = jnp.pad(kernel, ((0, 0), (0, 0), (0, 0), (0, PADDED_WIDTH - cout)))
    kb_h, kb_w = kernel.shape[:2]
    high_h = max(0, out_h - 1 + kb_h - low_h - x.shape[1])  # block rows the last output still reads
    high_w = max(0, out_w - 1 + kb_w - low_w - x.shape[2])
    y = lax.conv_general_dilated(x, kernel, (1, 1), ((low_h, high_h), (low_w, high_w)), dimension_numbers=DIMS)
    return y[:, :out_h, :out_w, :cout]
