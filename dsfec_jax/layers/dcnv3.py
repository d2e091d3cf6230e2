"""DCNv3 (InternImage, Wang et al., CVPR 2023), the deformable layer of RadarNeXt's MDFEN neck.

x = Linear_in(input); a side branch depthwise 3x3 -> LayerNorm -> GELU of the raw input predicts,
per group g and sampling point p, an offset (dx, dy) and a modulation m (softmax over the points).
Each output pixel (i, j) samples the projected map bilinearly (zeros outside) at

    x_s = j + s * (k_x + dx_{g,p}),   y_s = i + s * (k_y + dy_{g,p}),   k in {-1, 0, 1}

(s = offset_scale, 2.0 in RadarNeXt: it scales the base grid too; points ordered x-major,
p = 3 * ix + iy), sums m * sample over the points, and projects with Linear_out. No residual, no
norm around it. Facts from InternImage (github OpenGVLab/InternImage,
classification/ops_dcnv3/functions/dcnv3_func.py, dcnv3_core_pytorch) and the public RadarNeXt code
(github Pay246-git468/RadarNeXt, commit 72676df, projects/RadarNeXt/radarnext/DeformFFN.py; its
DeformLayer sets offset_scale 2.0). The sampling formula is our derivation from the reference
points and grid_sample (align_corners=False). The code is ours.
"""

from __future__ import annotations

import math

import flax.linen as nn
import jax
import jax.numpy as jnp

from .conv import kernel_init, shifted_depthwise


def base_grid(kernel: int = 3) -> tuple[jax.Array, jax.Array]:
    """(k_x, k_y) of the P = kernel^2 sampling points, x-major: p = kernel * ix + iy."""
    k = jnp.arange(kernel, dtype=jnp.float32) - kernel // 2
    return jnp.repeat(k, kernel), jnp.tile(k, kernel)


def deformable_sample(value_BxHxWxGxC, offset_BxHxWxGxPx2, mask_BxHxWxGxP, offset_scale: float = 1.0,
                      kernel: int = 3):
    """The DCNv3 core: sum over points of mask * bilinear(value) at the deformed locations
    -> (B, H, W, G * C). Bilinear taps outside the map read zeros."""
    b, h, w, g, c = value_BxHxWxGxC.shape
    kx, ky = base_grid(kernel)
    rows = jnp.arange(h, dtype=jnp.float32)[:, None, None, None]
    cols = jnp.arange(w, dtype=jnp.float32)[None, :, None, None]
    xs = cols + offset_scale * (kx + offset_BxHxWxGxPx2[..., 0])  # (B, H, W, G, P)
    ys = rows + offset_scale * (ky + offset_BxHxWxGxPx2[..., 1])
    x0, y0 = jnp.floor(xs), jnp.floor(ys)
    fx, fy = xs - x0, ys - y0
    # (B, G, H*W, C): one gather per (image, group)
    table = value_BxHxWxGxC.reshape(b, h * w, g, c).transpose(0, 2, 1, 3)
    gather = jax.vmap(jax.vmap(lambda t, i: t[i]))
    out = 0.0
    for dy, wy in ((0, 1 - fy), (1, fy)):
        for dx, wx in ((0, 1 - fx), (1, fx)):
            yy, xx = y0 + dy, x0 + dx
            inside = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
            index = (jnp.clip(yy, 0, h - 1) * w + jnp.clip(xx, 0, w - 1)).astype(jnp.int32)
            index = index.transpose(0, 3, 1, 2, 4).reshape(b, g, -1)  # (B, G, H*W*P)
            taps = gather(table, index).reshape(b, g, h, w, -1, c)  # (B, G, H, W, P, C)
            weight = (wy * wx * inside * mask_BxHxWxGxP).transpose(0, 3, 1, 2, 4)[..., None]
            out = out + (taps * weight).sum(axis=4)
    return out.transpose(0, 2, 3, 1, 4).reshape(b, h, w, g * c)


class DCNv3(nn.Module):
    """DCNv3 over an NHWC map with `groups` groups and kernel x kernel sampling points."""

    channels: int
    groups: int = 4
    kernel: int = 3
    offset_scale: float = 2.0

    @nn.compact
    def __call__(self, x_BxHxWxC):
        b, h, w, _ = x_BxHxWxC.shape
        g, p = self.groups, self.kernel**2
        if self.channels % g:
            raise ValueError(f"DCNv3: channels {self.channels} must be a multiple of groups {g}")
        xavier = nn.initializers.xavier_uniform()
        value = nn.Dense(self.channels, kernel_init=xavier, name="input_proj")(x_BxHxWxC)
        dw = self.param("dw_kernel", kernel_init, (self.kernel, self.kernel, x_BxHxWxC.shape[-1]))
        side = shifted_depthwise(x_BxHxWxC, dw, 1, (self.kernel // 2, self.kernel // 2))
        side = side + self.param("dw_bias", nn.initializers.zeros, (x_BxHxWxC.shape[-1],))
        side = nn.gelu(nn.LayerNorm(epsilon=1e-6, name="dw_norm")(side), approximate=False)
        # offsets and modulation start at zero: the layer starts as a plain (dilated) 3x3 mean
        offset = nn.Dense(g * p * 2, kernel_init=nn.initializers.zeros, name="offset")(side)
        logits = nn.Dense(g * p, kernel_init=nn.initializers.zeros, name="mask")(side)
        mask = jax.nn.softmax(logits.reshape(b, h, w, g, p), axis=-1)
        sampled = deformable_sample(value.reshape(b, h, w, g, self.channels // g),
                                    offset.reshape(b, h, w, g, p, 2), mask, self.offset_scale, self.kernel)
        return nn.Dense(self.channels, kernel_init=xavier, name="output_proj")(sampled)

    def macs(self, in_shape, out_shape) -> int:
        """Projections, side branch, offset/mask heads and 4 bilinear taps per point and channel."""
        pixels, cin, c, p = math.prod(out_shape[:-1]), in_shape[-1], self.channels, self.kernel**2
        return pixels * (cin * c + cin * self.kernel**2 + cin * self.groups * p * 3 + c * p * 4 + c * c)
