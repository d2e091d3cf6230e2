"""Winograd's minimal filtering for stride-1 3x3 convolutions (NHWC, HWIO), the backward pass.

Lavin & Gray, "Fast Algorithms for Convolutional Neural Networks" (CVPR 2016): F(4x4, 3x3)
computes a 4x4 output tile from a 6x6 input tile with 36 multiplies instead of 144. Over
channels each of the 36 transformed positions becomes one matrix product, so a conv turns into
36 batched GEMMs with a 2.25x (instead of 9x im2col) blow-up of the tiles.

The kernel gradient uses the same algorithm's dual, F(3x3, 4x4) (the roles of the filter and the
output swapped: the 3x3 "output" is the kernel gradient, the 4x4 "filter" a tile of the output
gradient). It is used where it beats conv.py's per-tap products, which ran a wide 3x3 kernel
gradient slower than the forward (the timings: docs/profiler.md, "Winograd's algorithm";
re-measure: `python -m dsfec_jax.profile.conv_backward --threads 2`).

float32 error: ~1e-5 of the largest element (the transforms' coefficients reach 8 and 1/24), well
inside the 1e-4 the gradient-equality tests hold the fast kernels to.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import lax

# F(4, 3) in one dimension: y = A^T [(G w) * (B^T d)] for a 6-sample input d and a 3-tap w
# (Lavin & Gray, section 4.2; interpolation points 0, +-1, +-2 and infinity).
TILE = 4
TAPS = 3
SPAN = TILE + TAPS - 1  # input samples a tile reads
A_T = np.array([[1, 1, 1, 1, 1, 0], [0, 1, -1, 2, -2, 0], [0, 1, 1, 4, 4, 0], [0, 1, -1, 8, -8, 1]], np.float64)
G = np.array([[1 / 4, 0, 0], [-1 / 6, -1 / 6, -1 / 6], [-1 / 6, 1 / 6, -1 / 6],
              [1 / 24, 1 / 12, 1 / 6], [1 / 24, -1 / 12, 1 / 6], [0, 0, 1]], np.float64)
B_T = np.array([[4, 0, -5, 0, 1, 0], [0, -4, -4, 1, 1, 0], [0, 4, -4, -1, 1, 0],
                [0, -2, -1, 2, 1, 0], [0, 2, -1, -2, 1, 0], [0, 4, 0, -5, 0, 1]], np.float64)

Pads = tuple[tuple[int, int], tuple[int, int]]


def conv3x3(x_BxHxWxI, w_3x3xIxO, pads: Pads):
    """The stride-1 3x3 convolution of x padded by `pads` ((top, bottom), (left, right), each >= 0)."""
    b, h, w, cin = x_BxHxWxI.shape
    cout = w_3x3xIxO.shape[-1]
    (top, bottom), (left, right) = pads
    ho, wo = h + top + bottom - TAPS + 1, w + left + right - TAPS + 1
    # the output rounded up to whole tiles; the extra rows read zeros and are cropped off
    u, nh, nw = _input_tiles(x_BxHxWxI, pads, ho, wo)
    gm = jnp.asarray(G, x_BxHxWxI.dtype)
    v = jnp.einsum("ua,abio,vb->uvio", gm, w_3x3xIxO, gm).reshape(SPAN * SPAN, cin, cout)
    m = jnp.einsum("uti,uio->uto", u, v).reshape(SPAN, SPAN, b, nh, nw, cout)
    rows = _combine([m[i] for i in range(SPAN)], A_T)  # TILE of (SPAN, b, nh, nw, O)
    tiles = jnp.stack([jnp.stack(_combine([r[j] for j in range(SPAN)], A_T), 3) for r in rows], 2)
    return tiles.reshape(b, nh * TILE, nw * TILE, cout)[:, :ho, :wo]


def conv3x3_input_grad(g_BxHoxWoxO, w_3x3xIxO, pads: Pads):
    """d x of `conv3x3(x, w, pads)` (each pad at most 2): the conv of g with the flipped,
    transposed kernel, padded by 2 - pad on each side."""
    flipped = jnp.flip(w_3x3xIxO, (0, 1)).transpose(0, 1, 3, 2)
    return conv3x3(g_BxHoxWoxO, flipped, tuple((TAPS - 1 - lo, TAPS - 1 - hi) for lo, hi in pads))


def conv3x3_kernel_grad(x_BxHxWxI, g_BxHoxWoxO, pads: Pads):
    """d w of `conv3x3(x, w, pads)`: sum over images and pixels of tap (i, j)'s view of the padded
    input times g, by F(3x3, 4x4): y = G^T [(A h) * (B^T d)] in one dimension, where h is a
    4-pixel tile of g and d the 6 input pixels it meets."""
    cin = x_BxHxWxI.shape[-1]
    _, ho, wo, cout = g_BxHoxWoxO.shape
    u, nh, nw = _input_tiles(x_BxHxWxI, pads, ho, wo)
    # g's padding rows are zeros, so whatever input they meet adds nothing
    gp = jnp.pad(g_BxHoxWoxO, ((0, 0), (0, TILE * nh - ho), (0, TILE * nw - wo), (0, 0)))
    v = _tiles_2d(gp, A_T.T, TILE, nh, nw).reshape(SPAN * SPAN, -1, cout)
    # a long contraction over tiles, both operands row-major (as pointwise_conv's kernel gradient)
    m = jnp.einsum("uti,uto->uio", u, v).reshape(SPAN, SPAN, cin, cout)
    gt = jnp.asarray(G.T, x_BxHxWxI.dtype)
    return jnp.einsum("au,uvio,bv->abio", gt, m, gt)


def _input_tiles(x_BxHxWxC, pads: Pads, ho: int, wo: int):
    """B^T d B of every SPAN x SPAN input tile that an (ho, wo) output, rounded up to whole
    TILE x TILE tiles, reads from x padded by `pads` -> ((SPAN^2, tiles, C), nh, nw)."""
    (top, bottom), (left, right) = pads
    nh, nw = -(-ho // TILE), -(-wo // TILE)
    xp = jnp.pad(x_BxHxWxC, ((0, 0), (top, bottom + TILE * nh - ho), (left, right + TILE * nw - wo), (0, 0)))
    return _tiles_2d(xp, B_T, SPAN, nh, nw).reshape(SPAN * SPAN, -1, x_BxHxWxC.shape[-1]), nh, nw


def _tiles_2d(a_BxHxWxC, transform: np.ndarray, span: int, nh: int, nw: int):
    """`transform` (R x span) applied to every tile's rows and then its columns: tile (p, q)
    reads rows TILE*p .. TILE*p + span - 1 and the same columns -> (R, R, B, nh, nw, C)."""
    rows = _combine(_strided(a_BxHxWxC, 1, span, nh), transform)
    return jnp.stack([jnp.stack(_combine(_strided(r, 2, span, nw), transform)) for r in rows])


def _strided(a, axis: int, span: int, tiles: int) -> list:
    """For k < span: the view of element k of every tile along `axis` (tiles start TILE apart)."""
    return [lax.slice_in_dim(a, k, k + TILE * (tiles - 1) + 1, TILE, axis) for k in range(span)]


def _combine(parts: list, matrix: np.ndarray) -> list:
    """Each row of `matrix` as a sum of `parts` times its coefficients, skipping zeros: XLA fuses
    the sums into one pass over the parts instead of a small matrix product."""
    out = []
    for row in matrix:
        terms = [p if c == 1 else -p if c == -1 else p * np.asarray(c, p.dtype) for c, p in zip(row, parts) if c != 0]
        total = terms[0]
        for t in terms[1:]:
            total = total + t
        out.append(total)
    return out
