"""PointPillars pillar feature net and the scatter to a BEV pseudo-image.

Inputs are fixed-size masked tensors so everything jits:
  points_BxPxNxF : raw per-point features (columns named by the config, x, y, z first)
  mask_BxPxN     : True where a point slot holds a real point
  coords_BxPx2   : integer (ix, iy) cell of each pillar, -1 for an unused pillar slot
"""

from __future__ import annotations

import flax.linen as nn
import jax.numpy as jnp

from ..core.grid import Grid
from .activations import activation
from .conv import Kernels, PointLinear, batch_norm
from .fec import FEC

NEG = -1e9  # masked-out points never win the max; finite so gradients stay finite


def decorate_points(points_BxPxNxF, mask_BxPxN, coords_BxPx2, grid: Grid, origin_Bx2=None):
    """Append offsets to the pillar's point mean (3) and to the pillar centre (3). `origin_Bx2`
    (traced) replaces the grid's (x_min, y_min) per sample: one compiled network then serves
    every training window of the same shape."""
    m = mask_BxPxN[..., None].astype(points_BxPxNxF.dtype)
    xyz = points_BxPxNxF[..., :3]
    count = jnp.maximum(m.sum(axis=2, keepdims=True), 1.0)
    mean_xyz = (xyz * m).sum(axis=2, keepdims=True) / count
    origin = (jnp.array([grid.x_range[0], grid.y_range[0]], xyz.dtype) if origin_Bx2 is None
              else origin_Bx2[:, None, :].astype(xyz.dtype))
    centre_xy = (coords_BxPx2.astype(xyz.dtype) + 0.5) * grid.cell + origin
    centre = jnp.concatenate([centre_xy, jnp.full_like(centre_xy[..., :1], grid.z_center)], -1)
    feats = jnp.concatenate([points_BxPxNxF, xyz - mean_xyz, xyz - centre[:, :, None, :]], -1)
    return feats * m  # padding slots are exactly zero


def masked_max(h_BxPxNxC, mask_BxPxN):
    """Max over a pillar's real points; an empty pillar gives zeros."""
    h = jnp.where(mask_BxPxN[..., None], h_BxPxNxC, NEG).max(axis=2)
    return jnp.where(mask_BxPxN.any(axis=2)[..., None], h, 0.0)


class PointPillarsEncoder(nn.Module):
    """The original PointPillars encoder: linear (no bias) + BN over real points + act."""

    features: int = 32
    act: str = "relu"
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x_BxPxNxD, mask_BxPxN, train: bool = False):
        x = PointLinear(self.features, use_bias=False, kernels=self.kernels, name="linear")(x_BxPxNxD)
        # a batch without a single point (a training window outside a narrow field of view)
        # would give BN statistics of 0/0 = NaN: let it see the zero slots instead
        bn_mask = jnp.where(mask_BxPxN.any(), mask_BxPxN, True)
        x = batch_norm(train, "bn")(x, mask=bn_mask[..., None])
        return activation(self.act)(x)


class PillarFeatureNet(nn.Module):
    """Decorate points, encode each point (FEC or PointPillars), max over each pillar."""

    grid: Grid
    encoder: str = "fec"  # "fec" | "pointpillars"
    filters: tuple[int, ...] = (32, 128, 12)
    act: str = "relu"
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, points_BxPxNxF, mask_BxPxN, coords_BxPx2, train: bool = False, origin_Bx2=None):
        x = decorate_points(points_BxPxNxF, mask_BxPxN, coords_BxPx2, self.grid, origin_Bx2)
        if self.encoder == "fec":
            h = FEC(tuple(self.filters), self.act, self.kernels, name="fec")(x, mask_BxPxN, train)
        elif self.encoder == "pointpillars":
            h = PointPillarsEncoder(self.filters[-1], self.act, self.kernels, name="pointpillars")(x, mask_BxPxN, train)
        else:
            raise ValueError(f"encoder={self.encoder!r}; valid: 'fec', 'pointpillars'")
        return masked_max(h, mask_BxPxN)


def scatter_to_bev(pillars_BxPxC, coords_BxPx2, grid: Grid):
    """Place pillar features at their cells: (B, nx, ny, C). Unused slots go to a spill cell."""
    b, p, c = pillars_BxPxC.shape
    nx, ny = grid.shape
    ix, iy = coords_BxPx2[..., 0], coords_BxPx2[..., 1]
    valid = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
    flat = jnp.where(valid, ix * ny + iy, nx * ny)  # index nx*ny is the spill cell
    flat = flat + jnp.arange(b)[:, None] * (nx * ny + 1)
    canvas = jnp.zeros((b * (nx * ny + 1), c), pillars_BxPxC.dtype)
    canvas = canvas.at[flat.reshape(-1)].set(pillars_BxPxC.reshape(-1, c))
    return canvas.reshape(b, nx * ny + 1, c)[:, : nx * ny].reshape(b, nx, ny, c)
