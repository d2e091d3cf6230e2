"""The YOLOv8 (legacy) Detect head: per level a box branch and a class branch, no shared weights.

Facts from ultralytics/ultralytics:ultralytics/nn/modules/head.py (the code here is ours):
- box branch: Conv 3x3 (c2), Conv 3x3 (c2), 1x1 conv with bias to 4 * reg_max, with
  c2 = max(16, ch0 // 4, 4 * reg_max);
- class branch: Conv 3x3 (c3), Conv 3x3 (c3), 1x1 conv with bias to nc, c3 = max(ch0, min(nc, 100))
  (the legacy form YOLOv8's published counts use; newer releases put depthwise convs here:
  `light_classes`, which v10Detect uses, head_v10.py);
- Detect.bias_init: box biases 1.0 in ultralytics 8.0-8.3 (2.0 in later releases; a config
  field), class biases log(5 / nc / (640 / stride)^2) (".01 objects, 80 classes, 640 img").
Output per level: (B, H/s, W/s, 4 * reg_max + nc), box bins first, as ultralytics concatenates.
The DFL decode (boxes/dfl.py) has no trainable weights and is not part of this module.
"""

from __future__ import annotations

import math

import flax.linen as nn
import jax.numpy as jnp

from ...layers.yolo import PaddedConv, YoloConv
from ...layers.yolo_v10 import YoloDWConv
from .layout import scaled_width


def class_bias(num_classes: int, stride: int) -> float:
    """Prior logit for 5 objects per 640x640 image spread over the level's cells and the classes."""
    return math.log(5 / num_classes / (640 / stride) ** 2)


def branch_widths(ch0: int, num_classes: int, reg_max: int) -> tuple[int, int]:
    """(box branch c2, class branch c3) from the first level's channels."""
    return max(16, ch0 // 4, 4 * reg_max), max(ch0, min(num_classes, 100))


def full_conv(width: int, name: str):
    """Detect's branch Conv: Conv 3x3 to `width`."""
    return YoloConv(width, 3, name=name)


def light_conv(width: int, name: str):
    """v10Detect's class-branch Conv (head_v10.py): depthwise Conv 3x3 `<name>_dw`, then Conv 1x1
    `<name>_pw` to `width`, both with SiLU (siblings in the head, as ultralytics' Sequential)."""
    return lambda x, train: YoloConv(width, 1, name=f"{name}_pw")(YoloDWConv(3, name=f"{name}_dw")(x, train), train)


def branch(x, conv, width: int, outputs: int, bias: float, name: str, train: bool):
    """`conv(width, name)` twice (`<name>_0`, `<name>_1`), then `<name>_out`: 1x1 conv with bias to
    `outputs`, the bias initialised to `bias`. Call it inside a compact method."""
    for j in range(2):
        x = conv(width, f"{name}_{j}")(x, train)
    return PaddedConv(outputs, 1, use_bias=True, bias_init=nn.initializers.constant(bias), name=f"{name}_out")(x)


class DetectHead(nn.Module):
    num_classes: int
    reg_max: int = 16
    strides: tuple[int, ...] = (8, 16, 32)
    box_bias: float = 1.0
    light_classes: bool = False  # v10Detect's class branch (`light_conv`) instead of Detect's
    # elastic widths (config.py): each level's branch widths are the full model's (from its first
    # level's width `full_ch0`) times the level's ratio; None: ultralytics' rule on the inputs
    width_ratios: tuple[float, ...] | None = None
    full_ch0: int | None = None

    @nn.compact
    def __call__(self, feats, train: bool = False):
        c2, c3 = branch_widths(self.full_ch0 or feats[0].shape[-1], self.num_classes, self.reg_max)
        ratios = self.width_ratios or (1.0,) * len(feats)
        cls_conv = light_conv if self.light_classes else full_conv
        outs = []
        for i, (x, stride, r) in enumerate(zip(feats, self.strides, ratios)):
            box = branch(x, full_conv, scaled_width(c2, r), 4 * self.reg_max, self.box_bias, f"box{i}", train)
            cls = branch(x, cls_conv, scaled_width(c3, r), self.num_classes, class_bias(self.num_classes, stride),
                         f"cls{i}", train)
            outs.append(jnp.concatenate([box, cls], axis=-1))
        return tuple(outs)
