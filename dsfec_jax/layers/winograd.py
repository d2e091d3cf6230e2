"""Winograd's minimal filtering for stride-1 3x3 convolutions (NHWC, HWIO): the backward pass of
training, and the forward of the CPU inference form.

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

The forward also comes as F(2x2, 3x3) (`F2`: a 2x2 tile from 4x4 inputs, 16 products, coefficients
0, +-1 and 1/2: float32 error of the order of a direct conv's own rounding, ~1e-6). XLA's CPU conv
runs 3x3 convs two to three times slower than these products do, so the JAX runtime's inference
form computes its stride-1 3x3 convs with them (layers/conv_product.py picks F4 or F2 per shape);
the grid and whole-network timings are in docs/performance.md.
"""


from __future__ import annotations

import dataclasses

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

# F(2, 3) in one dimension (interpolation points 0, +-1 and infinity)
A_T_2 = np.array([[1, 1, 1, 0], [0, 1, -1, -1]], np.float64)
G_2 = np.array([[1, 0, 0], [1 / 2, 1 / 2, 1 / 2], [1 / 2, -1 / 2, 1 / 2], [0, 0, 1]], np.float64)
B_T_2 = np.array([[1, 0, -1, 0], [0, 1, 1, 0], [0, -1, 1, 0], [0, 1, 0, -1]], np.float64)

Pads = tuple[tuple[int, int], tuple[int, int]]


@dataclasses.dataclass(frozen=True)
class Minimal:
    """One F(tile x tile, 3x3): y = A^T [(G w G^T) * (B^T d B)] A over (tile + 2)^2 input tiles.
    The matrices are looked up by name at call time (a test swaps one to see the result break)."""

    tile: int
    a_t: str
    g: str
    b_t: str

    @property
    def span(self) -> int:
        return self.tile + TAPS - 1

    def matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return tuple(globals()[name] for name in (self.a_t, self.g, self.b_t))


F4 = Minimal(4, "A_T", "G", "B_T")
F2 = Minimal(2, "A_T_2", "G_2", "B_T_2")


def conv3x3(x_BxHxWxI, w_3x3xIxO, pads: Pads, f: Minimal = F4):
    """The stride-1 3x3 convolution of x padded by `pads` ((top, bottom), (left, right), each >= 0)."""
    g = jnp.asarray(f.matrices()[1], x_BxHxWxI.dtype)
    v = jnp.einsum("ua,abio,vb->uvio", g, w_3x3xIxO, g).reshape(f.span * f.span, *w_3x3xIxO.shape[2:])
    return conv3x3_transformed(x_BxHxWxI, v, pads, f, stacked=False)


def transformed_kernel(w_3x3xIxO, f: Minimal = F4) -> np.ndarray:
    """G w G^T of a known kernel, in float64 and then the kernel's dtype -> (span^2, I, O): what
    `conv3x3_transformed` takes (a network whose weights are constants transforms them once)."""
    g = f.matrices()[1]
    v = np.einsum("ua,abio,vb->uvio", g, np.asarray(w_3x3xIxO, np.float64), g)
    return v.reshape(f.span * f.span, *v.shape[2:]).astype(np.asarray(w_3x3xIxO).dtype)


def conv3x3_transformed(x_BxHxWxI, v_SxIxO, pads: Pads, f: Minimal = F4, stacked: bool = True):
    """`conv3x3` of a kernel already transformed (`transformed_kernel`). `stacked`: each transform
    pass one stacked array, which XLA emits as one fusion (the inference form's single image gains);
    else one array per tile row, as training's backward has run (a batch of 8 on 48-96 px maps
    measured mixed with the stacked form, so it stays)."""
    b, h, w, _ = x_BxHxWxI.shape
    cout = v_SxIxO.shape[-1]
    (top, bottom), (left, right) = pads
    ho, wo = h + top + bottom - TAPS + 1, w + left + right - TAPS + 1
    a_t = f.matrices()[0]
    span, tile = f.span, f.tile
    # the output rounded up to whole tiles; the extra rows read zeros and are cropped off
    u, nh, nw = _input_tiles(x_BxHxWxI, pads, ho, wo, f, stacked)
    m = jnp.einsum("uti,uio->uto", u, v_SxIxO).reshape(span, span, b, nh, nw, cout)
    if stacked:
        rows = jnp.stack(_combine([m[i] for i in range(span)], a_t))  # (tile, span, b, nh, nw, O)
        tiles = jnp.stack(_combine([rows[:, j] for j in range(span)], a_t), -2)  # (tile, b, nh, nw, tile, O)
        tiles = tiles.transpose(1, 2, 0, 3, 4, 5)
    else:
        row_list = _combine([m[i] for i in range(span)], a_t)  # tile of (span, b, nh, nw, O)
        tiles = jnp.stack([jnp.stack(_combine([r[j] for j in range(span)], a_t), 3) for r in row_list], 2)
    return tiles.reshape(b, nh * tile, nw * tile, cout)[:, :ho, :wo]


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
    v = _tiles_2d(gp, A_T.T, TILE, nh, nw, TILE).reshape(SPAN * SPAN, -1, cout)
    # a long contraction over tiles, both operands row-major (as pointwise_conv's kernel gradient)
    m = jnp.einsum("uti,uto->uio", u, v).reshape(SPAN, SPAN, cin, cout)
    gt = jnp.asarray(G.T, x_BxHxWxI.dtype)
    return jnp.einsum("au,uvio,bv->abio", gt, m, gt)


def _input_tiles(x_BxHxWxC, pads: Pads, ho: int, wo: int, f: Minimal = F4, stacked: bool = False):
    """B^T d B of every span x span input tile that an (ho, wo) output, rounded up to whole
    tile x tile tiles, reads from x padded by `pads` -> ((span^2, tiles, C), nh, nw)."""
    (top, bottom), (left, right) = pads
    tile, span = f.tile, f.span
    nh, nw = -(-ho // tile), -(-wo // tile)
    xp = jnp.pad(x_BxHxWxC, ((0, 0), (top, bottom + tile * nh - ho), (left, right + tile * nw - wo), (0, 0)))
    tiles = _tiles_2d(xp, f.matrices()[2], span, nh, nw, tile, stacked)
    return tiles.reshape(span * span, -1, x_BxHxWxC.shape[-1]), nh, nw


def _tiles_2d(a_BxHxWxC, transform: np.ndarray, span: int, nh: int, nw: int, tile: int, stacked: bool = False):
    """`transform` (R x span) applied to every tile's rows and then its columns: tile (p, q)
    reads rows tile*p .. tile*p + span - 1 and the same columns -> (R, R, B, nh, nw, C).
    `stacked`: each pass one stacked array (one XLA fusion), else one array per row."""
    if stacked:
        rows = jnp.stack(_combine(_strided(a_BxHxWxC, 1, span, nh, tile), transform))  # (R, B, nh, W, C)
        return jnp.stack(_combine(_strided(rows, 3, span, nw, tile), transform), 1)
    rows = _combine(_strided(a_BxHxWxC, 1, span, nh, tile), transform)
    return jnp.stack([jnp.stack(_combine(_strided(r, 2, span, nw, tile), transform)) for r in rows])


def _strided(a, axis: int, span: int, tiles: int, tile: int) -> list:
    """For k < span: the view of element k of every tile along `axis` (tiles start `tile` apart)."""
    return [lax.slice_in_dim(a, k, k + tile * (tiles - 1) + 1, tile, axis) for k in range(span)]


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
