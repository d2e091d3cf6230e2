"""Head maps -> scored oriented boxes (jittable): sigmoid scores, PIXOR decode, top-k per head.

NMS runs on the host afterwards (`boxes.nms`), as in the field's deploy tools.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from . import pixor


def decode_head(cls_HxWxC, box_HxWx6, cell_xy_HxWx2, top_k: int):
    """One head of one frame -> (boxes (K, 5) as x, y, w, l, yaw; scores (K,); class idx (K,))."""
    h, w, c = cls_HxWxC.shape
    scores = jax.nn.sigmoid(cls_HxWxC).reshape(-1)
    k = min(top_k, scores.shape[0])
    top, idx = jax.lax.top_k(scores, k)
    cell, label = idx // c, idx % c
    code = box_HxWx6.reshape(-1, box_HxWx6.shape[-1])[cell]
    centre, size, yaw = pixor.decode(code, jnp.asarray(cell_xy_HxWx2).reshape(-1, 2)[cell], xp=jnp)
    return jnp.concatenate([centre, size, yaw[:, None]], -1), top, label


def decode_heads(outputs: dict, head_classes: dict, cell_xy, top_k: int = 100):
    """Batched: {head: {'cls', 'box'}} -> boxes (B, K, 5), scores (B, K), labels (B, K) where
    labels index the concatenation of the heads' class tuples (in `head_classes` order)."""
    boxes, scores, labels, offset = [], [], [], 0
    for name, classes in head_classes.items():
        out = outputs[name]
        b, s, l = jax.vmap(lambda c, x: decode_head(c, x, cell_xy, top_k))(out["cls"], out["box"])
        boxes.append(b), scores.append(s), labels.append(l + offset)
        offset += len(classes)
    return jnp.concatenate(boxes, 1), jnp.concatenate(scores, 1), jnp.concatenate(labels, 1)
