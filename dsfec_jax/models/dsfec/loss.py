"""Detection losses for dense heads: sigmoid focal loss on class maps, smooth-L1 on box codes
at positive cells, each normalised by the number of positive cells of its head."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp


@dataclasses.dataclass(frozen=True)
class LossConfig:
    focal_alpha: float = 0.25
    focal_gamma: float = 2.0
    smooth_l1_beta: float = 1.0 / 9.0
    cls_weight: float = 1.0
    box_weight: float = 0.25  # PIXOR re-implementations weight the box term 0.1 (on normalised codes); 2.0 let it swamp the classifier
    head_weights: tuple[tuple[str, float], ...] = (("car", 1.0), ("truck", 1.0), ("vru", 1.0))


def sigmoid_focal_loss(logits, targets, alpha: float, gamma: float):
    """RetinaNet focal loss, elementwise; log-sigmoid form is stable for large |logits|."""
    p = jax.nn.sigmoid(logits)
    ce = -(targets * jax.nn.log_sigmoid(logits) + (1 - targets) * jax.nn.log_sigmoid(-logits))
    p_t = targets * p + (1 - targets) * (1 - p)
    alpha_t = targets * alpha + (1 - targets) * (1 - alpha)
    return alpha_t * (1 - p_t) ** gamma * ce


def smooth_l1(x, beta: float):
    ax = jnp.abs(x)
    return jnp.where(ax < beta, 0.5 * ax**2 / beta, ax - 0.5 * beta)


def head_loss(outputs: dict, targets: dict, cfg: LossConfig) -> dict:
    positives = jnp.maximum(targets["reg_mask"].sum(), 1.0)
    cls = sigmoid_focal_loss(outputs["cls"], targets["cls"], cfg.focal_alpha, cfg.focal_gamma).sum() / positives
    reg = smooth_l1(outputs["box"] - targets["box"], cfg.smooth_l1_beta).sum(-1)
    box = (reg * targets["reg_mask"]).sum() / positives
    return {"cls": cls, "box": box}


def detection_loss(outputs: dict, targets: dict, cfg: LossConfig) -> tuple[jax.Array, dict]:
    """Weighted sum over heads; returns (loss, per-head parts for logging)."""
    weights = dict(cfg.head_weights)
    parts, total = {}, 0.0
    for name, out in outputs.items():
        h = head_loss(out, targets[name], cfg)
        parts[f"{name}/cls"], parts[f"{name}/box"] = h["cls"], h["box"]
        total = total + weights.get(name, 1.0) * (cfg.cls_weight * h["cls"] + cfg.box_weight * h["box"])
    return total, parts
