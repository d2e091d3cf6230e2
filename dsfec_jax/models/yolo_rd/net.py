"""The YOLO-on-RD detector: backbone (+ Adapter) -> PAN neck -> Detect head, for the YOLOv8, YOLOv9t
and YOLOv10n bases (`cfg.arch`, architectures.py).

inputs {'heat': (B, H, W, 3), 'gray': (B, H, W, 1)} (those `cfg.input_names` lists) -> a tuple of
raw head maps (B, H/s, W/s, 4 * reg_max + nc) for s = 8, 16, 32 (DFL bins first, then class
logits; decode with boxes/dfl.py and anchors at cell centres). YOLOv10 returns a dict of two such
tuples, {'one2many', 'one2one'} (head_v10.py); `inference_maps` picks the maps to decode.

Variables: {'params', 'batch_stats'} with subtrees 'backbone', 'neck', 'head' and, with the
Adapter, 'adapter'. The first three have the same names and shapes in YOLOv8 and in
YOLOv8-Adapter of the same scale and backbone input, so `with_base_weights` can copy one into
the other (and, gamma = alpha = 0 at init, the two then compute the same outputs).
"""

from __future__ import annotations

from typing import Any

import flax.linen as nn

from .adapter import Adapter
from .architectures import build_parts

SHARED_SUBTREES = ("backbone", "neck", "head")
STRIDE = 32  # the largest stride


class YoloRDNet(nn.Module):
    cfg: Any  # a YoloRDConfig (config.py imports this module to build the net, so it is not imported here)

    def setup(self):
        c = self.cfg
        self.backbone, self.neck, self.head = build_parts(c)
        if c.has_adapter:
            self.adapter = Adapter(c)

    def features(self, inputs: dict, train: bool = False):
        """(P3, P4, P5) of the backbone, with the Adapter's exchanges when the config has one."""
        image = inputs[self.cfg.backbone_input]
        if image.shape[1] % STRIDE or image.shape[2] % STRIDE:
            # the neck concatenates upsampled P5 with P4 (and P4 with P3): sizes must halve exactly
            raise ValueError(f"{self.cfg.name}: input {image.shape[1]}x{image.shape[2]} must be a multiple of "
                             f"{STRIDE} on both sides (pad the map; data/rd fit='pad' does)")
        if not self.cfg.has_adapter:
            return self.backbone(image, train)
        aux = {"x": self.adapter(inputs[self.cfg.adapter_input], train)}

        def exchange(layer, x):
            x, aux["x"] = self.adapter.exchange(layer, x, aux["x"], train)
            return x

        return self.backbone(image, train, exchange)

    def __call__(self, inputs: dict | None = None, train: bool = False, **maps):
        """Raw head maps of the representations in `inputs` ({name: map}), or given by name
        (`heat=..., gray=...`: how zoo.Detector passes every family's inputs)."""
        inputs = {**(inputs or {}), **maps}
        missing = [n for n in self.cfg.input_names if n not in inputs]
        if missing:
            raise ValueError(f"{self.cfg.name}: inputs {sorted(inputs)} lack {missing}; it reads {self.cfg.input_names}")
        return self.head(self.neck(self.features(inputs, train), train), train)

    # Stages for the profiler (modalities/rd/profile.py times each alone): `features`, then these
    # two. The Adapter runs inside `features` (its Exchangers are interleaved with the backbone's layers).
    def neck_outputs(self, feats, train: bool = False):
        """(N3, N4, N5) of the neck from the backbone's (P3, P4, P5)."""
        return self.neck(feats, train)

    def head_outputs(self, neck_feats, train: bool = False):
        """The raw head maps (as `__call__` returns them) from the neck's (N3, N4, N5)."""
        return self.head(neck_feats, train)


def inference_maps(outputs):
    """The head maps to decode: the tuple itself, or YOLOv10's one-to-one maps (its inference head)."""
    return outputs["one2one"] if isinstance(outputs, dict) else outputs


def with_base_weights(variables: dict, base_variables: dict) -> dict:
    """`variables` of an Adapter model with the backbone, neck and head of `base_variables` (a
    model without the Adapter, same scale and backbone input); the Adapter's own are kept."""
    out = {}
    for collection, tree in variables.items():
        tree = dict(tree)
        for name in SHARED_SUBTREES:
            if name in base_variables.get(collection, {}):
                tree[name] = base_variables[collection][name]
        out[collection] = tree
    return out
