"""YOLOv3's detection layers with their FPN, shared by both backbones: the backbone's (C3, C4, C5)
at strides 8, 16, 32 -> three raw maps (B, H/s, W/s, num_anchors, 5 + num_classes), stride 8 first.

The scaffold (pjreddie/darknet:cfg/yolov3-voc.cfg layers 75-106), coarsest level first:
  x = C5;  for each level, from stride 32 down to 8:
    branch, out = level block(x)                  (`level<l>`)
    map = 1x1 conv with bias to A (5 + C)         (`out<l>`; reshaped to (A, 5 + C): darknet's
                                                   anchor-major channel layout)
    lateral = 1x1 conv + BN + act (branch)        (`lateral<l>`, toward the finer level)
    x = merge(upsample x2 (lateral), next tap)    (`merge<l>`: concat [up, tap] as darknet's
                                                   `[route] layers = -1, 61`, or add)
Level <l> counts strides 8, 16, 32 as 0, 1, 2. What differs between the two models is the level
block (net.py's table names one per backbone):
- Darknet53-YOLOv3 (`DarknetLevel`): five convs 1x1 w/2, 3x3 w, 1x1 w/2, 3x3 w, 1x1 w/2 (the
  branch, read by the route), then 3x3 w (out); laterals to half the next level's width (256, 128).
- Shuffle-YOLOv3 (`ShuffleLevel`): 1x1 conv + BN + act to w (the entry), `head_units` stride-1
  shuffle units (the branch, also the out); laterals to half the next width (concat) or to the
  tap's width (add).
"""

from __future__ import annotations

import math
from typing import Any, Callable

import flax.linen as nn
import jax.numpy as jnp
import numpy as np

from ...layers.blocks import ConvBNAct
from ...layers.conv import Conv
from ...layers.shufflenet import ShuffleUnit
from ...layers.yolo import upsample_nearest


def output_bias(num_anchors: int, num_classes: int, stride: int, prior: bool) -> np.ndarray:
    """Initial biases of a level's output conv, (A (5 + C),): zeros (darknet) or, with `prior`,
    ultralytics/yolov3's: objectness log(8 / (640 / s)^2), classes log(0.6 / (C - 0.99))."""
    b = np.zeros((num_anchors, 5 + num_classes), np.float32)
    if prior:
        b[:, 4] = math.log(8 / (640 / stride) ** 2)
        b[:, 5:] = math.log(0.6 / (num_classes - 0.99))
    return b.reshape(-1)


def constant_init(values: np.ndarray) -> nn.initializers.Initializer:
    def init(key, shape, dtype=jnp.float32):
        return jnp.asarray(values, dtype).reshape(shape)

    return init


class DarknetLevel(nn.Module):
    """YOLOv3's five-conv set and its 3x3 conv: x -> (branch at width / 2, out at width)."""

    width: int
    act: str = "leaky_relu"
    kernels: str = "auto"

    @nn.compact
    def __call__(self, x, train: bool = False):
        for i in range(5):
            wide = i % 2 == 1
            x = ConvBNAct(self.width if wide else self.width // 2, 3 if wide else 1, 1, self.act, self.kernels,
                          name=f"conv{i}")(x, train)
        return x, ConvBNAct(self.width, 3, 1, self.act, self.kernels, name="conv5")(x, train)


class ShuffleLevel(nn.Module):
    """Shuffle-YOLOv3's YOLO layer: 1x1 conv + BN + act to `width`, then `units` stride-1 shuffle
    units; x -> (branch, out), the same map."""

    width: int
    units: int = 3
    kernel: int = 5
    act: str = "hard_swish"
    split: str = "chunk"
    depthwise_impl: str = "shifted"
    kernels: str = "auto"

    @nn.compact
    def __call__(self, x, train: bool = False):
        x = ConvBNAct(self.width, 1, 1, self.act, self.kernels, name="entry")(x, train)
        for i in range(self.units):
            x = ShuffleUnit(self.width, 1, self.kernel, self.act, self.split, self.depthwise_impl, self.kernels,
                            name=f"unit{i}")(x, train)
        return x, x


def darknet_level(cfg, level: int, name: str) -> nn.Module:
    return DarknetLevel(cfg.head_widths[level], cfg.act, cfg.kernels, name=name)


def shuffle_level(cfg, level: int, name: str) -> nn.Module:
    kernel, act = cfg.head_style(level)
    return ShuffleLevel(cfg.head_widths[level], cfg.head_units, kernel, act, cfg.split, cfg.depthwise_impl,
                        cfg.kernels, name=name)


def lateral_width(cfg, level: int, tap_width: int) -> int:
    """Width of the lateral into finer level `level`: half that level's width (YOLOv3's 256 and 128)
    to concatenate, the tap's width to add."""
    return cfg.head_widths[level] // 2 if cfg.fpn_merge == "concat" else tap_width


class FpnMerge(nn.Module):
    """Upsample the lateral x2 (nearest) and concatenate [up, tap] (darknet's route order) or add."""

    mode: str = "concat"

    @nn.compact
    def __call__(self, lateral, tap):
        up = upsample_nearest(lateral, 2)
        return jnp.concatenate([up, tap], axis=-1) if self.mode == "concat" else up + tap


class YoloV3Head(nn.Module):
    """(C3, C4, C5) -> raw maps at strides 8, 16, 32 (module docstring); `level(cfg, l, name)` builds
    level l's block."""

    cfg: Any  # a CameraConfig (config.py imports the net to build it, so the net never imports config.py)
    level: Callable[[Any, int, str], nn.Module]

    @nn.compact
    def __call__(self, feats, train: bool = False):
        c = self.cfg
        a, n_out = c.num_anchors, c.outputs_per_anchor
        maps: list = [None] * len(feats)
        x, block = feats[-1], None
        for lv in reversed(range(len(feats))):
            if block is not None:  # the lateral takes the activation of the level it leaves
                lat = lateral_width(c, lv, feats[lv].shape[-1])
                lateral = ConvBNAct(lat, 1, 1, block.act, c.kernels, name=f"lateral{lv}")(branch, train)
                x = FpnMerge(c.fpn_merge, name=f"merge{lv}")(lateral, feats[lv])
            block = self.level(c, lv, f"level{lv}")
            branch, out = block(x, train)
            bias = output_bias(a, c.num_classes, c.strides[lv], c.prior_bias)
            y = Conv(a * n_out, 1, use_bias=True, bias_init=constant_init(bias), kernels=c.kernels,
                     name=f"out{lv}")(out)
            maps[lv] = y.reshape(*y.shape[:-1], a, n_out)
        return tuple(maps)
