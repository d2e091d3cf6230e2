"""Every knob of a YOLO-on-RD detector (with or without the multi-representation Adapter).

`arch` picks the base: 'v8' (yolov8.yaml, any scale below), 'v9' (ultralytics' yolov9t.yaml, scale
't' only: its widths are written out) or 'v10' (yolov10n.yaml, scale 'n' only: the same multipliers
as yolov8n); architectures.py maps each to its backbone, neck and head. The Adapter's fields below
hold for all three: its Exchangers follow backbone layers 2-8 on each (see backbone_v9.py,
backbone_v10.py).

Scales from ultralytics/ultralytics:ultralytics/cfg/models/v8/yolov8.yaml ([depth, width,
max_channels]); widths are make_divisible(min(c, max_channels) * width, 8) and repeats
max(round(n * depth), 1) for n > 1 (`nn/tasks.py` parse_model).

The Adapter (arXiv paper in ../shared/papers/yolov8_adapter_nas_rd.txt, Sec. 3.3; no public code):
what the paper leaves open is a field here. Defaults and why:
- `stem_widths` (32, 64, 128), `stem_strides` (2, 2, 1): three 3x3 Convs, so the auxiliary
  branch meets the backbone at stride 4 (after its first two blocks) with 128 channels. The
  branch is light: after the Stem it has no convs of its own, only the Exchangers' fusions,
  and it stays at the Stem's width and resolution (an Exchanger "adjusts its width to align
  with backbone and Stem outputs", Sec. 3.4). These widths are what the paper's parameter counts
  point to (Table 7: the Stem adds ~0.09 M, four mode-1 Exchangers ~0.08 M, three mode-2 ~0.06 M):
  here 0.093 M, 0.075 M and 0.068 M: 3,248,056 in all at nc = 6, about 3.242 M with the BNs
  folded into the convs (paper 3.24 M; see paper.py on which convention its counts use).
- `exchanger_positions` (2, ..., 8): the ultralytics backbone layer after which each Exchanger
  runs. "The first two blocks primarily extract low-level features ... starting from the third
  block, each block incorporates features from the Adapter": layers 0-1 are the two stride-2
  Convs, and 2-8 are the seven blocks up to the last C2f (SPPF follows the last Exchanger).
- `adapter_layout` (1, 2, 1, 2, 1, 2, 1): mode 1 = the backbone's features are primary, mode 2 =
  the auxiliary branch's (the paper implies the alternation; Table 7 counts four mode-1 ones).
- `fusion` 1 | 2 | 3, one for all or one per Exchanger (Table 6): see adapter.py.

Elastic widths (the paper's Table 1 search space, Sec. 3.4; YOLOv8 bases only): a subnet of the
one-shot search is an ordinary config with these ratios, trained stand-alone like any other.
- `backbone_width_ratios`, one per backbone block 1-5, a block being a stride stage of
  yolov8.yaml (BACKBONE_BLOCKS: layer 0; layers 1-2; 3-4; 5-6; 7-9 with SPPF);
- `neck_width_ratios`, one per pyramid level (P3, P4, P5: the paper's "Neck & Head Block 1-3";
  NECK_LEVELS maps the neck layers, the stride-2 Conv going to the level it produces), applied to
  that level's Detect branches too (their widths from the full model's first level, scaled);
- the Stem's widths are `stem_widths` themselves (the search scales them).
A width is make_divisible(full width x ratio, 8); at ratio 1 it is the full width.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .layout import FUSIONS, MODES, SEARCHABLE, make_divisible, scaled_width

# ultralytics yolov8.yaml `scales`: depth multiple, width multiple, max channels
SCALES: dict[str, tuple[float, float, int]] = {
    "n": (0.33, 0.25, 1024),
    "s": (0.33, 0.50, 1024),
    "m": (0.67, 0.75, 768),
    "l": (1.00, 1.00, 512),
    "x": (1.00, 1.25, 512),
}
# RADDet's six classes (ZhangAoCanada/RADDet config.json); models/ may not import data/, so the
# tuple is repeated here (data/rd/classes.py RD_CLASSES holds the same names in the same order).
RADDET_CLASSES = ("person", "bicycle", "car", "motorcycle", "bus", "truck")
REPRESENTATIONS = {"heat": 3, "gray": 1}  # input name -> channels (pseudo-colour heatmap, grayscale)
STRIDES = (8, 16, 32)
BACKBONE_BLOCKS = (0, 1, 1, 2, 2, 3, 3, 4, 4, 4)  # yolov8 backbone layer -> searchable block (stride stage)
NECK_LEVELS = {12: 1, 15: 0, 16: 1, 18: 1, 19: 2, 21: 2}  # yolov8 neck layer -> pyramid level (P3, P4, P5)
BACKBONE_LAYERS = 10  # ultralytics layers 0-9 (Conv, Conv, C2f, Conv, C2f, Conv, C2f, Conv, C2f, SPPF)
# The base detector: 'v8' yolov8.yaml (scales n/s/m/l/x), 'v9' yolov9t.yaml (GELAN, scale 't' only),
# 'v10' yolov10n.yaml (scale 'n' only); value = (scales built, backbone layers). See architectures.py.
ARCHS: dict[str, tuple[tuple[str, ...], int]] = {
    "v8": (tuple(SCALES), BACKBONE_LAYERS),
    "v9": (("t",), 10),  # 0-9: Conv, Conv, ELAN1, AConv, RepNCSPELAN4 x3 with AConv between, SPPELAN
    "v10": (("n",), 11),  # 0-10: yolov8's 0-9 with SCDown at 5 and 7, then PSA
}


# The assigner's small-box rule (below, widened_to): ultralytics 8.4.190's (every GT side under
# 16 px widened to 16 px), and the earlier one (only sides under 8 px widened) that the first shipped
# weights, docs/range-doppler.md's v1 tables and the NAS records were trained with before issue 49,
# kept so that their commands reproduce them.
REFERENCE_SMALL_SIDE = (16.0, 16.0)
EARLIER_SMALL_SIDE = (8.0, 16.0)


@dataclasses.dataclass(frozen=True)
class YoloRDConfig:
    name: str = "yolov8n"
    arch: str = "v8"  # 'v8' | 'v9' | 'v10' (ARCHS)
    scale: str = "n"
    classes: tuple[str, ...] = RADDET_CLASSES
    reg_max: int = 16
    box_bias: float = 1.0  # Detect.bias_init of ultralytics 8.0-8.3 (YOLOv8's releases); newer code uses 2.0
    backbone_input: str = "heat"  # 'heat' | 'gray'
    adapter_input: str | None = None  # 'gray' | 'heat' | None (no Adapter)
    adapter_layout: tuple[int, ...] = (1, 2, 1, 2, 1, 2, 1)
    exchanger_positions: tuple[int, ...] = (2, 3, 4, 5, 6, 7, 8)
    fusion: int | tuple[int, ...] = 1
    stem_widths: tuple[int, ...] = (32, 64, 128)
    stem_strides: tuple[int, ...] = (2, 2, 1)
    attention_reduction: int = 32  # Coordinate Attention: mip = max(attention_min_mip, C // reduction)
    attention_min_mip: int = 8
    # training: the assigner's small-box rule (assigner.py): GT sides under 16 px count as 16 px for
    # the anchor-inside test, as ultralytics 8.4.190's TaskAlignedAssigner does (stride_val = stride[1]
    # = 16). On the synthetic RD benchmark at 256x64, half of the GTs (Doppler extent: median 4 px)
    # hold no stride-8 anchor centre and would never be learned without it (measured: 63 of 126 in one
    # batch of 64). The v1 tables of docs/range-doppler.md and the NAS records were trained with
    # EARLIER_SMALL_SIDE (their records pin it). None: the YOLOv8-era rule (no widening).
    assign_small_side: tuple[float, float] | None = REFERENCE_SMALL_SIDE
    backbone_width_ratios: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0, 1.0)  # elastic widths (module docstring)
    neck_width_ratios: tuple[float, ...] = (1.0, 1.0, 1.0)
    notes: str = ""

    def __post_init__(self):
        validate(self)

    @property
    def num_classes(self) -> int:
        return len(self.classes)

    @property
    def depth_multiple(self) -> float:
        return SCALES[self.scale][0]

    @property
    def width_multiple(self) -> float:
        return SCALES[self.scale][1]

    @property
    def max_channels(self) -> int:
        return SCALES[self.scale][2]

    def width(self, channels: int) -> int:
        """A yolov8.yaml width at this scale."""
        return make_divisible(min(channels, self.max_channels) * self.width_multiple, 8)

    def backbone_width(self, layer: int, channels: int) -> int:
        """Backbone layer `layer`'s width: the yaml width at this scale, times its block's ratio."""
        full = self.width(channels)
        return scaled_width(full, self.backbone_width_ratios[BACKBONE_BLOCKS[layer]]) if self.arch == "v8" else full

    def neck_width(self, layer: int, channels: int) -> int:
        """Neck layer `layer`'s width: the yaml width at this scale, times its level's ratio."""
        full = self.width(channels)
        return scaled_width(full, self.neck_width_ratios[NECK_LEVELS[layer]]) if self.arch == "v8" else full

    @property
    def elastic(self) -> bool:
        """Whether any width ratio differs from 1 (a searched subnet rather than a scale of the yaml)."""
        return any(r != 1 for r in tuple(self.backbone_width_ratios) + tuple(self.neck_width_ratios))

    def repeats(self, n: int) -> int:
        """A yolov8.yaml repeat count at this scale."""
        return max(round(n * self.depth_multiple), 1) if n > 1 else n

    @property
    def backbone_layers(self) -> int:
        """How many ultralytics backbone layers this arch has (Exchangers may follow any of them)."""
        return ARCHS[self.arch][1]

    @property
    def has_adapter(self) -> bool:
        return self.adapter_input is not None

    @property
    def fusions(self) -> tuple[int, ...]:
        """The fusion option of each Exchanger."""
        f = self.fusion
        return tuple(f) if isinstance(f, (tuple, list)) else (f,) * len(self.adapter_layout)

    @property
    def input_names(self) -> tuple[str, ...]:
        """The representations the network reads, backbone first."""
        names = (self.backbone_input,)
        return names + ((self.adapter_input,) if self.has_adapter and self.adapter_input != self.backbone_input else ())

    @property
    def strides(self) -> tuple[int, ...]:
        return STRIDES

    @property
    def outputs_per_anchor(self) -> int:
        """Channels of each head map: 4 sides x reg_max DFL bins, then the class logits."""
        return 4 * self.reg_max + self.num_classes

    def build(self):
        from .net import YoloRDNet  # here: the net's modules load only when a network is built

        return YoloRDNet(self)

    def dummy_inputs(self, batch_size: int = 1, seed: int = 0, occupancy: float | None = None,
                     hw: tuple[int, int] = (256, 64)) -> dict:
        """Random maps in [0, 1] for every representation the network reads: {name: (B, H, W, C)}.
        (`occupancy`, the point families' share of filled pillars, means nothing for a map.)"""
        rng = np.random.default_rng(seed)
        return {name: rng.random((batch_size, *hw, REPRESENTATIONS[name]), dtype=np.float32)
                for name in self.input_names}


def validate(cfg: YoloRDConfig) -> None:
    """Fail early, naming the field and what was expected."""
    def need(ok, field, expected):
        if not ok:
            raise ValueError(f"{cfg.name}: {field}={getattr(cfg, field)!r}; expected {expected}")

    need(cfg.arch in ARCHS, "arch", f"one of {tuple(ARCHS)}")
    need(cfg.scale in ARCHS[cfg.arch][0], "scale", f"one of {ARCHS[cfg.arch][0]} for arch {cfg.arch!r}")
    need(len(cfg.classes) >= 1, "classes", "at least one class")
    need(int(cfg.reg_max) >= 2, "reg_max", "an integer >= 2 (the DFL bins)")
    need(cfg.backbone_input in REPRESENTATIONS, "backbone_input", f"one of {tuple(REPRESENTATIONS)}")
    need(cfg.adapter_input is None or cfg.adapter_input in REPRESENTATIONS, "adapter_input",
         f"None or one of {tuple(REPRESENTATIONS)}")
    for field, n in (("backbone_width_ratios", 5), ("neck_width_ratios", 3)):
        ratios = tuple(getattr(cfg, field))
        need(len(ratios) == n and all(0 < float(r) <= 1 for r in ratios), field, f"{n} ratios in (0, 1]")
    for field in ("backbone_width_ratios", "neck_width_ratios"):
        need(cfg.arch == "v8" or all(r == 1 for r in getattr(cfg, field)), field, "all 1 unless arch is 'v8' "
             "(elastic widths are built for the YOLOv8 bases, the paper's search space)")
    if not cfg.has_adapter:
        return
    n = len(cfg.adapter_layout)
    need(n >= 1 and all(m in MODES for m in cfg.adapter_layout), "adapter_layout", f"modes from {MODES}")
    pos = tuple(cfg.exchanger_positions)
    layers = cfg.backbone_layers
    need(len(pos) == n and all(0 <= p < layers for p in pos) and all(a < b for a, b in zip(pos, pos[1:])),
         "exchanger_positions", f"{n} increasing backbone layer indices in 0..{layers - 1}")
    need(len(cfg.fusions) == n and all(f in FUSIONS + (SEARCHABLE,) for f in cfg.fusions), "fusion",
         f"one option from {FUSIONS} (or {SEARCHABLE}: searchable), or one per Exchanger ({n})")
    need(len(cfg.stem_widths) == len(cfg.stem_strides) >= 1 and all(int(w) >= 1 for w in cfg.stem_widths)
         and all(int(s) >= 1 for s in cfg.stem_strides), "stem_widths", "as many positive widths as stem_strides")
    need(int(cfg.attention_reduction) >= 1 and int(cfg.attention_min_mip) >= 1, "attention_reduction",
         "positive reduction and min_mip")
