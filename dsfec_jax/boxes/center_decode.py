"""Decode CenterHead maps into scored 3D boxes (jit-able; rotated NMS follows on the host).

Top-K over every class's sigmoid heatmap; at each picked cell (i, j):
x = (i + dx) * step + x_min, y = (j + dy) * step + y_min, z = the predicted centre height,
sizes = exp(log sizes), yaw = atan2(sin, cos); score = s^0.5 * ((iou + 1) / 2)^0.5, the
heatmap score rescored by the IoU branch (RadarNeXt / PillarNeXt). Boxes are (x, y, z, w, l, h,
yaw) with z the box centre (the public code's z - h / 2 is KITTI's bottom-centre convention).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def decode_center_head(outputs: dict, grid, stride: int, top_k: int = 500):
    """-> boxes (B, K, 7), scores (B, K), labels (B, K) int32."""
    hm = jax.nn.sigmoid(outputs["hm"])
    b, h, w, c = hm.shape
    heat, flat = jax.lax.top_k(hm.reshape(b, h * w * c), min(top_k, h * w * c))
    cell, labels = flat // c, flat % c

    def at(name):
        m = outputs[name]
        return jnp.take_along_axis(m.reshape(b, h * w, m.shape[-1]), cell[..., None], axis=1)

    reg, z, dims, rot, iou = at("reg"), at("height"), at("dim"), at("rot"), at("iou")[..., 0]
    step = grid.cell * stride
    i, j = (cell // w).astype(hm.dtype), (cell % w).astype(hm.dtype)
    x = (i + reg[..., 0]) * step + grid.x_range[0]
    y = (j + reg[..., 1]) * step + grid.y_range[0]
    size = jnp.exp(jnp.clip(dims, -5.0, 5.0))
    yaw = jnp.arctan2(rot[..., 0], rot[..., 1])
    boxes = jnp.concatenate([x[..., None], y[..., None], z, size, yaw[..., None]], -1)
    quality = (jnp.clip(iou, -1.0, 1.0) + 1) / 2
    return boxes, jnp.sqrt(heat) * jnp.sqrt(quality), labels.astype(jnp.int32)
