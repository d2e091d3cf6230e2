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


def safe_arctan2(sin, cos):
    """atan2 whose gradient is finite at sin = cos = 0 (0 there). The losses decode every target
    slot, padding included, and a cell of an empty map can give exactly (0, 0): plain atan2's
    0/0 gradient there, times a zero mask, is still NaN and poisons the whole update."""
    degenerate = (sin == 0) & (cos == 0)
    return jnp.where(degenerate, 0.0, jnp.arctan2(sin, jnp.where(degenerate, 1.0, cos)))


def decode_codes(code_BxKx8, cell_BxK, width: int, step: float, origin_Bx2):
    """(x, y, z, w, l, h, yaw) of box codes (offset, z, log sizes, sin, cos) at flat cells
    i * width + j of a map whose cells are `step` metres, per-sample origin (x_min, y_min)."""
    i, j = (cell_BxK // width).astype(code_BxKx8.dtype), (cell_BxK % width).astype(code_BxKx8.dtype)
    origin = jnp.asarray(origin_Bx2, code_BxKx8.dtype)
    x = (i + code_BxKx8[..., 0]) * step + origin[:, 0:1]
    y = (j + code_BxKx8[..., 1]) * step + origin[:, 1:2]
    size = jnp.exp(jnp.clip(code_BxKx8[..., 3:6], -5.0, 5.0))  # bounded: a wild early step cannot overflow
    yaw = safe_arctan2(code_BxKx8[..., 6], code_BxKx8[..., 7])
    return jnp.concatenate([x[..., None], y[..., None], code_BxKx8[..., 2:3], size, yaw[..., None]], -1)


def decode_center_head(outputs: dict, grid, stride: int, top_k: int = 500):
    """-> boxes (B, K, 7), scores (B, K), labels (B, K) int32."""
    hm = jax.nn.sigmoid(outputs["hm"])
    b, h, w, c = hm.shape
    heat, flat = jax.lax.top_k(hm.reshape(b, h * w * c), min(top_k, h * w * c))
    cell, labels = flat // c, flat % c

    def at(name):
        m = outputs[name]
        return jnp.take_along_axis(m.reshape(b, h * w, m.shape[-1]), cell[..., None], axis=1)

    code = jnp.concatenate([at("reg"), at("height"), at("dim"), at("rot")], -1)
    iou = at("iou")[..., 0]
    origin = jnp.broadcast_to(jnp.array([grid.x_range[0], grid.y_range[0]], hm.dtype), (b, 2))
    boxes = decode_codes(code, cell, w, grid.cell * stride, origin)
    quality = (jnp.clip(iou, -1.0, 1.0) + 1) / 2
    return boxes, jnp.sqrt(heat) * jnp.sqrt(quality), labels.astype(jnp.int32)
