"""CenterHead losses (RadarNeXt, after PillarNeXt), each normalised by the number of objects N in
the batch. Facts from the public RadarNeXt code (github Pay246-git468/RadarNeXt, commit 72676df):
projects/RadarNeXt/radarnext/radarnext_head.py and projects/PillarNeXt/pillarnext/loss.py.

- heatmap: CornerNet focal loss (alpha 2, beta 4) on sigmoid maps clamped to [1e-4, 1 - 1e-4];
- box: L1 on (offset, z, log sizes, sin, cos) at the objects' centre cells;
- IoU branch: L1 of the predicted IoU against 2 * IoU3D(decoded box, ground truth) - 1, with the
  decoded box detached (the branch learns to judge boxes, not to move them);
- dIoU: 1 - (IoU - d^2 / c^2) of axis-aligned 3D boxes (yaw ignored, as in the public code);
- corner heatmap: MSE where the target is above 0.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from ...boxes.center_decode import decode_codes as decode_at
from ...boxes.rotated_iou_jax import iou_3d_aligned

EPS = 1e-4


@dataclasses.dataclass(frozen=True)
class CenterLossConfig:
    hm_weight: float = 1.0
    box_weight: float = 1.0
    iou_weight: float = 1.0
    diou_weight: float = 0.5
    corner_weight: float = 1.0


def cornernet_focal_loss(logits, target, alpha: float = 2.0, beta: float = 4.0):
    """Summed focal loss and the number of positive (peak) cells."""
    p = jnp.clip(jax.nn.sigmoid(logits), EPS, 1 - EPS)
    pos = (target >= 1.0).astype(p.dtype)
    pos_loss = jnp.log(p) * (1 - p) ** alpha * pos
    neg_loss = jnp.log(1 - p) * p**alpha * (1 - target) ** beta * (1 - pos)
    return -(pos_loss.sum() + neg_loss.sum()), pos.sum()


def gather_cells(map_BxHxWxC, ind_BxK):
    b, h, w, c = map_BxHxWxC.shape
    return jnp.take_along_axis(map_BxHxWxC.reshape(b, h * w, c), ind_BxK[..., None], axis=1)


def axis_aligned_diou(pred_Kx7, gt_Kx7):
    """dIoU of 3D boxes with yaw ignored: extents l along x, w along y, h along z."""
    def extents(b):
        return jnp.stack([b[..., 4], b[..., 3], b[..., 5]], -1)
    pc, gc, pe, ge = pred_Kx7[..., :3], gt_Kx7[..., :3], extents(pred_Kx7), extents(gt_Kx7)
    lo, hi = jnp.maximum(pc - pe / 2, gc - ge / 2), jnp.minimum(pc + pe / 2, gc + ge / 2)
    inter = jnp.prod(jnp.clip(hi - lo, 0), -1)
    union = jnp.prod(pe, -1) + jnp.prod(ge, -1) - inter
    outer = jnp.maximum(pc + pe / 2, gc + ge / 2) - jnp.minimum(pc - pe / 2, gc - ge / 2)
    d2, c2 = jnp.sum((pc - gc) ** 2, -1), jnp.sum(outer**2, -1)
    return inter / jnp.maximum(union, 1e-6) - d2 / jnp.maximum(c2, 1e-6)


def center_head_loss(outputs: dict, targets: dict, model_cfg, cfg: CenterLossConfig = CenterLossConfig()):
    """(total loss, parts) for a batch of CenterHead outputs and `center_head_targets`."""
    grid, stride = model_cfg.grid, model_cfg.output_stride
    mask = targets["mask"].astype(jnp.float32)
    n = jnp.maximum(mask.sum(), 1.0)
    hm, _ = cornernet_focal_loss(outputs["hm"], targets["hm"])
    pred_code = gather_cells(jnp.concatenate([outputs[k] for k in ("reg", "height", "dim", "rot")], -1),
                             targets["ind"])
    box = (jnp.abs(pred_code - targets["box"]).sum(-1) * mask).sum() / n
    width = outputs["hm"].shape[2]
    default_origin = jnp.broadcast_to(jnp.array([grid.x_range[0], grid.y_range[0]]), (pred_code.shape[0], 2))
    origin = targets.get("origin", default_origin)
    decoded = decode_at(pred_code, targets["ind"], width, grid.cell * stride, origin)
    iou_target = 2 * iou_3d_aligned(jax.lax.stop_gradient(decoded), targets["gt_box"]) - 1
    pred_iou = gather_cells(outputs["iou"], targets["ind"])[..., 0]
    iou = (jnp.abs(pred_iou - iou_target) * mask).sum() / n
    diou = ((1 - axis_aligned_diou(decoded, targets["gt_box"])) * mask).sum() / n
    parts = {"hm": hm / n, "box": box, "iou": iou, "diou": diou}
    total = cfg.hm_weight * parts["hm"] + cfg.box_weight * box + cfg.iou_weight * iou + cfg.diou_weight * diou
    if "corner_hm" in outputs:
        on = (targets["corner_hm"] > 0).astype(jnp.float32)
        err = (jax.nn.sigmoid(outputs["corner_hm"]) - targets["corner_hm"]) ** 2
        parts["corner"] = (err * on).sum() / jnp.maximum(on.sum(), 1.0)
        total = total + cfg.corner_weight * parts["corner"]
    return total, parts
