"""The PAN neck of every base, and YOLOv8's blocks for it (ultralytics yolov8.yaml `head` layers
10-21): top-down with nearest upsampling and concatenation, then bottom-up with stride-2 Convs; its
C2f blocks have no shortcut. Modules carry ultralytics' layer indices; concatenation order as the
YAML ([-1, skip]). neck_v9.py and neck_v10.py give `PanNeck` their own blocks."""

from __future__ import annotations

import functools
from typing import Any, Callable

import flax.linen as nn
import jax.numpy as jnp

from ...layers.yolo import C2f, YoloConv, upsample_nearest


def _cat(*xs):
    return jnp.concatenate(xs, axis=-1)


class PanNeck(nn.Module):
    """(P3, P4, P5) of the backbone -> (N3, N4, N5), the Detect head's inputs.

    `stages(cfg)` names the six modules, in the order they run: the top-down block at P4, the
    top-down block at P3 (N3), the downsampler from N3, the bottom-up block at P4 (N4), the
    downsampler from N4, the bottom-up block at P5 (N5)."""

    cfg: Any  # a YoloRDConfig (config.py imports the net to build it, so the net never imports config.py)
    stages: Callable[[Any], tuple[nn.Module, ...]]

    @nn.compact
    def __call__(self, feats, train: bool = False):
        p3, p4, p5 = feats
        top4, top3, down3, bottom4, down4, bottom5 = self.stages(self.cfg)
        h4 = top4(_cat(upsample_nearest(p5), p4), train)
        n3 = top3(_cat(upsample_nearest(h4), p3), train)
        n4 = bottom4(_cat(down3(n3, train), h4), train)
        n5 = bottom5(_cat(down4(n4, train), p5), train)
        return n3, n4, n5


def yolov8_neck_stages(cfg) -> tuple[nn.Module, ...]:
    w, n = cfg.neck_width, cfg.repeats(3)
    return (C2f(w(12, 512), n, name="layer12"), C2f(w(15, 256), n, name="layer15"),
            YoloConv(w(16, 256), 3, 2, name="layer16"), C2f(w(18, 512), n, name="layer18"),
            YoloConv(w(19, 512), 3, 2, name="layer19"), C2f(w(21, 1024), n, name="layer21"))


YoloNeck = functools.partial(PanNeck, stages=yolov8_neck_stages)
