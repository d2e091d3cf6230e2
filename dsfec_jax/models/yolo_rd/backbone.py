"""The YOLOv8 backbone, layer for layer as ultralytics/ultralytics:ultralytics/cfg/models/v8/yolov8.yaml.

Layers are named `layer<i>` with ultralytics' indices, so a weight map or a reader of the YAML
finds them. An optional `exchange(i, x) -> x` hook runs after every layer: the Adapter (adapter.py)
uses it to fuse its branch into the backbone, and without it this is plain YOLOv8. `Backbone` is
that loop for every base (backbone_v9.py and backbone_v10.py give it their own layer tables).
"""

from __future__ import annotations

import functools
from typing import Any, Callable

import flax.linen as nn

from ...layers.yolo import C2f, SPPF, YoloConv

# (module, yaml channels, yaml repeats, stride) of yolov8.yaml's backbone, layers 0-9
BACKBONE = (
    ("conv", 64, 1, 2),  # 0 P1/2
    ("conv", 128, 1, 2),  # 1 P2/4
    ("c2f", 128, 3, 1),  # 2
    ("conv", 256, 1, 2),  # 3 P3/8
    ("c2f", 256, 6, 1),  # 4
    ("conv", 512, 1, 2),  # 5 P4/16
    ("c2f", 512, 6, 1),  # 6
    ("conv", 1024, 1, 2),  # 7 P5/32
    ("c2f", 1024, 3, 1),  # 8
    ("sppf", 1024, 1, 1),  # 9
)
PYRAMID_LAYERS = (4, 6, 9)  # P3, P4, P5: what the neck reads


# a table's module kinds, each from (scaled width, scaled repeats, stride, name)
YOLOV8_MODULES = {
    "conv": lambda c, n, s, name: YoloConv(c, 3, s, name=name),
    "c2f": lambda c, n, s, name: C2f(c, n, shortcut=True, name=name),
    "sppf": lambda c, n, s, name: SPPF(c, 5, name=name),
}


def scaled_layer(table: tuple, modules: dict, cfg, index: int) -> nn.Module:
    """Layer `index` of a (kind, yaml channels, yaml repeats, stride) table at `cfg`'s scale."""
    kind, channels, repeats, stride = table[index]
    return modules[kind](cfg.backbone_width(index, channels), cfg.repeats(repeats), stride, f"layer{index}")


backbone_layer = functools.partial(scaled_layer, BACKBONE, YOLOV8_MODULES)


class Backbone(nn.Module):
    """Image (B, H, W, C) -> (P3, P4, P5) at strides 8, 16, 32: `layer(cfg, i)` for i < depth in
    order, `exchange(i, x)` after each (the Adapter's hook), the `pyramid` layers' outputs."""

    cfg: Any  # a YoloRDConfig (config.py imports the net to build it, so the net never imports config.py)
    layer: Callable[[Any, int], nn.Module]
    depth: int
    pyramid: tuple[int, int, int]

    @nn.compact
    def __call__(self, x, train: bool = False, exchange: Callable | None = None):
        outs = []
        for i in range(self.depth):
            x = self.layer(self.cfg, i)(x, train)
            if exchange is not None:
                x = exchange(i, x)
            outs.append(x)
        return tuple(outs[i] for i in self.pyramid)


YoloBackbone = functools.partial(Backbone, layer=backbone_layer, depth=len(BACKBONE), pyramid=PYRAMID_LAYERS)
