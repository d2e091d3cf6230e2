"""Every knob of a camera YOLOv3 detector: Shuffle-YOLOv3 (the paper, ../shared/papers/
shuffle_yolov3_edge.txt, Table 1) and the Darknet53-YOLOv3 baseline (pjreddie/darknet:cfg/yolov3-voc.cfg).

`backbone` picks the kind ('shuffle' | 'darknet53'); net.py maps each kind to its backbone and to
the blocks of the shared YOLOv3 head (yolo3_neck_head.py). Both output, per stride 8 / 16 / 32,
raw maps (B, H/s, W/s, num_anchors, 5 + num_classes) = [tx, ty, tw, th, objectness, classes].

Shuffle-YOLOv3: the paper gives Table 1 (repeats 1-2-6-6-4, widths 64-128-192-256-384, YOLO layers
yolo(3-3-3) at widths 384-256-192, shuffle blocks everywhere, 5x5 depthwise and h-swish "in the deep
layers"); its Figs. 3-4 (the exact layout) are missing. Each choice below is a field; defaults and why:
- `first_repeat` 'stem': Table 1's first "1" (width 64) is a 3x3 stride-2 conv + BN + act to
  widths[0], as ShuffleNetV2's own column ("1-4-8-4-1", width 24) counts Conv1. No max-pool after
  it (ShuffleNetV2's Conv1 has one): with it the five stages would end at stride 64, and the three
  YOLO layers at widths 384/256/192 could not sit on the stride-32/16/8 stages of widths 384/256/
  192. 'unit': darknet's arrangement instead (its first "1" is one residual block at stride 2):
  a 3x3 stride-1 conv to `stem_width` at full resolution, then repeats[0] shuffle units.
- stages 2-5 (repeats 2-6-6-4) each open with one stride-2 unit and count it, ShuffleNetV2's
  convention ("4-8-4" include the stride-2 unit); stride-2 units at every stage keep darknet's
  scales: stage widths 64/128/192/256/384 at strides 2/4/8/16/32, taps at 8/16/32. "We reduce four
  layers in the middle part of the backbone": darknet's 8-8 become 6-6.
- the YOLO layers (`head_widths`, ordered by stride 8/16/32 = 192/256/384, Table 1 lists them
  32 first): per level a 1x1 conv + BN + act to the width (the entry: mixes the concatenated maps
  before the first split), `head_units` (3: "yolo(3-3-3)") stride-1 shuffle units, the output 1x1
  conv with bias. No 3x3 dense conv before the output (YOLOv3's has one): the units are the
  level's convolutions.
- `fpn_merge` 'concat': YOLOv3's route: the level's branch -> 1x1 conv + BN + act to half the
  next level's width (darknet: 512 -> 256, 256 -> 128), nearest upsample x2, concatenated
  [upsampled, backbone tap] as darknet's `[route] layers = -1, 61`. 'add': the public
  ShuffleNetV2-YOLOv3 (CnybTseng/YOLOv3) adds instead; the lateral then goes to the tap's width.
- `deep_stages` / `deep_heads`: which layers are "deep" (5x5 depthwise `deep_kernel` and
  `deep_act` h-swish; the others use `kernel` 3 and `act` ReLU, ShuffleNetV2's). Default: the
  stride-16 and stride-32 backbone stages and all three YOLO layers (they run after the whole
  backbone), as MobileNetV3 (the paper's source of h-swish) uses h-swish from its stride-16
  layers on. The stem and stages 1-3 keep ReLU and 3x3.
- `split` 'chunk' (torchvision's split and shuffle; 'even_odd' is megvii's, layers/shufflenet.py).
Darknet53-YOLOv3 reads `widths`, `repeats`, `stem_width`, `act` and `head_widths` (its 3x3
widths per level; 1x1 convs at half); the shuffle-only fields are ignored.

Output biases (`prior_bias`): darknet starts them at 0; True uses ultralytics/yolov3's
`_initialize_biases` priors instead: objectness log(8 / (640 / s)^2) ("8 objects per 640 image"),
classes log(0.6 / (nc - 0.99)); box biases stay 0.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...layers.kernels import KERNELS
from .layout import INPUT, STAGES, STRIDES

# PASCAL VOC's 20 classes in the order of darknet's data/voc.names (and py-faster-rcnn); models/ may
# not import data/, so the tuple lives here (data/camera/voc.py names the same classes).
VOC_CLASSES = ("aeroplane", "bicycle", "bird", "boat", "bottle", "bus", "car", "cat", "chair", "cow",
               "diningtable", "dog", "horse", "motorbike", "person", "pottedplant", "sheep", "sofa",
               "train", "tvmonitor")
BACKBONES = ("shuffle", "darknet53")
FIRST_REPEATS = ("stem", "unit")
FPN_MERGES = ("concat", "add")


@dataclasses.dataclass(frozen=True)
class CameraConfig:
    name: str = "shuffle_yolov3"
    backbone: str = "shuffle"  # 'shuffle' | 'darknet53' (net.py's table)
    num_classes: int = 20  # VOC
    # class names in logit order; () names them by num_classes (VOC's 20, else class0..). A model
    # trained on the street benchmark carries its 5 names (the train command sets both fields)
    class_names: tuple[str, ...] = ()
    num_anchors: int = 3  # anchors per scale (YOLOv3: 9 over 3 scales)
    # backbone: five stages at strides 2, 4, 8, 16, 32 (Table 1 columns)
    widths: tuple[int, ...] = (64, 128, 192, 256, 384)
    repeats: tuple[int, ...] = (1, 2, 6, 6, 4)
    first_repeat: str = "stem"  # shuffle: 'stem' | 'unit' (module docstring)
    stem_width: int = 32  # darknet's stem conv; shuffle with first_repeat 'unit' only
    # YOLO layers, ordered by stride (8, 16, 32): the width each level works at
    head_widths: tuple[int, ...] = (192, 256, 384)
    head_units: int = 3  # shuffle units per YOLO layer ("yolo(3-3-3)")
    fpn_merge: str = "concat"  # 'concat' (YOLOv3's route) | 'add' (CnybTseng's)
    # shuffle units: plain and deep layers
    kernel: int = 3
    act: str = "relu"  # darknet53: 'leaky_relu' (slope 0.1)
    deep_kernel: int = 5
    deep_act: str = "hard_swish"
    deep_stages: tuple[bool, ...] = (False, False, False, True, True)  # per backbone stage (stride 2..32)
    deep_heads: tuple[bool, ...] = (True, True, True)  # per YOLO layer (stride 8, 16, 32)
    split: str = "chunk"  # 'chunk' (torchvision) | 'even_odd' (megvii)
    prior_bias: bool = True  # output biases: ultralytics' priors (True) or darknet's zeros
    depthwise_impl: str = "shifted"  # "shifted" (fast jitted CPU) | "grouped" (ONNX export)
    kernels: str = "auto"  # "auto" (the CPU training formulations on the CPU) | "fast" | "plain" (layers/kernels.py)
    notes: str = ""

    def __post_init__(self):
        validate(self)

    @property
    def classes(self) -> tuple[str, ...]:
        """Class names: `class_names` when given, else VOC's at 20 classes, else class0..class{n-1}."""
        if self.class_names:
            return tuple(self.class_names)
        return VOC_CLASSES if self.num_classes == len(VOC_CLASSES) else tuple(
            f"class{i}" for i in range(self.num_classes))

    @property
    def strides(self) -> tuple[int, ...]:
        return STRIDES

    @property
    def outputs_per_anchor(self) -> int:
        """The last axis of each head map: tx, ty, tw, th, objectness, then the class logits."""
        return 5 + self.num_classes

    @property
    def input_names(self) -> tuple[str, ...]:
        return (INPUT,)

    def stage_style(self, stage: int) -> tuple[int, str]:
        """(depthwise kernel, activation) of backbone stage `stage` (0-4)."""
        return (self.deep_kernel, self.deep_act) if self.deep_stages[stage] else (self.kernel, self.act)

    def head_style(self, level: int) -> tuple[int, str]:
        """(depthwise kernel, activation) of YOLO layer `level` (0-2: strides 8, 16, 32)."""
        return (self.deep_kernel, self.deep_act) if self.deep_heads[level] else (self.kernel, self.act)

    def build(self):
        from .net import CameraNet  # here: the net's modules load only when a network is built

        return CameraNet(self)

    def dummy_inputs(self, batch_size: int = 1, seed: int = 0, occupancy: float | None = None,
                     hw: tuple[int, int] = (416, 416)) -> dict:
        """Random images in [0, 1]: {'image': (B, H, W, 3)}. (`occupancy` means nothing for images.)"""
        rng = np.random.default_rng(seed)
        return {INPUT: rng.random((batch_size, *hw, 3), dtype=np.float32)}


def validate(cfg: CameraConfig) -> None:
    """Fail early, naming the field and what was expected."""
    def need(ok, field, expected):
        if not ok:
            raise ValueError(f"{cfg.name}: {field}={getattr(cfg, field)!r}; expected {expected}")

    need(cfg.backbone in BACKBONES, "backbone", f"one of {BACKBONES}")
    need(int(cfg.num_classes) >= 1, "num_classes", "at least 1")
    need(int(cfg.num_anchors) >= 1, "num_anchors", "at least 1")
    need(not cfg.class_names or (len(cfg.class_names) == cfg.num_classes
                                 and len(set(cfg.class_names)) == len(cfg.class_names)), "class_names",
         f"() or {cfg.num_classes} distinct names (one per class: num_classes)")
    need(len(cfg.widths) == STAGES and all(int(w) >= 2 for w in cfg.widths), "widths", f"{STAGES} widths")
    need(len(cfg.repeats) == STAGES and all(int(r) >= 1 for r in cfg.repeats), "repeats", f"{STAGES} repeats >= 1")
    need(len(cfg.head_widths) == len(STRIDES) and all(int(w) >= 4 for w in cfg.head_widths), "head_widths",
         f"{len(STRIDES)} widths, ordered by stride {STRIDES}")
    need(cfg.fpn_merge in FPN_MERGES, "fpn_merge", f"one of {FPN_MERGES}")
    need(cfg.depthwise_impl in ("shifted", "grouped"), "depthwise_impl", "'shifted' or 'grouped'")
    need(cfg.kernels in KERNELS, "kernels", " or ".join(map(repr, KERNELS)))
    if cfg.backbone != "shuffle":
        return
    need(cfg.first_repeat in FIRST_REPEATS, "first_repeat", f"one of {FIRST_REPEATS}")
    need(cfg.first_repeat != "stem" or cfg.repeats[0] == 1, "repeats", "repeats[0] == 1 when the first "
         "repeat is the stem conv (first_repeat 'stem')")
    need(all(int(w) % 2 == 0 for w in cfg.widths[1:]) and (cfg.first_repeat == "stem" or cfg.widths[0] % 2 == 0),
         "widths", "even widths for the shuffle stages (two branches)")
    need(all(int(w) % 2 == 0 for w in cfg.head_widths), "head_widths", "even widths (shuffle units)")
    need(int(cfg.head_units) >= 0, "head_units", ">= 0")
    need(cfg.kernel % 2 == 1 and cfg.deep_kernel % 2 == 1, "kernel", "odd depthwise kernels (kernel, deep_kernel)")
    need(len(cfg.deep_stages) == STAGES, "deep_stages", f"{STAGES} flags, one per backbone stage")
    need(len(cfg.deep_heads) == len(STRIDES), "deep_heads", f"{len(STRIDES)} flags, one per YOLO layer")
    need(cfg.split in ("chunk", "even_odd"), "split", "'chunk' or 'even_odd'")
